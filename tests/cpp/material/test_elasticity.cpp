#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>

#include "pnet/material/elasticity.hpp"
#include "support/finite_difference.hpp"
#include "support/random.hpp"

namespace pnet {
namespace {

struct Case {
    ElasticityModel model;
    int dim;
};

std::string case_name(const ::testing::TestParamInfo<Case>& info) {
    return to_string(info.param.model) + "_" + std::to_string(info.param.dim) + "d";
}

class ElasticityTest : public ::testing::TestWithParam<Case> {
protected:
    template <int dim>
    void run_all();
};

const ElasticParams kParams{1.0, 0.3};  // nondimensional: stresses are O(1)

/// Random deformations including near-identity, large stretch/compression,
/// nearly repeated singular values and reflections (inverted F).
template <int dim>
std::vector<Mat<dim>> sample_F(test::Random& rng) {
    std::vector<Mat<dim>> out;
    for (double magnitude : {1e-3, 0.1, 0.5, 1.0})
        for (int k = 0; k < 6; ++k) out.push_back(rng.template deformation<dim>(magnitude));
    const Mat<dim> Q = rng.template rotation<dim>();
    Vec<dim> Sigma = Vec<dim>::Constant(1.2);
    Sigma[0] += 1e-9;
    out.push_back(Q * Sigma.asDiagonal() * rng.template rotation<dim>());
    out.push_back(rng.template rotation<dim>() * 0.8);  // all singular values equal
    return out;
}

template <int dim>
void ElasticityTest::run_all() {
    const Elasticity<dim> model(GetParam().model, kParams);
    test::Random rng(11 + dim);
    test::FdStats tau_stats, P_stats, dPdF_stats;
    using VecX = Eigen::VectorXd;

    // Zero energy and stress at rest.
    EXPECT_NEAR(model.psi(Vec<dim>::Ones()), 0.0, 1e-15);
    EXPECT_LT(model.tau(Vec<dim>::Ones()).norm(), 1e-15);

    for (const Mat<dim>& F : sample_F<dim>(rng)) {
        const PolarSVD<dim> svd = clamped_svd<dim>(F);
        // tau_i = d psi / d eps_i.
        const VecX eps = svd.Sigma.array().log().matrix();
        auto psi_of_eps = [&](const VecX& e) { return model.psi(Vec<dim>(e.array().exp().matrix())); };
        EXPECT_TRUE(test::check_gradient(psi_of_eps, model.tau(svd.Sigma), eps, tau_stats, 1e-6, 1e-6));

        // P = d psi / dF.
        const VecX x = flatten<dim>(F);
        auto psi_of_F = [&](const VecX& v) { return model.psi_F(unflatten<dim>(v)); };
        EXPECT_TRUE(test::check_gradient(psi_of_F, flatten<dim>(model.P(F)), x, P_stats, 1e-6, 1e-6));

        // dP/dF = d vec(P) / d vec(F); symmetric as the Hessian of psi.
        const Tensor4<dim> dPdF = model.dPdF(F);
        auto P_of_F = [&](const VecX& v) { return VecX(flatten<dim>(model.P(unflatten<dim>(v)))); };
        EXPECT_TRUE(test::check_jacobian(P_of_F, dPdF, x, dPdF_stats, 1e-6, 1e-5));
        EXPECT_LT((dPdF - dPdF.transpose()).norm(), 1e-10 * dPdF.norm());

        // The projected tensor is PSD and equals dP/dF when dP/dF is PSD.
        const Tensor4<dim> projected = model.dPdF(F, true);
        Eigen::SelfAdjointEigenSolver<Tensor4<dim>> eig_raw(dPdF), eig_proj(projected);
        EXPECT_GE(eig_proj.eigenvalues().minCoeff(), -1e-10 * dPdF.norm());
        if (eig_raw.eigenvalues().minCoeff() > 1e-10 * dPdF.norm()) {
            EXPECT_LT((projected - dPdF).norm(), 1e-10 * dPdF.norm());
        }
    }
    // The harness ran: every entry of every sample was compared.
    EXPECT_EQ(tau_stats.checks, 26 * dim);
    EXPECT_EQ(P_stats.checks, 26 * dim * dim);
    EXPECT_EQ(dPdF_stats.checks, 26 * dim * dim * dim * dim);
    RecordProperty("max_fd_error_dPdF", std::to_string(dPdF_stats.max_error));
}

TEST_P(ElasticityTest, DerivativesMatchFiniteDifferences) {
    if (GetParam().dim == 2)
        run_all<2>();
    else
        run_all<3>();
}

INSTANTIATE_TEST_SUITE_P(AllModels, ElasticityTest,
                         ::testing::Values(Case{ElasticityModel::StvkHencky, 2}, Case{ElasticityModel::StvkHencky, 3},
                                           Case{ElasticityModel::NeoHookeanSnow, 2},
                                           Case{ElasticityModel::NeoHookeanSnow, 3},
                                           Case{ElasticityModel::NeoHookeanMetal, 2},
                                           Case{ElasticityModel::NeoHookeanMetal, 3}),
                         case_name);

TEST(Elasticity, RepeatedSingularValuesGiveFiniteExactTangent) {
    // At F = s I the pair blocks use the closed-form difference quotient; the
    // result must equal the limit of nearby distinct values.
    for (auto model : {ElasticityModel::StvkHencky, ElasticityModel::NeoHookeanSnow, ElasticityModel::NeoHookeanMetal}) {
        const Elasticity<3> e(model, kParams);
        const Tensor4<3> at = e.dPdF(Mat<3>(0.9 * Mat<3>::Identity()));
        Mat<3> near = 0.9 * Mat<3>::Identity();
        near(0, 0) += 1e-7;
        near(1, 1) -= 1e-7;
        const Tensor4<3> close = e.dPdF(near);
        ASSERT_TRUE(at.allFinite());
        EXPECT_LT((at - close).norm(), 1e-5 * at.norm()) << to_string(model);
    }
}

// The 2D snow elasticity's tau(Sigma) has its own form without log or expm1 (the Cam-Clay tangent's
// elastic branch calls it per point): the same stress as eq. 17 through the Hencky strain, relative to
// the stress itself down to strains of 1e-9, where a naive J^{-1} b - 1 loses half its digits.
TEST(Elasticity, SnowStressFromSingularValuesIsTheStressFromTheStrain) {
    const Elasticity<2> snow(ElasticityModel::NeoHookeanSnow, kParams);
    test::Random rng(17);
    for (double magnitude : {1e-9, 1e-6, 1e-3, 0.1, 0.5}) {
        for (int k = 0; k < 20; ++k) {
            const Vec<2> Sigma = clamped_svd<2>(rng.deformation<2>(magnitude)).Sigma;
            const Vec<2> expected = snow.tau_of_strain(Sigma.array().log().matrix());
            EXPECT_LE((snow.tau(Sigma) - expected).cwiseAbs().maxCoeff(), 1e-12 * expected.cwiseAbs().maxCoeff())
                << "magnitude " << magnitude << " sample " << k;
        }
    }
}

TEST(Elasticity, InvertedFIsClampedNotNaN) {
    Mat<3> F = Mat<3>::Identity();
    F(2, 2) = -0.5;
    for (auto model : {ElasticityModel::StvkHencky, ElasticityModel::NeoHookeanSnow, ElasticityModel::NeoHookeanMetal}) {
        const Elasticity<3> e(model, kParams);
        EXPECT_TRUE(std::isfinite(e.psi_F(F)));
        EXPECT_TRUE(e.P(F).allFinite());
        EXPECT_TRUE(e.dPdF(F, true).allFinite());
    }
}

}  // namespace
}  // namespace pnet
