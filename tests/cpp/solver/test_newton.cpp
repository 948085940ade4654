// The shared Newton / PCG / line-search solver on objectives with known
// minimizers, and its failure reports.
#include <gtest/gtest.h>

#include <Eigen/Dense>
#include <cmath>
#include <limits>
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
        for (Eigen::Index i = 0; i < x.size(); ++i)
            e += 0.5 * m_[i] * std::pow(x[i] - c_[i], 2) + 0.25 * std::pow(x[i], 4);
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
    /// Moves every target c_i by `by` (the next problem of a sequence, as F0 moves in a fixed point).
    void shift_targets(double by) { c_.array() += by; }
    int value_calls = 0, hessians = 0;
    std::vector<double> energies;  // at every accepted iterate

private:
    VecX m_, c_, x_;
    double k_ = 40.0;
};

/// M M^T + shift I with M's entries ~ U[-1, 1]: a random symmetric positive definite n x n matrix.
Eigen::MatrixXd random_spd(test::Random& rng, int n, double shift) {
    const Eigen::MatrixXd M = rng.uniform_matrix(n, n, -1.0, 1.0);
    return M * M.transpose() + shift * Eigen::MatrixXd::Identity(n, n);
}

TEST(Pcg, SolvesASymmetricPositiveDefiniteSystem) {
    test::Random rng(3);
    const int n = 40;
    const Eigen::MatrixXd A = random_spd(rng, n, n);
    const VecX b = rng.uniform_vector(n, -1.0, 1.0);
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

// BiCGSTAB (Objective::hessian_symmetric false): H = S + K with S symmetric positive definite and K
// skew, the shape of a tangent that keeps the skew part of non-associative flow; the products it
// counts are two per iteration.
TEST(Bicgstab, SolvesAPositiveRealNonSymmetricSystem) {
    test::Random rng(5);
    const int n = 40;
    Eigen::MatrixXd M(n, n), N(n, n);
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) {
            M(i, j) = rng.uniform(-1.0, 1.0);
            N(i, j) = rng.uniform(-1.0, 1.0);
        }
    const Eigen::MatrixXd S = M * M.transpose() + n * Eigen::MatrixXd::Identity(n, n);
    const Eigen::MatrixXd K = 4.0 * (N - N.transpose());
    const Eigen::MatrixXd A = S + K;
    ASSERT_GT((A - A.transpose()).norm(), 0.5 * A.norm()) << "a strongly non-symmetric test matrix";
    const VecX b = rng.uniform_vector(n, -1.0, 1.0);
    Quadratic q(A, b);
    VecX d;
    BicgstabWorkspace work;
    const PcgResult r = solve_bicgstab(q, b, Preconditioner::jacobi(A.diagonal()), d, 1e-12, 400, work);
    EXPECT_TRUE(r.converged);
    EXPECT_EQ(r.iterations % 2, 0) << "two products per iteration";
    EXPECT_LT((A * d - b).norm(), 1e-11 * b.norm());
    EXPECT_NEAR(r.relative_residual, (A * d - b).norm() / b.norm(), 1e-11);
    // PCG, which assumes symmetry, does not solve it.
    VecX e;
    solve_pcg(q, b, Preconditioner::jacobi(A.diagonal()), e, 1e-12, 400);
    EXPECT_GT((A * e - b).norm(), 1e-6 * b.norm());
    // With b = -g the solution descends: g . d = -(A d) . d = -d . S d < 0.
    EXPECT_NEAR(b.dot(d), d.dot(S * d), 1e-9 * d.dot(S * d));
    EXPECT_GT(b.dot(d), 0.0);
}

/// S + K with S symmetric positive definite and K skew (4 (N - N^T)): the shape of a tangent that
/// keeps the skew part of non-associative flow.
Eigen::MatrixXd positive_real_matrix(test::Random& rng, int n) {
    const Eigen::MatrixXd M = rng.uniform_matrix(n, n, -1.0, 1.0), N = rng.uniform_matrix(n, n, -1.0, 1.0);
    return M * M.transpose() + n * Eigen::MatrixXd::Identity(n, n) + 4.0 * (N - N.transpose());
}

