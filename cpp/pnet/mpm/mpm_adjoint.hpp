#pragma once
// The adjoint of an implicit MPM rollout (issue 57's MPM half; docs/adjoint.md): the gradient of a loss
// of the states' particle positions and velocities with respect to the start's positions, velocities,
// APIC matrices, F and hardening, to the materials' Young's modulus and to their plasticity parameters (the
// friction angle of Drucker-Prager and Cam-Clay, Cam-Clay's xi and beta), for elastic, Drucker-Prager sand,
// Cam-Clay snow (its exact variant) and von Mises metal (StVK-Hencky) bodies under backward Euler with APIC or
// AFLIP transfers, slip walls and a sticky or Coulomb floor: the `lagged`
// step (the elastic energy, then the return mapping) or `return_map`'s (the return-mapped stress Ptilde
// and its consistent tangent T, with its skew part, within the solve; plasticitynet converges to it).
// With plasticity, R's Jacobian M + sum_p V dt^2 B_p^T T_p B_p is not symmetric: lambda solves its
// transpose (assembled, sparse LU; T is the return mapping's exact Jacobian where written, return_map_tangent),
// the stress terms below take T^T where the elastic step has dP/dF, G2P's trial F gets dF^E/dF_trial^T and
// dh'/dF_trial of its F's and hardening's cotangents (material/return_map_derivative.hpp), the start's
// hardening gets dF^E/dh, dh'/dh and lambda's dPtilde/dh term, and each plasticity parameter's cotangent
// gathers lambda's dPtilde/dparameter term and G2P's dF^E/dparameter and dh'/dparameter.
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
// The forward steps are the production integrator's (ImplicitIntegrator, `lagged` or `return_map`), at a
// fixed dt (the advection limit is the simulation's, not applied here), solved to the options' tolerance,
// which the gradient's accuracy follows. The forward pass keeps a checkpoint every C steps (about sqrt(N)); the
// backward pass recomputes each segment from its checkpoint, the last first (about 2 sqrt(N) states at
// once), as the FEM adjoint does. Sand at rest from F = I (a column's free surface) sits at the cone's tip,
// where the projection has no derivative: the gradient is one-sided there (docs/adjoint.md). Refused,
// naming what: Cam-Clay's paper variant, von Mises with another elasticity, a Coulomb floor under lagged, BDF2.
// The sticky floor's nodes are held at 0 by the solve: constants, whose lambda is 0. A Coulomb floor (return_map:
// its friction in the one solve, floor_friction_solve "newton") adds the friction's Jacobian to J^T, with the
// held normal rows of its contacts as unknowns that carry the floor impulse's cotangent, and the floor's
// projection after the solve (docs/adjoint.md).
#include <array>
#include <functional>
#include <map>
#include <string>
#include <vector>

#include "pnet/energy/particle_energy.hpp"
#include "pnet/material/return_map_derivative.hpp"
#include "pnet/mpm/implicit_integrator.hpp"

