#pragma once
// The adjoint of an implicit FEM rollout (issue 57's first part; docs/adjoint.md): the gradient of a
// loss L of the rollout's states (the last one's, or any step's) with respect to the start's positions and velocities
// and to the Young's modulus of the material (and, for von Mises metal, each element's initial hardening: the yield
// stress), for bodies under backward Euler or BDF2 with IPC contact (the ground, between bodies) and lagged friction.
//
// A converged step solves R(v; x^n, v^n, E) = M (v - v^n - dt g) + dt grad Psi(x^n + dt v) = 0 (Psi the
// elastic energy and the barrier), and x^{n+1} = x^n + dt v^{n+1}. Its Jacobian in v is the Hessian
// H = M + dt^2 Hess Psi (unprojected: the exact derivative, not the PSD one Newton steps with), so the
// step's adjoint, from the cotangents (xb, vb) of x^{n+1} and v^{n+1}, is
//   lambda = H^-1 (vb + dt xb),
//   xb^n = xb - dR/dx^n^T lambda = xb - (vb + dt xb - M lambda) / dt   (dR/dx^n = dt Hess Psi = (H - M) / dt),
//   vb^n = M lambda                                                     (dR/dv^n = -M),
//   Eb  -= lambda . dR/dE = lambda . g_el / E                           (Psi_el is linear in E at fixed nu:
//                                                                        g_el = dt grad_x Psi_el, the element
//                                                                        form's gradient in v).
// Memory: the forward pass keeps a checkpoint every C steps (C about sqrt(N): about 2 sqrt(N) states
// with the segment the backward pass recomputes; C = 1 keeps every state); the backward pass
// recomputes each segment from its checkpoint, the last first, and runs the adjoint through it. The
// forward steps are the integrator's own (FemImplicitIntegrator, `lagged`: backward Euler on the
// elastic energy), solved to the options' tolerance, which the gradient's accuracy follows (state it
// with a result); a recomputed step is the same step to the last bit.
// Plasticity (von Mises with StVK-Hencky): each element's (F^P)^-1 and h are state too. The `lagged`
// step solves the elastic energy about the step's (F^P)^-1, then return-maps; the `return_map` step
// (the classical integrator; the learned one converges to the same step) has the return-mapped stress
// Ptilde(F (F^P)^-1, h) in its residual, its Jacobian the consistent tangent T, so that its residual's
// (F^P)^-1 term has T^T and Ptilde for C and P, and its h term is -dt V (dPtilde/dh) : (G (F^P)^-1). The return
// mapping's update (F^P)^-1' = F^-1 F^E(F (F^P)^-1, h), h' = h'(...) is differentiated through
// material/return_map_derivative.hpp (one-sided, elastic, at the yield onset), and the step's
// residual through its dependence on (F^P)^-1: d(lambda . g_el)/d(F^P)^-1 = dt V [F^T (C : (G (F^P)^-1))
// + G^T P], G = sum_a lambda_a g_a^T, C = dP/dF^E.
// Clamps (fixed nodes at rest) are allowed: no unknowns, nothing flows back through their velocity.
// Friction (set_friction) is lagged: its pairs are held at their values of each step's start, so the
// x^n term of the step's adjoint uses the Hessian without friction, (H_nf - M) / dt.
// BDF2 (options.time_integrator): the step is the same potential about x^ = c x^n - p x^{n-1} with h = beta dt
// (solver/bdf2.hpp), so the step's cotangents of x^ and v^ go to x^n, v^n (times c) and to the state's
// history x^{n-1}, v^{n-1} (times -p); the first step, without history, is backward Euler.
// Refused, naming what: other plasticity, moving kinematic nodes, more than one material.
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "pnet/fem/fem_integrator.hpp"
#include "pnet/material/return_map_derivative.hpp"

