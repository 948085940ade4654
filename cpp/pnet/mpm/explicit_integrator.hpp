#pragma once
// The ground-truth integrator (DESIGN.md §4, paper sec. 3.1-3.2): symplectic
// Euler MPM with APIC transfers and the analytic return mappings.
//
//   P2G:   m_i = sum w_ip m_p,  m_i v_i = sum w_ip m_p (v_p + C_p (x_i - x_p)) - dt sum V0_p tau_p grad w_ip
//          (tau_p = P(F^E_p) F^E_p^T, the Kirchhoff stress: F^E is inside the elastic region, so Ptilde = P)
//   grid:  v_i += dt g, boundary conditions
//   G2P:   v_p = sum w_ip v_i,  C_p = 4/dx^2 sum w_ip v_i (x_i - x_p)^T,  grad v_p = sum v_i grad w_ip^T,
//          F^E <- Z((I + dt grad v_p) F^E, h), h updated,  x_p += dt v_p.
// The SVD of the return mapping also gives the next step's stress, so each
// particle is decomposed once per step.
#include <cstddef>
#include <string>
#include <vector>

#include "pnet/mpm/grid.hpp"
#include "pnet/mpm/mpm_system.hpp"
#include "pnet/mpm/particles.hpp"

namespace pnet {

/// What one step did (for stats.csv and progress).
struct StepStats {
    double dt = 0.0;
    std::size_t clamped = 0;   // particles pulled back inside the domain
    double max_grid_speed = 0.0;
    double wall_seconds = 0.0;
    // Phases of wall_seconds: P2G (with binning and stress forces), grid
    // update, G2P (with return mapping, advection and clamping).
    double p2g_seconds = 0.0, grid_seconds = 0.0, g2p_seconds = 0.0;
};

/// A NaN or a blow-up: names the step and the particle.
class SimulationError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

template <int dim>
class ExplicitIntegrator {
public:
    explicit ExplicitIntegrator(const MpmSystem<dim>& system);

    /// The largest stable step: cfl dx / (c + max |v_p|) with c the largest
    /// P-wave speed of the materials.
    double stable_dt(const Particles<dim>& particles, double cfl) const;

    /// Advances the particles by dt. `step_index` only names the step in errors.
    StepStats step(Particles<dim>& particles, double dt, long step_index);

    const Grid<dim>& grid() const { return grid_; }

    /// V0_p tau_p of the particles' current F^E (what the next step's P2G uses),
    /// saved in checkpoints so that a resumed run is bit-identical.
    const std::vector<Mat<dim>>& cached_stress() const { return scaled_stress_; }
    void set_cached_stress(std::vector<Mat<dim>> stress) {
        scaled_stress_ = std::move(stress);
        stress_valid_ = true;
    }

    /// Forget the cached stresses (after the particles were changed from outside).
    void invalidate() { stress_valid_ = false; }

    /// Computes the stresses of the particles' current F^E (done by step() when needed).
    void compute_stress(const Particles<dim>& particles);

private:
    const MpmSystem<dim>& system_;
    Grid<dim> grid_;
    std::vector<Mat<dim>> scaled_stress_;  // V0_p tau_p, N m
    std::vector<Mat<dim>> force_matrix_;   // -dt V0_p tau_p
    bool stress_valid_ = false;
};

/// Pulls particles back inside [lower_limit, upper_limit] of the grid, so that
/// no stencil leaves it; returns how many moved. Throws SimulationError naming
/// the step and particle for a non-finite position or velocity, or a speed
/// above speed_limit (dx / dt: a particle crossing more than a cell per step
/// has blown up).
template <int dim>
std::size_t clamp_to_grid(Particles<dim>& particles, const Grid<dim>& grid, long step_index, double speed_limit);

}  // namespace pnet
