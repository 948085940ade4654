// EnergyNetwork: the energy MLP's value and derivatives in F for both input
// representations. Principal: gradient and Hessian against finite differences
// (also where F0's singular values repeat: F0 = I), invariance under rotations
// on both sides in 2D (exact: the 2D frame is unique up to (U, V) -> (-U, -V),
// which leaves U^T F V unchanged), and the MLP input it feeds; Raw: the fused
// MLP on [F, F0, h] itself.
#include <gtest/gtest.h>

#include <vector>

#include "pnet/math/svd.hpp"
#include "pnet/nn/energy_network.hpp"

#include "support/finite_difference.hpp"
#include "support/random.hpp"

namespace pnet {
namespace {

using test::FdStats;

template <int dim>
std::vector<int> widths(EnergyRepresentation representation) {
    const int in = (representation == EnergyRepresentation::Raw ? 2 * dim * dim : dim * dim + dim) + 1;
    const int w = dim == 2 ? 32 : 64;
    return {in, w, w, w, 1};
}

template <int dim>
std::vector<Mat<dim>> states(test::Random& random, std::size_t n, double spread) {
    std::vector<Mat<dim>> out;
    for (std::size_t p = 0; p < n; ++p)
        out.push_back(random.rotation<dim>() * Mat<dim>(random.uniform_vec<dim>(1 - spread, 1 + spread).asDiagonal()) *
                      random.rotation<dim>());
    return out;
}

template <int dim>
void check_derivatives(EnergyRepresentation representation) {
    constexpr int m = dim * dim;
    test::Random random(11);
    const MlpWeights weights = random_mlp(widths<dim>(representation), 5);
    EnergyNetwork<dim> network(weights, representation, true, "test");
    std::vector<Mat<dim>> F0 = states<dim>(random, 6, 0.3);
    F0.push_back(Mat<dim>::Identity());  // repeated singular values: the frame is I
    const std::size_t n = F0.size();
    std::vector<double> h(n, -0.2);
    network.set_reference(F0.data(), h.data(), n);
    std::vector<Mat<dim>> F(n);
    for (std::size_t p = 0; p < n; ++p) F[p] = F0[p] + 0.1 * Mat<dim>::Random();
    std::vector<double> value(n), gradient(n * m), hessian(n * m * m);
    network.evaluate(F.data(), FusedMlp::Order::Hessian, value.data(), gradient.data(), hessian.data());

    FdStats stats;
    for (std::size_t p = 0; p < n; ++p) {
        auto N = [&](const Eigen::VectorXd& x) {
            std::vector<Mat<dim>> Fp = F;
            Fp[p] = unflatten<dim>(Eigen::Matrix<double, m, 1>(x));
            std::vector<double> v(n);
            network.evaluate(Fp.data(), FusedMlp::Order::Value, v.data());
            return v[p];
        };
        auto grad = [&](const Eigen::VectorXd& x) {
            std::vector<Mat<dim>> Fp = F;
            Fp[p] = unflatten<dim>(Eigen::Matrix<double, m, 1>(x));
            std::vector<double> v(n), g(n * m);
            network.evaluate(Fp.data(), FusedMlp::Order::Gradient, v.data(), g.data());
            return Eigen::VectorXd(Eigen::Map<const Eigen::VectorXd>(&g[p * m], m));
        };
        const Eigen::VectorXd x = flatten<dim>(F[p]);
        const Eigen::VectorXd g = Eigen::Map<const Eigen::VectorXd>(&gradient[p * m], m);
        const Eigen::MatrixXd H = Eigen::Map<const Eigen::MatrixXd>(&hessian[p * m * m], m, m);
        EXPECT_TRUE(test::check_gradient(N, g, x, stats, 1e-6, 1e-6, 1e-3)) << "row " << p;
        EXPECT_TRUE(test::check_jacobian(grad, H, x, stats, 1e-6, 1e-6, 1e-3)) << "row " << p;
        EXPECT_LE((H - H.transpose()).cwiseAbs().maxCoeff(), 1e-13 * H.cwiseAbs().maxCoeff());
    }
    EXPECT_EQ(stats.checks, static_cast<int>(n) * (m + m * m));
}

TEST(EnergyNetwork, PrincipalDerivativesMatchFiniteDifferences2d) { check_derivatives<2>(EnergyRepresentation::Principal); }
TEST(EnergyNetwork, PrincipalDerivativesMatchFiniteDifferences3d) { check_derivatives<3>(EnergyRepresentation::Principal); }
TEST(EnergyNetwork, RawDerivativesMatchFiniteDifferences2d) { check_derivatives<2>(EnergyRepresentation::Raw); }

TEST(EnergyNetwork, PrincipalIsFrameIndifferentIn2d) {
    constexpr int m = 4;
    test::Random random(3);
    const MlpWeights weights = random_mlp(widths<2>(EnergyRepresentation::Principal), 7);
    EnergyNetwork<2> a(weights, EnergyRepresentation::Principal, true, "test");
    EnergyNetwork<2> b(weights, EnergyRepresentation::Principal, true, "test");
    const std::size_t n = 50;
    std::vector<Mat<2>> F0 = states<2>(random, n, 0.4), F(n), F0r(n), Fr(n), Q(n), R(n);
    std::vector<double> h(n);
    for (std::size_t p = 0; p < n; ++p) {
        F[p] = F0[p] + 0.2 * Mat<2>::Random();
        Q[p] = random.rotation<2>();
        R[p] = random.rotation<2>();
        F0r[p] = Q[p] * F0[p] * R[p];
        Fr[p] = Q[p] * F[p] * R[p];
        h[p] = random.uniform(-0.5, 0.0);
    }
    a.set_reference(F0.data(), h.data(), n);
    b.set_reference(F0r.data(), h.data(), n);
    std::vector<double> va(n), ga(n * m), Ha(n * m * m), vb(n), gb(n * m), Hb(n * m * m);
    a.evaluate(F.data(), FusedMlp::Order::Hessian, va.data(), ga.data(), Ha.data());
    b.evaluate(Fr.data(), FusedMlp::Order::Hessian, vb.data(), gb.data(), Hb.data());
    for (std::size_t p = 0; p < n; ++p) {
        EXPECT_NEAR(va[p], vb[p], 1e-12 * (1 + std::abs(va[p])));
        const Mat<2> rotated = Q[p] * unflatten<2>(Eigen::Matrix<double, m, 1>(&ga[p * m])) * R[p];
        EXPECT_LE((rotated - unflatten<2>(Eigen::Matrix<double, m, 1>(&gb[p * m]))).cwiseAbs().maxCoeff(),
                  1e-12 * (1 + rotated.cwiseAbs().maxCoeff()));
    }
}

TEST(EnergyNetwork, MlpInputIsTheFrameOfF0) {
    test::Random random(5);
    const Mat<3> F0 = states<3>(random, 1, 0.3)[0], F = F0 + 0.1 * Mat<3>::Random();
    double row[19], x[13];
    for (int k = 0; k < 9; ++k) {
        row[k] = F(k / 3, k % 3);
        row[9 + k] = F0(k / 3, k % 3);
    }
    row[18] = -0.3;
    EnergyNetwork<3>::mlp_input(EnergyRepresentation::Principal, true, row, x);
    const PolarSVD<3> frame = polar_svd<3>(F0);
    const Mat<3> G = frame.U.transpose() * F * frame.V;
    for (int k = 0; k < 9; ++k) EXPECT_DOUBLE_EQ(x[k], G(k / 3, k % 3));
    for (int i = 0; i < 3; ++i) EXPECT_DOUBLE_EQ(x[9 + i], frame.Sigma[i]);
    EXPECT_EQ(x[12], -0.3);
    // At F = F0, G is diag(Sigma0) to round-off.
    for (int k = 0; k < 9; ++k) row[k] = row[9 + k];
    EnergyNetwork<3>::mlp_input(EnergyRepresentation::Principal, true, row, x);
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) EXPECT_NEAR(x[i * 3 + j], i == j ? frame.Sigma[i] : 0.0, 1e-14);
}

TEST(EnergyNetwork, RejectsAMlpOfTheOtherRepresentation) {
    const MlpWeights raw = random_mlp(widths<2>(EnergyRepresentation::Raw), 1);
    try {
        EnergyNetwork<2>(raw, EnergyRepresentation::Principal, true, "model.pt");
        FAIL() << "expected std::invalid_argument";
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("model.pt: a 2D principal energy network takes 7 inputs, not 9"),
                  std::string::npos)
            << e.what();
    }
}

}  // namespace
}  // namespace pnet
