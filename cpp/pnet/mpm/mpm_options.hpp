#pragma once
// The implicit MPM step's own options (and those of coupling's particles): the advection limit, the
// Coulomb floor's friction and the grid's linear solve. Keys of a scene's "integrator" block beside
// the solver's (solver/implicit_options.hpp); declared once, in mpm_option_fields().
#include <string>
#include <vector>

#include "pnet/solver/option_field.hpp"

namespace pnet {

/// The advection limit's default (MpmOptions::advection_cfl), in grid cells per step: snowball_2d,
/// which uncapped ends 58% short of the ground truth's spread, is at explicit's noise floor with it;
/// the sand column's accuracy is unchanged (docs/solver.md, "The advection limit").
inline constexpr double kDefaultAdvectionCfl = 0.2;

struct MpmOptions {
    // Implicit MPM (and the particles of coupling): cap each step so that no particle moves more
    // than this fraction of a grid cell, dt <= advection_cfl dx / max_p |v_p| (start-of-step
    // velocities); 0: off (the scene's dt throughout). A particle that crosses about a cell in one
    // step leaves the stencil its motion was solved on: snowball_2d at 1e-3 (impact at 3.9 m/s,
    // v dt / dx = 0.99) spreads 54% less than the ground truth, at 5e-4 (0.49) 20% less. On by
    // default at kDefaultAdvectionCfl (docs/solver.md, "The advection limit", measured).
    double advection_cfl = kDefaultAdvectionCfl;
    // A Coulomb floor (MPM, coupling; every implicit integrator): "newton", the friction itself in the
    // one solve's residual, mu J_k(v) f1(|u_k|) u_k / |u_k| with the normal impulse J_k at the iterate,
    // and in its Jacobian with J's derivative (FloorFrictionForm::begin_newton); "passes",
    // floor_friction_passes majorize-minimize passes of whole solves, each with the contacts of the last
    // (docs/methods.md); "auto" (the default): newton in 2D under the work line search, where a step
    // whose one solve fails is solved again by the passes, else passes (floor_friction_in_one_solve).
    std::string floor_friction_solve = "auto";
    // The majorize-minimize passes (whole solves) of a step on a Coulomb floor under "passes", and of a
    // step whose one solve failed under "auto".
    int floor_friction_passes = 3;
    // Where a step's Newton solve starts: "last_step", v* plus the last step's implicit velocity change
    // (v - v*) scaled to this step, on the nodes both steps share (mpm/step_predictor.hpp: held nodes and
    // light ones start at v*; a resumed run keeps it); "v_star", v* (free fall for one step); "auto" (the
    // default): the integrator's entry (IntegratorInfo::predicts_newton_start: last_step under return_map
    // and lagged, v_star under plasticitynet). Measured: docs/solver.md, "Where Newton starts".
    std::string newton_start = "auto";
    // The linear solve of MPM's Newton iterations: "pcg" (matrix-free, with the solver's
    // preconditioner) or "cholesky" (CHOLMOD on the assembled grid Hessian, its symbolic analysis kept
    // while the active grid is the same).
    std::string linear_solver = "pcg";
};

/// Whether a step on a Coulomb floor is one solve: floor_friction_solve "newton", or "auto" in 2D with
/// the work line search (`work_line_search`: the step's Hessian is the consistent tangent, so the line
/// search judges the residual itself, which the friction makes no potential's gradient). Measured
/// (docs/methods.md): on the 2D sand column one solve is 1.5x faster than the passes and as accurate;
/// on the 3D column, stopped at the default tolerance, it ends 0.008 below the passes' J(4dx) minimum
/// (0.978 against 0.986, the floor 0.987) and the tolerance that closes the gap costs what the passes
/// cost. Under the learned energy's energy line search one solve is 1.23x faster on the 2D sand column
/// (25 frames, as accurate), but on the stiff column its line search failed in 196 of 430 steps and it
/// ended farther from the ground truth than the passes (spread -3.4% against -2.5%); solved again by
/// the passes where it failed, that column took 1.5x the passes' time.
inline bool floor_friction_in_one_solve(const MpmOptions& options, int dim, bool work_line_search) {
    return options.floor_friction_solve == "newton" ||
           (options.floor_friction_solve == "auto" && dim == 2 && work_line_search);
}

/// Whether a one solve that fails (its line search, its iteration cap, or a NewtonError) is solved again
/// by the passes from the step's start (solve_on_coulomb_floor): under "auto", whose one solve is then
/// the measured default; "newton" reports such a step unconverged instead.
inline bool floor_friction_retries(const MpmOptions& options) {
    return options.floor_friction_solve == "auto";
}

/// Every key of MpmOptions, in the order --help lists them.
inline const std::vector<OptionField<MpmOptions>>& mpm_option_fields() {
    using O = MpmOptions;
    static const std::vector<OptionField<O>> fields = {
        number_option("advection_cfl", "--advection-cfl", 0.0, false, 1.0, false, &O::advection_cfl,
                      "MPM: cap a step so that no particle moves more than this many cells (0: off)"),
        choice_option("floor_friction_solve", "--floor-friction-solve", {"auto", "newton", "passes"},
                      &O::floor_friction_solve,
                      "a Coulomb floor's friction: in the one Newton solve's residual and Jacobian (newton), or "
                      "three majorize-minimize passes (passes); auto: newton in 2D under the work line search "
                      "(return_map; a step it fails solved again by passes), else passes"),
        integer_option("floor_friction_passes", "--floor-friction-passes", 1, 100, &O::floor_friction_passes,
                       "a Coulomb floor's passes per step (floor_friction_solve passes, or after a failed one solve)"),
        choice_option("newton_start", "--newton-start", {"auto", "last_step", "v_star"}, &O::newton_start,
                      "MPM, coupling: where a step's Newton solve starts: v* plus the last step's implicit velocity "
                      "change (last_step), or v*; auto: last_step under return_map and lagged, v_star under "
                      "plasticitynet"),
        choice_option("linear_solver", nullptr, {"pcg", "cholesky"}, &O::linear_solver,
                      "MPM's linear solve: matrix-free PCG or CHOLMOD on the assembled Hessian"),
    };
    return fields;
}

}  // namespace pnet