namespace pnet {

/// Throws std::invalid_argument, prefixed by `who` and naming the field, for a particle material the MPM adjoint
/// does not differentiate (Cam-Clay's paper variant, von Mises with another elasticity than stvk_hencky).
template <int dim>
void require_adjoint_materials(const MpmSystem<dim>& system, const std::string& who);

template <int dim>
struct MpmRolloutGradient {
    std::vector<Vec<dim>> x, v;   // per particle: dL/dx^0 (1/m), dL/dv^0 (s/m), times L's unit
    std::vector<Mat<dim>> C, F;   // dL/dC^0 (s), dL/dF^0
    std::vector<double> hardening;  // per particle: dL/dh^0 (Cam-Clay a; von Mises h = tau_Y / (2 mu))
    double youngs_modulus = 0.0;    // dL/dE, every material's E scaled together (1/Pa)
    /// dL/dphi: every Drucker-Prager and Cam-Clay material's friction angle together (1/degree).
    double friction_angle = 0.0;
    double xi = 0.0, beta = 0.0;  // dL/dxi, dL/dbeta: every Cam-Clay material's together
    /// dL/dp of each field MpmAdjoint::set_parameter_fields asked for, in its order: every material that has the
    /// field moved together.
    std::vector<double> fields;
};

/// A Coulomb floor's contact at the step's solution: its node's unknown, the floor's normal impulse J_k (the
/// residual's held row (k, y) with v*_k,y as update_velocity left it; <= 0: the floor pulls, no friction), the
/// friction's coefficient c = mu f1(|u|) u / |u| on the node's tangential velocity u (the force c J_k) and
/// J_k dc/du.
template <int dim>
struct FloorContact {
    using Tangent = Eigen::Matrix<double, dim - 1, 1>;
    using TangentMatrix = Eigen::Matrix<double, dim - 1, dim - 1>;
    int dof;
    double impulse = 0.0;
    Tangent c = Tangent::Zero();
    TangentMatrix dc = TangentMatrix::Zero();
};

/// One implicit MPM step's adjoint, in the parts MpmAdjoint and the coupled adjoint (coupling/coupled_adjoint.hpp)
/// share: the step rebuilt from its start and its solution v (P2G, the potential, the projection after the solve,
/// the stress and its exact tangent at v); G2P's adjoint, from the cotangents of the step's output to the
/// right-hand side of J^T lambda = rhs on the step's unknowns; J^T (assembled) or the solve itself; and, from
/// lambda, the cotangents of the step's start (through the solve's residual, AFLIP's residual and P2G).
template <int dim>
class MpmStepAdjoint {
public:
    using Parameters = std::array<double, kPlasticityParameters>;

    /// start: the step's start (kept by reference); v: its solution on the unknowns (before the projection);
    /// fields: the material fields whose gradients g.fields gathers (kept by pointer; null: none).
    MpmStepAdjoint(const MpmSystem<dim>& system, Method method, const Particles<dim>& start, const VecX& v, double dt,
                   const std::vector<PerturbedMaterials<dim>>* fields = nullptr);
    MpmStepAdjoint(const MpmStepAdjoint&) = delete;  // its potential refers to its grid and energy
    MpmStepAdjoint& operator=(const MpmStepAdjoint&) = delete;

    /// The step's potential (its exact Hessian: no PSD projection), set up as the integrator's.
    IncrementalPotential<dim>& potential() { return potential_; }
    const Grid<dim>& grid() const { return grid_; }

    /// G2P's adjoint from the cotangents of the step's output (g's x, v, C, F, hardening): the right-hand side of
    /// J^T lambda = rhs (zero on the components the solve holds).
    VecX output_adjoint(const MpmRolloutGradient<dim>& g);
    /// Whether J is symmetric (an elastic stress in the solve, no Coulomb floor): the potential's own Hessian.
    bool symmetric() const;
    /// J^T's entries, rows and columns shifted by `offset` (the held components' rows and columns the identity's).
    void jacobian_transpose(std::vector<Eigen::Triplet<double>>& triplets, Eigen::Index offset = 0);
    /// lambda = J^-T rhs (PCG where symmetric, else sparse LU); `step` names the step in errors.
    VecX solve(const VecX& rhs, int step);
    /// From lambda (after output_adjoint): the cotangents of the step's start into g (x, v, C, F and hardening
    /// replaced; E and the plasticity parameters added to).
    void input_adjoint(const VecX& lambda, MpmRolloutGradient<dim>& g);

private:
    const MpmSystem<dim>& system_;
    Method method_;
    const Particles<dim>& start_;
    VecX v_;
    double dt_;
    std::size_t n_;
    Grid<dim> grid_;
    std::int64_t storage_ = 0;
    std::vector<double> mass_;
    std::vector<Vec<dim>> momentum_, node_v_star_;
    bool coulomb_ = false;
    ElasticParticleEnergy<dim> energy_;
    IncrementalPotential<dim> potential_;
    std::vector<int> dof_;  // storage index -> unknown node (-1: none)
    std::vector<Vec<dim>> grid_v_;
    std::vector<Mat<dim>> projection_;
    std::vector<Mat<dim>> F_, P_, dP_dh_;
    std::vector<std::array<Mat<dim>, kPlasticityParameters>> dP_dparameter_;
    std::vector<Tensor4<dim>> T_;
    std::vector<FloorContact<dim>> contacts_;
    std::vector<int> contact_of_;
    std::vector<PerturbedMaterials<dim>> no_fields_;
    const std::vector<PerturbedMaterials<dim>>& fields_;
    std::vector<std::vector<Mat<dim>>> dP_dfield_;  // [field][particle]
    std::vector<std::vector<double>> field_bar_;    // [field][particle]: G2P's share
    // What output_adjoint leaves for input_adjoint.
    std::vector<Vec<dim>> x_bar_, residual_bar_;
    std::vector<Mat<dim>> F_bar_;
    std::vector<double> h_bar_;
    Parameters parameter_bar_{};
    double alpha_ = 0.0;
};

template <int dim>
class MpmAdjoint {
public:
    /// method: Lagged (the elastic energy, the return mapping after the step) or ReturnMap (the
    /// return-mapped stress and its consistent tangent within the solve). Throws std::invalid_argument
    /// naming what the adjoint does not cover.
    MpmAdjoint(const MpmSystem<dim>& system, const ImplicitOptions& options, const MpmOptions& mpm_options,
               Method method = Method::Lagged);

