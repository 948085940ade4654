#pragma once
// The solve of one implicit step with a reference deformation (paper eq. 10,
// docs/solver.md), shared by MPM, FEM and coupling around the one Newton
// loop. The learned energy is exact (in slope) only at F = F0, so the step is converged when v is
// the root of the true residual R(v) = grad E(v; F0 = F(v)): inertia, the exact elastoplastic stress
// Ptilde(F(v), h^n) and contact, in Newton's units (m/s, mass-weighted).
//
//   plasticitynet, outer iteration "newton" (the default): one Newton solve whose reference follows
//     the iterate (NewtonOptions::rebase): at every accepted iterate F0 = F(v), so the gradient
//     Newton tests and steps on is R(v) itself and the network is evaluated only within one Newton
//     step of its reference. Converged when |R| <= the Newton tolerance.
//   plasticitynet, outer iteration "fixed_point" (paper eq. 10): F0^0 = F(v); solve j minimizes
//     E(v; F0^j) from the previous v, then F0^{j+1} = F(v^{j+1}), until max_p ||F(v) - F0||_F <=
//     tolerance or max_solves. If the change grows from one solve to the next it stops; the solution
//     with the smallest change is kept.
//   otherwise (lagged, analytic): one solve with the reference the caller set.
// Either plasticitynet iteration reports |R| at the v it returns (ReferenceSolveStats::true_residual).
#include <functional>
#include <string>
#include <vector>

#include "pnet/math/types.hpp"
#include "pnet/solver/newton.hpp"
#include "pnet/solver/objective.hpp"

namespace pnet {

/// An objective whose energy is evaluated about a reference deformation per
/// material point (MPM particle, FEM element).
template <int dim>
class ReferencedObjective : public Objective {
public:
    /// The deformation of every material point at the unknowns v (MPM: F_p(v);
    /// FEM: F^E_e(v)).
    virtual void deformation(const VecX& v, std::vector<Mat<dim>>& F) const = 0;
    /// The energy's reference F0 (with the points' start-of-step hardening).
    virtual void set_reference(const std::vector<Mat<dim>>& F0) = 0;
};

/// How plasticitynet's reference F0 is iterated to F(v).
enum class OuterIteration {
    Newton,      // F0 = F(v) at every Newton iterate: one solve on the true residual
    FixedPoint,  // paper eq. 10: a full solve per F0, then F0 = F(v)
};

struct ReferenceSolveOptions {
    bool fixed_point = false;          // iterate on F0 (plasticitynet)
    OuterIteration outer = OuterIteration::Newton;
    // Newton outer iteration: line search on the work of the true residual
    // (NewtonOptions::work_line_search), for an energy whose Hessian is the consistent tangent.
    bool work_line_search = false;
    int max_solves = 8;                // fixed point: the cap
    double tolerance = 1e-3;           // fixed point: on max_p ||F(v) - F0||_F
    bool fail_on_unconverged = false;  // an unconverged Newton solve throws NewtonError
    // Fixed point: Anderson acceleration of the map F0 -> F(v(F0)) over the last
    // `anderson_depth` iterates (0: the plain iteration of eq. 10). The next
    // reference is the combination of the last images F(v) whose residuals
    // F(v) - F0, combined alike, are smallest (least squares; Walker and Ni 2011).
    int anderson_depth = 0;
    // Fixed point: the solves after the first start from the Hessian the previous one prepared
    // (NewtonOptions::keep_prepared_hessian; at the same v, with F0 moved by the last change).
    bool keep_hessian = false;
    // Fixed point: inexact inner solves while F0 still moves. A solve after the first whose F0 moved
    // by more than the tolerance stops once its residual has fallen by this factor (or reached the
    // Newton tolerance; NewtonOptions::relative_tolerance); the loop ends only on a solve converged to
    // the Newton tolerance, and only such a solve's v is returned. 0: exact solves.
    double inexact_forcing = 0.0;
};

/// Totals over the step's solves.
struct ReferenceSolveStats {
    int solves = 0, newton_iterations = 0, cg_iterations = 0, line_search_steps = 0;
    double initial_residual = 0.0, residual = 0.0, energy = 0.0;
    double change = 0.0;    // fixed point: the smallest max_p ||F(v) - F0|| reached
    int reference_updates = 0;  // times F0 was set to F(v) (plasticitynet)
    double true_residual = 0.0;  // plasticitynet: |R(v)| at the returned v, m/s (Newton's residual units)
    bool converged = true;  // every Newton solve reached its tolerance
    bool line_search_failed = false;
    bool fixed_point_converged = true;  // the change reached the tolerance (not the cap)

    /// Adds a later solve of the same step: counts sum, the last solve's
    /// residual, energy and fixed-point outcome stand, failures stick.
    void append(const ReferenceSolveStats& later) {
        solves += later.solves;
        newton_iterations += later.newton_iterations;
        cg_iterations += later.cg_iterations;
        line_search_steps += later.line_search_steps;
        residual = later.residual;
        energy = later.energy;
        change = later.change;
        reference_updates += later.reference_updates;
        true_residual = later.true_residual;
        converged = converged && later.converged;
        line_search_failed = line_search_failed || later.line_search_failed;
        fixed_point_converged = later.fixed_point_converged;
    }
};

/// Work arrays kept between steps.
template <int dim>
struct ReferenceSolveWork {
    std::vector<Mat<dim>> F0, F;
    VecX best_v;
    // Anderson acceleration: differences of the last iterates' residuals and images (columns).
    Eigen::MatrixXd dR, dG;
    VecX last_r, last_g;
    NewtonWorkspace newton;  // the direct solver's analysis, shared by the solves
};

/// Whether solve_with_reference() follows the iterate with the reference within one Newton solve
/// (options.fixed_point with the Newton outer iteration).
inline bool follows_iterate(const ReferenceSolveOptions& options) {
    return options.fixed_point && options.outer == OuterIteration::Newton;
}

/// Solves the step from v (updated). `after_reference`, if given, runs after
/// every set_reference (statistics of the energy's reference). Throws NewtonError from the solves, and, with
/// fail_on_unconverged, for a solve that ends above its tolerance ("<context>: the Newton solve did not
/// converge ...").
template <int dim>
ReferenceSolveStats solve_with_reference(ReferencedObjective<dim>& objective, VecX& v, const NewtonOptions& newton,
                                         const ReferenceSolveOptions& options, const std::string& context,
                                         ReferenceSolveWork<dim>& work,
                                         const std::function<void()>& after_reference = {});

}  // namespace pnet
