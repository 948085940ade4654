#include "pnet/material/return_map_derivative.hpp"

#include "pnet/material/elastoplastic_tangent.hpp"
#include "pnet/math/dual2.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace pnet {

namespace {

/// (e^a - e^b) / (a - b), exact as b -> a (e^a there).
double exp_difference_quotient(double a, double b) {
    const double d = a - b;
    if (std::abs(d) < 1e-6) return std::exp(0.5 * (a + b)) * (1.0 + d * d / 24.0);
    return (std::exp(a) - std::exp(b)) / d;
}

/// The (U, V)-frame derivative of F^E = U diag(Z) V^T given Z_i d log Z_i / d eps_j (= dZ_i / d log Sigma_j)
/// and, for each pair, D = (Z_i - Z_j) / (Sigma_i - Sigma_j) (isotropic_dPdF's structure).
template <int dim, typename PairQuotient>
Tensor4<dim> principal_derivative(const Vec<dim>& S, const Vec<dim>& Z, const Mat<dim>& dZ_deps, PairQuotient&& D) {
    Tensor4<dim> A = Tensor4<dim>::Zero();
    for (int i = 0; i < dim; ++i)
        for (int j = 0; j < dim; ++j) A(i * dim + i, j * dim + j) = dZ_deps(i, j) / S[j];
    for (int i = 0; i < dim; ++i)
        for (int j = i + 1; j < dim; ++j) {
            const double d = D(i, j), e = (Z[i] + Z[j]) / (S[i] + S[j]);
            const int ij = i * dim + j, ji = j * dim + i;
            A(ij, ij) = A(ji, ji) = 0.5 * (d + e);
            A(ij, ji) = A(ji, ij) = 0.5 * (d - e);
        }
    return A;
}

/// Drucker-Prager's projection in Hencky strain with its Jacobian (DruckerPrager::project_strain), on the branch
/// the mapping takes (one-sided at the boundaries), and what the friction angle's derivative needs (n, tr,
/// stiffness): log Z = eps inside the cone, 0 at the apex (tr > 0), and on the cone log Z = tr/d 1 - c tr n with
/// d log Z / d eps = 1 1^T / d - c n 1^T + k (I - 1 1^T / d - n n^T), k = -c tr / ||dev eps|| (so log Z_i -
/// log Z_j = k (eps_i - eps_j)); c = alpha(phi) stiffness, stiffness = (d lambda + 2 mu) / (2 mu).
template <int dim>
struct DruckerPragerStrain {
    ReturnBranch branch = ReturnBranch::Elastic;
    Vec<dim> eps, logZ, n = Vec<dim>::Zero();
    Mat<dim> dlogZ = Mat<dim>::Identity();
    double tr = 0.0, k = 1.0, stiffness = 0.0;

    DruckerPragerStrain(const Material<dim>& material, const Vec<dim>& Sigma) {
        const double mu = material.elasticity().mu(), lambda = material.elasticity().lambda();
        eps = Sigma.array().log().matrix();
        tr = eps.sum();
        stiffness = (dim * lambda + 2.0 * mu) / (2.0 * mu);
        double margin = 0.0;
        logZ = material.template plasticity_model<DruckerPrager<dim>>()->project_strain(eps, dlogZ, k, margin, &branch);
        if (branch == ReturnBranch::Cone) n = (eps - tr / dim * Vec<dim>::Ones()).normalized();
    }
    static double sine(const Material<dim>& material) {
        return std::sin(material.description().drucker_prager.friction_angle_deg * M_PI / 180.0);
    }
};

/// Von Mises with StVK-Hencky in Hencky strain (eq. 22), on the branch the mapping takes (elastic at L = h): log Z
/// = mean 1 + c eps_hat, c = h / L, where L = ||eps_hat|| > h, with d log Z / d eps = 1 1^T / d + c (I - 1 1^T / d -
/// n n^T) (so log Z_i - log Z_j = c (eps_i - eps_j)).
template <int dim>
struct VonMisesStrain {
    Vec<dim> eps, eps_hat, logZ, n = Vec<dim>::Zero();
    Mat<dim> dlogZ = Mat<dim>::Identity();
    double mean = 0.0, c = 1.0;
    bool yielded = false;