// GMRES solves the same kind of system to round-off, through its restarts (40 unknowns, about 26
// products unrestarted, restarted every 10), and counts one product per iteration plus one per
// restart's true residual.
TEST(Gmres, SolvesAPositiveRealNonSymmetricSystemThroughItsRestarts) {
    test::Random rng(5);
    const int n = 40;
    const Eigen::MatrixXd A = positive_real_matrix(rng, n);
    ASSERT_GT((A - A.transpose()).norm(), 0.5 * A.norm()) << "a strongly non-symmetric test matrix";
    const VecX b = rng.uniform_vector(n, -1.0, 1.0);
    Quadratic q(A, b);
    VecX d;
    GmresWorkspace work;
    const PcgResult r = solve_gmres(q, b, Preconditioner::jacobi(A.diagonal()), d, 1e-12, 400, work, 10);
    EXPECT_TRUE(r.converged);
    EXPECT_GT(r.iterations, 22) << "restarted at least twice";
    EXPECT_LT((A * d - b).norm(), 1e-11 * b.norm());
    EXPECT_NEAR(r.relative_residual, (A * d - b).norm() / b.norm(), 1e-10);
    // Unrestarted, GMRES ends within n products (the Krylov space is then the whole space).
    VecX e;
    const PcgResult full = solve_gmres(q, b, Preconditioner::jacobi(A.diagonal()), e, 1e-12, 400, work, 400);
    EXPECT_TRUE(full.converged);
    EXPECT_LE(full.iterations, n);
    EXPECT_LT((A * e - b).norm(), 1e-11 * b.norm());
}

// GMRES's iterate after k products minimizes |b - A d|_W over the Krylov space that BiCGSTAB's iterate
// after k products lies in (both right-preconditioned: d in M^-1 K_k(A M^-1, b)), so its residual is
// never larger, and it never grows with k: in the Euclidean norm (W = I) and in a weighted one (what
// Newton passes, 1 / diag(H)).
TEST(Gmres, ItsResidualAfterKProductsIsAtMostBicgstabs) {
    test::Random rng(7);
    const int n = 60;
    const Eigen::MatrixXd A = positive_real_matrix(rng, n);
    const VecX b = rng.uniform_vector(n, -1.0, 1.0);
    Quadratic q(A, b);
    const Preconditioner m = Preconditioner::jacobi(A.diagonal());
    GmresWorkspace gmres;
    BicgstabWorkspace bicgstab;
    const VecX weight = rng.uniform_vector(n, 0.1, 10.0);
    for (const VecX* w : {static_cast<const VecX*>(nullptr), &weight}) {
        const VecX W = w ? *w : VecX::Ones(n);
        auto norm = [&](const VecX& r) { return std::sqrt(r.dot(W.cwiseProduct(r))); };
        double last = norm(b);
        for (int k : {2, 4, 6, 8, 12, 16}) {
            VecX d, e;
            const PcgResult g = solve_gmres(q, b, m, d, 0.0, k, gmres, 30, w);
            const PcgResult s = solve_bicgstab(q, b, m, e, 0.0, k, bicgstab);
            ASSERT_EQ(g.iterations, k);
            ASSERT_EQ(s.iterations, k);
            const double rg = norm(VecX(A * d - b)), rs = norm(VecX(A * e - b));
            EXPECT_LE(rg, rs * (1.0 + 1e-10)) << k << " products, weighted " << (w != nullptr);
            EXPECT_LE(rg, last * (1.0 + 1e-10)) << k << " products, weighted " << (w != nullptr);
            EXPECT_NEAR(g.relative_residual, rg / norm(b), 1e-10);
            last = rg;
        }
    }
    // The weight changes the iterate: GMRES minimizes the norm it is given.
    VecX plain, weighted;
    solve_gmres(q, b, m, plain, 0.0, 6, gmres, 30);
    solve_gmres(q, b, m, weighted, 0.0, 6, gmres, 30, &weight);
    auto weighted_norm = [&](const VecX& r) { return std::sqrt(r.dot(weight.cwiseProduct(r))); };
    EXPECT_LT(weighted_norm(VecX(A * weighted - b)), weighted_norm(VecX(A * plain - b)));
    EXPECT_LT((A * plain - b).norm(), (A * weighted - b).norm());
    // A weight that is no norm (zero, non-finite) is not used: the Euclidean solve, not NaN.
    for (const double bad : {0.0, std::numeric_limits<double>::quiet_NaN()}) {
        const VecX no_norm = VecX::Constant(n, bad);
        VecX e;
        const PcgResult r = solve_gmres(q, b, m, e, 1e-10, 200, gmres, 30, &no_norm);
        EXPECT_TRUE(r.converged) << bad;
        EXPECT_LT((A * e - b).norm(), 1e-9 * b.norm()) << bad;
    }
}

