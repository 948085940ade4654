#pragma once
// What one time step did: the statistics of any step (its dt, phases and solves) that a run writes to
// steps.csv and Python reads as a dict, declared with their column names (StepStats::for_each_field);
// the record that adds each layer's own fields (StepStatsWith); and the error a step raises when it
// cannot go on (docs/architecture.md).
#include <cstddef>
#include <stdexcept>
#include <type_traits>

#include "pnet/math/clock.hpp"
#include "pnet/solver/fixed_point.hpp"

namespace pnet {

/// What any step did, whatever the method (the solver's part of steps.csv): its dt and phases, and the
/// statistics of its solves. Each method's layer adds its own fields (StepStatsWith below:
/// mpm/mpm_step_stats.hpp, fem/fem_step_stats.hpp, contact/contact_step_stats.hpp).
struct StepStats {
    double dt = 0.0;
    double max_grid_speed = 0.0;  // the largest speed of the step's unknowns (grid nodes; FEM: mesh nodes), m/s
    double wall_seconds = 0.0;
    // Phases of wall_seconds: before the solve (MPM: P2G with binning and, explicit, stress forces),
    // the grid update or implicit solve, after it (MPM: G2P with return mapping, advection and
    // clamping; FEM: the return mappings and the position update).
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
    // plasticitynet: the points (particles, elements) those passes evaluated, summed over the passes:
    // passes x points where every pass covers every point, fewer where network_reuse keeps a point's
    // Hessian or values a trial point by the energy's expansion (ParticleEnergy::network_points).
    long network_points = 0;
    // Where an implicit step's time went (parts of grid_seconds).
    double energy_seconds = 0.0;     // per-particle energies, stresses and Hessians
    double cg_seconds = 0.0;         // Hessian-vector products and PCG

    /// Calls f(StepField, member pointer) for each field above, in steps.csv's column order.
    template <typename F>
    static void for_each_field(F&& f);
};

/// How one step statistic is shown: its steps.csv column (nullptr: not in the file), its key in
/// Python's step dicts (nullptr: not shown there), whether it is a FEM column (steps.csv of FEM
/// and coupled runs only), and the printf format of a floating-point value in the CSV.
struct StepField {
    const char* column;
    const char* key;
    bool fem = false;
    const char* format = "%.6g";
};

template <typename F>
void StepStats::for_each_field(F&& f) {
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
    f(StepField{"network_points", "network_points"}, &StepStats::network_points);
    f(StepField{"fixed_point_iterations", "fixed_point_iterations"}, &StepStats::fixed_point_iterations);
    f(StepField{"fixed_point_change", "fixed_point_change"}, &StepStats::fixed_point_change);
    f(StepField{"initial_residual_m_per_s", "initial_residual"}, &StepStats::initial_residual);
    f(StepField{"residual_m_per_s", "residual"}, &StepStats::residual);
    f(StepField{"energy_J", "energy", false, "%.12g"}, &StepStats::energy);
    f(StepField{"converged", "converged"}, &StepStats::converged);
    f(StepField{"line_search_failed", "line_search_failed"}, &StepStats::line_search_failed);
    f(StepField{"hardening_clamped", "hardening_clamped"}, &StepStats::hardening_clamped);
    f(StepField{"fixed_point_converged", "fixed_point_converged"}, &StepStats::fixed_point_converged);
    f(StepField{"reference_updates", "reference_updates"}, &StepStats::reference_updates);
    f(StepField{"true_residual_m_per_s", "true_residual"}, &StepStats::true_residual);
    f(StepField{nullptr, "max_grid_speed"}, &StepStats::max_grid_speed);
}

/// A step's statistics with the fields of the layers that took it: StepStats and each Part, a struct
/// of one layer's fields with its own static for_each_field (MpmStepFields, FemStepFields,
/// ContactStepFields). A record converts to one with more parts (the fields it lacks keep their
/// defaults), so a driver above every method keeps the union (sim/step_record.hpp).
template <typename... Parts>
struct StepStatsWith : StepStats, Parts... {
    StepStatsWith() = default;
    template <typename... Other>
    StepStatsWith(const StepStatsWith<Other...>& other) : StepStats(other) {  // NOLINT: widening, implicit
        auto copy = [&](auto* part) {
            using Part = std::remove_pointer_t<decltype(part)>;
            if constexpr ((std::is_same_v<Part, Other> || ...)) static_cast<Part&>(*this) = other;
        };
        (copy(static_cast<Parts*>(nullptr)), ...);
    }

    /// StepStats' fields, then each part's, in steps.csv's column order.
    template <typename F>
    static void for_each_field(F&& f) {
        StepStats::for_each_field(f);
        (Parts::for_each_field(f), ...);
    }
};

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
