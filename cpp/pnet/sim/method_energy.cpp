#include "pnet/sim/method_energy.hpp"

#include <stdexcept>

#include "pnet/energy/analytic_elastoplastic.hpp"
#include "pnet/energy/return_mapping_energy.hpp"

namespace pnet {

template <int dim>
MethodEnergy<dim> make_method_energy(const IntegratorSettings& settings, const std::vector<Material<dim>>& materials,
                                     const std::vector<std::shared_ptr<const ModelFile>>& models,
                                     const std::vector<std::string>& where) {
    MethodEnergy<dim> out;
    std::vector<std::string> context;
    const ImplicitOptions& o = settings.implicit;
    switch (settings.method()) {
        case Method::Lagged: out.energy = std::make_unique<ElasticParticleEnergy<dim>>(materials); break;
        case Method::ReturnMap:
            out.energy = std::make_unique<ReturnMappingEnergy<dim>>(materials, o.tangent_damping);
            break;
        case Method::Analytic:
            for (const std::string& w : where) context.push_back(w + ".material");
            out.energy = std::make_unique<AnalyticElastoplasticEnergy<dim>>(materials, context, o.analytic_regularizer);
            break;
        case Method::PlasticityNet: {
            for (const std::string& w : where) context.push_back(w + ".model");
            std::vector<std::shared_ptr<const ModelFile>> per_object = models;
            per_object.resize(materials.size());
            std::vector<double> w;
            for (const Material<dim>& m : materials) w.push_back(o.resolved_regularizer_weight(m.description().plasticity));
            auto neural = std::make_unique<NeuralParticleEnergy<dim>>(per_object, materials, context, w,
                                                                      o.neural_hessian<dim>(), o.tangent_damping,
                                                                      o.network_hessian_precision());
            for (std::size_t k = 0; k < materials.size(); ++k)
                out.return_maps.push_back(o.learned_return_map ? neural->object_energy(k).learned_return_map() : nullptr);
            out.energy = std::move(neural);
            break;
        }
        case Method::Explicit:
            throw std::invalid_argument("make_method_energy: explicit integration has no energy to minimize");
    }
    return out;
}

template MethodEnergy<2> make_method_energy<2>(const IntegratorSettings&, const std::vector<Material<2>>&,
                                               const std::vector<std::shared_ptr<const ModelFile>>&,
                                               const std::vector<std::string>&);
template MethodEnergy<3> make_method_energy<3>(const IntegratorSettings&, const std::vector<Material<3>>&,
                                               const std::vector<std::shared_ptr<const ModelFile>>&,
                                               const std::vector<std::string>&);

}  // namespace pnet
