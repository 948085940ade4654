#include "pnet/solver/integrators.hpp"

#include <stdexcept>

#include "pnet/energy/analytic_elastoplastic.hpp"
#include "pnet/energy/return_mapping_energy.hpp"
#include "pnet/solver/method_energy.hpp"

namespace pnet {

namespace {

// The energy of each implicit integrator (solver/method_energy.hpp), beside its entry below.

/// The objects' places with a suffix: "scene.json: objects[0]" -> "scene.json: objects[0].model".
std::vector<std::string> places(const std::vector<std::string>& where, const std::string& suffix) {
    std::vector<std::string> out;
    for (const std::string& w : where) out.push_back(w + suffix);
    return out;
}

template <int dim>
MethodEnergy<dim> plasticitynet_energy(const EnergyRequest<dim>& r) {
    const ImplicitOptions& o = r.options;
    std::vector<std::shared_ptr<const ModelFile>> per_object = r.models;
    per_object.resize(r.materials.size());
    std::vector<double> w;
    for (const Material<dim>& m : r.materials) w.push_back(o.resolved_regularizer_weight(m.description().plasticity));
    auto neural = std::make_unique<NeuralParticleEnergy<dim>>(per_object, r.materials, places(r.where, ".model"), w,
                                                              o.neural_hessian<dim>(), o.tangent_damping,
                                                              o.network_hessian_precision(), o.network_reuse);
    MethodEnergy<dim> out;
    for (std::size_t k = 0; k < r.materials.size(); ++k)
        out.return_maps.push_back(o.learned_return_map ? neural->object_energy(k).learned_return_map() : nullptr);
    out.energy = std::move(neural);
    return out;
}

template <int dim>
MethodEnergy<dim> return_map_energy(const EnergyRequest<dim>& r) {
    MethodEnergy<dim> out;
    out.energy = std::make_unique<ReturnMappingEnergy<dim>>(r.materials, r.options.tangent_damping);
    return out;
}

template <int dim>
MethodEnergy<dim> lagged_energy(const EnergyRequest<dim>& r) {
    MethodEnergy<dim> out;
    out.energy = std::make_unique<ElasticParticleEnergy<dim>>(r.materials);
    return out;
}

template <int dim>
MethodEnergy<dim> analytic_energy(const EnergyRequest<dim>& r) {
    MethodEnergy<dim> out;
    out.energy = std::make_unique<AnalyticElastoplasticEnergy<dim>>(r.materials, places(r.where, ".material"),
                                                                    r.options.analytic_regularizer);
    return out;
}

}  // namespace

const std::vector<IntegratorInfo>& integrators() {
    static const std::vector<IntegratorInfo> list = {
        {Method::Explicit, "explicit",
         "symplectic Euler: the return mapping's stress as a force, at the CFL step (or a given dt); the ground "
         "truth",
         /*implicit=*/false, /*reads_models=*/false, /*particles=*/true, /*meshes=*/true, /*references=*/false, "cfl",
         0.0},
        {Method::PlasticityNet, "plasticitynet",
         "backward Euler on the learned energy (eqs. 8, 10, 11): the network's value judges the line search and its "
         "Hessian (+ w mu I, projected) is Newton's, at every iteration; the reference F0 follows F(v) (outer "
         "iteration newton) or is iterated by full solves (fixed_point)",
         true, true, true, true, true,
         "outer_iteration, hessian (auto = network), regularizer_weight, fixed_point_*, learned_return_map", 0.8,
         /*predicts_newton_start=*/false, plasticitynet_energy<2>, plasticitynet_energy<3>},
        {Method::ReturnMap, "return_map",
         "backward Euler with the return mapping's stress and its consistent tangent (skew part kept for "
         "non-associative flow), Newton with the work line search; the classical implicit solver, no model file",
         true, false, true, true, true, "tangent_damping", 0.1, /*predicts_newton_start=*/true, return_map_energy<2>,
         return_map_energy<3>},
        {Method::Lagged, "lagged",
         "backward Euler on the elastic energy alone; the return mapping after the step (Ziran, HOT)", true, false,
         true, true, false, "", 0.5, /*predicts_newton_start=*/true, lagged_energy<2>, lagged_energy<3>},
        {Method::Analytic, "analytic",
         "FEM, StVK-Hencky + von Mises: backward Euler on the closed-form elastoplastic energy (ECI)", true, false,
         false, true, false, "analytic_regularizer", 0.5, /*predicts_newton_start=*/false, analytic_energy<2>,
         analytic_energy<3>},
    };
    return list;
}

PlasticityNetDefaults plasticitynet_defaults(PlasticityModel family) {
    switch (family) {
        case PlasticityModel::VonMises: return {"newton", 0.05};
        case PlasticityModel::DruckerPrager: return {"newton", 0.1};
        case PlasticityModel::CamClay:
        case PlasticityModel::None: break;
    }
    return {"newton", 1.0};
}

template <int dim>
MethodEnergy<dim> make_method_energy(Method method, const EnergyRequest<dim>& request) {
    const IntegratorInfo& info = integrator_info(method);
    const EnergyFactory<dim> factory = [&] {
        if constexpr (dim == 2)
            return info.energy_2d;
        else
            return info.energy_3d;
    }();
    if (!factory)
        throw std::invalid_argument(std::string("make_method_energy: ") + info.name + " has no energy to minimize");
    return factory(request);
}

template MethodEnergy<2> make_method_energy<2>(Method, const EnergyRequest<2>&);
template MethodEnergy<3> make_method_energy<3>(Method, const EnergyRequest<3>&);

const IntegratorInfo& integrator_info(Method method) {
    for (const IntegratorInfo& info : integrators())
        if (info.method == method) return info;
    throw std::logic_error("integrator_info: a method without an entry");
}

std::string integrator_names(bool particles, bool meshes) {
    std::vector<const char*> names;
    for (const IntegratorInfo& info : integrators())
        if ((particles && info.particles) || (meshes && info.meshes)) names.push_back(info.name);
    std::string out;
    for (std::size_t k = 0; k < names.size(); ++k) {
        if (k > 0) out += k + 1 == names.size() ? " or " : ", ";
        out += names[k];
    }
    return out;
}

bool is_integrator(const std::string& name) {
    for (const IntegratorInfo& info : integrators())
        if (name == info.name) return true;
    return false;
}

Method parse_integrator(const std::string& name, const std::string& context) {
    for (const IntegratorInfo& info : integrators())
        if (name == info.name) return info.method;
    throw std::invalid_argument((context.empty() ? "" : context + ": ") + "unknown integrator \"" + name +
                                "\" (expected " + integrator_names() + ")");
}

}  // namespace pnet