    /// `steps` steps of dt from `start`, keeping a checkpoint every `checkpoint_every` steps (0:
    /// ceil(sqrt(steps)); 1: every state), calling observe(k, state) at each state k = 0..steps (where a
    /// loss reads them); returns the last state.
    Particles<dim> forward(const Particles<dim>& start, double dt, int steps,
                           const std::function<void(int, const Particles<dim>&)>& observe = {},
                           int checkpoint_every = 0);

    /// The gradient of L, given dL/dx and dL/dv of the last forward state's particles.
    MpmRolloutGradient<dim> backward(const std::vector<Vec<dim>>& x_bar, const std::vector<Vec<dim>>& v_bar) const;
    /// The same for a loss of any states: x_bar[k], v_bar[k] (k = 0..steps; an empty entry: L does not
    /// read that state's positions or velocities).
    MpmRolloutGradient<dim> backward(const std::vector<std::vector<Vec<dim>>>& x_bar,
                                     const std::vector<std::vector<Vec<dim>>>& v_bar) const;
    /// Material fields whose dL/dp the backward pass gathers too (MpmRolloutGradient::fields, in this order):
    /// material_parameter's names ("elasticity.nu", "plasticity.hardening_coefficient", "plasticity.xi", ...),
    /// every material that has a field moved together; their derivatives by central differences of each
    /// particle's stress and return mapping at p -+ 1e-6 max(|p|, 1). Throws std::invalid_argument naming a field
    /// no material has.
    void set_parameter_fields(const std::vector<std::string>& fields);

    /// Steps of the last forward pass (-1: none).
    int steps() const { return steps_; }
    /// Its steps whose solve did not reach the tolerance (Newton's cap, a failed line search): the gradient
    /// is then that of the path taken, not of converged steps.
    int unconverged_steps() const { return unconverged_; }
    /// The most particle states held at once by the last forward and backward passes (checkpoints and a
    /// recomputed segment).
    std::size_t peak_states() const { return peak_states_; }

private:
    /// One step's adjoint, the step from `start` whose solution (on its unknowns, before the projection)
    /// is `solution`: from the cotangents of its output (g, overwritten) to those of its start.
    void step_adjoint(const Particles<dim>& start, const VecX& solution, int step, MpmRolloutGradient<dim>& g) const;
    /// The steps first..last from checkpoint `first`: their start states and solutions (recomputed, the
    /// same to the last bit).
    void replay(int first, int last, std::vector<Particles<dim>>& starts, std::vector<VecX>& solutions) const;

    /// The production integrator of `method_` (forward and replay).
    std::unique_ptr<ImplicitIntegrator<dim>> make_integrator() const;

    const MpmSystem<dim>& system_;
    ImplicitOptions options_;
    MpmOptions mpm_options_;
    Method method_;
    std::vector<PerturbedMaterials<dim>> fields_;
    std::map<int, Particles<dim>> checkpoints_;  // state k, every checkpoint_every steps and the last
    double dt_ = 0.0;
    int steps_ = -1, unconverged_ = 0;
    std::size_t last_size_ = 0;  // particles
    mutable std::size_t peak_states_ = 0;
};

}  // namespace pnet