    VonMisesStrain(const Vec<dim>& Sigma, double h) {
        eps = Sigma.array().log().matrix();
        logZ = eps;
        mean = eps.sum() / dim;
        eps_hat = eps - mean * Vec<dim>::Ones();
        const double L = eps_hat.norm();
        if (!(L > h)) return;
        yielded = true;
        c = h / L;
        n = eps_hat / L;
        const Mat<dim> P = Mat<dim>::Identity() - Mat<dim>::Constant(1.0 / dim);
        dlogZ = Mat<dim>::Constant(1.0 / dim) + c * (P - n * n.transpose());
        logZ = mean * Vec<dim>::Ones() + c * eps_hat;
    }
};

/// Drucker-Prager with StVK-Hencky (the only elasticity it takes).
template <int dim>
ReturnMapDerivative<dim> drucker_prager_derivative(const Material<dim>& material, const PolarSVD<dim>& svd,
                                                   bool update) {
    ReturnMapDerivative<dim> out;
    const DruckerPragerStrain<dim> z(material, svd.Sigma);
    if (z.branch == ReturnBranch::Elastic) return out;
    out.yielded = true;
    const Vec<dim>& S = svd.Sigma;
    const Vec<dim> Z = z.logZ.array().exp().matrix();
    if (z.branch == ReturnBranch::Apex) {  // Z = 1, F^E = U V^T (its rotation still follows F); Ptilde = 0
        if (update)
            out.dFE_dF = to_f_space<dim>(
                svd, principal_derivative<dim>(S, Z, Z.asDiagonal() * z.dlogZ, [](int, int) { return 0.0; }));
        return out;
    }
    // d log Z / d phi = -(dc/dphi) tr n, phi in degrees; the stress's tau = 2 mu log Z + lambda tr(log Z) 1
    // changes by 2 mu d log Z (n has no trace).
    const double s = DruckerPragerStrain<dim>::sine(material);
    const double dalpha_ds = std::sqrt(2.0 / 3.0) * 6.0 / ((3.0 - s) * (3.0 - s));
    const double ds_dphi =
        std::cos(material.description().drucker_prager.friction_angle_deg * M_PI / 180.0) * M_PI / 180.0;
    const Vec<dim> dlogZ_dphi = -(dalpha_ds * ds_dphi * z.stiffness) * z.tr * z.n;
    constexpr int angle = static_cast<int>(PlasticityParameter::FrictionAngle);
    out.dP_dparameter[angle] =
        svd.compose(Vec<dim>((2.0 * material.elasticity().mu() * dlogZ_dphi).cwiseQuotient(S)));
    if (!update) return out;
    out.dFE_dF = to_f_space<dim>(svd, principal_derivative<dim>(S, Z, Z.asDiagonal() * z.dlogZ, [&](int i, int j) {
                                     return z.k * exp_difference_quotient(z.logZ[i], z.logZ[j]) /
                                            exp_difference_quotient(z.eps[i], z.eps[j]);
                                 }));
    out.dFE_dparameter[angle] = svd.compose(Z.cwiseProduct(dlogZ_dphi));
    return out;
}

/// Cam-Clay's exact variant on dual numbers (Dual1, math/dual2.hpp): the projection Z(Sigma, a), the new hardening a',
/// the return-mapped Kirchhoff stress tau(Sigma, p0(a)) and their derivatives in Sigma, a, xi, beta and M;
/// k and k_tau the deviatoric scales of the projection and of the stress's (CamClay::project_with).
template <int dim>
struct CamClayDuals {
    static constexpr int n = kCamClayDirections<dim>;
    using D = Dual1<n>;
    static constexpr int kA = dim, kXi = dim + 1, kBeta = dim + 2, kM = dim + 3;
    typename CamClay<dim>::template Projected<D> projected;
    Eigen::Matrix<D, dim, 1> tau;
    D k_tau;

