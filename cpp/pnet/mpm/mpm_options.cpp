#include "pnet/mpm/mpm_options.hpp"

namespace pnet {

const std::vector<OptionField<MpmOptions>>& mpm_option_fields() {
    using O = MpmOptions;
    static const std::vector<OptionField<O>> fields = {
        number_option("advection_cfl", "--advection-cfl", 0.0, false, 1.0, false, &O::advection_cfl,
                      "MPM: cap a step so that no particle moves more than this many cells (0: off)"),
        choice_option("floor_friction_solve", "--floor-friction-solve", {"auto", "newton", "passes"},
                      &O::floor_friction_solve,
                      "a Coulomb floor's friction: in the one Newton solve's residual and Jacobian (newton), or "
                      "three majorize-minimize passes (passes); auto: newton in 2D under the work line search "
                      "(return_map; a step it fails solved again by passes), else passes"),
        choice_option("linear_solver", nullptr, {"pcg", "cholesky"}, &O::linear_solver,
                      "MPM's linear solve: matrix-free PCG or CHOLMOD on the assembled Hessian"),
    };
    return fields;
}

}  // namespace pnet
