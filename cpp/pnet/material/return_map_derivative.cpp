#include "pnet/material/return_map_derivative.hpp"

#include "pnet/material/elastoplastic_tangent.hpp"

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

/// The (U, V)-frame derivative of F^E = U diag(Z) V^T, Z = exp(log Z(eps)), given d log Z / d eps and,
/// for each pair, D = (Z_i - Z_j) / (Sigma_i - Sigma_j) (isotropic_dPdF's structure).
template <int dim, typename PairQuotient>
Tensor4<dim> principal_derivative(const Vec<dim>& S, const Vec<dim>& Z, const Mat<dim>& dlogZ, PairQuotient&& D) {
    Tensor4<dim> A = Tensor4<dim>::Zero();
    for (int i = 0; i < dim; ++i)
        for (int j = 0; j < dim; ++j) A(i * dim + i, j * dim + j) = Z[i] * dlogZ(i, j) / S[j];
    for (int i = 0; i < dim; ++i)
        for (int j = i + 1; j < dim; ++j) {
            const double d = D(i, j), e = (Z[i] + Z[j]) / (S[i] + S[j]);
            const int ij = i * dim + j, ji = j * dim + i;
            A(ij, ij) = A(ji, ji) = 0.5 * (d + e);
            A(ij, ji) = A(ji, ij) = 0.5 * (d - e);
        }
    return A;
}

/// Drucker-Prager's projection in Hencky strain with its Jacobian, on the branch the mapping takes (one-sided
/// at the boundaries): log Z = eps inside the cone, 0 at the apex (tr > 0), and on the cone log Z = tr/d 1 -
/// c tr n with d log Z / d eps = 1 1^T / d - c n 1^T + k (I - 1 1^T / d - n n^T), k = -c tr / ||dev eps||
/// (so log Z_i - log Z_j = k (eps_i - eps_j)); c = alpha(phi) stiffness, stiffness = (d lambda + 2 mu) / (2 mu).
template <int dim>
struct DruckerPragerStrain {
    ReturnBranch branch = ReturnBranch::Elastic;
    Vec<dim> eps, logZ, n = Vec<dim>::Zero();
    Mat<dim> dlogZ = Mat<dim>::Identity();
    double tr = 0.0, k = 1.0, stiffness = 0.0;

    DruckerPragerStrain(const Material<dim>& material, const Vec<dim>& Sigma) {
        const double mu = material.elasticity().mu(), lambda = material.elasticity().lambda();
        eps = Sigma.array().log().matrix();
        logZ = eps;
        tr = eps.sum();
        stiffness = (dim * lambda + 2.0 * mu) / (2.0 * mu);
        if (tr > 0.0) {
            branch = ReturnBranch::Apex;
            logZ.setZero();
            dlogZ.setZero();
            return;
        }
        const Vec<dim> eps_hat = eps - tr / dim * Vec<dim>::Ones();
        const double L = eps_hat.norm();
        const double c = alpha(material) * stiffness;
        if (!(L + c * tr > 0.0)) return;  // inside the cone (the mapping's branch on its surface too)
        branch = ReturnBranch::Cone;
        n = eps_hat / L;
        k = -c * tr / L;
        const Mat<dim> mean = Mat<dim>::Constant(1.0 / dim);
        dlogZ = mean - c * n * Vec<dim>::Ones().transpose() + k * (Mat<dim>::Identity() - mean - n * n.transpose());
        logZ = tr / dim * Vec<dim>::Ones() - c * tr * n;
    }
    static double sine(const Material<dim>& material) {
        return std::sin(material.description().drucker_prager.friction_angle_deg * M_PI / 180.0);
    }
    static double alpha(const Material<dim>& material) {
        const double s = sine(material);
        return std::sqrt(2.0 / 3.0) * 2.0 * s / (3.0 - s);
    }
};

