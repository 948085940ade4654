#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>

#include "pnet/math/psd.hpp"
#include "support/random.hpp"

namespace pnet {
namespace {

template <int n>
Eigen::Matrix<double, n, n> random_symmetric(test::Random& rng) {
    Eigen::Matrix<double, n, n> A;
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) A(i, j) = rng.uniform(-1.0, 1.0);
    return A + A.transpose();
}

template <int n>
double min_eigenvalue(const Eigen::Matrix<double, n, n>& A) {
    return Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, n, n>>(A).eigenvalues().minCoeff();
}

template <int n>
void check_projection(int seed) {
    test::Random rng(seed);
    int projected = 0;
    for (int k = 0; k < 100; ++k) {
        const Eigen::Matrix<double, n, n> A = random_symmetric<n>(rng);
        const Eigen::Matrix<double, n, n> P = project_psd<n>(A);
        EXPECT_GE(min_eigenvalue<n>(P), -1e-12 * A.norm());
        // Idempotent, and the identity on PSD matrices.
        EXPECT_LT((project_psd<n>(P) - P).norm(), 1e-12 * std::max(1.0, A.norm()));
        const Eigen::Matrix<double, n, n> psd = A * A.transpose();
        EXPECT_LT((project_psd<n>(psd) - psd).norm(), 1e-12 * psd.norm());
        if (min_eigenvalue<n>(A) < 0) ++projected;
    }
    EXPECT_GT(projected, 10) << "too few indefinite samples: the clamp was barely exercised";
}

TEST(ProjectPsd, ClampsNegativeEigenvaluesOnly) {
    check_projection<2>(1);
    check_projection<3>(2);
    check_projection<4>(3);
    check_projection<9>(4);
}

// The eigenvalue clamp written out, for the closed forms to match.
template <int n>
Eigen::Matrix<double, n, n> clamped_by_eigensolver(const Eigen::Matrix<double, n, n>& A) {
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, n, n>> eig(0.5 * (A + A.transpose()));
    return eig.eigenvectors() * eig.eigenvalues().cwiseMax(0.0).asDiagonal() * eig.eigenvectors().transpose();
}

template <int n>
void check_against_eigensolver(int seed) {
    test::Random rng(seed);
    for (int k = 0; k < 200; ++k) {
        Eigen::Matrix<double, n, n> A = random_symmetric<n>(rng);
        if (k % 4 == 1) A = -A * A.transpose();                        // negative semi-definite: projects to 0
        if (k % 4 == 2) A(0, n - 1) = A(n - 1, 0) = 0.0, A(0, 0) = 0.0;  // a zero row and column entry
        const Eigen::Matrix<double, n, n> expected = clamped_by_eigensolver<n>(A);
        EXPECT_LT((project_psd<n>(A) - expected).norm(), 1e-12 * std::max(1.0, A.norm())) << A;
    }
    // Multiples of the identity (equal eigenvalues) and zero.
    for (double c : {-2.0, 0.0, 3.0}) {
        const Eigen::Matrix<double, n, n> I = c * Eigen::Matrix<double, n, n>::Identity();
        EXPECT_LT((project_psd<n>(I) - clamped_by_eigensolver<n>(I)).norm(), 1e-15);
    }
}

TEST(ProjectPsd, IsTheEigenvalueClamp) {
    check_against_eigensolver<2>(5);
    check_against_eigensolver<3>(6);
    check_against_eigensolver<4>(7);
}

TEST(ProjectPsd, PairBlock) {
    double a = 1.0, b = 3.0;  // eigenvalues 4 and -2
    project_psd_pair(a, b);
    EXPECT_DOUBLE_EQ(a + b, 4.0);
    EXPECT_DOUBLE_EQ(a - b, 0.0);
    a = 2.0, b = 0.5;  // already PSD
    project_psd_pair(a, b);
    EXPECT_DOUBLE_EQ(a, 2.0);
    EXPECT_DOUBLE_EQ(b, 0.5);
}

}  // namespace
}  // namespace pnet
