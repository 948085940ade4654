#include "pnet/material/elasticity.hpp"

#include <cmath>
#include <sstream>
#include <stdexcept>

#include "pnet/math/psd.hpp"
#include "pnet/material/constants.hpp"

namespace pnet {

/// (log a - log b) / (a - b) for a, b > 0, exact also as a -> b.
double log_difference_quotient(double a, double b) {
    const double x = (a - b) / b;
    if (x == 0.0) return 1.0 / b;
    return std::log1p(x) / (x * b);
}

std::string to_string(ElasticityModel model) {
    switch (model) {
        case ElasticityModel::StvkHencky: return "stvk_hencky";
        case ElasticityModel::NeoHookeanSnow: return "neo_hookean_snow";
        case ElasticityModel::NeoHookeanMetal: return "neo_hookean_metal";
    }
    return "unknown";
}

ElasticityModel elasticity_model_from_string(const std::string& name) {
    if (name == "stvk_hencky") return ElasticityModel::StvkHencky;
    if (name == "neo_hookean_snow") return ElasticityModel::NeoHookeanSnow;
    if (name == "neo_hookean_metal") return ElasticityModel::NeoHookeanMetal;
    throw std::invalid_argument("unknown elasticity model '" + name +
                                "' (expected stvk_hencky, neo_hookean_snow or neo_hookean_metal)");
}

void ElasticParams::validate() const {
    if (!std::isfinite(E) || E <= 0.0) {
        std::ostringstream msg;
        msg << "elasticity parameter E = " << E << " must be finite and > 0 (Young's modulus, Pa)";
        throw std::invalid_argument(msg.str());
    }
    if (!std::isfinite(nu) || nu <= -1.0 || nu >= 0.5) {
        std::ostringstream msg;
        msg << "elasticity parameter nu = " << nu << " must be finite with -1 < nu < 0.5 (Poisson ratio)";
        throw std::invalid_argument(msg.str());
    }
}

template <int dim>
Elasticity<dim>::Elasticity(ElasticityModel model, const ElasticParams& params)
    : model_(model), params_(params) {
    params_.validate();
    mu_ = params_.mu();
    lambda_ = params_.lambda();
    K_ = params_.K();
}

template <int dim>
double Elasticity<dim>::psi(const Vec<dim>& Sigma) const {
    const Vec<dim> eps = Sigma.array().log().matrix();
    const double log_J = eps.sum();
    switch (model_) {
        case ElasticityModel::StvkHencky:
            return mu_ * eps.squaredNorm() + 0.5 * lambda_ * log_J * log_J;
        case ElasticityModel::NeoHookeanSnow: {
            // mu/2 (J^{-2/d} tr(b) - d) + K/4 (J^2 - 1) - K/2 log J, written with
            // J^{-2/d} b_i = exp(2 dev(eps)_i) and expm1 so that nothing cancels
            // near F = I.
            const Vec<dim> dev_eps = eps - log_J / dim * Vec<dim>::Ones();
            double iso = 0.0;
            for (int i = 0; i < dim; ++i) iso += std::expm1(2.0 * dev_eps[i]);
            return 0.5 * mu_ * iso + 0.25 * K_ * (std::expm1(2.0 * log_J) - 2.0 * log_J);
        }
        case ElasticityModel::NeoHookeanMetal: {
            // mu/2 (tr(b) - d) - mu log J + lambda/2 (log J)^2, with
            // tr(b) - d - 2 log J = sum_i (expm1(2 eps_i) - 2 eps_i).
            double iso = 0.0;
            for (int i = 0; i < dim; ++i) iso += std::expm1(2.0 * eps[i]) - 2.0 * eps[i];
            return 0.5 * mu_ * iso + 0.5 * lambda_ * log_J * log_J;
        }
    }
    return 0.0;
}

template <int dim>
Vec<dim> Elasticity<dim>::tau(const Vec<dim>& Sigma) const {
    if constexpr (dim == 2) {
        if (model_ == ElasticityModel::NeoHookeanSnow) {
            // tau_of_strain's eq. 17 without log or expm1, as accurate near F = I: J^{-1} b_0 - 1 =
            // (Sigma_0 - Sigma_1) / Sigma_1, and J - 1 = a + b + a b with a, b = Sigma - 1 (exact
            // differences of nearby numbers).
            const double a = Sigma[0] - 1.0, b = Sigma[1] - 1.0;
            const double J_m1 = a + b + a * b;
            const Vec<2> bbar_m1((Sigma[0] - Sigma[1]) / Sigma[1], (Sigma[1] - Sigma[0]) / Sigma[0]);
            return mu_ * (bbar_m1 - 0.5 * bbar_m1.sum() * Vec<2>::Ones()) +
                   0.5 * K_ * J_m1 * (J_m1 + 2.0) * Vec<2>::Ones();
        }
    }
    return tau_of_strain(Sigma.array().log().matrix());
}

namespace {

/// J^{-2/d}.
template <int dim>
double isochoric_factor(double J) {
    if constexpr (dim == 2) return 1.0 / J;
    else return std::pow(J, -2.0 / dim);
}

}  // namespace

template <int dim>
Vec<dim> Elasticity<dim>::tau_of_strain(const Vec<dim>& eps) const {
    const double log_J = eps.sum();
    const Vec<dim> ones = Vec<dim>::Ones();
    switch (model_) {
        case ElasticityModel::StvkHencky:  // eq. 14: 2 mu eps + lambda tr(eps) 1
            return 2.0 * mu_ * eps + lambda_ * log_J * ones;
        case ElasticityModel::NeoHookeanSnow: {
            // eq. 17: mu J^{-2/d} dev(b) + K/2 (J^2 - 1) 1, with
            // J^{-2/d} b_i = exp(2 dev(eps)_i) (expm1: accurate near F = I).
            Vec<dim> bbar_m1;  // J^{-2/d} b - 1
            for (int i = 0; i < dim; ++i) bbar_m1[i] = std::expm1(2.0 * (eps[i] - log_J / dim));
            return mu_ * (bbar_m1 - bbar_m1.sum() / dim * ones) + 0.5 * K_ * std::expm1(2.0 * log_J) * ones;
        }
        case ElasticityModel::NeoHookeanMetal: {  // eq. 24: mu (b - 1) + lambda log(J) 1
            Vec<dim> b_m1;
            for (int i = 0; i < dim; ++i) b_m1[i] = std::expm1(2.0 * eps[i]);
            return mu_ * b_m1 + lambda_ * log_J * ones;
        }
    }
    return Vec<dim>::Zero();
}

template <int dim>
Mat<dim> Elasticity<dim>::dtau_deps(const Vec<dim>& Sigma) const {
    const Mat<dim> ones = Mat<dim>::Ones();
    switch (model_) {
        case ElasticityModel::StvkHencky:
            return 2.0 * mu_ * Mat<dim>::Identity() + lambda_ * ones;
        case ElasticityModel::NeoHookeanSnow: {
            // d/d eps_j of mu J^{-2/d} (b_i - tr(b)/d) + K/2 (J^2 - 1), using
            // dJ/d eps_j = J and d b_i / d eps_j = 2 b_i delta_ij.
            const Vec<dim> b = Sigma.cwiseProduct(Sigma);
            const double J = Sigma.prod();
            const double J2 = J * J;
            const double iso = mu_ * isochoric_factor<dim>(J);
            const Vec<dim> dev_b = b - b.sum() / dim * Vec<dim>::Ones();
            Mat<dim> H;
            for (int i = 0; i < dim; ++i)
                for (int j = 0; j < dim; ++j)
                    H(i, j) = iso * (-2.0 / dim * dev_b[i] + (i == j ? 2.0 * b[i] : 0.0) - 2.0 / dim * b[j]) +
                              K_ * J2;
            return H;
        }
        case ElasticityModel::NeoHookeanMetal: {
            const Vec<dim> b = Sigma.cwiseProduct(Sigma);
            return Mat<dim>(2.0 * mu_ * b.asDiagonal()) + lambda_ * ones;
        }
    }
    return Mat<dim>::Zero();
}

template <int dim>
double Elasticity<dim>::tau_difference_quotient(const Vec<dim>& Sigma, int i, int j) const {
    switch (model_) {
        case ElasticityModel::StvkHencky:  // 2 mu (eps_i - eps_j) / (Sigma_i - Sigma_j)
            return 2.0 * mu_ * log_difference_quotient(Sigma[i], Sigma[j]);
        case ElasticityModel::NeoHookeanSnow:  // mu J^{-2/d} (b_i - b_j) / (Sigma_i - Sigma_j)
            return mu_ * isochoric_factor<dim>(Sigma.prod()) * (Sigma[i] + Sigma[j]);
        case ElasticityModel::NeoHookeanMetal:  // mu (b_i - b_j) / (Sigma_i - Sigma_j)
            return mu_ * (Sigma[i] + Sigma[j]);
    }
    return 0.0;
}

template <int dim>
double Elasticity<dim>::psi_F(const Mat<dim>& F) const {
    return psi(clamped_svd<dim>(F).Sigma);
}

template <int dim>
Mat<dim> Elasticity<dim>::P(const Mat<dim>& F) const {
    const PolarSVD<dim> svd = clamped_svd<dim>(F);
    return svd.compose(tau(svd.Sigma).cwiseQuotient(svd.Sigma));
}

template <int dim>
Tensor4<dim> Elasticity<dim>::dPdF(const Mat<dim>& F, bool project_psd) const {
    return dPdF(clamped_svd<dim>(F), project_psd);
}

template <int dim>
Tensor4<dim> Elasticity<dim>::dPdF(const PolarSVD<dim>& svd, bool project_psd) const {
    const Vec<dim>& S = svd.Sigma;
    return isotropic_dPdF<dim>(svd, tau(S), dtau_deps(S),
                               [&](int i, int j) { return tau_difference_quotient(S, i, j); }, project_psd);
}

// dP/dF of an isotropic energy (Irving et al. 2004; Teran et al. 2005): in the
// basis rotated by U and V it decouples into the d x d block of
// d^2 psi / d Sigma_i d Sigma_j on the diagonal entries and, for each pair
// i < j, the 2x2 block [[a, b], [b, a]] acting on the (ij, ji) entries with
//   a = (D + E)/2, b = (D - E)/2,
//   D = (P_i - P_j)/(Sigma_i - Sigma_j), E = (P_i + P_j)/(Sigma_i + Sigma_j),
// P_i = tau_i / Sigma_i. D is formed from the difference quotient of tau so that
// it is exact for equal singular values.
template <int dim>
Tensor4<dim> isotropic_dPdF(const PolarSVD<dim>& svd, const Vec<dim>& t, const Mat<dim>& H_eps,
                            const std::function<double(int, int)>& tau_quotient, bool project_psd) {
    const Vec<dim>& S = svd.Sigma;
    // d^2 psi / d Sigma_i d Sigma_j = (d tau_i/d eps_j - delta_ij tau_i) / (Sigma_i Sigma_j)
    Mat<dim> H_sigma;
    for (int i = 0; i < dim; ++i)
        for (int j = 0; j < dim; ++j) H_sigma(i, j) = (H_eps(i, j) - (i == j ? t[i] : 0.0)) / (S[i] * S[j]);
    if (project_psd) H_sigma = pnet::project_psd<dim>(H_sigma);

    Tensor4<dim> A = Tensor4<dim>::Zero();
    for (int i = 0; i < dim; ++i)
        for (int j = 0; j < dim; ++j) A(i * dim + i, j * dim + j) = H_sigma(i, j);
    for (int i = 0; i < dim; ++i) {
        for (int j = i + 1; j < dim; ++j) {
            const double Q = tau_quotient(i, j);
            const double D = (0.5 * Q * (S[i] + S[j]) - 0.5 * (t[i] + t[j])) / (S[i] * S[j]);
            const double E = (t[i] / S[i] + t[j] / S[j]) / (S[i] + S[j]);
            double a = 0.5 * (D + E), b = 0.5 * (D - E);
            if (project_psd) project_psd_pair(a, b);
            const int ij = i * dim + j, ji = j * dim + i;
            A(ij, ij) = a;
            A(ji, ji) = a;
            A(ij, ji) = b;
            A(ji, ij) = b;
        }
    }
    return to_f_space<dim>(svd, A);
}

template <int dim>
Tensor4<dim> to_f_space(const PolarSVD<dim>& svd, const Tensor4<dim>& A) {
    // Column (i*d+j) of W is vec(u_i v_j^T).
    Tensor4<dim> W;
    for (int i = 0; i < dim; ++i)
        for (int j = 0; j < dim; ++j)
            W.col(i * dim + j) = flatten<dim>(Mat<dim>(svd.U.col(i) * svd.V.col(j).transpose()));
    return W * A * W.transpose();
}

template <int dim>
Vec<dim> clamp_singular_values(const Vec<dim>& Sigma) {
    return Sigma.cwiseMax(kSigmaMin);
}

template <int dim>
void require_finite(const Mat<dim>& F, const char* what) {
    for (int i = 0; i < dim; ++i)
        for (int j = 0; j < dim; ++j)
            if (!std::isfinite(F(i, j))) {
                std::ostringstream msg;
                msg << what << " has a non-finite entry at (" << i << ", " << j << "): " << F(i, j);
                throw std::invalid_argument(msg.str());
            }
}

template <int dim>
PolarSVD<dim> clamped_svd(const Mat<dim>& F) {
    require_finite<dim>(F, "deformation gradient F");
    PolarSVD<dim> svd = polar_svd<dim>(F);
    svd.Sigma = clamp_singular_values<dim>(svd.Sigma);
    return svd;
}

template <int dim>
PolarSVD<dim> clamped_svd(const Mat<dim>& F, const Mat<dim>& V_start) {
    require_finite<dim>(F, "deformation gradient F");
    PolarSVD<dim> svd = polar_svd<dim>(F, V_start);
    svd.Sigma = clamp_singular_values<dim>(svd.Sigma);
    return svd;
}

template class Elasticity<2>;
template class Elasticity<3>;
template Tensor4<2> isotropic_dPdF<2>(const PolarSVD<2>&, const Vec<2>&, const Mat<2>&,
                                      const std::function<double(int, int)>&, bool);
template Tensor4<2> to_f_space<2>(const PolarSVD<2>&, const Tensor4<2>&);
template Tensor4<3> to_f_space<3>(const PolarSVD<3>&, const Tensor4<3>&);
template Tensor4<3> isotropic_dPdF<3>(const PolarSVD<3>&, const Vec<3>&, const Mat<3>&,
                                      const std::function<double(int, int)>&, bool);
template Vec<2> clamp_singular_values<2>(const Vec<2>&);
template Vec<3> clamp_singular_values<3>(const Vec<3>&);
template PolarSVD<2> clamped_svd<2>(const Mat<2>&);
template PolarSVD<3> clamped_svd<3>(const Mat<3>&);
template PolarSVD<2> clamped_svd<2>(const Mat<2>&, const Mat<2>&);
template PolarSVD<3> clamped_svd<3>(const Mat<3>&, const Mat<3>&);
template void require_finite<2>(const Mat<2>&, const char*);
template void require_finite<3>(const Mat<3>&, const char*);

}  // namespace pnet
