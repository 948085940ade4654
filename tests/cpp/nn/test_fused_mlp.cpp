// The fused MLP kernel against LibTorch autograd (1e-10 relative), the scalar
// reference, finite differences, and itself across thread counts.
#include <gtest/gtest.h>
#include <omp.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "pnet/nn/fused_mlp.hpp"
#include "pnet/nn/simd.hpp"
#include "pnet/nn/torchscript.hpp"
#include "support/finite_difference.hpp"

namespace pnet {
namespace {

struct Architecture {
    std::vector<int> widths;
    int m;
};

std::vector<double> random_inputs(int input_width, std::size_t rows, unsigned seed, double spread = 1.5) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> uniform(-spread, spread);
    std::vector<double> x(rows * input_width);
    for (double& v : x) v = uniform(rng);
    return x;
}

/// max_r |a_r - b_r|_inf / |b_r|_inf over the rows of a per-row quantity of `size` entries.
double max_relative_difference(const std::vector<double>& a, const std::vector<double>& b, std::size_t size) {
    double worst = 0.0;
    for (std::size_t r = 0; r * size < a.size(); ++r) {
        double diff = 0.0, scale = 0.0;
        for (std::size_t k = r * size; k < (r + 1) * size; ++k) {
            diff = std::max(diff, std::abs(a[k] - b[k]));
            scale = std::max(scale, std::abs(b[k]));
        }
        worst = std::max(worst, diff / std::max(scale, 1e-300));
    }
    return worst;
}

class FusedMlpTest : public ::testing::TestWithParam<std::tuple<Architecture, double>> {};

// Weight scales 1 (PyTorch's initialisation) and 3 (saturating SiLUs, large
// second derivatives); 37 rows: nine full blocks of four and a short one.
TEST_P(FusedMlpTest, MatchesLibTorchAutograd) {
    const auto& [arch, scale] = GetParam();
    const MlpWeights weights = random_mlp(arch.widths, 11, scale);
    const FusedMlp fused(weights, arch.m);
    const TorchAutograd reference = TorchAutograd::from_weights(weights);
    const std::size_t rows = 37;
    const int m = arch.m, in = arch.widths[0];
    const std::vector<double> x = random_inputs(in, rows, 5);
    std::vector<double> v(rows), g(rows * m), H(rows * m * m), rv(rows), rg(rows * m), rH(rows * m * m);
    fused.evaluate(x.data(), rows, FusedMlp::Order::Hessian, v.data(), g.data(), H.data());
    reference.evaluate(x.data(), rows, m, FusedMlp::Order::Hessian, rv.data(), rg.data(), rH.data());
    EXPECT_LT(max_relative_difference(v, rv, 1), 1e-10);
    if (m == 0) return;
    EXPECT_LT(max_relative_difference(g, rg, m), 1e-10);
    EXPECT_LT(max_relative_difference(H, rH, m * m), 1e-10);
    // The lower orders give the same numbers.
    std::vector<double> v1(rows), g1(rows * m), v0(rows);
    fused.evaluate(x.data(), rows, FusedMlp::Order::Gradient, v1.data(), g1.data());
    fused.evaluate(x.data(), rows, FusedMlp::Order::Value, v0.data());
    EXPECT_EQ(v1, v);
    EXPECT_EQ(v0, v);
    EXPECT_EQ(g1, g);
}

TEST_P(FusedMlpTest, ValueMatchesScalarReference) {
    const auto& [arch, scale] = GetParam();
    const MlpWeights weights = random_mlp(arch.widths, 12, scale);
    const FusedMlp fused(weights, arch.m);
    const std::size_t rows = 13;
    const std::vector<double> x = random_inputs(arch.widths[0], rows, 6);
    std::vector<double> v(rows);
    fused.evaluate(x.data(), rows, FusedMlp::Order::Value, v.data());
    for (std::size_t r = 0; r < rows; ++r) {
        const double expected = weights.evaluate_reference(&x[r * arch.widths[0]]);
        EXPECT_NEAR(v[r], expected, 1e-12 * (1.0 + std::abs(expected))) << "row " << r;
    }
}

// Only the architectures with derivatives (the energy nets).
class FusedMlpDerivativeTest : public FusedMlpTest {};

TEST_P(FusedMlpDerivativeTest, DerivativesMatchFiniteDifferences) {
    const auto& [arch, scale] = GetParam();
    ASSERT_GT(arch.m, 0);
    const MlpWeights weights = random_mlp(arch.widths, 13, scale);
    const FusedMlp fused(weights, arch.m);
    const int in = arch.widths[0], m = arch.m;
    const std::vector<double> x = random_inputs(in, 3, 7);
    test::FdStats stats;
    for (int r = 0; r < 3; ++r) {
        const Eigen::VectorXd x0 = Eigen::Map<const Eigen::VectorXd>(&x[r * in], in);
        // The network at x0 with its first m inputs replaced by F, to the given order.
        struct Evaluation {
            double value = 0.0;
            Eigen::VectorXd grad;
            Eigen::MatrixXd hess;
        };
        auto eval = [&](const Eigen::VectorXd& F, FusedMlp::Order order) {
            Eigen::VectorXd row = x0;
            row.head(m) = F;
            Evaluation e{0.0, Eigen::VectorXd(m), Eigen::MatrixXd(m, m)};
            fused.evaluate(row.data(), 1, order, &e.value, e.grad.data(), e.hess.data());
            return e;
        };
        const Evaluation at_x0 = eval(x0.head(m), FusedMlp::Order::Hessian);
        auto f = [&](const Eigen::VectorXd& F) { return eval(F, FusedMlp::Order::Value).value; };
        auto gradient = [&](const Eigen::VectorXd& F) { return eval(F, FusedMlp::Order::Gradient).grad; };
        EXPECT_TRUE(test::check_gradient(f, at_x0.grad, x0.head(m), stats, 1e-6, 1e-6, 1e-3));
        EXPECT_TRUE(test::check_jacobian(gradient, at_x0.hess, x0.head(m), stats, 1e-6, 1e-6, 1e-3));
    }
    EXPECT_EQ(stats.checks, 3 * (m + m * m));
}

// Single precision (eight rows per register): the same network within float's rounding, every
// order, a short last block included (37 rows: four blocks of eight and one of five).
TEST_P(FusedMlpTest, SinglePrecisionMatchesDouble) {
    const auto& [arch, scale] = GetParam();
    const MlpWeights weights = random_mlp(arch.widths, 15, scale);
    const FusedMlp exact(weights, arch.m);
    const FusedMlp single(weights, arch.m, FusedMlp::Precision::Single);
    EXPECT_EQ(single.precision(), FusedMlp::Precision::Single);
    const std::size_t rows = 37;
    const int m = arch.m;
    const std::vector<double> x = random_inputs(arch.widths[0], rows, 9);
    std::vector<double> v(rows), g(rows * m), H(rows * m * m), sv(rows), sg(rows * m), sH(rows * m * m);
    exact.evaluate(x.data(), rows, FusedMlp::Order::Hessian, v.data(), g.data(), H.data());
    single.evaluate(x.data(), rows, FusedMlp::Order::Hessian, sv.data(), sg.data(), sH.data());
    // Each row against the largest entry of its quantity: float rounds at 6e-8, and the sums of up to
    // 128 products (weights rounded too) stay within a few 1e-6; a wrong lane or layer is O(1).
    const double tolerance = scale > 1.0 ? 1e-4 : 2e-5;
    // The value against the largest value (a row whose N nearly cancels has no relative accuracy).
    EXPECT_LT(max_relative_difference(sv, v, rows), tolerance);
    EXPECT_GT(max_relative_difference(sv, v, rows), 0.0);  // it is float arithmetic
    if (m == 0) return;
    EXPECT_LT(max_relative_difference(sg, g, m), tolerance);
    EXPECT_LT(max_relative_difference(sH, H, m * m), tolerance);
    std::vector<double> v0(rows);
    single.evaluate(x.data(), rows, FusedMlp::Order::Value, v0.data());
    EXPECT_EQ(v0, sv);
}

// N(x) - N(x0) as a pass of the change (the line search's values from the reference): in double,
// the difference of two values where they have digits to spare (t >= 1e-2) and the linearization
// grad N . (x - x0) where t is small; in float, within float's rounding of the double change at every
// size, down to changes where float's N(x) - N(x0) is mostly rounding; 0 at x0; a short last block
// (37 rows) and 1 or 2 threads alike.
TEST_P(FusedMlpTest, DifferenceIsAccurateRelativeToTheChange) {
    const auto& [arch, scale] = GetParam();
    const MlpWeights weights = random_mlp(arch.widths, 16, scale);
    const int m = arch.m, in = arch.widths[0];
    const FusedMlp exact(weights, m);
    const FusedMlp single(weights, m, FusedMlp::Precision::Single);
    const std::size_t rows = 37;
    const std::vector<double> x0 = random_inputs(in, rows, 17);
    const std::vector<double> u = random_inputs(in, rows, 18, 1.0);
    const int moved = m > 0 ? m : in;  // the energies' F entries; every input of a return map's net
    const double tolerance = scale > 1.0 ? 1e-4 : 2e-5;
    std::vector<double> change(rows), single_change(rows), v(rows), v0(rows), g(rows * std::max(m, 1));
    for (double t : {1.0, 1e-2, 1e-4, 1e-6}) {
        SCOPED_TRACE("t = " + std::to_string(t));
        std::vector<double> x = x0;
        for (std::size_t r = 0; r < rows; ++r)
            for (int i = 0; i < moved; ++i) x[r * in + i] += t * u[r * in + i];
        exact.difference(x.data(), x0.data(), rows, change.data());
        single.difference(x.data(), x0.data(), rows, single_change.data());
        if (t >= 1e-2) {
            exact.evaluate(x.data(), rows, FusedMlp::Order::Value, v.data());
            exact.evaluate(x0.data(), rows, FusedMlp::Order::Value, v0.data());
            std::vector<double> subtracted(rows);
            for (std::size_t r = 0; r < rows; ++r) subtracted[r] = v[r] - v0[r];
            // The subtraction's own rounding: 1e-16 of N (up to about 10 here) over the change.
            EXPECT_LT(max_relative_difference(change, subtracted, rows), 1e-12 + 1e-13 / t);
        } else if (m > 0) {
            exact.evaluate(x0.data(), rows, FusedMlp::Order::Gradient, v0.data(), g.data());
            std::vector<double> linear(rows, 0.0);
            for (std::size_t r = 0; r < rows; ++r)
                for (int i = 0; i < m; ++i) linear[r] += g[r * m + i] * t * u[r * in + i];
            EXPECT_LT(max_relative_difference(change, linear, rows), 1e3 * t);  // the second-order term
        }
        EXPECT_LT(max_relative_difference(single_change, change, rows), tolerance);
        if (t <= 1e-6) {
            // Float's values subtracted: their rounding (6e-8 of N) against a change of 1e-6.
            std::vector<double> sv(rows), sv0(rows), subtracted(rows);
            single.evaluate(x.data(), rows, FusedMlp::Order::Value, sv.data());
            single.evaluate(x0.data(), rows, FusedMlp::Order::Value, sv0.data());
            for (std::size_t r = 0; r < rows; ++r) subtracted[r] = sv[r] - sv0[r];
            EXPECT_GT(max_relative_difference(subtracted, change, rows),
                      100.0 * max_relative_difference(single_change, change, rows));
        }
    }
    single.difference(x0.data(), x0.data(), rows, single_change.data());
    exact.difference(x0.data(), x0.data(), rows, change.data());
    for (std::size_t r = 0; r < rows; ++r) {
        EXPECT_EQ(single_change[r], 0.0);
        EXPECT_EQ(change[r], 0.0);
    }
    const std::size_t many = 1001;
    const std::vector<double> y0 = random_inputs(in, many, 19), y = random_inputs(in, many, 20);
    std::vector<double> by_threads[2];
    for (int threads : {1, 2}) {
        omp_set_num_threads(threads);
        by_threads[threads - 1].resize(many);
        single.difference(y.data(), y0.data(), many, by_threads[threads - 1].data());
    }
    omp_set_num_threads(omp_get_num_procs());
    EXPECT_EQ(by_threads[0], by_threads[1]);
}

// The SiLU's change against long double, relative to |dz| (the float and double packs), over
// pre-activations and changes from 1e-7 to 40: finite and accurate where the two sigmoids are far
// apart (z0 = -30, z0 + dz = 10: a denominator written as 1 + (1 - s0)(q - 1) was 0 there; z0 = 30,
// z0 + dz = -10: 1 - s0 is all rounding, so t0 = e^-z0 s0).
template <class S>
void check_silu_change(double tolerance) {
    using V = typename simd::Pack<S>::V;
    constexpr int lanes = simd::Pack<S>::kLanes;
    auto silu = [](long double z) { return z / (1.0L + std::exp(-z)); };
    double worst = 0.0;
    for (double z0 : {-30.0, -17.0, -5.0, -1.2785, 0.0, 0.7, 4.0, 17.0, 30.0})
        for (double magnitude : {1e-7, 1e-4, 0.3, 0.6, 3.0, 40.0})
            for (double sign : {-1.0, 1.0}) {
                const double dz = sign * magnitude;
                V z = simd::splat<V>(static_cast<S>(z0)), d = simd::splat<V>(static_cast<S>(dz));
                const V change = simd::silu_change(z, d).change;
                // The reference at the pack's own rounding of z0 and dz.
                const long double zr = static_cast<long double>(z[0]), dr = static_cast<long double>(d[0]);
                const long double exact = silu(zr + dr) - silu(zr);
                // The reference's own rounding: long double's of the two values it subtracts.
                const long double rounding =
                    4 * std::numeric_limits<long double>::epsilon() * (std::abs(silu(zr + dr)) + std::abs(silu(zr)));
                for (int l = 0; l < lanes; ++l) ASSERT_TRUE(std::isfinite(change[l])) << z0 << " " << dz;
                const long double error = std::max(0.0L, std::abs(change[0] - exact) - rounding);
                worst = std::max(worst, static_cast<double>(error / std::abs(dr)));
            }
    EXPECT_LT(worst, tolerance);
}

TEST(Simd, SiluChangeIsAccurateRelativeToTheChangeAndFinite) {
    check_silu_change<float>(2e-6 * 30);   // float's rounding of z0 s0 terms up to |z0| = 30
    check_silu_change<double>(1e-14 * 30);
}

TEST_P(FusedMlpTest, ThreadCountDoesNotChangeResults) {
    const auto& [arch, scale] = GetParam();
    const MlpWeights weights = random_mlp(arch.widths, 14, scale);
    const FusedMlp fused(weights, arch.m);
    const int m = arch.m;
    const std::size_t rows = 1001;
    const std::vector<double> x = random_inputs(arch.widths[0], rows, 8);
    std::vector<double> results[2][3];
    for (int threads : {1, 2}) {
        omp_set_num_threads(threads);
        auto& out = results[threads - 1];
        out[0].resize(rows);
        out[1].resize(rows * m);
        out[2].resize(rows * m * m);
        fused.evaluate(x.data(), rows, FusedMlp::Order::Hessian, out[0].data(), out[1].data(), out[2].data());
    }
    omp_set_num_threads(omp_get_num_procs());
    for (int k = 0; k < 3; ++k) EXPECT_EQ(results[0][k], results[1][k]);
    const FusedMlp single(weights, arch.m, FusedMlp::Precision::Single);
    for (int threads : {1, 2}) {
        omp_set_num_threads(threads);
        auto& out = results[threads - 1];
        single.evaluate(x.data(), rows, FusedMlp::Order::Hessian, out[0].data(), out[1].data(), out[2].data());
    }
    omp_set_num_threads(omp_get_num_procs());
    for (int k = 0; k < 3; ++k) EXPECT_EQ(results[0][k], results[1][k]);
}

INSTANTIATE_TEST_SUITE_P(
    Architectures, FusedMlpTest,
    ::testing::Combine(::testing::Values(Architecture{{8, 32, 32, 32, 1}, 4}, Architecture{{9, 32, 32, 32, 1}, 4},
                                         Architecture{{18, 64, 64, 64, 1}, 9},
                                         Architecture{{19, 64, 64, 64, 1}, 9}, Architecture{{3, 32, 32, 32, 1}, 0},
                                         Architecture{{4, 64, 64, 64, 1}, 0}),
                       ::testing::Values(1.0, 3.0)));

INSTANTIATE_TEST_SUITE_P(
    EnergyArchitectures, FusedMlpDerivativeTest,
    ::testing::Combine(::testing::Values(Architecture{{8, 32, 32, 32, 1}, 4}, Architecture{{9, 32, 32, 32, 1}, 4},
                                         Architecture{{18, 64, 64, 64, 1}, 9},
                                         Architecture{{19, 64, 64, 64, 1}, 9}),
                       ::testing::Values(1.0, 3.0)));

// The principal-input energies (derivatives in the d^2 entries of G), Table 2's width and twice it.
INSTANTIATE_TEST_SUITE_P(
    PrincipalArchitectures, FusedMlpTest,
    ::testing::Combine(::testing::Values(Architecture{{7, 32, 32, 32, 1}, 4}, Architecture{{13, 64, 64, 64, 1}, 9},
                                         Architecture{{6, 64, 64, 64, 1}, 4}, Architecture{{7, 64, 64, 64, 1}, 4},
                                         Architecture{{12, 128, 128, 128, 1}, 9},
                                         Architecture{{13, 128, 128, 128, 1}, 9}),
                       ::testing::Values(1.0)));

INSTANTIATE_TEST_SUITE_P(
    PrincipalArchitectures, FusedMlpDerivativeTest,
    ::testing::Combine(::testing::Values(Architecture{{7, 64, 64, 64, 1}, 4}, Architecture{{13, 128, 128, 128, 1}, 9}),
                       ::testing::Values(1.0)));

// The parametric energies (train.py --parametric): principal inputs, h where the material hardens, then
// the material's parameters: sand 2D, metal 2D, snow 2D, sand 3D, snow 3D.
INSTANTIATE_TEST_SUITE_P(
    ParametricArchitectures, FusedMlpTest,
    ::testing::Combine(::testing::Values(Architecture{{8, 64, 64, 64, 1}, 4}, Architecture{{9, 64, 64, 64, 1}, 4},
                                         Architecture{{11, 64, 64, 64, 1}, 4},
                                         Architecture{{14, 128, 128, 128, 1}, 9},
                                         Architecture{{17, 128, 128, 128, 1}, 9}),
                       ::testing::Values(1.0)));

TEST(FusedMlp, RejectsArchitecturesWithoutAKernel) {
    EXPECT_FALSE(FusedMlp::supports({9, 16, 16, 16, 1}, 4));
    EXPECT_FALSE(FusedMlp::supports({9, 32, 32, 1}, 4));
    EXPECT_FALSE(FusedMlp::supports({9, 32, 32, 32, 1}, 9));
    try {
        FusedMlp(random_mlp({9, 16, 16, 16, 1}, 1), 4);
        FAIL() << "expected std::invalid_argument";
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("[9, 16, 16, 16, 1]"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("compiled"), std::string::npos) << e.what();
    }
}

TEST(FusedMlp, RequiresTheOutputArraysOfTheOrder) {
    const FusedMlp fused(random_mlp({9, 32, 32, 32, 1}, 1), 4);
    const std::vector<double> x(9, 0.1);
    double v, g[4];
    EXPECT_THROW(fused.evaluate(x.data(), 1, FusedMlp::Order::Gradient, &v), std::invalid_argument);
    EXPECT_THROW(fused.evaluate(x.data(), 1, FusedMlp::Order::Hessian, &v, g), std::invalid_argument);
    EXPECT_NO_THROW(fused.evaluate(x.data(), 1, FusedMlp::Order::Value, &v));
}

TEST(MlpWeights, ValidateNamesTheProblem) {
    MlpWeights w = random_mlp({9, 32, 32, 32, 1}, 1);
    w.weight[1][5] = std::nan("");
    try {
        w.validate("net.pt");
        FAIL() << "expected std::invalid_argument";
    } catch (const std::invalid_argument& e) {
        EXPECT_EQ(std::string(e.what()), "net.pt: layer 1 weight entry (0, 5) is not finite");
    }
    w = random_mlp({9, 32, 32, 32, 1}, 1);
    w.bias[2].pop_back();
    EXPECT_THROW(w.validate("net.pt"), std::invalid_argument);
    w = random_mlp({9, 32, 32, 32, 1}, 1);
    w.widths.back() = 2;
    EXPECT_THROW(w.validate("net.pt"), std::invalid_argument);
}

}  // namespace
}  // namespace pnet
