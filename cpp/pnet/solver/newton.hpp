#pragma once
// Newton's method with a PSD Hessian, matrix-free PCG and backtracking line
// search on E: the one optimization loop of every implicit integrator
// (docs/methods.md; Gast et al. 2015, Li et al. 2020). Per iteration:
//   g = grad E(x); stop if the residual (below) <= tolerance;
//   H d = -g by PCG (Jacobi, block Jacobi, or the objective's own preconditioner; BiCGSTAB where H has a
//   skew part, Objective::hessian_symmetric) to the relative tolerance
//   min(cg_tolerance, sqrt(|g| / |g0|)) (inexact Newton: loose far from the solution, tighter as it converges); alpha =
//   1, halved (at most max_line_search times) until E(x + alpha d) <= E(x) + c alpha g.d (Armijo). The full step is
//   evaluated with value_gradient_hessian(), so an accepted full step costs one energy pass and arrives with its
//   Hessian prepared. Once |g.d| is below the round-off of E, the full step is taken if it lowers |g|. If no halving
//   lowers E, the full step is still taken when it lowers |g| and changes E by less than its round-off; otherwise the
//   solve stops, unconverged, at the last accepted iterate (stats.line_search_failed; an error only with
//   throw_on_line_search_failure, or when E was not finite at any trial point).
// Residual: max_i |g_i| residual_scale_i (by default), or, with residual_mass (per-component masses
// m_i, 0 on fixed components), the mass-weighted velocity residual
//   r = sqrt( sum_i g_i^2 / H_ii / sum_i m_i )  (m/s; sums over components with m_i > 0),
// the energy norm of the Jacobi correction g_i / H_ii per unit mass: E(x) - min E ~ M r^2 / 2 with
// M = sum m_i, so r measures what the energy can still gain, and nodes that hold little mass (a
// body's rim) weigh little. Where inertia dominates H it is the rms velocity error sqrt(sum m_i
// (g_i / m_i)^2 / M).
// Lazy Hessian (lazy_hessian > 0): an iterate reached by a full step that cut the residual by that
// factor keeps the previous Hessian (a chord / Shamanskii step: its trial point was evaluated by
// value_gradient(), about half the cost of a Hessian pass for a learned energy); any other iterate
// (a backtracked step, or a full step that did not contract enough) gets its own Hessian before its
// direction and convergence test are computed.
#include <memory>
#include <stdexcept>
#include <string>

#include "pnet/solver/objective.hpp"

