#pragma once
// The adjoint of an implicit MPM rollout (issue 57's MPM half, its first part; docs/adjoint.md): the
// gradient of a loss of the last state's particle positions and velocities with respect to the start's
// positions, velocities, APIC matrices and F, and to the materials' Young's modulus, for elastic bodies
// under `lagged` backward Euler (the elastic energy: with no plasticity every implicit MPM integrator
// solves this step) with APIC transfers and slip walls.
//
// A step: P2G (m_i, q_i), v* = q / m + dt g; the solve R(v) = M (v - v*) + sum_p V_p dt P(F_p(v)) F_p^T
// grad w_ip = 0 with F_p(v) = (I + dt sum_i v_i grad w_ip^T) F_p; the slip walls' projection (the
// wall-ward normal velocity of the nodes within Grid::kWallNodes of a wall set to 0); G2P. Its adjoint,
// from the cotangents of the step's output: G2P's (transfer_adjoint.hpp) gives the grid velocities'
// cotangent vb; the projected components' is dropped (the projection's active set held: one-sided
// where a component is exactly at 0); lambda = H^-1 vb with H = dR/dv, the exact (unprojected) Hessian
// at the solution; then
//   vb*_i = m_i lambda_i,   mb_i = -lambda_i . (v_i - v*_i),
//   with S_p = V_p dt P(F_p) : (Lambda_p F^n_p), Lambda_p = sum_i lambda_i grad w_ip^T (lambda . R's
//   particle term), A_p = I + dt G_p, Q_p = dP/dF : (Lambda_p F^n_p):
//   Fb^n_p -= V_p dt [A_p^T Q_p + Lambda_p^T P],
//   xb_p -= V_p dt sum_i Hess w_ip F^n_p (P^T lambda_i + dt Q_p^T v_i),
//   Eb -= sum_p S_p / E (the energy is linear in E at fixed nu);
// and P2G's adjoint from qb_i = vb*_i / m_i, mb_i -= vb*_i . q_i / m_i^2.
//
// The forward steps are the production integrator's (ImplicitIntegrator, `lagged`), at a fixed dt (the
// advection limit is the simulation's, not applied here), solved to the options' tolerance, which the
// gradient's accuracy follows. Every step's start state and solution are kept (the tape; about 2 sqrt(N)
// states with checkpoints is the FEM adjoint's and is not yet written here). Refused, naming what:
// plasticity, AFLIP transfers, a sticky or Coulomb floor, BDF2.
#include <functional>
#include <vector>

#include "pnet/mpm/implicit_integrator.hpp"

namespace pnet {

template <int dim>
struct MpmRolloutGradient {
    std::vector<Vec<dim>> x, v;   // per particle: dL/dx^0 (1/m), dL/dv^0 (s/m), times L's unit
    std::vector<Mat<dim>> C, F;   // dL/dC^0 (s), dL/dF^0
    double youngs_modulus = 0.0;  // dL/dE, every material's E scaled together (1/Pa)
};

template <int dim>
class MpmAdjoint {
public:
    /// Throws std::invalid_argument naming what the adjoint does not cover.
    MpmAdjoint(const MpmSystem<dim>& system, const ImplicitOptions& options, const MpmOptions& mpm_options);

    /// `steps` steps of dt from `start`, kept on the tape, calling observe(k, state) at each state k =
    /// 0..steps (where a loss reads them); returns the last state.
    Particles<dim> forward(const Particles<dim>& start, double dt, int steps,
                           const std::function<void(int, const Particles<dim>&)>& observe = {});

    /// The gradient of L, given dL/dx and dL/dv of the last forward state's particles.
    MpmRolloutGradient<dim> backward(const std::vector<Vec<dim>>& x_bar, const std::vector<Vec<dim>>& v_bar) const;
    /// The same for a loss of any states: x_bar[k], v_bar[k] (k = 0..steps; an empty entry: L does not
    /// read that state's positions or velocities).
    MpmRolloutGradient<dim> backward(const std::vector<std::vector<Vec<dim>>>& x_bar,
                                     const std::vector<std::vector<Vec<dim>>>& v_bar) const;
    /// Steps of the last forward pass (-1: none).
    int steps() const { return forwarded_ ? static_cast<int>(tape_.size()) : -1; }

private:
    /// One step's adjoint: from the cotangents of its output (g, overwritten) to those of its start.
    void step_adjoint(std::size_t k, MpmRolloutGradient<dim>& g) const;

    const MpmSystem<dim>& system_;
    ImplicitOptions options_;
    MpmOptions mpm_options_;
    std::vector<Particles<dim>> tape_;  // each step's start state
    std::vector<VecX> solutions_;       // each step's solution on its unknowns, before the projection
    std::vector<double> dts_;
    std::size_t last_size_ = 0;  // particles
    bool forwarded_ = false;
};

}  // namespace pnet
