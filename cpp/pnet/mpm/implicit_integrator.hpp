#pragma once
// The optimization time integrators of implicit MPM (docs/methods.md, paper sec.
// 3.1 and 4.2). A step:
//   P2G (mass, APIC momentum), v* = momentum / m + dt g with boundary values;
//   minimize the incremental potential E(v) (incremental_potential.hpp) by
//   Newton (solver/newton.hpp) from v = v*;
//   G2P with the return mapping and advection (grid_to_particles.hpp).
//
// `plasticitynet`: psi = the learned energy Psi(F; F0, h). F0 comes from the
//   fixed-point loop of paper eq. 10: F0^0 = F_p(v*); after solve j,
//   F0^{j+1} = F_p(v^{j+1}), until max_p ||F_p(v^{j+1}) - F0^j||_F is below
//   fixed_point_tolerance or max_fixed_point_iterations solves were made (each
//   solve starts from the previous one's v). If the change grows from one
//   iteration to the next (the loop is not contracting: deformations far from
//   the training regime), the loop stops; the step always takes the solution
//   with the smallest change.
// `lagged`: psi = the elastic energy of F_p(v) alone; plasticity is applied
//   after the step by the return mapping (as in Ziran and HOT).
//
// BDF2 (ImplicitOptions::time_integrator "bdf2"): the particles carry the last step's velocity (v^{n-1})
// and displacement rate u = (x^n - x^{n-1}) / dt, each with an APIC affine matrix, transferred to the
// grid with the current step's weights; the potential is then BDF2's (IncrementalPotential::use_bdf2,
// with the variable-step coefficients when dt differs from the last step's),
// and G2P moves the particles and their F by the displacement rate while v_p, C_p come from the grid
// velocity at the start-of-step positions. The first step (no history) is backward Euler.
//
// Boundary conditions are those of explicit MPM (docs/methods.md): the sticky
// floor's nodes are fixed at zero velocity during the solve, and slip walls
// act after it, removing the wall-ward normal velocity of the nodes within
// Grid::kWallNodes of a wall, just as explicit MPM projects its updated grid
// velocity (so v* of a wall node is not projected either). A one-sided
// constraint inside the solve (v_n >= 0) would need a bound-constrained Newton
// and would differ from explicit MPM, which has no such constraint on the
// internal forces; with the projection after the solve the two integrators
// differ only by the time integration.
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "pnet/energy/particle_energy.hpp"
#include "pnet/mpm/grid.hpp"
#include "pnet/mpm/incremental_potential.hpp"
#include "pnet/mpm/integrator.hpp"
#include "pnet/mpm/mpm_options.hpp"
#include "pnet/mpm/mpm_system.hpp"
#include "pnet/mpm/step_predictor.hpp"
#include "pnet/nn/learned_return_map.hpp"
#include "pnet/solver/fixed_point.hpp"
#include "pnet/solver/implicit_options.hpp"
#include "pnet/solver/integrators.hpp"
#include "pnet/solver/newton.hpp"

namespace pnet {

/// The implicit MPM methods: plasticitynet, return_map, lagged (solver/integrators.hpp).
using ImplicitMethod = Method;

template <int dim>
class ImplicitIntegrator final : public MpmIntegrator<dim> {
public:
    /// `energy`: the per-particle energy (NeuralParticleEnergy for plasticitynet,
    /// ReturnMappingEnergy for return_map, ElasticParticleEnergy for lagged). `return_maps[k]`:
    /// object k's learned return mapping, or null for its material's analytic
    /// one (empty: analytic for all).
    ImplicitIntegrator(const MpmSystem<dim>& system, ImplicitMethod method, const ImplicitOptions& options,
                       const MpmOptions& mpm_options, std::unique_ptr<ParticleEnergy<dim>> energy,
                       std::vector<const LearnedReturnMap<dim>*> return_maps = {});

    std::string name() const override { return to_string(method_); }

    /// Throws SimulationError ("step N: ...") when a Newton solve fails (NaN,
    /// non-descent direction, line-search stall: the particles are left as they
    /// were before the step) or a particle blows up after it.
    MpmStepStats step(Particles<dim>& particles, double dt, long step_index) override;

    /// The history and the Newton start's prediction reset with the particles (the next step is
    /// backward Euler's start-up, from v*).
    void reset(const Particles<dim>& particles) override;
    /// BDF2's history (empty before a BDF2 run's first step): 3 n + 1 matrices, the previous velocities'
    /// affine parts, the displacement rates' affine parts, (v^{n-1}_p, u_p) as the first two columns, and
    /// the last step's dt in (0, 0) (a state of 3 n matrices, written before it was kept, still loads).
    std::vector<Mat<dim>> checkpoint_state() const override;
    void restore_checkpoint_state(std::vector<Mat<dim>> state) override;
    /// The Newton start's prediction (MpmOptions::newton_start; StepPredictor::state).
    std::vector<Mat<dim>> checkpoint_prediction() const override { return predictor_.state(); }
    void restore_checkpoint_prediction(const std::vector<Mat<dim>>& state) override;

    const ImplicitOptions& options() const { return options_; }
    const MpmOptions& mpm_options() const { return mpm_options_; }
    const Grid<dim>& grid() const { return grid_; }
    IncrementalPotential<dim>& potential() { return potential_; }
    /// The last step's solution on the potential's unknowns, before the slip walls' projection (the
    /// adjoint's linearization point: mpm_adjoint.hpp).
    const VecX& solution() const { return v_; }

private:
    /// The step's grid solve, from v* or (`predicted`) v* plus the Newton start's prediction, into v_
    /// and `stats`: the potential set up on grid_'s P2G (BDF2's history, the Coulomb floor), then the
    /// Newton solves (floor_friction_passes.hpp).
    void solve_grid(const Particles<dim>& particles, double dt, long step_index, const BoundaryConditions& boundary,
                    bool predicted, MpmStepStats& stats);

    const MpmSystem<dim>& system_;
    ImplicitMethod method_;
    ImplicitOptions options_;
    MpmOptions mpm_options_;
    std::unique_ptr<ParticleEnergy<dim>> energy_;
    std::vector<const LearnedReturnMap<dim>*> return_maps_;
    Grid<dim> grid_;
    IncrementalPotential<dim> potential_;
    ReferenceSolveWork<dim> work_;
    VecX v_;
    StepPredictor<dim> predictor_;  // MpmOptions::newton_start "last_step"
    // BDF2's history per particle (time_integrator "bdf2"; empty before the first step): the velocity
    // and APIC matrix at the start of the last step (v^{n-1}), and that step's displacement rate
    // u = (x^n - x^{n-1}) / dt with its affine part, each transferred to the grid like the velocity.
    std::vector<Vec<dim>> previous_v_, rate_;
    std::vector<Vec<dim>> residual_;  // AFLIP's r_p (MpmSystem::flip_relaxation_time)
    std::vector<Mat<dim>> previous_C_, rate_C_;
    Grid<dim> history_grid_;  // the P2G of a history field
    VecX history_u_, history_v_;
    std::vector<Vec<dim>> start_x_;
    double history_dt_ = 0.0;  // the last BDF2 step's dt (0: none, or restored without it)
};

}  // namespace pnet