    CamClayDuals(const CamClay<dim>& model, const Vec<dim>& S, double h, bool with_projection) {
        const CamClayParams& params = model.params();
        if (params.variant != CamClayVariant::Exact)
            throw std::invalid_argument(
                "return_map_derivative: plasticity.variant 'paper' of cam_clay: only the exact variant (J kept) is "
                "written");
        Eigen::Matrix<D, dim, 1> Sigma;
        for (int i = 0; i < dim; ++i) Sigma[i] = D::variable(i, S[i]);
        const D a = D::variable(kA, h), xi = D::variable(kXi, params.xi);
        const D beta = D::variable(kBeta, params.beta), M = D::variable(kM, model.M());
        if (with_projection) projected = model.template project_with<D>(Sigma, a, xi, beta, M);
        tau = model.template project_tau_with<D>(Sigma, model.template p0_with<D>(a, xi), beta, M, &k_tau);
    }
    /// dM / d friction_angle_deg, M = sqrt(2/3) 2 s / (3 - s) d / sqrt(2 / (6 - d)), s = sin(phi).
    static double dM_dangle(const CamClay<dim>& model) {
        const double phi = model.params().friction_angle_deg * M_PI / 180.0, s = std::sin(phi);
        return std::sqrt(2.0 / 3.0) * 6.0 / ((3.0 - s) * (3.0 - s)) * dim / std::sqrt(2.0 / (6.0 - dim)) *
               std::cos(phi) * M_PI / 180.0;
    }
    /// A dual's derivatives in the three plasticity parameters (PlasticityParameter's order).
    static std::array<double, kPlasticityParameters> in_parameters(const D& x, double dM_dangle) {
        return {x.gradient[kM] * dM_dangle, x.gradient[kXi], x.gradient[kBeta]};
    }
};

template <int dim>
ReturnMapDerivative<dim> cam_clay_derivative(const Material<dim>& material, const PolarSVD<dim>& svd, double h,
                                             bool update) {
    const CamClay<dim>& model = *material.template plasticity_model<CamClay<dim>>();
    using Duals = CamClayDuals<dim>;
    const Duals duals(model, svd.Sigma, h, update);
    const auto& r = duals.projected;
    ReturnMapDerivative<dim> out;
    const Vec<dim>& S = svd.Sigma;
    const double dM = Duals::dM_dangle(model);
    // The stress at F_trial with a held: tau(Sigma, p0(a)) is the elastic stress inside, whatever a is.
    for (int q = 0; q < kPlasticityParameters; ++q) {
        Vec<dim> dtau;
        for (int i = 0; i < dim; ++i) dtau[i] = Duals::in_parameters(duals.tau[i], dM)[q];
        out.dP_dparameter[q] = svd.compose(Vec<dim>(dtau.cwiseQuotient(S)));
    }
    Vec<dim> dtau_da;
    for (int i = 0; i < dim; ++i) dtau_da[i] = duals.tau[i].gradient[Duals::kA];
    out.dP_dh = svd.compose(Vec<dim>(dtau_da.cwiseQuotient(S)));
    if (!update || r.branch == ReturnBranch::Elastic) return out;  // elastic: F^E = F_trial, a' = a
    out.yielded = true;
    Vec<dim> Z, dZ_da, dh_dS;
    Mat<dim> dZ_deps;
    for (int i = 0; i < dim; ++i) {
        Z[i] = r.Z[i].value;
        dZ_da[i] = r.Z[i].gradient[Duals::kA];
        for (int j = 0; j < dim; ++j) dZ_deps(i, j) = r.Z[i].gradient[j] * S[j];
        dh_dS[i] = r.hardening.gradient[i];
    }
    const double k = r.scale.value;  // Z_i - Z_j = k (Sigma_i^2 - Sigma_j^2) / (Z_i + Z_j)
    out.dFE_dF = to_f_space<dim>(
        svd, principal_derivative<dim>(S, Z, dZ_deps, [&](int i, int j) { return k * (S[i] + S[j]) / (Z[i] + Z[j]); }));
    out.dFE_dh = svd.compose(dZ_da);
    out.dh_dF = svd.compose(dh_dS);
    out.dh_dh = r.hardening.gradient[Duals::kA];
    out.dh_dparameter = Duals::in_parameters(r.hardening, dM);
    for (int q = 0; q < kPlasticityParameters; ++q) {
        Vec<dim> dZ;
        for (int i = 0; i < dim; ++i) dZ[i] = Duals::in_parameters(r.Z[i], dM)[q];
        out.dFE_dparameter[q] = svd.compose(dZ);
    }
    return out;
}

}  // namespace