TEST(Pcg, BlockJacobiSolvesABlockDiagonalSystemInOneIteration) {
    test::Random rng(5);
    const int n = 12;
    Eigen::MatrixXd A = Eigen::MatrixXd::Zero(n, n);
    VecX blocks(n * 3);
    for (int k = 0; k < n / 3; ++k) {
        const Eigen::Matrix3d M = rng.uniform_matrix(3, 3, -1.0, 1.0);
        const Eigen::Matrix3d B = M * M.transpose() + 0.1 * Eigen::Matrix3d::Identity();
        A.block<3, 3>(3 * k, 3 * k) = B;
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j) blocks[9 * k + 3 * i + j] = B(i, j);
    }
    const VecX b = rng.uniform_vector(n, -1.0, 1.0);
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
    const Eigen::MatrixXd A = random_spd(rng, n, 1.0);
    const VecX b = rng.uniform_vector(n, -1.0, 1.0);
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
        EXPECT_LT(g_final.lpNorm<Eigen::Infinity>(), 1e-10)
            << "seed " << seed << " stats residual " << s.residual << " iterations " << s.iterations;
        // The solver's count of Hessian passes is the objective's (plus the probe above).
        EXPECT_EQ(chain.hessians, s.hessians + 1);
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

// A solve that starts from the Hessian the previous solve prepared (the fixed point's later solves,
// NewtonOptions::keep_prepared_hessian) reaches the same minimizer as a fresh start, with at least
// one Hessian pass fewer (none at the start); a start already converged costs no Hessian pass.
TEST(Newton, KeptHessianStartReachesTheSameMinimizer) {
    for (unsigned seed : {1u, 2u, 3u})
        for (double shift : {0.01, 0.3}) {
            Chain fresh(60, seed), kept(60, seed);
            VecX x_fresh = VecX::Zero(60), x_kept = VecX::Zero(60);
            NewtonOptions options;
            options.tolerance = 1e-10;
            options.lazy_hessian = 0.5;
            minimize(fresh, x_fresh, options, "chain");
            minimize(kept, x_kept, options, "chain");
            ASSERT_EQ(x_fresh, x_kept);
            fresh.shift_targets(shift);
            kept.shift_targets(shift);
            const int fresh_before = fresh.hessians, kept_before = kept.hessians;
            kept.energies.clear();  // those of the last problem
            const NewtonStats s_fresh = minimize(fresh, x_fresh, options, "chain");
            options.keep_prepared_hessian = true;
            const NewtonStats s_kept = minimize(kept, x_kept, options, "chain");
            SCOPED_TRACE("seed " + std::to_string(seed) + " shift " + std::to_string(shift));
            EXPECT_TRUE(s_fresh.converged);
            EXPECT_TRUE(s_kept.converged);
            EXPECT_LT((x_kept - x_fresh).lpNorm<Eigen::Infinity>(), 1e-8);
            EXPECT_EQ(kept.hessians - kept_before, s_kept.hessians);
            EXPECT_LT(s_kept.hessians, s_fresh.hessians);
            EXPECT_EQ(fresh.hessians - fresh_before, s_fresh.hessians);
            for (std::size_t i = 1; i < kept.energies.size(); ++i)
                EXPECT_LE(kept.energies[i], kept.energies[i - 1] + 1e-13 * std::abs(kept.energies[i - 1]));
            // Already at the minimizer: one gradient, no Hessian pass.
            const NewtonStats s_again = minimize(kept, x_kept, options, "chain");
            EXPECT_TRUE(s_again.converged);
            EXPECT_EQ(s_again.hessians, 0);
            EXPECT_EQ(s_again.iterations, 0);
        }
}

