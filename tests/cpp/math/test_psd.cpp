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
