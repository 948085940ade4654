#pragma once
// Projection of a small symmetric matrix onto the positive semi-definite cone
// (eigenvalues clamped at zero), as used by projected Newton (Teran et al. 2005).
#include <cmath>

#include <Eigen/Core>
#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

namespace pnet {

/// Nearest (Frobenius) PSD matrix to the symmetric part of A.
template <int n>
Eigen::Matrix<double, n, n> project_psd(const Eigen::Matrix<double, n, n>& A) {
    const Eigen::Matrix<double, n, n> S = 0.5 * (A + A.transpose());
    if constexpr (n == 2) {
        // Closed form: eigenvalues m +- r; with one negative, S - l2 I = (l1 - l2) v1 v1^T, so the
        // clamp l1 v1 v1^T is l1 (S - l2 I) / (2 r).
        const double a = S(0, 0), b = S(0, 1), c = S(1, 1);
        if (a >= 0.0 && c >= 0.0 && a * c >= b * b) return S;
        const double m = 0.5 * (a + c),
                     r = std::sqrt(0.25 * (a - c) * (a - c) + b * b);  // no hypot: its overflow guard is slow here
        const double l1 = m + r, l2 = m - r;
        if (!(l1 > 0.0)) return Eigen::Matrix<double, 2, 2>::Zero();
        if (!(l2 < 0.0)) return S;
        return (l1 / (2.0 * r)) * (S - l2 * Eigen::Matrix<double, 2, 2>::Identity());
    }
    // Most Hessians near the reference state are positive definite: a Cholesky
    // factorization (n^3/6 flops) proves it far cheaper than the eigensolver.
    if (Eigen::LLT<Eigen::Matrix<double, n, n>>(S).info() == Eigen::Success) return S;
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, n, n>> eig(S);
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
