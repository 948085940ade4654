#pragma once
// The solves of an implicit MPM step (ImplicitIntegrator, CoupledIntegrator): one; on a Coulomb floor
// (floor_friction_form.hpp) one with the friction itself in the residual (MpmOptions::
// floor_friction_solve "newton"; "auto", the default, in 2D under the work line search), or
// kFloorFrictionSolves majorize-minimize passes ("passes"), each pass after the first with the floor's
// contacts taken from the last solution.
#include <functional>
#include <string>

#include "pnet/solver/fixed_point.hpp"
#include "pnet/solver/newton.hpp"
#include "pnet/solver/step_stats.hpp"

namespace pnet {

/// Passes on a Coulomb floor under floor_friction_solve "passes" (docs/methods.md). Each pass after the
/// first takes at least one Newton step: it changes the friction on the floor's nodes only, which the
/// residual over every node could hide below the tolerance, and the pass would then keep the last
/// pass's friction.
inline constexpr int kFloorFrictionSolves = 3;

/// Solves the step from v (solve_with_reference) in `passes` solves, the solves recorded in `stats`
/// (Newton and CG iterations summed, the fixed-point solves of all passes); `relag(v)` sets the floor's
/// contacts from v before each pass after the first. A failed Newton solve throws SimulationError.
template <int dim, typename Relag>
void solve_floor_friction_passes(ReferencedObjective<dim>& objective, VecX& v, const NewtonOptions& newton,
                                 const ReferenceSolveOptions& options, const std::string& context,
                                 ReferenceSolveWork<dim>& work, int passes, Relag&& relag,
                                 const std::function<void()>& after_reference, StepStats& stats) {
    int fixed_point_solves = 0;
    NewtonOptions pass_newton = newton;
    for (int pass = 0; pass < passes; ++pass) {
        if (pass > 0) {
            relag(v);
            pass_newton.min_iterations = 1;
        }
        ReferenceSolveStats s;
        try {
            s = solve_with_reference<dim>(objective, v, pass_newton, options, context, work, after_reference);
        } catch (const NewtonError& e) {
            throw SimulationError(e.what());
        }
        record_solve(s, stats);
        fixed_point_solves += s.solves;
    }
    stats.fixed_point_iterations = fixed_point_solves;
}

}  // namespace pnet
