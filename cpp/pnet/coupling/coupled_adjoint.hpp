#pragma once
// The adjoint of an implicit MPM-FEM coupled rollout (issue 57's coupling part; docs/adjoint.md): the gradient
// of a loss of the particles' and the mesh nodes' positions and velocities with respect to the start's particle
// state (x, v, C, F, hardening), the nodes' positions and velocities, the particles' and the mesh's Young's
// modulus and the particles' plasticity parameters.
//
// A coupled step (coupled_integrator.hpp) solves R(v) = 0 over v = [grid velocities; node velocities]:
//   R = [R_mpm(v_g); R_fem(v_f)] + W^T dt grad B(y(v)),   y = [x^n + dt v_f; X^n + dt sum_i w_ip(X^n) v_i],
// B the particle / mesh barrier in the contact's vertex positions y (the mesh's nodes, then the particles), W
// the vertices' weights on the unknowns (a node's own velocity; a particle's stencil weights w_ip). Its
// Jacobian is J = blockdiag(J_mpm, H_fem) + dt^2 W^T Hess B W, J_mpm the MPM step's (mpm_adjoint.hpp:
// symmetric for the elastic stress of lagged, the consistent tangent with its skew part for return_map), H_fem
// the mesh's potential's exact Hessian (its elasticity and its own contact), Hess B unprojected. From the
// cotangents of the step's output, lambda = J^-T [G2P's adjoint on the grid; vb + dt xb on the nodes]
// (assembled, sparse LU); then the MPM part's start cotangents as MpmAdjoint's (MpmStepAdjoint), the nodes'
//   vb^n = M lambda_f,   xb^n = xb - (H_fem - M) lambda_f / dt,   Eb_fem -= lambda_f . g_el / E,
// and the barrier's dependence on the start's positions, with mu = W dt lambda (the vertices' motion along
// lambda) and B's gradient g_B and Hessian H_B at y:
//   xb_a^n -= (H_B mu)_a                                          (a node: y_a = x_a^n + dt v_a),
//   Xb_p^n -= (I + dt sum_i grad w_ip v_i^T) (H_B mu)_p + dt sum_i (lambda_i . g_B,p) grad w_ip
//                                                                 (a particle: y_p and mu_p move with X_p^n).
// Memory and recomputation as the MPM and FEM adjoints': a checkpoint every C steps (about sqrt(N)), each segment
// recomputed from its checkpoint, the last first. The forward steps are the production coupled integrator's
// (lagged or return_map for the particles), at a fixed dt, solved to the options' tolerance.
// Friction (set_friction) is lagged: each step's pairs are held at their values of its start (their normal forces,
// tangents and the closest points' weights), so the particle-mesh friction dt D(u(v)) adds its Hessian in the
// vertices' velocities u = W v to J and, through a particle's u_p = sum_i w_ip(X^n) v_i, with G its gradient in u
// and nu = W lambda:  Xb_p^n -= sum_i ((lambda_i . G_p) + (v_i . (Hess D nu)_p)) grad w_ip;  the meshes' own
// friction is in H_fem, and their x^n term takes H_fem without it (FemAdjoint's).
// Refused, naming what: a Coulomb floor, plastic or kinematic meshes, more than one mesh material, and what
// MpmAdjoint refuses of the particles' materials.
#include <functional>
#include <map>
#include <memory>
#include <vector>

#include "pnet/contact/collisions/contact_potential.hpp"
#include "pnet/coupling/coupled_integrator.hpp"
#include "pnet/mpm/mpm_adjoint.hpp"

