// The shared Newton / PCG / line-search solver on objectives with known
// minimizers, and its failure reports.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <vector>

#include "pnet/solver/newton.hpp"
#include "pnet/solver/pcg.hpp"
#include "support/finite_difference.hpp"
#include "support/random.hpp"

namespace pnet {
namespace {

/// E(x) = 1/2 x^T A x - b^T x with A SPD (dense, for the tests).
class Quadratic : public Objective {
public:
    Quadratic(Eigen::MatrixXd A, VecX b) : A_(std::move(A)), b_(std::move(b)) {}
    Eigen::Index size() const override { return b_.size(); }
    double value(const VecX& x) override { return 0.5 * x.dot(A_ * x) - b_.dot(x); }
    double value_gradient(const VecX& x, VecX& g) override {
        g = A_ * x - b_;
        return value(x);
    }
    void prepare_hessian(const VecX&) override {}
    void hessian_multiply(const VecX& d, VecX& out) const override { out = A_ * d; }
    void hessian_diagonal(VecX& diagonal) const override { diagonal = A_.diagonal(); }

private:
    Eigen::MatrixXd A_;
    VecX b_;
};

/// A strictly convex, non-quadratic chain (the shape of an incremental
/// potential: inertia plus a convex elastic term between neighbours):
/// E(x) = sum m_i/2 (x_i - c_i)^2 + k sum log cosh(x_i - x_{i+1}) + sum x_i^4 / 4.
class Chain : public Objective {
public:
    explicit Chain(int n, unsigned seed) : m_(n), c_(n) {
        test::Random rng(seed);
        for (int i = 0; i < n; ++i) {
            m_[i] = 0.5 + rng.uniform(0.0, 1.0);
            c_[i] = rng.uniform(-3.0, 3.0);
        }
    }
    Eigen::Index size() const override { return m_.size(); }
    double value(const VecX& x) override {
        ++value_calls;
        double e = 0.0;
        for (Eigen::Index i = 0; i < x.size(); ++i) e += 0.5 * m_[i] * std::pow(x[i] - c_[i], 2) + 0.25 * std::pow(x[i], 4);
        for (Eigen::Index i = 0; i + 1 < x.size(); ++i) e += k_ * std::log(std::cosh(x[i] - x[i + 1]));
        return e;
    }
    double value_gradient(const VecX& x, VecX& g) override {
        g.setZero(x.size());
        for (Eigen::Index i = 0; i < x.size(); ++i) g[i] = m_[i] * (x[i] - c_[i]) + std::pow(x[i], 3);
        for (Eigen::Index i = 0; i + 1 < x.size(); ++i) {
            const double t = k_ * std::tanh(x[i] - x[i + 1]);
            g[i] += t;
            g[i + 1] -= t;
        }
        const double e = value(x);
        energies.push_back(e);
        return e;
    }
    void prepare_hessian(const VecX& x) override {
        x_ = x;
        ++hessians;
    }
    void hessian_multiply(const VecX& d, VecX& out) const override {
        out.setZero(d.size());
        for (Eigen::Index i = 0; i < d.size(); ++i) out[i] = (m_[i] + 3.0 * x_[i] * x_[i]) * d[i];
        for (Eigen::Index i = 0; i + 1 < d.size(); ++i) {
            const double s = k_ / std::pow(std::cosh(x_[i] - x_[i + 1]), 2);
            out[i] += s * (d[i] - d[i + 1]);
            out[i + 1] -= s * (d[i] - d[i + 1]);
        }
    }
    void hessian_diagonal(VecX& diagonal) const override {
        diagonal.resize(x_.size());
        for (Eigen::Index i = 0; i < x_.size(); ++i) {
            diagonal[i] = m_[i] + 3.0 * x_[i] * x_[i];
            if (i > 0) diagonal[i] += k_ / std::pow(std::cosh(x_[i - 1] - x_[i]), 2);
            if (i + 1 < x_.size()) diagonal[i] += k_ / std::pow(std::cosh(x_[i] - x_[i + 1]), 2);
        }
    }
    int value_calls = 0, hessians = 0;
    std::vector<double> energies;  // at every accepted iterate

private:
    VecX m_, c_, x_;
    double k_ = 40.0;
};

TEST(Pcg, SolvesASymmetricPositiveDefiniteSystem) {
    test::Random rng(3);
    const int n = 40;
    Eigen::MatrixXd M(n, n);
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) M(i, j) = rng.uniform(-1.0, 1.0);
    const Eigen::MatrixXd A = M * M.transpose() + n * Eigen::MatrixXd::Identity(n, n);
    VecX b(n);
    for (int i = 0; i < n; ++i) b[i] = rng.uniform(-1.0, 1.0);
    Quadratic q(A, b);
    for (int block : {1, 2}) {
        VecX blocks(n * block);
        for (int k = 0; k < n / block; ++k)
            for (int i = 0; i < block; ++i)
                for (int j = 0; j < block; ++j) blocks[(k * block + i) * block + j] = A(k * block + i, k * block + j);
        const Preconditioner m =
            block == 1 ? Preconditioner::jacobi(A.diagonal()) : Preconditioner::block_jacobi(blocks, block);
        VecX d;
        const PcgResult r = solve_pcg(q, b, m, d, 1e-12, 200);
        EXPECT_TRUE(r.converged) << block;
        EXPECT_GT(r.iterations, 1);
        EXPECT_LE(r.iterations, n + 5);
        EXPECT_LT((A * d - b).norm(), 1e-11 * b.norm());
        EXPECT_NEAR(r.relative_residual, (A * d - b).norm() / b.norm(), 1e-12);
    }
}

TEST(Pcg, BlockJacobiSolvesABlockDiagonalSystemInOneIteration) {
    test::Random rng(5);
    const int n = 12;
    Eigen::MatrixXd A = Eigen::MatrixXd::Zero(n, n);
    VecX blocks(n * 3), b(n);
    for (int k = 0; k < n / 3; ++k) {
        Eigen::Matrix3d M;
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) M(i, j) = rng.uniform(-1.0, 1.0);
        const Eigen::Matrix3d B = M * M.transpose() + 0.1 * Eigen::Matrix3d::Identity();
        A.block<3, 3>(3 * k, 3 * k) = B;
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) blocks[9 * k + 3 * i + j] = B(i, j);
    }
    for (int i = 0; i < n; ++i) b[i] = rng.uniform(-1.0, 1.0);
    Quadratic q(A, b);
    VecX d;
    const PcgResult block = solve_pcg(q, b, Preconditioner::block_jacobi(blocks, 3), d, 1e-12, 50);
    EXPECT_TRUE(block.converged);
    EXPECT_EQ(block.iterations, 1);
    EXPECT_LT((A * d - b).norm(), 1e-10 * b.norm());
    const PcgResult jacobi = solve_pcg(q, b, Preconditioner::jacobi(A.diagonal()), d, 1e-12, 50);
    EXPECT_GT(jacobi.iterations, 1);
    // A block that is not positive definite falls back to its diagonal.
    blocks.head<9>() << 1, 2, 0, 2, 1, 0, 0, 0, 1;
    VecX z;
    Preconditioner::block_jacobi(blocks, 3).apply(VecX::Ones(n), z);
    EXPECT_DOUBLE_EQ(z[0], 1.0);
    EXPECT_DOUBLE_EQ(z[1], 1.0);
}

