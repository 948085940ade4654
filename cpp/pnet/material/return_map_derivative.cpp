#include "pnet/material/return_map_derivative.hpp"

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

}  // namespace

template <int dim>
ReturnMapDerivative<dim> return_map_derivative(const Material<dim>& material, const PolarSVD<dim>& svd, double h) {
    ReturnMapDerivative<dim> out;
    const MaterialDescription& m = material.description();
    if (m.plasticity == PlasticityModel::None) return out;  // F^E = F_trial, h' = h
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
    // The (U, V) frame: dZ_i / dSigma_j = Z_i dlogZ_ij / Sigma_j on the diagonal entries, the pairs'
    // blocks off it.
    Tensor4<dim> A = Tensor4<dim>::Zero();
    for (int i = 0; i < dim; ++i)
        for (int j = 0; j < dim; ++j) A(i * dim + i, j * dim + j) = Z[i] * dlogZ(i, j) / S[j];
    for (int i = 0; i < dim; ++i)
        for (int j = i + 1; j < dim; ++j) {
            // D = (Z_i - Z_j) / (Sigma_i - Sigma_j) = e^mean c q(c eps_hat_i, c eps_hat_j) / q(eps_i, eps_j).
            const double D = std::exp(mean) * c * exp_difference_quotient(c * eps_hat[i], c * eps_hat[j]) /
                             exp_difference_quotient(eps[i], eps[j]);
            const double E = (Z[i] + Z[j]) / (S[i] + S[j]);
            const int ij = i * dim + j, ji = j * dim + i;
            A(ij, ij) = A(ji, ji) = 0.5 * (D + E);
            A(ij, ji) = A(ji, ij) = 0.5 * (D - E);
        }
    out.dFE_dF = to_f_space<dim>(svd, A);
    // d log Z / dh = n; h' = h + xi (L - h): dh'/d eps = xi n, dh'/dh = 1 - xi.
    out.dFE_dh = svd.compose(Z.cwiseProduct(n));
    out.dh_dF = svd.compose(Vec<dim>(xi * n.cwiseQuotient(S)));
    out.dh_dh = 1.0 - xi;
    // Ptilde = U diag(tau(Z) / Sigma) V^T: d tau / dh = (d tau / d eps)(Z) n.
    out.dP_dh = svd.compose(Vec<dim>((material.elasticity().dtau_deps(Z) * n).cwiseQuotient(S)));
    return out;
}

template ReturnMapDerivative<2> return_map_derivative<2>(const Material<2>&, const PolarSVD<2>&, double);
template ReturnMapDerivative<3> return_map_derivative<3>(const Material<3>&, const PolarSVD<3>&, double);

}  // namespace pnet