/// Drucker-Prager with StVK-Hencky (the only elasticity it takes).
template <int dim>
ReturnMapDerivative<dim> drucker_prager_derivative(const Material<dim>& material, const PolarSVD<dim>& svd) {
    ReturnMapDerivative<dim> out;
    const DruckerPragerStrain<dim> z(material, svd.Sigma);
    if (z.branch == ReturnBranch::Elastic) return out;
    out.yielded = true;
    const Vec<dim>& S = svd.Sigma;
    const Vec<dim> Z = z.logZ.array().exp().matrix();
    if (z.branch == ReturnBranch::Apex) {  // Z = 1, F^E = U V^T (its rotation still follows F)
        out.dFE_dF = to_f_space<dim>(svd, principal_derivative<dim>(S, Z, z.dlogZ, [](int, int) { return 0.0; }));
        return out;
    }
    out.dFE_dF = to_f_space<dim>(svd, principal_derivative<dim>(S, Z, z.dlogZ, [&](int i, int j) {
                                     return z.k * exp_difference_quotient(z.logZ[i], z.logZ[j]) /
                                            exp_difference_quotient(z.eps[i], z.eps[j]);
                                 }));
    // d log Z / d phi = -(dc/dphi) tr n, phi in degrees; the stress's tau = 2 mu log Z + lambda tr(log Z) 1
    // changes by 2 mu d log Z (n has no trace).
    const double s = DruckerPragerStrain<dim>::sine(material);
    const double dalpha_ds = std::sqrt(2.0 / 3.0) * 6.0 / ((3.0 - s) * (3.0 - s));
    const double ds_dphi =
        std::cos(material.description().drucker_prager.friction_angle_deg * M_PI / 180.0) * M_PI / 180.0;
    const Vec<dim> dlogZ_dphi = -(dalpha_ds * ds_dphi * z.stiffness) * z.tr * z.n;
    out.dFE_dangle = svd.compose(Z.cwiseProduct(dlogZ_dphi));
    out.dP_dangle = svd.compose(Vec<dim>((2.0 * material.elasticity().mu() * dlogZ_dphi).cwiseQuotient(S)));
    return out;
}

}  // namespace

template <int dim>
ReturnMapDerivative<dim> return_map_derivative(const Material<dim>& material, const PolarSVD<dim>& svd, double h) {
    ReturnMapDerivative<dim> out;
    const MaterialDescription& m = material.description();
    if (m.plasticity == PlasticityModel::None) return out;  // F^E = F_trial, h' = h
    if (m.plasticity == PlasticityModel::DruckerPrager) return drucker_prager_derivative(material, svd);
    if (m.plasticity != PlasticityModel::VonMises || m.elasticity != ElasticityModel::StvkHencky)
        throw std::invalid_argument("return_map_derivative: plasticity \"" + to_string(m.plasticity) + "\" with " +
                                    to_string(m.elasticity) +
                                    ": only von Mises with StVK-Hencky (and elastic materials) are written");
    const Vec<dim>& S = svd.Sigma;
    const Vec<dim> eps = S.array().log().matrix();
    const double mean = eps.sum() / dim;
    const Vec<dim> eps_hat = eps - mean * Vec<dim>::Ones();
    const double L = eps_hat.norm();
    if (!(L > h)) return out;  // elastic (the mapping's branch at L = h too)
    out.yielded = true;
    const double xi = m.von_mises.hardening_coefficient, c = h / L;
    const Vec<dim> n = eps_hat / L;
    // log Z = mean 1 + c eps_hat; d log Z / d eps = 1 1^T / dim + c (I - 1 1^T / dim - n n^T).
    const Mat<dim> P = Mat<dim>::Identity() - Mat<dim>::Constant(1.0 / dim);
    const Mat<dim> dlogZ = Mat<dim>::Constant(1.0 / dim) + c * (P - n * n.transpose());
    const Vec<dim> logZ = mean * Vec<dim>::Ones() + c * eps_hat;
    const Vec<dim> Z = logZ.array().exp().matrix();
    // D = (Z_i - Z_j) / (Sigma_i - Sigma_j) = e^mean c q(c eps_hat_i, c eps_hat_j) / q(eps_i, eps_j).
    out.dFE_dF = to_f_space<dim>(svd, principal_derivative<dim>(S, Z, dlogZ, [&](int i, int j) {
                                     return std::exp(mean) * c *
                                            exp_difference_quotient(c * eps_hat[i], c * eps_hat[j]) /
                                            exp_difference_quotient(eps[i], eps[j]);
                                 }));
    // d log Z / dh = n; h' = h + xi (L - h): dh'/d eps = xi n, dh'/dh = 1 - xi.
    out.dFE_dh = svd.compose(Z.cwiseProduct(n));
    out.dh_dF = svd.compose(Vec<dim>(xi * n.cwiseQuotient(S)));
    out.dh_dh = 1.0 - xi;
    // Ptilde = U diag(tau(Z) / Sigma) V^T: d tau / dh = (d tau / d eps)(Z) n.
    out.dP_dh = svd.compose(Vec<dim>((material.elasticity().dtau_deps(Z) * n).cwiseQuotient(S)));
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

template Tensor4<2> drucker_prager_tangent<2>(const Material<2>&, const PolarSVD<2>&);
template Tensor4<3> drucker_prager_tangent<3>(const Material<3>&, const PolarSVD<3>&);
template ReturnMapDerivative<2> return_map_derivative<2>(const Material<2>&, const PolarSVD<2>&, double);
template ReturnMapDerivative<3> return_map_derivative<3>(const Material<3>&, const PolarSVD<3>&, double);

}  // namespace pnet
