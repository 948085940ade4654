#pragma once
// The ground-truth integrator (docs/methods.md, paper sec. 3.1-3.2): symplectic
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
#include <functional>
#include <string>
#include <vector>

#include "pnet/mpm/grid.hpp"
#include "pnet/mpm/integrator.hpp"
#include "pnet/mpm/mpm_system.hpp"
#include "pnet/mpm/particles.hpp"

namespace pnet {

template <int dim>
class ExplicitIntegrator final : public MpmIntegrator<dim> {
public:
    explicit ExplicitIntegrator(const MpmSystem<dim>& system);

    std::string name() const override { return "explicit"; }

    /// Advances the particles by dt. `step_index` only names the step in errors.
    MpmStepStats step(Particles<dim>& particles, double dt, long step_index) override;
    void reset(const Particles<dim>& particles) override { compute_stress(particles); }
    std::vector<Mat<dim>> checkpoint_state() const override { return scaled_stress_; }
    void restore_checkpoint_state(std::vector<Mat<dim>> state) override { set_cached_stress(std::move(state)); }

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

    /// Called by step() after the grid update (velocities with gravity and boundary conditions),
    /// before G2P, with the grid and dt: the MPM-FEM coupling adds its barrier impulses there
    /// and checks the motion with CCD. Empty: none.
    void set_grid_hook(std::function<void(Grid<dim>&, double)> hook) { grid_hook_ = std::move(hook); }

private:
    const MpmSystem<dim>& system_;
    Grid<dim> grid_;
    std::vector<Vec<dim>> residual_;  // AFLIP's r_p (MpmSystem::flip_relaxation_time)
    std::vector<Mat<dim>> scaled_stress_;  // V0_p tau_p, N m
    std::vector<Mat<dim>> force_matrix_;   // -dt V0_p tau_p
    bool stress_valid_ = false;
    std::function<void(Grid<dim>&, double)> grid_hook_;
};

/// The largest stable explicit step: cfl dx / (c + max |v_p|) with c the
/// largest P-wave speed of the materials.
template <int dim>
double cfl_time_step(const MpmSystem<dim>& system, const Particles<dim>& particles, double cfl);

/// The step dt capped so that no particle moves more than `cfl` grid cells at its velocity:
/// min(dt, cfl dx / max_p |v_p|) (dt when cfl = 0 or nothing moves). MpmOptions::advection_cfl.
template <int dim>
double advection_time_step(const MpmSystem<dim>& system, const Particles<dim>& particles, double dt, double cfl);

/// Pulls particles back inside [lower_limit, upper_limit] of the grid, so that
/// no stencil leaves it; returns how many moved. Throws SimulationError naming
/// the step and particle for a non-finite position or velocity, or a speed
/// above speed_limit (explicit MPM: dx / dt, a particle crossing more than a cell per step
/// has blown up).
template <int dim>
std::size_t clamp_to_grid(Particles<dim>& particles, const Grid<dim>& grid, long step_index, double speed_limit);

/// clamp_to_grid() after an implicit MPM step of dt (ImplicitIntegrator, CoupledImplicitIntegrator): large
/// steps legitimately move particles several cells, a quarter of the domain in one step only after a
/// blow-up. Where the step is not capped by the particles' motion (advection_cfl = 0) the error also names
/// that cap: particles that cross a cell or more per step cost the solve its convergence and the step
/// its accuracy (docs/solver.md, "The advection limit").
template <int dim>
std::size_t clamp_implicit_step(Particles<dim>& particles, const MpmSystem<dim>& system, const Grid<dim>& grid,
                                long step_index, double dt, double advection_cfl);

}  // namespace pnet