/// Audits which Hessian each Newton direction is computed with: a direction
/// whose Hessian is not that of the current iterate (a lazy one) is allowed
/// only at an iterate reached by a full step (no line-search value() calls)
/// that cut the residual |g|_inf by the lazy factor 0.5 (newton.hpp).
class LazyAudit : public Chain {
public:
    LazyAudit(int n, unsigned seed) : Chain(n, seed) {}
    double value(const VecX& x) override {
        ++values_since_direction;
        return Chain::value(x);
    }
    double value_gradient(const VecX& x, VecX& g) override {
        const int saved = values_since_direction;  // Chain::value_gradient calls value()
        const double e = Chain::value_gradient(x, g);
        values_since_direction = saved;
        last_x = x;
        last_g = g;
        ++gradients;
        return e;
    }
    void prepare_hessian(const VecX& x) override {
        Chain::prepare_hessian(x);
        hessian_x = x;
    }
    void hessian_multiply(const VecX& d, VecX& out) const override {
        if (gradients != direction_gradients) {  // the first product of a new direction
            auto* self = const_cast<LazyAudit*>(this);
            const double r = last_g.lpNorm<Eigen::Infinity>();
            const bool contracting_full_step = values_since_direction == 0 && r <= 0.5 * previous_residual;
            if (hessian_x != last_x) {
                self->stale_directions += 1;
                if (!contracting_full_step) self->violations += 1;
            }
            if (!contracting_full_step && previous_contracting) self->bad_after_contracting += 1;
            self->previous_contracting = contracting_full_step;
            self->previous_residual = r;
            self->values_since_direction = 0;
            self->direction_gradients = gradients;
        }
        Chain::hessian_multiply(d, out);
    }
    VecX last_x, last_g, hessian_x;
    int values_since_direction = 0, gradients = 0, direction_gradients = -1;
    int stale_directions = 0, violations = 0, bad_after_contracting = 0;
    bool previous_contracting = false;
    double previous_residual = std::numeric_limits<double>::infinity();
};

