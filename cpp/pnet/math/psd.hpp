#pragma once
// Projection of a small symmetric matrix onto the positive semi-definite cone
// (eigenvalues clamped at zero), as used by projected Newton (Teran et al. 2005).
#include <Eigen/Core>
#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

namespace pnet {

/// Nearest (Frobenius) PSD matrix to the symmetric part of A.
template <int n>
Eigen::Matrix<double, n, n> project_psd(const Eigen::Matrix<double, n, n>& A) {
    const Eigen::Matrix<double, n, n> S = 0.5 * (A + A.transpose());
    // Most Hessians near the reference state are positive definite: a Cholesky
    // factorization (n^3/6 flops) proves it far cheaper than the eigensolver.
    if (Eigen::LLT<Eigen::Matrix<double, n, n>>(S).info() == Eigen::Success) return S;
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, n, n>> eig;
    if constexpr (n == 2)
        eig.computeDirect(S);  // closed form, as accurate as the iterative solver in 2x2
    else
        eig.compute(S);
    Eigen::Matrix<double, n, 1> lambda = eig.eigenvalues();
    if (lambda.minCoeff() >= 0.0) return S;
    lambda = lambda.cwiseMax(0.0);
    return eig.eigenvectors() * lambda.asDiagonal() * eig.eigenvectors().transpose();
}

/// Eigenvalue clamp of the symmetric 2x2 block [[a, b], [b, a]] in place:
/// its eigenvalues are a + b and a - b with eigenvectors (1, 1) and (1, -1).
inline void project_psd_pair(double& a, double& b) {
    const double plus = std::max(a + b, 0.0);
    const double minus = std::max(a - b, 0.0);
    a = 0.5 * (plus + minus);
    b = 0.5 * (plus - minus);
}

}  // namespace pnet