TEST(Newton, QuadraticIsSolvedInOneIteration) {
    test::Random rng(4);
    const int n = 25;
    Eigen::MatrixXd M(n, n);
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) M(i, j) = rng.uniform(-1.0, 1.0);
    const Eigen::MatrixXd A = M * M.transpose() + Eigen::MatrixXd::Identity(n, n);
    VecX b(n);
    for (int i = 0; i < n; ++i) b[i] = rng.uniform(-1.0, 1.0);
    Quadratic q(A, b);
    VecX x = VecX::Zero(n);
    NewtonOptions options;
    options.tolerance = 1e-9;
    options.max_cg_iterations = 1000;
    options.cg_tolerance = 1e-13;  // an exact linear solve: Newton is exact on a quadratic
    const NewtonStats s = minimize(q, x, options);
    EXPECT_TRUE(s.converged);
    EXPECT_EQ(s.iterations, 1);
    EXPECT_EQ(s.line_search_steps, 1);  // the full step is accepted
    EXPECT_LT((x - A.llt().solve(b)).norm(), 1e-8);
    EXPECT_LT(s.energy, s.initial_energy);
}

TEST(Newton, ConvexChainConvergesAndEveryStepLowersTheEnergy) {
    for (unsigned seed : {1u, 2u, 3u}) {
        Chain chain(60, seed);
        VecX x = VecX::Zero(60);
        // The analytic gradient and Hessian of the test objective itself, by the shared harness.
        test::FdStats fd;
        VecX g;
        const VecX x_probe = VecX::LinSpaced(60, -1.0, 1.0);
        chain.value_gradient(x_probe, g);
        chain.prepare_hessian(x_probe);
        Eigen::MatrixXd H(60, 60);
        for (int k = 0; k < 60; ++k) {
            VecX e = VecX::Unit(60, k), col;
            chain.hessian_multiply(e, col);
            H.col(k) = col;
        }
        auto grad_of = [&](const VecX& y) {
            VecX gy;
            chain.value_gradient(y, gy);
            return gy;
        };
        EXPECT_TRUE(test::check_jacobian(grad_of, H, x_probe, fd));
        EXPECT_EQ(fd.checks, 60 * 60);
        chain.energies.clear();

        NewtonOptions options;
        options.tolerance = 1e-10;
        const NewtonStats s = minimize(chain, x, options, "chain");
        EXPECT_TRUE(s.converged) << "seed " << seed << ", residual " << s.residual;
        EXPECT_GE(s.iterations, 2);
        EXPECT_LT(s.iterations, 40);
        ASSERT_EQ(static_cast<int>(chain.energies.size()), s.iterations + 1);
        // Every accepted step lowers E, down to E's round-off (where the solver ranks steps by |g|).
        int strict = 0;
        for (std::size_t i = 1; i < chain.energies.size(); ++i) {
            EXPECT_LE(chain.energies[i], chain.energies[i - 1] + 1e-13 * std::abs(chain.energies[i - 1]));
            strict += chain.energies[i] < chain.energies[i - 1];
        }
        EXPECT_GE(strict, s.iterations / 2);
        VecX g_final;
        chain.value_gradient(x, g_final);
        EXPECT_LT(g_final.lpNorm<Eigen::Infinity>(), 1e-10) << "seed " << seed << " stats residual " << s.residual << " iterations " << s.iterations;
        // One Hessian per accepted iterate (the start included: value_gradient_hessian) and the probe.
        EXPECT_EQ(chain.hessians, s.iterations + 2);
    }
}

