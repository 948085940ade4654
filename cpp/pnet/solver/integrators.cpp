#include "pnet/solver/integrators.hpp"

#include <stdexcept>

namespace pnet {

const std::vector<IntegratorInfo>& integrators() {
    static const std::vector<IntegratorInfo> list = {
        {Method::Explicit, "explicit",
         "symplectic Euler: the return mapping's stress as a force, at the CFL step (or a given dt); the ground "
         "truth",
         /*implicit=*/false, /*reads_models=*/false, /*particles=*/true, /*meshes=*/true, /*references=*/false,
         "cfl", 0.0},
        {Method::PlasticityNet, "plasticitynet",
         "backward Euler on the learned energy (eqs. 8, 10, 11): the network's value judges the line search and its "
         "Hessian (+ w mu I, projected) is Newton's, at every iteration; the reference F0 follows F(v) (outer "
         "iteration newton) or is iterated by full solves (fixed_point)",
         true, true, true, true, true,
         "outer_iteration, hessian (auto = network), regularizer_weight, fixed_point_*, learned_return_map", 0.8},
        {Method::ReturnMap, "return_map",
         "backward Euler with the return mapping's stress and its consistent tangent (skew part kept for "
         "non-associative flow), Newton with the work line search; the classical implicit solver, no model file",
         true, false, true, true, true, "tangent_damping", 0.5},
        {Method::Lagged, "lagged",
         "backward Euler on the elastic energy alone; the return mapping after the step (Ziran, HOT)", true, false,
         true, true, false, "", 0.5},
        {Method::Analytic, "analytic",
         "FEM, StVK-Hencky + von Mises: backward Euler on the closed-form elastoplastic energy (ECI)", true, false,
         false, true, false, "analytic_regularizer", 0.5},
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
