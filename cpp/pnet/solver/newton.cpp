#include "pnet/solver/newton.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include "pnet/solver/pcg.hpp"

namespace pnet {

namespace {

/// |g|_scaled (NewtonOptions); `diagonal` is diag(H) at the same point.
double scaled_residual(const VecX& g, const NewtonOptions& options, const VecX& diagonal) {
    const VecX& scale = options.residual_scale;
    if (options.scale_by_hessian_diagonal) {
        double r = 0.0;
        for (Eigen::Index i = 0; i < g.size(); ++i)
            if (scale.size() == 0 || scale[i] > 0.0) r = std::max(r, std::abs(g[i]) / diagonal[i]);
        return r;
    }
    if (scale.size() == 0) return g.lpNorm<Eigen::Infinity>();
    return g.cwiseProduct(scale).lpNorm<Eigen::Infinity>();
}

std::string where(const std::string& context, int iteration, double residual) {
    char text[160];
    std::snprintf(text, sizeof text, "%sNewton iteration %d (residual %.3e): ",
                  context.empty() ? "" : (context + ": ").c_str(), iteration, residual);
    return text;
}

}  // namespace

NewtonStats minimize(Objective& objective, VecX& x, const NewtonOptions& options, const std::string& context) {
    const Eigen::Index n = objective.size();
    if (x.size() != n) throw std::invalid_argument("minimize: x has the wrong size");
    if (options.residual_scale.size() != 0 && options.residual_scale.size() != n)
        throw std::invalid_argument("minimize: residual_scale has the wrong size");
    NewtonStats stats;
    VecX g(n), g_trial(n), d(n), diagonal(n), x_trial(n), blocks;
    const int block = options.block_preconditioner ? objective.hessian_block_size() : 1;
    // Every accepted iterate comes with its Hessian prepared (value_gradient_hessian),
    // so an iteration whose full step passes the line search costs one energy pass.
    double energy = objective.value_gradient_hessian(x, g);
    objective.hessian_diagonal(diagonal);
    double residual = scaled_residual(g, options, diagonal);
    stats.initial_energy = stats.energy = energy;
    stats.initial_residual = stats.residual = residual;
    if (!std::isfinite(energy) || !g.allFinite())
        throw NewtonError(where(context, 0, residual) + "the energy or its gradient is not finite at the start");
    const double g0 = std::max(g.norm(), 1e-300);
    // Whether the next trial point re-forms the Hessian (always, unless lazy_hessian > 0).
    bool fresh_hessian = !(options.lazy_hessian > 0.0);

    for (int it = 0; it < options.max_iterations; ++it) {
        if (residual <= options.tolerance) {
            stats.converged = true;
            break;
        }
        Preconditioner preconditioner;
        if (block > 1) {
            objective.hessian_block_diagonal(blocks);
            preconditioner = Preconditioner::block_jacobi(blocks, block);
        } else {
            preconditioner = Preconditioner::jacobi(diagonal);
        }
        const double forcing = std::min(options.cg_tolerance, std::sqrt(g.norm() / g0));
        const PcgResult cg = solve_pcg(objective, -g, preconditioner, d, forcing, options.max_cg_iterations);
        stats.cg_iterations += cg.iterations;
        const double slope = g.dot(d);
        if (!(slope < 0.0))
            throw NewtonError(where(context, it, residual) + "the search direction is not a descent direction (g.d = " +
                              std::to_string(slope) + "); the Hessian is not positive definite");

        // The full step first, with its gradient (and Hessian, unless a lazy one is kept).
        x_trial = x + d;
        // A lazy Hessian is kept (value_gradient leaves it) while the iterations converge fast.
        const bool refresh = fresh_hessian;
        const double residual_before = residual;
        bool halved = false;
        const double e_full = refresh ? objective.value_gradient_hessian(x_trial, g_trial)
                                      : objective.value_gradient(x_trial, g_trial);
        ++stats.line_search_steps;
        const bool full_finite = std::isfinite(e_full) && g_trial.allFinite();
        // Near the solution the decrease g.d falls below the round-off of E: the
        // energy cannot rank the step any more, the gradient still can.
        const bool roundoff = -slope <= 16.0 * std::numeric_limits<double>::epsilon() * std::abs(energy);
        const bool lowers_gradient = full_finite && g_trial.norm() < g.norm();
        if (roundoff && !lowers_gradient) {
            stats.roundoff_floor = true;  // nothing left to gain in double precision
            break;
        }
        if (roundoff || (full_finite && e_full <= energy + options.armijo * slope)) {
            x.swap(x_trial);
            g.swap(g_trial);
            energy = e_full;
        } else {
            double alpha = 0.5, trial = e_full;
            bool decreased = false;
            halved = true;
            for (int halvings = 1; halvings <= options.max_line_search; ++halvings) {
                x_trial = x + alpha * d;
                trial = objective.value(x_trial);
                ++stats.line_search_steps;
                if (std::isfinite(trial) && trial <= energy + options.armijo * alpha * slope) {
                    decreased = true;
                    break;
                }
                alpha *= 0.5;
            }
            if (decreased) {
                x.swap(x_trial);
                energy = refresh ? objective.value_gradient_hessian(x, g) : objective.value_gradient(x, g);
                if (!std::isfinite(energy) || !g.allFinite())
                    throw NewtonError(where(context, it, residual) + "the gradient is not finite after the step");
            } else if (lowers_gradient && std::abs(e_full - energy) <= 1e-8 * std::max(std::abs(energy), 1.0)) {
                // E is a sum of large terms that may cancel (a learned energy's
                // N - c : F), so its round-off can exceed eps |E|: when the energy
                // cannot rank any step, the gradient decides. The Hessian last
                // prepared is the full step's (value() does not touch it).
                x.noalias() = x + d;
                g.swap(g_trial);
                energy = e_full;
            } else {
                throw NewtonError(where(context, it, residual) + "line search stalled after " +
                                  std::to_string(options.max_line_search) + " halvings (E = " +
                                  std::to_string(energy) + ", last trial " + std::to_string(trial) + ")");
            }
        }
        objective.hessian_diagonal(diagonal);  // at the new iterate (its Hessian is prepared)
        residual = scaled_residual(g, options, diagonal);
        fresh_hessian = !(options.lazy_hessian > 0.0) || halved || residual > options.lazy_hessian * residual_before;
        stats.iterations = it + 1;
        stats.energy = energy;
        stats.residual = residual;
    }
    if (residual <= options.tolerance) stats.converged = true;
    return stats;
}

}  // namespace pnet
