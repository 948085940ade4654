#include <gtest/gtest.h>

#include "pnet/math/svd.hpp"
#include "support/dims.hpp"
#include "support/random.hpp"

namespace pnet {
namespace {

PNET_TYPED_TEST_SUITE_2D_3D(PolarSvdTest);

template <int dim>
void expect_polar(const Mat<dim>& F) {
    const PolarSVD<dim> svd = polar_svd<dim>(F);
    const double scale = std::max(1.0, F.norm());
    EXPECT_LT((svd.compose(svd.Sigma) - F).norm(), 1e-13 * scale) << "F =\n" << F;
    EXPECT_LT((svd.U.transpose() * svd.U - Mat<dim>::Identity()).norm(), 1e-13);
    EXPECT_LT((svd.V.transpose() * svd.V - Mat<dim>::Identity()).norm(), 1e-13);
    EXPECT_NEAR(svd.U.determinant(), 1.0, 1e-13);
    EXPECT_NEAR(svd.V.determinant(), 1.0, 1e-13);
    for (int i = 0; i + 1 < dim; ++i) EXPECT_GE(svd.Sigma[i], std::abs(svd.Sigma[i + 1]) - 1e-14 * scale);
    for (int i = 0; i + 1 < dim; ++i) EXPECT_GE(svd.Sigma[i], 0.0);
    // The sign of det F sits on the last singular value.
    if (std::abs(F.determinant()) > 1e-12 * std::pow(scale, dim)) {
        EXPECT_EQ(svd.Sigma[dim - 1] < 0, F.determinant() < 0);
    }
}

TYPED_TEST(PolarSvdTest, ReconstructsRandomAndReflectedMatrices) {
    constexpr int dim = TypeParam::value;
    test::Random rng(7);
    Mat<dim> reflect = Mat<dim>::Identity();
    reflect(0, 0) = -1.0;
    for (int k = 0; k < 200; ++k) {
        const Mat<dim> F = rng.template deformation<dim>(1.5);
        expect_polar<dim>(F);
        expect_polar<dim>(reflect * F);
    }
}

TYPED_TEST(PolarSvdTest, HandlesDegenerateMatrices) {
    constexpr int dim = TypeParam::value;
    test::Random rng(8);
    expect_polar<dim>(Mat<dim>::Identity());
    expect_polar<dim>(Mat<dim>::Zero());
    expect_polar<dim>(-Mat<dim>::Identity());
    expect_polar<dim>(2.0 * rng.template rotation<dim>());  // all singular values equal
    Mat<dim> rank_one = Mat<dim>::Zero();
    rank_one(0, dim - 1) = 3.0;
    expect_polar<dim>(rank_one);
    const Mat<dim> Q = rng.template rotation<dim>();
    Vec<dim> Sigma = Vec<dim>::Ones();
    Sigma[0] = 1.0 + 1e-12;  // nearly repeated
    expect_polar<dim>(Q * Sigma.asDiagonal() * rng.template rotation<dim>());
}

TYPED_TEST(PolarSvdTest, RecoversKnownSingularValues) {
    // F = Q1 diag(sigma) Q2 with known sigma, including strong compression
    // and stretch (the values a return mapping takes logarithms of).
    constexpr int dim = TypeParam::value;
    test::Random rng(9);
    const double spectra[][3] = {{3.0, 1.0, 1e-5}, {1.001, 1.0, 0.999}, {1.0, 1e-3, 1e-3}, {50.0, 2.0, -0.5},
                                 {1.0 + 1e-9, 1.0, 1.0 - 1e-9}};
    for (const auto& values : spectra) {
        Vec<dim> sigma;
        for (int i = 0; i < dim; ++i) sigma[i] = values[i];
        if (dim == 2) sigma[1] = values[2];
        for (int k = 0; k < 20; ++k) {
            const Mat<dim> F = rng.template rotation<dim>() * sigma.asDiagonal() * rng.template rotation<dim>();
            const PolarSVD<dim> svd = polar_svd<dim>(F);
            for (int i = 0; i < dim; ++i)
                EXPECT_NEAR(svd.Sigma[i], sigma[i], 4e-15 * sigma[0] + 1e-12 * std::abs(sigma[i]))
                    << "sigma " << sigma.transpose() << ", index " << i;
            expect_polar<dim>(F);
        }
    }
}

// A warm start (a nearby F's V, a random rotation, a reflection, a non-orthonormal guess) gives the
// decomposition of the cold start to round-off.
TEST(PolarSvd, WarmStartGivesTheSameDecomposition) {
    test::Random rng(11);
    auto random_matrix = [&](double scale) {
        Mat<3> M;
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) M(i, j) = rng.uniform(-scale, scale);
        return M;
    };
    int near = 0;
    for (int k = 0; k < 200; ++k) {
        const Mat<3> F = (k % 5 == 0 ? Mat<3>(Mat<3>::Identity()) : Mat<3>(Mat<3>::Zero())) + random_matrix(1.0);
        const PolarSVD<3> cold = polar_svd<3>(F);
        Mat<3> start;
        switch (k % 4) {
            case 0: start = polar_svd<3>(F + random_matrix(1e-3)).V, ++near; break;  // a nearby F's
            case 1: start = polar_svd<3>(random_matrix(1.0)).V; break;              // any rotation
            case 2: start = -Mat<3>::Identity(); break;                              // a reflection
            default: start = Mat<3>::Identity() + random_matrix(0.3); break;        // not orthonormal
        }
        const PolarSVD<3> warm = polar_svd<3>(F, start);
        EXPECT_LT((warm.Sigma - cold.Sigma).norm(), 1e-12 * std::max(1.0, cold.Sigma.norm())) << F;
        EXPECT_LT((warm.compose(warm.Sigma) - F).norm(), 1e-12 * std::max(1.0, F.norm()));
        EXPECT_NEAR(warm.U.determinant(), 1.0, 1e-12);
        EXPECT_NEAR(warm.V.determinant(), 1.0, 1e-12);
        EXPECT_LT((warm.V.transpose() * warm.V - Mat<3>::Identity()).norm(), 1e-12);
    }
    EXPECT_GT(near, 10);
    // A degenerate start falls back to the cold one.
    const Mat<3> F = random_matrix(1.0);
    EXPECT_LT((polar_svd<3>(F, Mat<3>::Zero()).Sigma - polar_svd<3>(F).Sigma).norm(), 1e-12);
}

}  // namespace
}  // namespace pnet
