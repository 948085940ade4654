#pragma once
// The implicit FEM step's own options: the kinematic nodes' stages and start, and plasticitynet's
// elastic predictor. Keys of a scene's "integrator" block beside the solver's
// (solver/implicit_options.hpp); declared once, in fem_option_fields().
#include <string>
#include <vector>

#include "pnet/solver/option_field.hpp"

namespace pnet {

struct FemOptions {
    // The most extra solves per step that move kinematic nodes (the plate) to targets that contact's
    // CCD kept them from at the start.
    int max_kinematic_stages = 20;
    // With kinematic nodes: the start of a step when CCD holds v* back: "scaled" (v* as far as CCD
    // allows, the kinematic nodes then led to their targets in stages) or "last_velocity" (the free
    // nodes at their last velocities with the kinematic nodes on their targets, where that is
    // intersection-free; else "scaled").
    std::string kinematic_start = "scaled";
    // plasticitynet with the Newton outer iteration: first solve the step with the elastic energy and
    // start from there (always done under the fixed point, whose first F0 must be near the solution).
    bool fem_predictor = true;
};

/// Every key of FemOptions, in the order --help lists them.
inline const std::vector<OptionField<FemOptions>>& fem_option_fields() {
    using O = FemOptions;
    static const std::vector<OptionField<O>> fields = {
        integer_option("max_kinematic_stages", nullptr, 0, 1000000, &O::max_kinematic_stages,
                       "FEM: the most extra solves per step that lead kinematic nodes to their targets"),
        choice_option("kinematic_start", "--kinematic-start", {"scaled", "last_velocity"}, &O::kinematic_start,
                      "FEM with kinematic nodes: the start of a step that CCD holds back"),
        boolean_option("fem_predictor", nullptr, &O::fem_predictor,
                       "FEM plasticitynet under newton: start from the elastic energy's solution"),
    };
    return fields;
}

}  // namespace pnet
