#include "pnet/material/material.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "pnet/material/elastoplastic_tangent.hpp"

namespace pnet {

std::string to_string(PlasticityModel model) {
    switch (model) {
        case PlasticityModel::None: return "none";
        case PlasticityModel::DruckerPrager: return "drucker_prager";
        case PlasticityModel::CamClay: return "cam_clay";
        case PlasticityModel::VonMises: return "von_mises";
    }
    return "unknown";
}

PlasticityModel plasticity_model_from_string(const std::string& name) {
    if (name == "none") return PlasticityModel::None;
    if (name == "drucker_prager") return PlasticityModel::DruckerPrager;
    if (name == "cam_clay") return PlasticityModel::CamClay;
    if (name == "von_mises") return PlasticityModel::VonMises;
    throw std::invalid_argument("unknown plasticity model '" + name +
                                "' (expected none, drucker_prager, cam_clay or von_mises)");
}

void MaterialDescription::validate() const {
    try {
        auto fail = [](const char* field, double value, const char* expected) {
            std::ostringstream msg;
            msg << field << " = " << value << " must be " << expected;
            throw std::invalid_argument(msg.str());
        };
        if (!std::isfinite(density) || density <= 0.0) fail("density", density, "finite and > 0 (kg/m^3)");
        if (!std::isfinite(initial_hardening)) fail("initial_hardening", initial_hardening, "finite");
        elastic.validate();
        switch (plasticity) {
            case PlasticityModel::None: break;
            case PlasticityModel::DruckerPrager:
                drucker_prager.validate();
                if (elasticity != ElasticityModel::StvkHencky)
                    throw std::invalid_argument("plasticity 'drucker_prager' requires elasticity 'stvk_hencky', got '" +
                                                to_string(elasticity) + "'");
                break;
            case PlasticityModel::CamClay:
                cam_clay.validate();
                if (elasticity != ElasticityModel::NeoHookeanSnow)
                    throw std::invalid_argument(
                        "plasticity 'cam_clay' requires elasticity 'neo_hookean_snow', got '" +
                        to_string(elasticity) + "'");
                break;
            case PlasticityModel::VonMises:
                von_mises.validate();
                if (initial_hardening < 0.0)
                    fail("initial_hardening", initial_hardening, ">= 0 for von_mises (h = tau_Y / (2 mu))");
                break;
        }
    } catch (const std::invalid_argument& e) {
        throw std::invalid_argument("material '" + name + "': " + e.what());
    }
}

MaterialDescription material_preset(const std::string& name) {
    MaterialDescription m;
    m.name = name;
    if (name == "sand") {  // docs/scenes.md, sand_column
        m.density = 2200.0;
        m.elasticity = ElasticityModel::StvkHencky;
        m.elastic = {3.537e5, 0.3};
        m.plasticity = PlasticityModel::DruckerPrager;
        m.drucker_prager.friction_angle_deg = 30.0;
    } else if (name == "snow") {  // docs/scenes.md, snowball
        m.density = 400.0;
        m.initial_hardening = -0.1;
        m.elasticity = ElasticityModel::NeoHookeanSnow;
        m.elastic = {1.4e5, 0.2};
        m.plasticity = PlasticityModel::CamClay;
        m.cam_clay = CamClayParams{45.0, 0.5, 0.3, CamClayVariant::Exact};
    } else if (name == "metal" || name == "metal_nh") {
        m.density = 7800.0;
        m.initial_hardening = 0.05;  // yield at 5% deviatoric Hencky strain
        m.elasticity = name == "metal" ? ElasticityModel::StvkHencky : ElasticityModel::NeoHookeanMetal;
        m.elastic = {1e7, 0.3};
        m.plasticity = PlasticityModel::VonMises;
        m.von_mises.hardening_coefficient = 0.1;
    } else {
        throw std::invalid_argument("unknown material preset '" + name + "' (expected sand, snow, metal or metal_nh)");
    }
    return m;
}

std::vector<std::string> material_preset_names() { return {"sand", "snow", "metal", "metal_nh"}; }

namespace {

template <int dim>
Elasticity<dim> make_elasticity(const MaterialDescription& d) {
    d.validate();
    return Elasticity<dim>(d.elasticity, d.elastic);
}

}  // namespace

double* material_parameter(MaterialDescription& d, const std::string& field) {
    if (field == "elasticity.nu") return &d.elastic.nu;
    switch (d.plasticity) {
        case PlasticityModel::None: break;
        case PlasticityModel::DruckerPrager:
            if (field == "plasticity.friction_angle_deg") return &d.drucker_prager.friction_angle_deg;
            break;
        case PlasticityModel::CamClay:
            if (field == "plasticity.friction_angle_deg") return &d.cam_clay.friction_angle_deg;
            if (field == "plasticity.xi") return &d.cam_clay.xi;
            if (field == "plasticity.beta") return &d.cam_clay.beta;
            break;
        case PlasticityModel::VonMises:
            if (field == "plasticity.hardening_coefficient") return &d.von_mises.hardening_coefficient;
            break;
    }
    return nullptr;
}

const double* material_parameter(const MaterialDescription& d, const std::string& field) {
    return material_parameter(const_cast<MaterialDescription&>(d), field);
}

std::vector<MaterialDifference> constitutive_differences(const MaterialDescription& a, const MaterialDescription& b) {
    std::vector<MaterialDifference> out;
    auto number = [&](const char* field, double x, double y) {
        if (std::abs(x - y) > 1e-9 * std::max(std::abs(x), std::abs(y)))
            out.push_back({field, nlohmann::json(x).dump(), nlohmann::json(y).dump()});
    };
    auto text = [&](const char* field, const std::string& x, const std::string& y) {
        if (x != y) out.push_back({field, "\"" + x + "\"", "\"" + y + "\""});
    };
    text("elasticity.model", to_string(a.elasticity), to_string(b.elasticity));
    number("elasticity.nu", a.elastic.nu, b.elastic.nu);
    text("plasticity.model", to_string(a.plasticity), to_string(b.plasticity));
    if (a.plasticity != b.plasticity) return out;
    switch (a.plasticity) {
        case PlasticityModel::None: break;
        case PlasticityModel::DruckerPrager:
            number("plasticity.friction_angle_deg", a.drucker_prager.friction_angle_deg,
                   b.drucker_prager.friction_angle_deg);
            break;
        case PlasticityModel::CamClay:
            number("plasticity.friction_angle_deg", a.cam_clay.friction_angle_deg, b.cam_clay.friction_angle_deg);
            number("plasticity.xi", a.cam_clay.xi, b.cam_clay.xi);
            number("plasticity.beta", a.cam_clay.beta, b.cam_clay.beta);
            text("plasticity.variant", to_string(a.cam_clay.variant), to_string(b.cam_clay.variant));
            break;
        case PlasticityModel::VonMises:
            number("plasticity.hardening_coefficient", a.von_mises.hardening_coefficient,
                   b.von_mises.hardening_coefficient);
            break;
    }
    return out;
}

template <int dim>
Material<dim>::Material(const MaterialDescription& description)
    : description_(description), elasticity_(make_elasticity<dim>(description)) {
    switch (description_.plasticity) {
        case PlasticityModel::None: break;
        case PlasticityModel::DruckerPrager:
            plasticity_.template emplace<DruckerPrager<dim>>(description_.drucker_prager, elasticity_);
            break;
        case PlasticityModel::CamClay:
            plasticity_.template emplace<CamClay<dim>>(description_.cam_clay, elasticity_);
            break;
        case PlasticityModel::VonMises:
            plasticity_.template emplace<VonMises<dim>>(description_.von_mises, elasticity_);
            break;
    }
}

template <int dim>
ReturnResult<dim> Material<dim>::return_map(const Vec<dim>& Sigma, double hardening) const {
    if (!std::isfinite(hardening)) {
        std::ostringstream msg;
        msg << "material '" << description_.name << "': hardening state is not finite: " << hardening;
        throw std::invalid_argument(msg.str());
    }
    return std::visit(
        [&](const auto& model) -> ReturnResult<dim> {
            using Model = std::decay_t<decltype(model)>;
            if constexpr (std::is_same_v<Model, std::monostate>)
                return {Sigma, hardening, ReturnBranch::Elastic};
            else
                return model.project(Sigma, hardening);
        },
        plasticity_);
}

template <int dim>
double Material<dim>::yield_function(const Vec<dim>& Sigma, double hardening) const {
    return yield(Sigma, hardening, false);
}

template <int dim>
double Material<dim>::yield_scale(const Vec<dim>& Sigma, double hardening) const {
    return yield(Sigma, hardening, true);
}

template <int dim>
double Material<dim>::yield(const Vec<dim>& Sigma, double hardening, bool scale) const {
    return std::visit(
        [&](const auto& model) -> double {
            using Model = std::decay_t<decltype(model)>;
            if constexpr (std::is_same_v<Model, std::monostate>) {
                return 0.0;
            } else if constexpr (std::is_same_v<Model, DruckerPrager<dim>>) {  // a function of tau alone
                const Vec<dim> tau = elasticity_.tau(Sigma);
                return scale ? model.yield_scale(tau) : model.yield_function(tau);
            } else {
                return scale ? model.yield_scale(Sigma, hardening) : model.yield_function(Sigma, hardening);
            }
        },
        plasticity_);
}

template <int dim>
Mat<dim> Material<dim>::elastoplastic_stress(const Mat<dim>& F, double hardening) const {
    return elastoplastic_stress(clamped_svd<dim>(F), hardening);
}

template <int dim>
Mat<dim> Material<dim>::elastoplastic_stress(const PolarSVD<dim>& svd, double hardening) const {
    if (const auto* cam_clay = std::get_if<CamClay<dim>>(&plasticity_);
        cam_clay && cam_clay->params().variant == CamClayVariant::Exact && std::isfinite(hardening))
        // The return-mapped stress without Z, its log or the snow elasticity's expm1 (CamClay::project_tau).
        return svd.compose(cam_clay->project_tau(svd.Sigma, cam_clay->p0(hardening)).cwiseQuotient(svd.Sigma));
    // Drucker-Prager: the projected strain alone (the stress needs log Z, which project() would exp into Z).
    const auto* drucker_prager = std::get_if<DruckerPrager<dim>>(&plasticity_);
    const Vec<dim> log_Z = drucker_prager && std::isfinite(hardening)
                               ? drucker_prager->project_strain(svd.Sigma.array().log().matrix())
                               : return_map(svd.Sigma, hardening).hencky_strain();
    return svd.compose(elasticity_.tau_of_strain(log_Z).cwiseQuotient(svd.Sigma));
}

template <int dim>
Tensor4<dim> Material<dim>::elastoplastic_tangent(const PolarSVD<dim>& svd, double hardening, bool project_psd,
                                                  bool keep_skew) const {
    if (const auto* cam_clay = std::get_if<CamClay<dim>>(&plasticity_)) {
        // Inside the yield surface the return mapping is the identity, so the tangent is the elastic
        // one in closed form (one-sided within the stencil's step of the surface, as the mapping's
        // branch there): the stencil's 2d + 1 projections, each a few exp/log/pow and the snow
        // elasticity's expm1, only where the point yields.
        if (cam_clay->project(svd.Sigma, hardening).branch == ReturnBranch::Elastic)
            return elasticity_.dPdF(svd, project_psd);
        if (cam_clay->params().variant == CamClayVariant::Exact) {  // the stencil on tau directly
            constexpr int k = kTangentStencil<dim>;
            Vec<dim> Sigma[k], tau[k];
            tangent_stencil<dim>(svd.Sigma, Sigma);
            const double p0 = cam_clay->p0(hardening);
            for (int j = 0; j < k; ++j) tau[j] = cam_clay->project_tau(Sigma[j], p0);
            return elastoplastic_tangent_of_stress<dim>(svd, tau, project_psd, keep_skew);
        }
    }
    const Vec<dim> eps = svd.Sigma.array().log().matrix();
    if (const auto* drucker_prager = std::get_if<DruckerPrager<dim>>(&plasticity_)) {
        // Where every point of the stencil lies on the branch of the center (beyond twice its step from the
        // apex and from the cone's surface), the stencil differences one smooth branch: its derivative
        // in closed form instead of 2d + 1 projections (the same tangent to the stencil's truncation error,
        // ~1e-10 relative). Nearer, the stencil's average of the two sides, which Newton converges faster
        // with on a column whose particles cross the surface between iterates (docs/solver.md).
        Mat<dim> dlogZ;
        double scale = 1.0, margin = 0.0;
        const Vec<dim> logZ = drucker_prager->project_strain(eps, dlogZ, scale, margin);
        if (margin > 2.0 * kTangentStencilStep) {
            // StVK-Hencky (DruckerPrager requires it): dtau/deps = 2 mu I + lambda 1 1^T, times d log Z / d eps.
            const double lambda = elasticity_.lambda(), mu = elasticity_.mu();
            const Vec<dim> tau = elasticity_.tau_of_strain(logZ);
            const Mat<dim> dtau = 2.0 * mu * dlogZ + lambda * Vec<dim>::Ones() * dlogZ.colwise().sum();
            const Mat<dim> quotient = deviatoric_scale_quotients<dim>(elasticity_, svd.Sigma, scale);
            return elastoplastic_tangent_of_derivative<dim>(svd, tau, dtau, project_psd, keep_skew, &quotient);
        }
    }
    constexpr int k = kTangentStencil<dim>;
    Vec<dim> strain[k], tau[k];
    tangent_strain_stencil<dim>(eps, strain);
    std::visit(
        [&](const auto& model) {
            using Model = std::decay_t<decltype(model)>;
            for (int j = 0; j < k; ++j) {
                if constexpr (std::is_same_v<Model, std::monostate>) {
                    tau[j] = elasticity_.tau_of_strain(strain[j]);
                } else if constexpr (std::is_same_v<Model, DruckerPrager<dim>>) {
                    tau[j] = elasticity_.tau_of_strain(model.project_strain(strain[j]));
                } else if constexpr (std::is_same_v<Model, VonMises<dim>>) {
                    tau[j] = elasticity_.tau_of_strain(model.project_strain(strain[j], hardening));
                } else {  // a return mapping in singular values
                    const ReturnResult<dim> Z = model.project(strain[j].array().exp().matrix(), hardening);
                    tau[j] = elasticity_.tau_of_strain(Z.hencky_strain());
                }
            }
        },
        plasticity_);
    if (const auto* drucker_prager = std::get_if<DruckerPrager<dim>>(&plasticity_)) {
        // The rotational part where principal strains nearly coincide (a pile's free surface, near the
        // cone's tip): k 2 mu (eps_i - eps_j) / (Sigma_i - Sigma_j), not the limit from the stencil
        // (elastoplastic_tangent.hpp).
        const Mat<dim> quotient =
            deviatoric_scale_quotients<dim>(elasticity_, svd.Sigma, drucker_prager->deviatoric_scale(strain[0]));
        return elastoplastic_tangent_of_stress<dim>(svd, tau, project_psd, keep_skew, &quotient);
    }
    return elastoplastic_tangent_of_stress<dim>(svd, tau, project_psd, keep_skew);
}

template <int dim>
typename Material<dim>::Projection Material<dim>::project(const Mat<dim>& F, double hardening) const {
    const PolarSVD<dim> svd = clamped_svd<dim>(F);
    const ReturnResult<dim> Z = return_map(svd.Sigma, hardening);
    return {svd.compose(Z.Sigma), Z.hardening, Z.branch};
}

template class Material<2>;
template class Material<3>;

}  // namespace pnet
