#pragma once
// What the simulation loop sees of an MPM time integrator (DESIGN.md §4):
// explicit (explicit_integrator.hpp), plasticitynet and lagged
// (implicit_integrator.hpp) all step the same particles on the same grid with
// the same transfers and boundary conditions, so runs differ only by the time
// integration.
#include <cstddef>
#include <stdexcept>
#include <string>
#include <vector>

#include "pnet/math/types.hpp"
#include "pnet/mpm/particles.hpp"
#include "pnet/solver/fixed_point.hpp"

namespace pnet {

/// What one step did (stats.csv, steps.csv, progress).
struct StepStats {
    double dt = 0.0;
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

/// A NaN, a blow-up or a failed solve: names the step (and the particle or
/// Newton iteration).
class SimulationError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

template <int dim>
class MpmIntegrator {
public:
    virtual ~MpmIntegrator() = default;

    /// "explicit", "plasticitynet" or "lagged".
    virtual std::string name() const = 0;

    /// Advances the particles by dt. `step_index` only names the step in errors.
    virtual StepStats step(Particles<dim>& particles, double dt, long step_index) = 0;

    /// Called when the particles were set from outside (start of a run).
    virtual void reset(const Particles<dim>& /*particles*/) {}

    /// State beyond the particles that a bit-identical resume needs (explicit:
    /// the cached stresses), saved in checkpoints.
    virtual std::vector<Mat<dim>> checkpoint_state() const { return {}; }
    virtual void restore_checkpoint_state(std::vector<Mat<dim>> /*state*/) {}
};

}  // namespace pnet
