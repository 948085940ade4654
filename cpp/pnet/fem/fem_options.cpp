#include "pnet/fem/fem_options.hpp"

namespace pnet {

const std::vector<OptionField<FemOptions>>& fem_option_fields() {
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