// A lazy Hessian reaches the same minimizer with fewer Hessian passes, and
// every accepted step still lowers E.
TEST(Newton, LazyHessianConvergesToTheSameMinimizerWithFewerHessians) {
    for (unsigned seed : {1u, 2u, 3u}) {
        Chain exact(60, seed), lazy(60, seed);
        VecX x_exact = VecX::Zero(60), x_lazy = VecX::Zero(60);
        NewtonOptions options;
        options.tolerance = 1e-10;
        const NewtonStats s_exact = minimize(exact, x_exact, options, "chain");
        options.lazy_hessian = 0.5;
        const NewtonStats s_lazy = minimize(lazy, x_lazy, options, "chain");
        EXPECT_TRUE(s_lazy.converged) << "seed " << seed;
        EXPECT_LT((x_lazy - x_exact).lpNorm<Eigen::Infinity>(), 1e-8);
        EXPECT_LT(lazy.hessians, s_lazy.iterations + 1) << "some iterates kept the Hessian";
        EXPECT_LT(lazy.hessians, exact.hessians);
        for (std::size_t i = 1; i < lazy.energies.size(); ++i)
            EXPECT_LE(lazy.energies[i], lazy.energies[i - 1] + 1e-13 * std::abs(lazy.energies[i - 1]));
        EXPECT_TRUE(s_exact.converged);
    }
}

TEST(Newton, ResidualScaleTurnsForcesIntoVelocities) {
    Chain chain(10, 5);
    VecX x = VecX::Zero(10), g;
    chain.value_gradient(x, g);
    NewtonOptions options;
    options.residual_scale = VecX::Constant(10, 0.5);
    options.max_iterations = 0;
    const NewtonStats s = minimize(chain, x, options);
    EXPECT_DOUBLE_EQ(s.initial_residual, 0.5 * g.lpNorm<Eigen::Infinity>());
    EXPECT_FALSE(s.converged);
    options.residual_scale = VecX::Ones(3);
    EXPECT_THROW(minimize(chain, x, options), std::invalid_argument);
}

/// An objective whose gradient has the wrong sign: every Newton direction goes uphill.
class WrongGradient : public Chain {
public:
    WrongGradient() : Chain(8, 6) {}
    double value_gradient(const VecX& x, VecX& g) override {
        const double e = Chain::value_gradient(x, g);
        g = -g;
        return e;
    }
};

/// An objective that is NaN everywhere but at the start.
class NanAway : public Chain {
public:
    NanAway() : Chain(8, 7) {}
    double value(const VecX& x) override { return x.isZero() ? Chain::value(x) : std::nan(""); }
};

TEST(Newton, LineSearchStallIsReportedWithContextIterationAndResidual) {
    WrongGradient objective;
    VecX x = VecX::Zero(8);
    try {
        minimize(objective, x, NewtonOptions{}, "step 12");
        FAIL() << "no error";
    } catch (const NewtonError& e) {
        const std::string what = e.what();
        EXPECT_EQ(what.rfind("step 12: Newton iteration 0 (residual ", 0), 0u) << what;
        EXPECT_NE(what.find("line search stalled after 40 halvings"), std::string::npos) << what;
    }
    EXPECT_TRUE(x.isZero()) << "a failed solve leaves x at the last accepted iterate";
}

TEST(Newton, NonFiniteEnergyIsReported) {
    NanAway objective;
    VecX x = VecX::Zero(8);
    EXPECT_THROW(minimize(objective, x, NewtonOptions{}), NewtonError);
    VecX bad = VecX::Constant(8, std::nan(""));
    Chain chain(8, 8);
    try {
        minimize(chain, bad, NewtonOptions{}, "step 3");
        FAIL() << "no error";
    } catch (const NewtonError& e) {
        EXPECT_NE(std::string(e.what()).find("not finite at the start"), std::string::npos) << e.what();
    }
}

}  // namespace
}  // namespace pnet
