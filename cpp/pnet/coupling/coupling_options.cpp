#include "pnet/coupling/coupling_options.hpp"

namespace pnet {

const std::vector<OptionField<CouplingOptions>>& coupling_option_fields() {
    using O = CouplingOptions;
    static const std::vector<OptionField<O>> fields = {
        choice_option("coupled_solver", nullptr, {"block", "cholesky"}, &O::coupled_solver,
                      "MPM-FEM coupling's linear solve: PCG with an exact FEM block, or CHOLMOD on the whole Hessian"),
    };
    return fields;
}

}  // namespace pnet