template <int dim>
ReturnMapDerivative<dim> return_map_derivative(const Material<dim>& material, const PolarSVD<dim>& svd, double h,
                                               bool update) {
    ReturnMapDerivative<dim> out;
    const MaterialDescription& m = material.description();
    if (m.plasticity == PlasticityModel::None) return out;  // F^E = F_trial, h' = h
    if (m.plasticity == PlasticityModel::DruckerPrager) return drucker_prager_derivative(material, svd, update);
    if (m.plasticity == PlasticityModel::CamClay) return cam_clay_derivative(material, svd, h, update);
    if (m.plasticity != PlasticityModel::VonMises || m.elasticity != ElasticityModel::StvkHencky)
        throw std::invalid_argument("return_map_derivative: plasticity \"" + to_string(m.plasticity) + "\" with " +
                                    to_string(m.elasticity) +
                                    ": only von Mises with StVK-Hencky (and elastic materials) are written");
    const Vec<dim>& S = svd.Sigma;
    const VonMisesStrain<dim> z(svd.Sigma, h);
    if (!z.yielded) return out;  // elastic (the mapping's branch at L = h too)
    out.yielded = true;
    const double xi = m.von_mises.hardening_coefficient;
    const Vec<dim> Z = z.logZ.array().exp().matrix();
    // Ptilde = U diag(tau(Z) / Sigma) V^T: d tau / dh = (d tau / d eps)(Z) n.
    out.dP_dh = svd.compose(Vec<dim>((material.elasticity().dtau_deps(Z) * z.n).cwiseQuotient(S)));
    if (!update) return out;
    // D = (Z_i - Z_j) / (Sigma_i - Sigma_j) = e^mean c q(c eps_hat_i, c eps_hat_j) / q(eps_i, eps_j).
    out.dFE_dF = to_f_space<dim>(svd, principal_derivative<dim>(S, Z, Z.asDiagonal() * z.dlogZ, [&](int i, int j) {
                                     return std::exp(z.mean) * z.c *
                                            exp_difference_quotient(z.c * z.eps_hat[i], z.c * z.eps_hat[j]) /
                                            exp_difference_quotient(z.eps[i], z.eps[j]);
                                 }));
    // d log Z / dh = n; h' = h + xi (L - h): dh'/d eps = xi n, dh'/dh = 1 - xi.
    out.dFE_dh = svd.compose(Z.cwiseProduct(z.n));
    out.dh_dF = svd.compose(Vec<dim>(xi * z.n.cwiseQuotient(S)));
    out.dh_dh = 1.0 - xi;
    return out;
}

template <int dim>
Tensor4<dim> drucker_prager_tangent(const Material<dim>& material, const PolarSVD<dim>& svd) {
    const MaterialDescription& m = material.description();
    if (m.plasticity != PlasticityModel::DruckerPrager)
        throw std::invalid_argument("drucker_prager_tangent: plasticity \"" + to_string(m.plasticity) + "\"");
    const double mu = material.elasticity().mu(), lambda = material.elasticity().lambda();
    const DruckerPragerStrain<dim> z(material, svd.Sigma);
    const Vec<dim> tau = 2.0 * mu * z.logZ + lambda * z.logZ.sum() * Vec<dim>::Ones();
    const Mat<dim> dtau = 2.0 * mu * z.dlogZ + lambda * Vec<dim>::Ones() * z.dlogZ.colwise().sum();
    // The rotational part where principal strains nearly coincide: log Z_i - log Z_j = k (eps_i - eps_j) on the
    // branch taken (DruckerPrager::deviatoric_scale), exact there (elastoplastic_tangent.hpp).
    const Mat<dim> quotient = deviatoric_scale_quotients<dim>(material.elasticity(), svd.Sigma,
                                                              z.branch == ReturnBranch::Apex ? 0.0 : z.k);
    return elastoplastic_tangent_of_derivative<dim>(svd, tau, dtau, false, true, &quotient);
}

