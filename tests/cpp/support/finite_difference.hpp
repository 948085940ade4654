#pragma once
// The one finite-difference harness of the C++ tests (docs/architecture.md, testing).
//
// A derivative is compared entry by entry with central differences and passes
// when |analytic - numeric| <= tol * max(|analytic|, |numeric|, scale). The
// harness counts the comparisons that actually ran, and a check whose analytic
// derivative is identically zero fails: two zero vectors must not pass.
#include <gtest/gtest.h>

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <functional>
#include <string>

namespace pnet::test {

struct FdStats {
    int checks = 0;           // entries compared
    double max_error = 0.0;   // largest |a - n| / max(|a|, |n|, scale)
};

/// Compares `jacobian` (m x n) with central differences of `f` at x.
inline ::testing::AssertionResult check_jacobian(const std::function<Eigen::VectorXd(const Eigen::VectorXd&)>& f,
                                                 const Eigen::MatrixXd& jacobian, const Eigen::VectorXd& x,
                                                 FdStats& stats, double step = 1e-6, double tol = 1e-5,
                                                 double scale = 1.0) {
    if (jacobian.cwiseAbs().maxCoeff() == 0.0)
        return ::testing::AssertionFailure() << "analytic derivative is identically zero";
    if (!jacobian.allFinite()) return ::testing::AssertionFailure() << "analytic derivative is not finite";
    for (int k = 0; k < x.size(); ++k) {
        Eigen::VectorXd xp = x, xm = x;
        const double h = step * std::max(1.0, std::abs(x[k]));
        xp[k] += h;
        xm[k] -= h;
        const Eigen::VectorXd numeric = (f(xp) - f(xm)) / (2.0 * h);
        for (int i = 0; i < jacobian.rows(); ++i) {
            const double a = jacobian(i, k), n = numeric[i];
            const double denom = std::max({std::abs(a), std::abs(n), scale});
            const double err = std::abs(a - n) / denom;
            stats.max_error = std::max(stats.max_error, err);
            ++stats.checks;
            if (err > tol)
                return ::testing::AssertionFailure()
                       << "entry (" << i << ", " << k << "): analytic " << a << " vs finite difference " << n
                       << " (relative error " << err << " > " << tol << ")";
        }
    }
    return ::testing::AssertionSuccess();
}

/// Gradient of a scalar function: a 1 x n Jacobian.
inline ::testing::AssertionResult check_gradient(const std::function<double(const Eigen::VectorXd&)>& f,
                                                 const Eigen::VectorXd& gradient, const Eigen::VectorXd& x,
                                                 FdStats& stats, double step = 1e-6, double tol = 1e-5,
                                                 double scale = 1.0) {
    auto wrapped = [&](const Eigen::VectorXd& y) { return Eigen::VectorXd::Constant(1, f(y)); };
    return check_jacobian(wrapped, gradient.transpose(), x, stats, step, tol, scale);
}

}  // namespace pnet::test
