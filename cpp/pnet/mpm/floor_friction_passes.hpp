#pragma once
// The solves of an implicit MPM step (ImplicitIntegrator, CoupledIntegrator): one; on a Coulomb floor
// (floor_friction_form.hpp) one with the friction itself in the residual (MpmOptions::
// floor_friction_solve "newton"; "auto", the default, in 2D under the work line search), or
// MpmOptions::floor_friction_passes majorize-minimize passes ("passes"), each pass after the first with the floor's
// contacts taken from the last solution.
// Under "auto" a one solve that fails (its line search, its iteration cap, or a NewtonError) is solved
// again by the passes from the step's start (solve_on_coulomb_floor).
#include <functional>
#include <string>

#include "pnet/mpm/mpm_options.hpp"
#include "pnet/solver/fixed_point.hpp"
#include "pnet/solver/newton.hpp"
#include "pnet/solver/step_stats.hpp"

namespace pnet {

/// Solves the step from v (solve_with_reference) in `passes` solves (docs/methods.md), the solves recorded
/// in `stats` (Newton and CG iterations summed, the fixed-point solves of all passes added to those `stats`
/// already counts: a failed one solve's, solve_on_coulomb_floor); `relag(v)` sets the floor's contacts
/// from v before each pass after the first. Each pass after the first takes at least one Newton step: it
/// changes the friction on the floor's nodes only, which the residual over every node could hide below
/// the tolerance, and the pass would then keep the last pass's friction. A failed Newton solve throws
/// SimulationError.
template <int dim, typename Relag>
void solve_floor_friction_passes(ReferencedObjective<dim>& objective, VecX& v, const NewtonOptions& newton,
                                 const ReferenceSolveOptions& options, const std::string& context,
                                 ReferenceSolveWork<dim>& work, int passes, Relag&& relag,
                                 const std::function<void()>& after_reference, StepStats& stats) {
    int fixed_point_solves = stats.fixed_point_iterations;
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

/// A step's solve on a Coulomb floor solved in one Newton solve (`one_solve`; without a floor, or with
/// the passes, solve_floor_friction_passes alone). When `retry` is set (a floor in one solve) and the
/// MPM options let a failed one solve be solved again (floor_friction_retries), and it fails (its line
/// search failed, it stopped unconverged, or it threw NewtonError), `retry(v)` puts v and the objective
/// back where the passes' first solve starts (the step's v*, the floor's contacts of the start-of-step stress) and the
/// step is solved again by the options' floor_friction_passes. The failed solve's iterations stay in `stats` (what the
/// step cost). Returns whether the passes took over.
template <int dim, typename Relag>
bool solve_on_coulomb_floor(ReferencedObjective<dim>& objective, VecX& v, const NewtonOptions& newton,
                            const ReferenceSolveOptions& options, const MpmOptions& mpm_options,
                            const std::string& context, ReferenceSolveWork<dim>& work, bool one_solve, Relag&& relag,
                            const std::function<void(VecX&)>& retry, const std::function<void()>& after_reference,
                            StepStats& stats) {
    if (!one_solve || !retry || !floor_friction_retries(mpm_options)) {
        solve_floor_friction_passes<dim>(objective, v, newton, options, context, work,
                                         one_solve ? 1 : mpm_options.floor_friction_passes, relag, after_reference,
                                         stats);
        return false;
    }
    bool failed = false;
    try {
        const ReferenceSolveStats s =
            solve_with_reference<dim>(objective, v, newton, options, context, work, after_reference);
        record_solve(s, stats);
        stats.fixed_point_iterations = s.solves;
        failed = !s.converged || s.line_search_failed;
    } catch (const NewtonError&) {
        failed = true;  // a solve that threw left no counts; the passes' own error, if any, is the one shown
    }
    if (!failed) return false;
    retry(v);
    solve_floor_friction_passes<dim>(objective, v, newton, options, context, work, mpm_options.floor_friction_passes,
                                     relag, after_reference, stats);
    return true;
}

}  // namespace pnet