namespace pnet {

/// dL/d(start state) and dL/dE of a rollout.
template <int dim>
struct FemRolloutGradient {
    std::vector<Vec<dim>> x, v;             // per node: dL/dx^0 (1/m), dL/dv^0 (s/m) times L's unit
    double youngs_modulus = 0.0;            // dL/dE (1/Pa times L's unit)
    std::vector<double> hardening;          // per element: dL/dh^0 (von Mises: h = tau_Y / (2 mu))
    std::vector<Mat<dim>> plastic_inverse;  // per element: dL/d(F^P)^-1 at the start
    std::vector<double> fields;             // dL/dp of each field set_parameter_fields asked for, in its order
};

template <int dim>
class FemAdjoint {
public:
    /// system: one material, elastic or von Mises with StVK-Hencky, no moving kinematic nodes
    /// (std::invalid_argument naming the field otherwise); contact may be null (no friction is applied); options: the
    /// forward steps' solver (the Newton tolerance sets how exact the gradient is).
    /// method: Lagged (the elastic energy about (F^P)^-1, then the return mapping) or ReturnMap (the
    /// return-mapped stress within the solve, the classical integrator; the learned one converges to the
    /// same step).
    FemAdjoint(const FemSystem<dim>& system, const ContactPotential<dim>* contact, const ImplicitOptions& options,
               FemMethod method = FemMethod::Lagged);

    /// Lagged IPC friction on the contact's pairs (Coulomb coefficient mu > 0, smoothed below eps_v
    /// m/s), as the scene's contact.friction: the adjoint holds each step's lagged pairs (their normal
    /// forces, tangents and weights, taken at the step's start) fixed, so it is the gradient of the
    /// rollout with those held (exact for one step's start velocities and E; docs/adjoint.md).
    void set_friction(double mu, double eps_v);

    /// Material fields whose dL/dp the backward pass gathers too (FemRolloutGradient::fields): material_parameter's
    /// names ("elasticity.nu", "plasticity.hardening_coefficient"), by central differences of the step's elastic
    /// force and each element's return mapping in p (material/return_map_derivative.hpp, PerturbedMaterials).
    /// Throws std::invalid_argument naming a field the material does not have.
    void set_parameter_fields(const std::vector<std::string>& fields);

    /// Runs `steps` steps of dt (backward Euler or BDF2, as the options say) from `start`, keeping a checkpoint every
    /// `checkpoint_every` steps (0: ceil(sqrt(steps)); 1: every state) and the last state, and calling
    /// observe(k, state) at each state k = 0..steps (where a loss reads them); returns the last state.
    FemState<dim> forward(const FemState<dim>& start, double dt, int steps, int checkpoint_every = 0,
                          const std::function<void(int, const FemState<dim>&)>& observe = {});

    /// The gradient of L through the last forward() run, given dL/dx^N and dL/dv^N per node.
    /// Recomputes the steps between checkpoints (at most checkpoint_every states held at once).
    FemRolloutGradient<dim> backward(const std::vector<Vec<dim>>& dL_dx, const std::vector<Vec<dim>>& dL_dv) const;
    /// The same for a loss of several states: dL_dx[k], dL_dv[k] of the state after step k (k = 0: the
    /// start; steps + 1 entries, each empty for none or one entry per node).
    FemRolloutGradient<dim> backward(const std::vector<std::vector<Vec<dim>>>& dL_dx,
                                     const std::vector<std::vector<Vec<dim>>>& dL_dv) const;

    /// The states forward() kept, by step index (the checkpoints and the last).
    const std::map<int, FemState<dim>>& checkpoints() const { return checkpoints_; }
    int steps() const { return steps_; }
    /// The most states held at once by the last forward() and backward(): the checkpoints and a
    /// recomputed segment.
    std::size_t peak_states() const { return peak_states_; }

private:
    /// The states of steps first..last (recomputed from the checkpoint at `first`).
    std::vector<FemState<dim>> segment(int first, int last) const;

    /// The element energy of the method's step.
    std::unique_ptr<ParticleEnergy<dim>> make_energy() const;

    /// An integrator of the method, with its friction when set (the friction outlives it).
    struct Stepper {
        std::unique_ptr<Friction<dim>> friction;
        std::unique_ptr<FemImplicitIntegrator<dim>> integrator;
    };
    Stepper make_stepper() const;

    const FemSystem<dim>& system_;
    const ContactPotential<dim>* contact_;
    ImplicitOptions options_;
    FemMethod method_;
    double mu_ = 0.0, eps_v_ = 1e-4;
    std::vector<PerturbedMaterials<dim>> fields_;
    std::map<int, FemState<dim>> checkpoints_;
    int steps_ = -1;
    double dt_ = 0.0;
    mutable std::size_t peak_states_ = 0;
};

}  // namespace pnet