namespace pnet {

struct NewtonOptions {
    double tolerance = 1e-6;  // on |g|_scaled (see residual_scale)
    int max_iterations = 100;
    int max_cg_iterations = 500;
    double cg_tolerance = 1e-2;  // largest relative CG residual
    double armijo = 1e-4;        // sufficient-decrease constant c
    int max_line_search = 12;    // halvings (alpha >= 2^-12) before the line search has failed
    /// Residual max_i |g_i| residual_scale_i (empty: max |g_i|). Ignored when
    /// residual_mass is given.
    VecX residual_scale;
    /// Per-component masses (kg; 0 on fixed components): the residual is then
    /// the mass-weighted velocity residual sqrt(sum g_i^2 / H_ii / sum m_i), m/s.
    VecX residual_mass;
    /// A failed line search throws NewtonError instead of ending the solve
    /// unconverged.
    bool throw_on_line_search_failure = false;
    /// Block Jacobi (the objective's hessian_block_diagonal(), when its block
    /// size is > 1) instead of Jacobi.
    bool block_preconditioner = false;
    /// Incomplete Cholesky of the objective's assembled hessian_matrix() as PCG's preconditioner
    /// (refactored with every new Hessian; objectives without a matrix use Jacobi).
    bool incomplete_cholesky = false;
    /// The linear solve of H d = -g: PCG (matrix-free), or a sparse Cholesky
    /// factorization by CHOLMOD of the objective's hessian_matrix() (FEM:
    /// small, stiff systems), whose symbolic analysis is kept while the
    /// sparsity pattern is unchanged. An objective without an assembled
    /// matrix, or a factorization that fails (H not positive definite), falls
    /// back to PCG for that iteration.
    enum class LinearSolver { Pcg, Cholesky } linear_solver = LinearSolver::Pcg;
    /// The Krylov method for a Hessian that is not symmetric (Objective::hessian_symmetric): restarted
    /// GMRES (solve_gmres) or BiCGSTAB (solve_bicgstab), with PCG's preconditioner.
    enum class NonsymmetricSolver { Gmres, Bicgstab } nonsymmetric_solver = NonsymmetricSolver::Gmres;
    /// Lazy Hessian: > 0 lets an iterate reached by a full step that cut the
    /// residual by at least this factor keep the previous Hessian; every other
    /// iterate gets a fresh one. 0: a fresh Hessian at every iterate (Newton).
    double lazy_hessian = 0.0;
    /// Start from the Hessian the objective prepared last instead of a fresh one (a modified Newton
    /// start: the solves of a fixed point on the reference F0 start where the previous one ended, with
    /// F0 moved a little). The start costs a gradient pass instead of a Hessian pass; the first
    /// direction uses the kept Hessian, which stays while full steps cut the residual by
    /// lazy_hessian (with lazy_hessian = 0 the first trial point gets a fresh one). The residual at
    /// the start is weighted by the kept Hessian's diagonal.
    bool keep_prepared_hessian = false;
    /// Inexact solve: also stop once the residual is at most this fraction of the starting one
    /// (0: only the absolute tolerance). converged then means the looser of the two was met.
    double relative_tolerance = 0.0;
    /// Newton steps taken even when the start already meets the tolerance (while the gradient is not
    /// zero): a solve that follows a change of the objective too local for the residual, which weighs
    /// every unknown, to see (a Coulomb floor's next friction pass, floor_friction_passes.hpp).
    int min_iterations = 0;
    /// Rebase the objective (Objective::rebase) at the start and at every accepted iterate: the
    /// learned energy's reference F0 follows F(v), so every gradient Newton tests and steps on is
    /// the exact one (the true residual of the elastoplastic step), the energy is only ever
    /// evaluated within one Newton step of its reference, and the outer fixed point on F0 (paper
    /// eq. 10) merges into the Newton loop. The line search compares energies about the iterate's
    /// own reference; the Hessian of the trial point (about the previous reference) is kept for the
    /// next direction, so a rebase costs one gradient pass. Where the true residual grows from one
    /// iterate to the next, a proximal damping lambda mu/2 |F - F0|^2 (Objective::set_damping; 0.01,
    /// x4 while it keeps growing, at most 1) is added until it falls again (docs/solver.md).
    bool rebase = false;
    /// With rebase: the line search evaluates each trial point about its own reference (its
    /// gradient is then the true residual R there) and takes Armijo's test on the work of R along
    /// the step, 1/2 alpha (R(x) + R(x + alpha d)) . d, instead of the energy about the iterate's
    /// reference. For a Hessian that is the Jacobian of R (the consistent tangent) rather than the
    /// energy's own: where the two disagree at second order (perfectly plastic flow) the energy
    /// rejects the tangent's steps (docs/solver.md). A trial point costs one gradient pass.
    bool work_line_search = false;
};

struct NewtonStats {
    int iterations = 0;                             // Newton iterations with a step taken
    int cg_iterations = 0;                          // total over the iterations
    int line_search_steps = 0;                      // energy evaluations in line searches, total
    double initial_residual = 0.0, residual = 0.0;  // |g|_scaled before and after
    double initial_energy = 0.0, energy = 0.0;
    bool converged = false;
    /// Stopped because neither E nor |g| could be lowered in double precision
    /// (the tolerance is below what this problem's round-off allows).
    bool roundoff_floor = false;
    /// Stopped because no step along the Newton direction lowered E (x is the
    /// last accepted iterate; converged is false).
    bool line_search_failed = false;
    int hessians = 0;                      // Hessian passes (value_gradient_hessian or prepare_hessian)
    int factorizations = 0, analyses = 0;  // Cholesky: numeric factorizations, symbolic analyses
    int rebases = 0;                       // Objective::rebase calls that changed the objective
    int dampings = 0;                      // rebased solves: iterates where the damping grew
    /// Non-symmetric Hessians (Objective::hessian_symmetric): iterations whose inexact BiCGSTAB
    /// direction did not descend and took the preconditioned gradient step instead.
    int nonsymmetric_fallbacks = 0;
};

/// A solve that cannot go on: non-finite energy or gradient at the start or
/// after a step, an energy that is not finite anywhere along the direction, a
/// non-descent direction (the Hessian is not PSD), or a failed
/// line search with throw_on_line_search_failure. The message names the
/// iteration, the residual and what happened; `context` (e.g. "step 120")
/// prefixes it.
class NewtonError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

/// What a sequence of solves of the same objective can share: CHOLMOD's
/// symbolic analysis (ordering and supernodes), kept while the Hessian's
/// sparsity pattern stays the same. The fixed point on F0 and the kinematic
/// stages of a FEM step solve one system tens of times.
class NewtonWorkspace {
public:
    NewtonWorkspace();
    ~NewtonWorkspace();
    NewtonWorkspace(NewtonWorkspace&&) noexcept;
    NewtonWorkspace& operator=(NewtonWorkspace&&) noexcept;
    struct Impl;
    Impl& impl() { return *impl_; }

private:
    std::unique_ptr<Impl> impl_;
};

/// The residual NewtonOptions defines (mass-weighted m/s, or the scaled max-norm) of a gradient g,
/// weighted by the diagonal of the Hessian the objective prepared last.
double newton_residual(const Objective& objective, const VecX& g, const NewtonOptions& options);

/// Minimizes `objective` from x (updated in place). Returns the statistics;
/// not converging within max_iterations, or a failed line search, is not an
/// error (stats.converged is false). Throws NewtonError as described above.
/// `workspace`, if given, carries the direct solver's analysis between calls.
NewtonStats minimize(Objective& objective, VecX& x, const NewtonOptions& options, const std::string& context = "",
                     NewtonWorkspace* workspace = nullptr);

}  // namespace pnet
