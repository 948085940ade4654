#pragma once
// The coupled MPM-FEM step's own option, its linear solve: a key of a scene's "integrator" block
// beside the solver's and MPM's (solver/implicit_options.hpp, mpm/mpm_options.hpp); declared once, in
// coupling_option_fields().
#include <string>
#include <vector>

#include "pnet/solver/option_field.hpp"

namespace pnet {

struct CouplingOptions {
    // The linear solve of the coupled Newton iterations, "block" (PCG with Jacobi on the grid and an
    // exact Cholesky solve of the FEM block) or "cholesky" (CHOLMOD on the whole assembled Hessian);
    // coupling/coupled_potential.hpp.
    std::string coupled_solver = "block";
};

/// Every key of CouplingOptions.
inline const std::vector<OptionField<CouplingOptions>>& coupling_option_fields() {
    using O = CouplingOptions;
    static const std::vector<OptionField<O>> fields = {
        choice_option("coupled_solver", nullptr, {"block", "cholesky"}, &O::coupled_solver,
                      "MPM-FEM coupling's linear solve: PCG with an exact FEM block, or CHOLMOD on the whole Hessian"),
    };
    return fields;
}

}  // namespace pnet