template <int dim>
Tensor4<dim> return_map_tangent(const Material<dim>& material, const PolarSVD<dim>& svd, double h) {
    const MaterialDescription& m = material.description();
    if (m.plasticity == PlasticityModel::DruckerPrager) return drucker_prager_tangent<dim>(material, svd);
    if (m.plasticity == PlasticityModel::VonMises && m.elasticity == ElasticityModel::StvkHencky) {
        const VonMisesStrain<dim> z(svd.Sigma, h);
        if (!z.yielded) return material.elasticity().dPdF(svd, false);
        const Vec<dim> Z = z.logZ.array().exp().matrix();
        const Vec<dim> tau = material.elasticity().tau_of_strain(z.logZ);
        const Mat<dim> dtau_deps = material.elasticity().dtau_deps(Z) * z.dlogZ;
        const Mat<dim> quotient = deviatoric_scale_quotients<dim>(material.elasticity(), svd.Sigma, z.c);
        return elastoplastic_tangent_of_derivative<dim>(svd, tau, dtau_deps, false, true, &quotient);
    }
    if (m.plasticity != PlasticityModel::CamClay) return material.elastoplastic_tangent(svd, h, false, true);
    using Duals = CamClayDuals<dim>;
    const Duals duals(*material.template plasticity_model<CamClay<dim>>(), svd.Sigma, h, false);
    Vec<dim> tau;
    Mat<dim> dtau_deps;
    for (int i = 0; i < dim; ++i) {
        tau[i] = duals.tau[i].value;
        for (int j = 0; j < dim; ++j) dtau_deps(i, j) = duals.tau[i].gradient[j] * svd.Sigma[j];
    }
    // tau_i - tau_j = k mu J^{-2/d} (Sigma_i^2 - Sigma_j^2): the snow elasticity's quotient scaled by k.
    const Mat<dim> quotient = deviatoric_scale_quotients<dim>(material.elasticity(), svd.Sigma, duals.k_tau.value);
    return elastoplastic_tangent_of_derivative<dim>(svd, tau, dtau_deps, false, true, &quotient);
}

template <int dim>
PerturbedMaterials<dim> perturbed_materials(const std::vector<Material<dim>>& materials, const std::string& field,
                                            const std::string& who) {
    PerturbedMaterials<dim> out;
    out.field = field;
    double scale = 0.0;
    for (const Material<dim>& m : materials) {
        const double* value = material_parameter(m.description(), field);
        out.has.push_back(value != nullptr);
        if (value) scale = std::max(scale, std::abs(*value));
    }
    if (std::none_of(out.has.begin(), out.has.end(), [](char has) { return has != 0; }))
        throw std::invalid_argument(who + ": parameter field '" + field +
                                    "': no material has it (its gradient would be 0)");
    out.delta = 1e-6 * std::max(scale, 1.0);
    for (const Material<dim>& m : materials) {
        MaterialDescription minus = m.description(), plus = m.description();
        if (double* value = material_parameter(minus, field)) *value -= out.delta;
        if (double* value = material_parameter(plus, field)) *value += out.delta;
        out.minus.emplace_back(minus);
        out.plus.emplace_back(plus);
    }
    return out;
}

template PerturbedMaterials<2> perturbed_materials<2>(const std::vector<Material<2>>&, const std::string&,
                                                      const std::string&);
template PerturbedMaterials<3> perturbed_materials<3>(const std::vector<Material<3>>&, const std::string&,
                                                      const std::string&);

template Tensor4<2> return_map_tangent<2>(const Material<2>&, const PolarSVD<2>&, double);
template Tensor4<3> return_map_tangent<3>(const Material<3>&, const PolarSVD<3>&, double);
template Tensor4<2> drucker_prager_tangent<2>(const Material<2>&, const PolarSVD<2>&);
template Tensor4<3> drucker_prager_tangent<3>(const Material<3>&, const PolarSVD<3>&);
template ReturnMapDerivative<2> return_map_derivative<2>(const Material<2>&, const PolarSVD<2>&, double, bool);
template ReturnMapDerivative<3> return_map_derivative<3>(const Material<3>&, const PolarSVD<3>&, double, bool);

}  // namespace pnet