// A lazy Hessian is kept only where newton.hpp says: an iterate reached after
// a backtrack or by a full step that did not contract gets a fresh Hessian
// before its direction is computed.
TEST(Newton, LazyHessianIsRefreshedAtTheIterateThatNeedsIt) {
    int stale = 0, bad_after_contracting = 0, violations = 0;
    for (unsigned seed = 1; seed <= 12; ++seed)
        for (double start : {0.0, 2.0, 4.0}) {
            LazyAudit chain(40, seed);
            VecX x = VecX::Constant(40, start);
            for (Eigen::Index i = 0; i < x.size(); i += 2) x[i] = -start;  // alternating: large differences
            NewtonOptions options;
            options.tolerance = 1e-9;
            options.lazy_hessian = 0.5;
            const NewtonStats s = minimize(chain, x, options, "chain");
            EXPECT_TRUE(s.converged) << "seed " << seed << " start " << start;
            stale += chain.stale_directions;
            violations += chain.violations;
            bad_after_contracting += chain.bad_after_contracting;
        }
    EXPECT_EQ(violations, 0) << "directions computed with a lazy Hessian at an iterate that needed a fresh one";
    EXPECT_GT(stale, 0) << "no lazy Hessian was ever kept: the test is vacuous";
    EXPECT_GT(bad_after_contracting, 0) << "no backtrack or slow step followed a contracting one: the test is vacuous";
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

// The mass-weighted velocity residual sqrt(sum g_i^2 / H_ii / sum m_i) over the
// components with m_i > 0.
TEST(Newton, MassWeightedResidualIsTheEnergyNormOfTheJacobiCorrection) {
    Chain chain(10, 5);
    VecX x = VecX::LinSpaced(10, -1.0, 1.0), g, diagonal;
    chain.value_gradient(x, g);
    chain.prepare_hessian(x);
    chain.hessian_diagonal(diagonal);
    NewtonOptions options;
    options.residual_mass = VecX::Constant(10, 2.0);
    options.residual_mass[3] = 0.0;  // a fixed component does not count
    options.max_iterations = 0;
    VecX x0 = x;
    const NewtonStats s = minimize(chain, x0, options);
    double sum = 0.0;
    for (int i = 0; i < 10; ++i)
        if (i != 3) sum += g[i] * g[i] / diagonal[i];
    EXPECT_NEAR(s.initial_residual, std::sqrt(sum / 18.0), 1e-14 * std::sqrt(sum / 18.0));
    options.residual_mass = VecX::Ones(3);
    EXPECT_THROW(minimize(chain, x0, options), std::invalid_argument);
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

// A line search that finds no decrease ends the solve unconverged after at
// most max_line_search halvings (it was 40, and a residual the energy could not
// reduce cost ~30 evaluations per iteration), or throws when asked to.
TEST(Newton, FailedLineSearchEndsTheSolveUnconvergedAfterCappedHalvings) {
    WrongGradient objective;
    VecX x = VecX::Zero(8);
    NewtonOptions options;
    const NewtonStats s = minimize(objective, x, options, "step 12");
    EXPECT_TRUE(s.line_search_failed);
    EXPECT_FALSE(s.converged);
    EXPECT_EQ(s.line_search_steps, 1 + options.max_line_search) << "the full step and the halvings";
    EXPECT_LE(options.max_line_search, 12);
    EXPECT_TRUE(x.isZero()) << "a failed solve leaves x at the last accepted iterate";
    options.throw_on_line_search_failure = true;
    try {
        minimize(objective, x, options, "step 12");
        FAIL() << "no error";
    } catch (const NewtonError& e) {
        const std::string what = e.what();
        EXPECT_EQ(what.rfind("step 12: Newton iteration 0 (residual ", 0), 0u) << what;
        EXPECT_NE(what.find("line search failed after 12 halvings"), std::string::npos) << what;
    }
}

/// A chain of double wells, E(x) = sum (x_i^2 - 1)^2 / 4 + k/2 sum (x_i - x_{i+1})^2, with its
/// assembled Hessian: indefinite where |x_i| < 1/sqrt(3) (less the coupling).
class DoubleWells : public Objective {
public:
    explicit DoubleWells(int n) : n_(n) {}
    Eigen::Index size() const override { return n_; }
    double value(const VecX& x) override {
        double e = 0.0;
        for (int i = 0; i < n_; ++i) e += 0.25 * std::pow(x[i] * x[i] - 1.0, 2);
        for (int i = 0; i + 1 < n_; ++i) e += 0.5 * k_ * std::pow(x[i] - x[i + 1], 2);
        return e;
    }
    double value_gradient(const VecX& x, VecX& g) override {
        g.resize(n_);
        for (int i = 0; i < n_; ++i) g[i] = x[i] * (x[i] * x[i] - 1.0);
        for (int i = 0; i + 1 < n_; ++i) {
            g[i] += k_ * (x[i] - x[i + 1]);
            g[i + 1] -= k_ * (x[i] - x[i + 1]);
        }
        return value(x);
    }
    void prepare_hessian(const VecX& x) override {
        std::vector<Eigen::Triplet<double>> t;
        for (int i = 0; i < n_; ++i) t.emplace_back(i, i, 3.0 * x[i] * x[i] - 1.0);
        for (int i = 0; i + 1 < n_; ++i) {
            t.emplace_back(i, i, k_);
            t.emplace_back(i + 1, i + 1, k_);
            t.emplace_back(i, i + 1, -k_);
            t.emplace_back(i + 1, i, -k_);
        }
        H_.resize(n_, n_);
        H_.setFromTriplets(t.begin(), t.end());
    }
    void hessian_multiply(const VecX& d, VecX& out) const override { out = H_ * d; }
    void hessian_diagonal(VecX& diagonal) const override { diagonal = H_.diagonal(); }
    const SparseMatrix* hessian_matrix() const override { return &H_; }

private:
    int n_;
    double k_ = 0.1;
    SparseMatrix H_;
};

// The direct solver must recognize an indefinite Hessian (the Newton direction would climb) and
// fall back to PCG, which stops at negative curvature along a descent direction: CHOLMOD's
// simplicial LDL^T factorizes an indefinite matrix without a complaint, so the factorization
// has to be LL^T.
TEST(Newton, DirectSolveFallsBackToPcgOnAnIndefiniteHessian) {
    for (const int n : {4, 3000}) {  // CHOLMOD picks simplicial for the short chain and long
        DoubleWells objective(n);
        VecX x = VecX::Constant(n, 0.3);  // where every diagonal entry of H is negative
        x[0] = 0.31;
        NewtonOptions options;
        options.linear_solver = NewtonOptions::LinearSolver::Cholesky;
        options.tolerance = 1e-10;
        const NewtonStats s = minimize(objective, x, options, "double wells");  // LDL^T: "not a descent direction"
        EXPECT_TRUE(s.converged) << n;
        EXPECT_LT(s.energy, s.initial_energy) << n;
        EXPECT_LT((x.cwiseAbs() - VecX::Ones(n)).cwiseAbs().maxCoeff(), 1e-6) << n << ": in a well";
    }
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

namespace pnet {
namespace {

// A rebased objective whose gradient is the true residual R(x) = x - 1 (a linear spring to 1) and
// whose Hessian is `stiffness` (the tangent Newton uses), counting its rebases.
class RebasedSpring : public Objective {
public:
    explicit RebasedSpring(double stiffness) : k_(stiffness) {}
    Eigen::Index size() const override { return 1; }
    double value(const VecX& x) override { return 0.5 * (x[0] - 1.0) * (x[0] - 1.0); }
    double value_gradient(const VecX& x, VecX& g) override {
        g.resize(1);
        g[0] = x[0] - 1.0;
        return value(x);
    }
    void prepare_hessian(const VecX&) override {}
    void hessian_multiply(const VecX& d, VecX& out) const override { out = k_ * d; }
    void hessian_diagonal(VecX& diagonal) const override { diagonal = VecX::Constant(1, k_); }
    bool rebase(const VecX&) override {
        ++rebases_;
        return true;
    }
    int rebases() const { return rebases_; }

private:
    double k_;
    int rebases_ = 0;
};

// With the work line search a Newton step whose tangent is right converges in one iteration, and
// every trial point is evaluated about its own reference.
TEST(Newton, WorkLineSearchTakesTheTangentStep) {
    RebasedSpring spring(1.0);
    NewtonOptions options;
    options.rebase = true;
    options.work_line_search = true;
    options.tolerance = 1e-12;
    VecX x = VecX::Constant(1, 5.0);
    const NewtonStats s = minimize(spring, x, options);
    EXPECT_TRUE(s.converged);
    EXPECT_EQ(s.iterations, 1);
    EXPECT_NEAR(x[0], 1.0, 1e-14);
    EXPECT_EQ(spring.rebases(), 2) << "the start and the trial point";
}

// A tangent far too soft (1e-6 for a true stiffness of 1) overshoots by 1e6: no halving within the
// cap makes the work of R along the step decrease, so the solve ends unconverged and says so, back
// at the last iterate and its own reference; with throw_on_line_search_failure it is an error.
TEST(Newton, FailedWorkLineSearchEndsTheSolveUnconvergedAtTheLastIterate) {
    RebasedSpring spring(1e-6);
    NewtonOptions options;
    options.rebase = true;
    options.work_line_search = true;
    VecX x = VecX::Constant(1, 2.0);
    const NewtonStats s = minimize(spring, x, options);
    EXPECT_FALSE(s.converged);
    EXPECT_TRUE(s.line_search_failed);
    EXPECT_EQ(x[0], 2.0) << "the last accepted iterate";
    EXPECT_EQ(spring.rebases(), 1 + (options.max_line_search + 1) + 1) << "start, trials, back to the iterate";
    options.throw_on_line_search_failure = true;
    x[0] = 2.0;
    EXPECT_THROW(minimize(spring, x, options), NewtonError);
}

}  // namespace
}  // namespace pnet
