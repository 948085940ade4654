#pragma once
// What one time step did, for every method (MPM, FEM, coupling): the statistics a run writes to
// steps.csv and Python reads as a dict, declared once with their column names
// (for_each_step_field), and the error a step raises when it cannot go on (docs/architecture.md).
#include <cstddef>
#include <stdexcept>

#include "pnet/math/clock.hpp"
#include "pnet/solver/fixed_point.hpp"

namespace pnet {

/// What one step did (stats.csv, steps.csv, progress).
struct StepStats {
    double dt = 0.0;
    bool advection_capped = false;  // implicit MPM, coupling: the advection limit cut dt below the scene's
    std::size_t clamped = 0;  // particles pulled back inside the domain
    double max_grid_speed = 0.0;
    double wall_seconds = 0.0;
    // Phases of wall_seconds: P2G (with binning and, explicit, stress forces),
    // grid update or implicit solve, G2P (with return mapping, advection and clamping).
    double p2g_seconds = 0.0, grid_seconds = 0.0, g2p_seconds = 0.0;
    // Implicit integrators (zero for explicit): totals over the step's solves.
    int newton_iterations = 0;
    int cg_iterations = 0;
    int line_search_steps = 0;
    int fixed_point_iterations = 0;  // Newton solves (plasticitynet: fixed-point iterations on F0, eq. 10)
    double fixed_point_change = 0.0; // max_p ||F_p(v) - F0_p|| after the last solve (plasticitynet)
    int reference_updates = 0;       // plasticitynet: times F0 was set to F(v) (outer iterations)
    double true_residual = 0.0;      // plasticitynet: |R(v)| of the exact elastoplastic step at the end, m/s
    double initial_residual = 0.0, residual = 0.0;  // scaled gradient before the first and after the last solve, m/s
    double energy = 0.0;             // incremental potential at the solution, J
    bool converged = true;           // every Newton solve reached its tolerance
    bool line_search_failed = false; // a solve stopped because no step lowered the energy
    bool fixed_point_converged = true;  // plasticitynet: the fixed point on F0 reached its tolerance (not the cap)
    std::size_t hardening_clamped = 0;  // plasticitynet: particles whose hardening input was clamped to the trained range
    // plasticitynet: passes of the learned energy's network over the points in this step (each one a
    // value, gradient or Hessian evaluation of every point; ParticleEnergy::network_evaluations). At
    // least one per Newton iteration: the network is on the path of every iteration. 0 for the others.
    long network_evaluations = 0;
    // FEM: the Newton iterations of the elastic predictor (FemOptions::fem_predictor), which are
    // part of newton_iterations and evaluate no network.
    int predictor_iterations = 0;
    // FEM with kinematic nodes: extra solves that moved them toward their targets, and whether they got there.
    int kinematic_stages = 0;
    bool kinematic_reached = true;
    // FEM contact: CCD queries of the step (line search and starts) and how many shortened a step;
    // contact pairs closer than dhat and the smallest pair distance (m) at the end of the step.
    int ccd_queries = 0, ccd_limited = 0;
    int substeps = 1;  // explicit FEM: substeps the barrier's stability needed
    double broad_phase_seconds = 0.0, ccd_seconds = 0.0;  // FEM contact (3D): parts of wall_seconds
    std::size_t contact_pairs = 0;
    double min_distance = 0.0;
    // Where an implicit step's time went (parts of grid_seconds).
    double energy_seconds = 0.0;     // per-particle energies, stresses and Hessians
    double cg_seconds = 0.0;         // Hessian-vector products and PCG
};

/// How one StepStats field is shown: its steps.csv column (nullptr: not in the file), its key in
/// Python's step dicts (nullptr: not shown there), whether it is a FEM column (steps.csv of FEM
/// and coupled runs only), and the printf format of a floating-point value in the CSV.
struct StepField {
    const char* column;
    const char* key;
    bool fem = false;
    const char* format = "%.6g";
};

/// Calls f(StepField, member pointer) for every StepStats field, in steps.csv's column order: the
/// one list behind steps.csv (sim/run_output.hpp) and Python's step statistics (bindings).
template <typename F>
void for_each_step_field(F&& f) {
    f(StepField{"dt_s", "dt"}, &StepStats::dt);
    f(StepField{"wall_s", "wall_s"}, &StepStats::wall_seconds);
    f(StepField{"p2g_s", "p2g_s"}, &StepStats::p2g_seconds);
    f(StepField{"solve_s", "solve_s"}, &StepStats::grid_seconds);
    f(StepField{"g2p_s", "g2p_s"}, &StepStats::g2p_seconds);
    f(StepField{"energy_s", "energy_s"}, &StepStats::energy_seconds);
    f(StepField{"cg_s", "cg_s"}, &StepStats::cg_seconds);
    f(StepField{"newton_iterations", "newton_iterations"}, &StepStats::newton_iterations);
    f(StepField{"cg_iterations", "cg_iterations"}, &StepStats::cg_iterations);
    f(StepField{"line_search_steps", "line_search_steps"}, &StepStats::line_search_steps);
    f(StepField{"network_evaluations", "network_evaluations"}, &StepStats::network_evaluations);
    f(StepField{"fixed_point_iterations", "fixed_point_iterations"}, &StepStats::fixed_point_iterations);
    f(StepField{"fixed_point_change", "fixed_point_change"}, &StepStats::fixed_point_change);
    f(StepField{"initial_residual_m_per_s", "initial_residual"}, &StepStats::initial_residual);
    f(StepField{"residual_m_per_s", "residual"}, &StepStats::residual);
    f(StepField{"energy_J", "energy", false, "%.12g"}, &StepStats::energy);
    f(StepField{"converged", "converged"}, &StepStats::converged);
    f(StepField{"clamped", "clamped"}, &StepStats::clamped);
    f(StepField{"line_search_failed", "line_search_failed"}, &StepStats::line_search_failed);
    f(StepField{"hardening_clamped", "hardening_clamped"}, &StepStats::hardening_clamped);
    f(StepField{"fixed_point_converged", "fixed_point_converged"}, &StepStats::fixed_point_converged);
    f(StepField{"reference_updates", "reference_updates"}, &StepStats::reference_updates);
    f(StepField{"true_residual_m_per_s", "true_residual"}, &StepStats::true_residual);
    f(StepField{"advection_capped", "advection_capped"}, &StepStats::advection_capped);
    f(StepField{"predictor_iterations", "predictor_iterations", true}, &StepStats::predictor_iterations);
    f(StepField{"kinematic_stages", "kinematic_stages", true}, &StepStats::kinematic_stages);
    f(StepField{"kinematic_reached", "kinematic_reached", true}, &StepStats::kinematic_reached);
    f(StepField{"ccd_queries", "ccd_queries", true}, &StepStats::ccd_queries);
    f(StepField{"ccd_limited", "ccd_limited", true}, &StepStats::ccd_limited);
    f(StepField{"contact_pairs", "contact_pairs", true}, &StepStats::contact_pairs);
    f(StepField{"min_distance_m", "min_distance", true}, &StepStats::min_distance);
    f(StepField{"substeps", "substeps", true}, &StepStats::substeps);
    f(StepField{"broad_phase_s", "broad_phase_s", true}, &StepStats::broad_phase_seconds);
    f(StepField{"ccd_s", "ccd_s", true}, &StepStats::ccd_seconds);
    f(StepField{nullptr, "max_grid_speed"}, &StepStats::max_grid_speed);
}

/// Adds a step's solve statistics (solver/fixed_point.hpp) to its StepStats;
/// iteration counts add to what is there (a predictor's).
inline void record_solve(const ReferenceSolveStats& s, StepStats& stats) {
    stats.initial_residual = s.initial_residual;
    stats.newton_iterations += s.newton_iterations;
    stats.cg_iterations += s.cg_iterations;
    stats.line_search_steps += s.line_search_steps;
    stats.fixed_point_iterations = s.solves;
    stats.fixed_point_change = s.change;
    stats.reference_updates = s.reference_updates;
    stats.true_residual = s.true_residual;
    stats.residual = s.residual;
    stats.energy = s.energy;
    stats.converged = s.converged;
    stats.line_search_failed = s.line_search_failed;
    stats.fixed_point_converged = s.fixed_point_converged;
}

/// The seconds of an MPM step's phases from its time points: P2G (start to after_p2g), the grid
/// update or solve (to after_grid), G2P (to end) and the whole step.
inline void record_phases(StepStats& stats, Clock::time_point start, Clock::time_point after_p2g,
                          Clock::time_point after_grid, Clock::time_point end) {
    stats.p2g_seconds = std::chrono::duration<double>(after_p2g - start).count();
    stats.grid_seconds = std::chrono::duration<double>(after_grid - after_p2g).count();
    stats.g2p_seconds = std::chrono::duration<double>(end - after_grid).count();
    stats.wall_seconds = std::chrono::duration<double>(end - start).count();
}

/// A NaN, a blow-up or a failed solve: names the step (and the particle or
/// Newton iteration).
class SimulationError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

}  // namespace pnet
