#include "pnet/material/elastoplastic_tangent.hpp"

#include <algorithm>
#include <cmath>

namespace pnet {

namespace {

constexpr double kDelta = kTangentStencilStep;
// Singular values closer than this (in log) take the limit of the difference quotient.
constexpr double kCloseLog = 1e-4;

}  // namespace

template <int dim>
void tangent_stencil(const Vec<dim>& Sigma, Vec<dim>* stencil) {
    stencil[0] = Sigma;
    for (int j = 0; j < dim; ++j) {
        stencil[1 + 2 * j] = Sigma;
        stencil[2 + 2 * j] = Sigma;
        stencil[1 + 2 * j][j] *= std::exp(kDelta);
        stencil[2 + 2 * j][j] *= std::exp(-kDelta);
    }
}

template <int dim>
void tangent_strain_stencil(const Vec<dim>& eps, Vec<dim>* stencil) {
    stencil[0] = eps;
    for (int j = 0; j < dim; ++j) {
        stencil[1 + 2 * j] = eps;
        stencil[2 + 2 * j] = eps;
        stencil[1 + 2 * j][j] += kDelta;
        stencil[2 + 2 * j][j] -= kDelta;
    }
}

template <int dim>
Tensor4<dim> elastoplastic_tangent_of_stress(const PolarSVD<dim>& svd, const Vec<dim>* tau, bool project_psd,
                                             bool keep_skew, const Mat<dim>* pair_quotient) {
    Mat<dim> dtau;
    for (int j = 0; j < dim; ++j) dtau.col(j) = (tau[1 + 2 * j] - tau[2 + 2 * j]) / (2.0 * kDelta);
    return elastoplastic_tangent_of_derivative<dim>(svd, tau[0], dtau, project_psd, keep_skew, pair_quotient);
}

template <int dim>
Mat<dim> deviatoric_scale_quotients(const Elasticity<dim>& elasticity, const Vec<dim>& Sigma, double k) {
    Mat<dim> quotient = Mat<dim>::Zero();
    for (int i = 0; i < dim; ++i)
        for (int j = 0; j < dim; ++j)
            if (i != j) quotient(i, j) = k * elasticity.tau_difference_quotient(Sigma, i, j);
    return quotient;
}

template <int dim>
Tensor4<dim> elastoplastic_tangent_of_derivative(const PolarSVD<dim>& svd, const Vec<dim>& t, Mat<dim> dtau,
                                                 bool project_psd, bool keep_skew, const Mat<dim>* pair_quotient) {
    const Vec<dim>& S = svd.Sigma;
    const Vec<dim> eps = S.array().log().matrix();
    const Mat<dim> skew = 0.5 * (dtau - dtau.transpose());
    dtau = 0.5 * (dtau + dtau.transpose()).eval();
    auto quotient = [&](int i, int j) {
        if (std::abs(eps[i] - eps[j]) > kCloseLog) return (t[i] - t[j]) / (S[i] - S[j]);
        if (pair_quotient) return (*pair_quotient)(i, j);
        // The limit Sigma_i -> Sigma_j: d(tau_i - tau_j)/d eps_i / Sigma_i.
        return (dtau(i, i) - dtau(j, i)) / (0.5 * (S[i] + S[j]));
    };
    Tensor4<dim> T = isotropic_dPdF<dim>(svd, t, dtau, quotient, project_psd);
    if (keep_skew) {
        // The skew part of d^2 psi / d Sigma_i d Sigma_j (the -delta_ij tau_i term is symmetric) acts on the
        // Sigma block only, whose basis vectors are vec(u_i v_i^T): sum_ij A_ij vec(u_i v_i^T) vec(u_j v_j^T)^T,
        // still skew.
        Eigen::Matrix<double, dim * dim, dim> D;
        Mat<dim> A;
        for (int i = 0; i < dim; ++i) {
            D.col(i) = flatten<dim>(Mat<dim>(svd.U.col(i) * svd.V.col(i).transpose()));
            for (int j = 0; j < dim; ++j) A(i, j) = skew(i, j) / (S[i] * S[j]);
        }
        T.noalias() += D * A * D.transpose();
    }
    return T;
}

template <int dim>
Tensor4<dim> elastoplastic_tangent_from(const PolarSVD<dim>& svd, const Elasticity<dim>& elasticity, const Vec<dim>* Z,
                                        bool project_psd, bool keep_skew) {
    Vec<dim> tau[kTangentStencil<dim>];
    for (int k = 0; k < kTangentStencil<dim>; ++k) tau[k] = elasticity.tau(Z[k]);
    return elastoplastic_tangent_of_stress<dim>(svd, tau, project_psd, keep_skew);
}

template <int dim>
Tensor4<dim> elastoplastic_tangent(const PolarSVD<dim>& svd, const Elasticity<dim>& elasticity,
                                   const PrincipalReturnMap<dim>& return_map, bool project_psd, bool keep_skew) {
    Vec<dim> stencil[kTangentStencil<dim>], Z[kTangentStencil<dim>];
    tangent_stencil<dim>(svd.Sigma, stencil);
    for (int k = 0; k < kTangentStencil<dim>; ++k) Z[k] = return_map(stencil[k]);
    return elastoplastic_tangent_from<dim>(svd, elasticity, Z, project_psd, keep_skew);
}

template Tensor4<2> elastoplastic_tangent<2>(const PolarSVD<2>&, const Elasticity<2>&, const PrincipalReturnMap<2>&,
                                             bool, bool);
template Tensor4<3> elastoplastic_tangent<3>(const PolarSVD<3>&, const Elasticity<3>&, const PrincipalReturnMap<3>&,
                                             bool, bool);
template void tangent_stencil<2>(const Vec<2>&, Vec<2>*);
template void tangent_stencil<3>(const Vec<3>&, Vec<3>*);
template void tangent_strain_stencil<2>(const Vec<2>&, Vec<2>*);
template void tangent_strain_stencil<3>(const Vec<3>&, Vec<3>*);
template Tensor4<2> elastoplastic_tangent_of_stress<2>(const PolarSVD<2>&, const Vec<2>*, bool, bool, const Mat<2>*);
template Tensor4<3> elastoplastic_tangent_of_stress<3>(const PolarSVD<3>&, const Vec<3>*, bool, bool, const Mat<3>*);
template Tensor4<2> elastoplastic_tangent_of_derivative<2>(const PolarSVD<2>&, const Vec<2>&, Mat<2>, bool, bool,
                                                            const Mat<2>*);
template Tensor4<3> elastoplastic_tangent_of_derivative<3>(const PolarSVD<3>&, const Vec<3>&, Mat<3>, bool, bool,
                                                            const Mat<3>*);
template Mat<2> deviatoric_scale_quotients<2>(const Elasticity<2>&, const Vec<2>&, double);
template Mat<3> deviatoric_scale_quotients<3>(const Elasticity<3>&, const Vec<3>&, double);
template Tensor4<2> elastoplastic_tangent_from<2>(const PolarSVD<2>&, const Elasticity<2>&, const Vec<2>*, bool, bool);
template Tensor4<3> elastoplastic_tangent_from<3>(const PolarSVD<3>&, const Elasticity<3>&, const Vec<3>*, bool, bool);

}  // namespace pnet
