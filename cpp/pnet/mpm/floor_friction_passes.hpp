#pragma once
// The solves of an implicit MPM step (ImplicitIntegrator, CoupledIntegrator): one; on a Coulomb floor
// (floor_friction_form.hpp) one whose floor contacts follow the iterate, for a solve that follows it
// with its reference (the rebased Newton of plasticitynet and return_map), or else kFloorFrictionSolves
// majorize-minimize passes, each pass after the first with the floor's contacts taken from the last
// solution.
#include <functional>
#include <string>

#include "pnet/solver/fixed_point.hpp"
#include "pnet/solver/newton.hpp"
#include "pnet/solver/step_stats.hpp"

namespace pnet {

/// Passes on a Coulomb floor where the solve does not follow the iterate (docs/methods.md). Each pass
/// after the first takes at least one Newton step: it changes the friction on the floor's nodes only,
/// which the residual over every node could hide below the tolerance, and the pass would then keep the
/// last pass's friction.
inline constexpr int kFloorFrictionSolves = 3;

/// Within one solve, the floor's contacts follow at most this many iterates and then stay: each move is
/// one majorize-minimize step of the friction (an iteratively reweighted quadratic), which converges
/// linearly where a node's slip hovers about eps_v, so a solve asked for far below the default tolerance
/// could chase the friction's stick-slip switches instead of converging (measured on the sliding box at
/// 1e-7 m/s: residuals stalled at 1e-7-1e-5 m/s in 8 of 20 frames). With the contacts held after that,
/// Newton converges on one quadratic, as each pass does.
inline constexpr int kFloorFrictionFollows = 8;

/// Within one solve, the Newton tolerance is this fraction of the step's: the friction's lag converges
/// with Newton's iterates instead of over whole solves, and a solve stopped at the full tolerance left
/// a bias the flow carries (the granular collapse of test_implicit.cpp, 0.5 s at 1e-3 s, return_map:
/// rms spread growth -2.0% from a 1e-5 m/s solve at 1e-3 m/s, -0.52% at 5e-4, -0.22% at 3e-4, against
/// the passes' -0.20% at 1e-3; 2.64 / 3.46 / 4.33 Newton iterations per step against the passes' 4.26,
/// 1.03 / 1.21 / 1.40 s against 1.63 s, measured 2026-11-29).
inline constexpr double kFloorFrictionInSolveTolerance = 0.3;

/// Solves the step from v (solve_with_reference), the solves recorded in `stats` (Newton and CG
/// iterations summed, the fixed-point solves of all passes). `relag(v)` sets the floor's contacts from
/// v: at each of the first kFloorFrictionFollows iterates of a solve that follows the iterate
/// (ReferenceSolveOptions::floor_friction_in_solve: as IPC lags its friction between Newton iterations;
/// at the default tolerance every iterate of a step), else before each pass after the first. A failed Newton solve throws SimulationError.
template <int dim, typename Relag>
void solve_floor_friction_passes(ReferencedObjective<dim>& objective, VecX& v, const NewtonOptions& newton,
                                 const ReferenceSolveOptions& options, const std::string& context,
                                 ReferenceSolveWork<dim>& work, bool coulomb_floor, Relag&& relag,
                                 const std::function<void()>& after_reference, StepStats& stats) {
    const bool in_solve = coulomb_floor && options.floor_friction_in_solve && follows_iterate(options);
    const int passes = coulomb_floor && !in_solve ? kFloorFrictionSolves : 1;
    std::function<void(const VecX&)> follow;
    int follows = 0;
    if (in_solve)
        follow = [&](const VecX& x) {
            if (follows++ < kFloorFrictionFollows) relag(x);
        };
    int fixed_point_solves = 0;
    NewtonOptions pass_newton = newton;
    if (in_solve) pass_newton.tolerance *= kFloorFrictionInSolveTolerance;
    for (int pass = 0; pass < passes; ++pass) {
        if (pass > 0) {
            relag(v);
            pass_newton.min_iterations = 1;
        }
        ReferenceSolveStats s;
        try {
            s = solve_with_reference<dim>(objective, v, pass_newton, options, context, work, after_reference, follow);
        } catch (const NewtonError& e) {
            throw SimulationError(e.what());
        }
        record_solve(s, stats);
        fixed_point_solves += s.solves;
    }
    stats.fixed_point_iterations = fixed_point_solves;
}

}  // namespace pnet