namespace pnet {

/// A coupled rollout's state: the particles and the meshes.
template <int dim>
struct CoupledState {
    Particles<dim> particles;
    FemState<dim> mesh;
};

template <int dim>
struct CoupledRolloutGradient {
    MpmRolloutGradient<dim> particles;     // dL/d(particle state), dL/dE of the particles, their plasticity's
    std::vector<Vec<dim>> node_x, node_v;  // per mesh node: dL/dx^0 (1/m), dL/dv^0 (s/m)
    double mesh_youngs_modulus = 0.0;      // dL/dE of the mesh's material (1/Pa)
};

template <int dim>
class CoupledAdjoint {
public:
    /// mesh_contact: the meshes' own contact (ground, between meshes; may be null); contact: the particles
    /// against the meshes (stand-alone points after the mesh's nodes). method: Lagged or ReturnMap (the
    /// particles' energy in the solve). Throws std::invalid_argument naming what it does not cover.
    CoupledAdjoint(const MpmSystem<dim>& mpm, const FemSystem<dim>& fem, const ContactPotential<dim>* mesh_contact,
                   const ContactPotential<dim>& contact, const ImplicitOptions& options, const MpmOptions& mpm_options,
                   const CouplingOptions& coupling_options, Method method = Method::Lagged);
    ~CoupledAdjoint();
    CoupledAdjoint(CoupledAdjoint&&) noexcept;

    /// `steps` steps of dt from `start`, a checkpoint every `checkpoint_every` steps (0: ceil(sqrt(steps)); 1:
    /// every state), observe(k, state) at each state k = 0..steps; returns the last state.
    CoupledState<dim> forward(const CoupledState<dim>& start, double dt, int steps,
                              const std::function<void(int, const CoupledState<dim>&)>& observe = {},
                              int checkpoint_every = 0);

    /// The gradient of L given, per state k = 0..steps, dL/dx and dL/dv of its particles and of its mesh's
    /// nodes (an empty entry: L does not read them).
    CoupledRolloutGradient<dim> backward(const std::vector<std::vector<Vec<dim>>>& particle_x_bar,
                                         const std::vector<std::vector<Vec<dim>>>& particle_v_bar,
                                         const std::vector<std::vector<Vec<dim>>>& node_x_bar,
                                         const std::vector<std::vector<Vec<dim>>>& node_v_bar) const;

    /// Lagged friction (Coulomb coefficient mu > 0, smoothed below eps_v m/s), as the scene's contact.friction:
    /// between the particles and the meshes and on the meshes' own contact. The adjoint holds each step's lagged
    /// pairs (their normal forces, tangents and weights, taken at the step's start) fixed, so it is the gradient
    /// of the rollout with those held: exact for one step's start velocities and the moduli (docs/adjoint.md).
    void set_friction(double mu, double eps_v);

    /// The particles' material fields whose dL/dp the backward pass gathers too (g.particles.fields): as
    /// MpmAdjoint::set_parameter_fields.
    void set_parameter_fields(const std::vector<std::string>& fields);

    int steps() const { return steps_; }
    /// Steps of the last forward pass whose solve did not reach the tolerance.
    int unconverged_steps() const { return unconverged_; }
    /// The most states held at once by the last forward and backward passes.
    std::size_t peak_states() const { return peak_states_; }

private:
    struct Stepper;
    std::unique_ptr<Stepper> make_stepper() const;
    /// A symmetric step's LDL^T, its analysis kept from step to step while J's pattern is the same.
    struct Factor;
    /// One step's adjoint: from the cotangents of its output (g, xb, vb: overwritten) to those of its start.
    void step_adjoint(const CoupledState<dim>& start, const VecX& solution, int step, CoupledRolloutGradient<dim>& g,
                      VecX& node_x_bar, VecX& node_v_bar) const;

    const MpmSystem<dim>& mpm_;
    const FemSystem<dim>& fem_;
    const ContactPotential<dim>* mesh_contact_;
    const ContactPotential<dim>& contact_;
    ImplicitOptions options_;
    MpmOptions mpm_options_;
    CouplingOptions coupling_options_;
    Method method_;
    double mu_ = 0.0, eps_v_ = 1e-4;
    std::vector<PerturbedMaterials<dim>> fields_;
    std::map<int, CoupledState<dim>> checkpoints_;
    double dt_ = 0.0;
    int steps_ = -1, unconverged_ = 0;
    std::size_t particles_ = 0;
    mutable std::size_t peak_states_ = 0;
    std::unique_ptr<Factor> factor_;
};

}  // namespace pnet
