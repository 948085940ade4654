#pragma once
// What an MPM step (explicit or implicit; the particles of a coupled step) adds to the statistics of
// any step (solver/step_stats.hpp).
#include <cstddef>

#include "pnet/solver/step_stats.hpp"

namespace pnet {

struct MpmStepFields {
    std::size_t clamped = 0;        // particles pulled back inside the domain
    bool advection_capped = false;  // implicit MPM, coupling: the advection limit cut dt below the scene's
    // implicit MPM, coupling: the Coulomb floor's one solve failed and the passes solved the step again
    // (floor_friction_solve "auto", floor_friction_passes.hpp)
    bool floor_friction_retried = false;
    // implicit MPM, coupling: the solve from the Newton start's prediction (MpmOptions::newton_start) ended
    // far from converged or failed, and the step was solved again from v* (step_predictor.hpp)
    bool prediction_rejected = false;

    template <typename F>
    static void for_each_field(F&& f) {
        f(StepField{"clamped", "clamped"}, &MpmStepFields::clamped);
        f(StepField{"advection_capped", "advection_capped"}, &MpmStepFields::advection_capped);
        f(StepField{"floor_friction_retried", "floor_friction_retried"}, &MpmStepFields::floor_friction_retried);
        f(StepField{"prediction_rejected", "prediction_rejected"}, &MpmStepFields::prediction_rejected);
    }
};

/// What an MPM integrator's step returns.
using MpmStepStats = StepStatsWith<MpmStepFields>;

}  // namespace pnet
