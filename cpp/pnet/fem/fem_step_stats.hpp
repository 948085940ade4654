#pragma once
// What a FEM step adds to the statistics of any step (solver/step_stats.hpp): its predictor, its
// kinematic stages, its explicit substeps and its contact (contact/contact_step_stats.hpp).
#include "pnet/contact/contact_step_stats.hpp"
#include "pnet/solver/step_stats.hpp"

namespace pnet {

struct FemStepFields {
    // The Newton iterations of the elastic predictor (FemOptions::fem_predictor), which are part of
    // newton_iterations and evaluate no network.
    int predictor_iterations = 0;
    // With kinematic nodes: extra solves that moved them toward their targets, and whether they got there.
    int kinematic_stages = 0;
    bool kinematic_reached = true;
    int substeps = 1;  // explicit: substeps the barrier's stability needed

    template <typename F>
    static void for_each_field(F&& f) {
        f(StepField{"predictor_iterations", "predictor_iterations", true}, &FemStepFields::predictor_iterations);
        f(StepField{"kinematic_stages", "kinematic_stages", true}, &FemStepFields::kinematic_stages);
        f(StepField{"kinematic_reached", "kinematic_reached", true}, &FemStepFields::kinematic_reached);
        f(StepField{"substeps", "substeps", true}, &FemStepFields::substeps);
    }
};

/// What a FEM integrator's step returns.
using FemStepStats = StepStatsWith<FemStepFields, ContactStepFields>;

}  // namespace pnet
