#pragma once
// What a step with IPC contact (FEM meshes, their coupling with particles) adds to the statistics of
// any step (solver/step_stats.hpp): steps.csv's contact columns, in FEM and coupled runs.
#include <cstddef>

#include "pnet/solver/step_stats.hpp"

namespace pnet {

struct ContactStepFields {
    // CCD queries of the step (line search and starts) and how many shortened a step.
    int ccd_queries = 0, ccd_limited = 0;
    // Contact pairs closer than dhat and the smallest pair distance (m) at the end of the step.
    std::size_t contact_pairs = 0;
    double min_distance = 0.0;
    double broad_phase_seconds = 0.0, ccd_seconds = 0.0;  // 3D: parts of wall_seconds

    template <typename F>
    static void for_each_field(F&& f) {
        f(StepField{"ccd_queries", "ccd_queries", true}, &ContactStepFields::ccd_queries);
        f(StepField{"ccd_limited", "ccd_limited", true}, &ContactStepFields::ccd_limited);
        f(StepField{"contact_pairs", "contact_pairs", true}, &ContactStepFields::contact_pairs);
        f(StepField{"min_distance_m", "min_distance", true}, &ContactStepFields::min_distance);
        f(StepField{"broad_phase_s", "broad_phase_s", true}, &ContactStepFields::broad_phase_seconds);
        f(StepField{"ccd_s", "ccd_s", true}, &ContactStepFields::ccd_seconds);
    }
};

}  // namespace pnet
