#pragma once
// Newton's method with a PSD Hessian, matrix-free PCG and backtracking line
// search on E: the one optimization loop of every implicit integrator
// (DESIGN.md §4; Gast et al. 2015, Li et al. 2020). Per iteration:
//   g = grad E(x); stop if |g|_scaled <= tolerance;
//   H d = -g by PCG (Jacobi or block Jacobi) to the relative tolerance min(cg_tolerance, sqrt(|g| / |g0|))
//   (inexact Newton: loose far from the solution, tighter as it converges);
//   alpha = 1, halved until E(x + alpha d) <= E(x) + c alpha g.d (Armijo; the full step is
//   evaluated with value_gradient_hessian(), so an accepted full step costs one energy
//   pass and arrives with its Hessian prepared); once |g.d| is
//   below the round-off of E, the full step is taken if it lowers |g|. If no halving
//   lowers E, the full step is still taken when it lowers |g| and changes E by less
//   than 1e-8 max(|E|, 1) (E's round-off exceeds eps |E| when large terms cancel);
//   otherwise the line search has stalled.
// With lazy_hessian > 0 an iterate reached by a full step that cut the residual
// by that factor is evaluated by value_gradient() and keeps the previous
// Hessian (a chord / Shamanskii step): for a learned energy the Hessian pass
// costs about twice the gradient pass.
#include <stdexcept>
#include <string>

#include "pnet/solver/objective.hpp"

namespace pnet {

struct NewtonOptions {
    double tolerance = 1e-6;        // on |g|_scaled (see residual_scale)
    int max_iterations = 100;
    int max_cg_iterations = 500;
    double cg_tolerance = 1e-2;     // largest relative CG residual
    double armijo = 1e-4;           // sufficient-decrease constant c
    int max_line_search = 40;       // halvings before a stall
    /// |g|_scaled = max_i |g_i| * residual_scale_i; with residual_scale_i =
    /// 1 / m_i (MPM) the residual is a velocity error in m/s. Empty: 1.
    VecX residual_scale;
    /// Scale by the Hessian's diagonal instead: |g|_scaled = max_i |g_i| / H_ii
    /// over the components where residual_scale_i > 0 (all if it is empty): the
    /// size of a Jacobi correction, which for MPM is a velocity error in m/s that
    /// stays meaningful where stiffness, not mass, dominates H (large dt, nodes
    /// at a body's rim holding little mass).
    bool scale_by_hessian_diagonal = false;
    /// Block Jacobi (the objective's hessian_block_diagonal(), when its block
    /// size is > 1) instead of Jacobi.
    bool block_preconditioner = false;
    /// Lazy Hessian: > 0 keeps the last Hessian at the next iterate (a value and
    /// gradient pass instead of a Hessian pass) as long as the previous
    /// iteration took the full step and cut the scaled residual by at least
    /// this factor; otherwise it is re-formed. 0: a fresh Hessian at every
    /// iterate (Newton).
    double lazy_hessian = 0.0;
};

struct NewtonStats {
    int iterations = 0;          // Newton iterations with a step taken
    int cg_iterations = 0;       // total over the iterations
    int line_search_steps = 0;   // energy evaluations in line searches, total
    double initial_residual = 0.0, residual = 0.0;  // |g|_scaled before and after
    double initial_energy = 0.0, energy = 0.0;
    bool converged = false;
    /// Stopped because neither E nor |g| could be lowered in double precision
    /// (the tolerance is below what this problem's round-off allows).
    bool roundoff_floor = false;
};

/// A solve that cannot go on: non-finite energy or gradient, a non-descent
/// direction, or a line-search stall. The message names the iteration, the
/// residual and what happened; `context` (e.g. "step 120") prefixes it.
class NewtonError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

/// Minimizes `objective` from x (updated in place). Returns the statistics;
/// not converging within max_iterations is not an error (stats.converged is
/// false). Throws NewtonError as described above.
NewtonStats minimize(Objective& objective, VecX& x, const NewtonOptions& options, const std::string& context = "");

}  // namespace pnet
