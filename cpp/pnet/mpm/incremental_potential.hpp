#pragma once
// The incremental potential of an implicit MPM step (docs/methods.md; Gast et al.
// 2015; paper sec. 3.1, 4.2), minimized over the grid velocities v:
//
//   E(v) = sum_i m_i/2 |v_i - v*_i|^2 + sum_p V0_p psi_p(F_p(v)),
//   F_p(v) = (I + dt G_p(v)) F^E_p,   G_p(v) = sum_i v_i grad w_ip^T,
//   dE/dv_i = m_i (v_i - v*_i) + sum_p V0_p dt P_p F^E_p^T grad w_ip,
//   H d |_i = m_i d_i + sum_p K_p[dG_p] grad w_ip,  dG_p = sum_i d_i grad w_ip^T,
//   K_p = V0_p dt^2 T_p^T (d2psi/dF2) T_p,  T_p: dG -> dG F^E_p,
//
// with psi_p a ParticleEnergy (elastic for `lagged`, the PlasticityNet energy
// for `plasticitynet`) and its Hessian projected to PSD, so H is PSD. K_p
// (d^2 x d^2) is formed once per Newton iteration; a Hessian-vector product
// is then a gather, a small matrix product and a scatter per particle.
//
// Unknowns: the velocities of the grid nodes that some particle's stencil
// reaches (dof k, component a at index dim k + a). Boundary conditions are
// fixed components (Grid::constrained_components) held at v*: their gradient
// is zeroed and their Hessian rows and columns replaced by m_i, so Newton never
// moves them. Scatters run in the grid's block-colour order, so every sum has
// a fixed order and results do not depend on the thread count.
#include <Eigen/SparseCore>
#include <cstdint>
#include <vector>

#include "pnet/energy/particle_energy.hpp"
#include "pnet/mpm/grid.hpp"
#include "pnet/mpm/particles.hpp"
#include "pnet/solver/fixed_point.hpp"

namespace pnet {

template <int dim>
class IncrementalPotential final : public ReferencedObjective<dim> {
public:
    static constexpr int kStencil = dim == 2 ? 9 : 27;
    static constexpr int kM = dim * dim;

    explicit IncrementalPotential(ParticleEnergy<dim>& energy) : energy_(energy) {}

    /// Sets up one step. `grid` holds this step's P2G (binning, node masses) and
    /// v* = momentum / mass + dt g with the boundary conditions applied, in
    /// Node::momentum (Grid::update_velocity()); both must outlive the step.
    void begin_step(const Grid<dim>& grid, const Particles<dim>& particles, double dt, const BoundaryConditions& bc);

    /// BDF2 (ImplicitOptions::time_integrator), after begin_step(): `u` the last step's grid displacement
    /// rate (x^n - x^{n-1}) / dt and `v_previous` v^{n-1}, on the unknowns (grid_field()). Then
    ///   v* = (4 v^n - v^{n-1}) / 3 + beta dt g,  F_p(v) = (I + beta dt G_p(u / 2 + v)) F^E_p,  beta = 2/3,
    /// on the free components (v^n = v*_BE - dt g; fixed ones keep their v* and move by beta dt v): the
    /// same potential with the step beta dt about the displacement BDF2 extrapolates, dt u / 3.
    void use_bdf2(const VecX& u, const VecX& v_previous, const Vec<dim>& gravity);
    /// momentum / mass of `grid`'s nodes on the unknowns (0 on massless ones): a P2G'd history field.
    void grid_field(const Grid<dim>& grid, VecX& out) const;
    /// The grid's displacement rate over the step, (x^{n+1} - x^n) / dt on the nodes: v for backward
    /// Euler, (u / 2 + v) beta for BDF2 (what moves the particles and their F).
    const VecX& displacement_rate(const VecX& v);

    /// v* on the unknowns: the starting point of the solve.
    const VecX& v_star() const { return v_star_; }
    /// 1 / m_i on free components, 0 on fixed ones.
    const VecX& residual_scale() const { return residual_scale_; }
    /// m_i on free components, 0 on fixed ones: Newton's mass-weighted
    /// velocity residual (NewtonOptions::residual_mass), m/s.
    const VecX& residual_mass() const { return residual_mass_; }
    /// Nodes that are unknowns.
    std::size_t nodes() const { return dof_node_.size(); }

    /// F_p(v) of every particle.
    void deformation(const VecX& v, std::vector<Mat<dim>>& F) const override;

    /// The energy's reference state (plasticitynet: F0 of eq. 10, with the
    /// particles' start-of-step hardening).
    void set_reference(const std::vector<Mat<dim>>& F0) override;
    bool set_damping(double lambda) override { return energy_.set_damping(lambda); }

    /// Writes v into the grid's Node::momentum (velocities) for G2P.
    void write_velocity(const VecX& v, Grid<dim>& grid) const;

    // Objective
    Eigen::Index size() const override { return v_star_.size(); }
    double value(const VecX& v) override;
    double value_gradient(const VecX& v, VecX& gradient) override;
    void prepare_hessian(const VecX& v) override;
    double value_gradient_hessian(const VecX& v, VecX& gradient) override;
    void hessian_multiply(const VecX& d, VecX& out) const override;
    void hessian_diagonal(VecX& diagonal) const override;
    int hessian_block_size() const override { return dim; }
    /// The d x d block of each node: sum_p over the particles it reaches of
    /// B_ab = g^T K_p[(a, .), (b, .)] g (g = grad w_ip), masked on fixed
    /// components, plus the node mass on the diagonal.
    void hessian_block_diagonal(VecX& blocks) const override;

    /// The particles' end-of-step positions X_p(v) = x_p^n + dt sum_i w_ip v_i
    /// (what G2P's advection gives; linear in v; BDF2: the step and offset of use_bdf2()). With
    /// `displacement`, the motion dt sum_i w_ip d_i of a change d instead (no x_p^n).
    void particle_positions(const VecX& v, std::vector<Vec<dim>>& X, bool displacement = false) const;
    /// Particle p's stencil: kStencil dofs and weights w_ip (at x_p^n).
    const int* stencil_dofs(std::size_t p) const { return &stencil_dof_[p * kStencil]; }
    const double* stencil_weights(std::size_t p) const { return &stencil_weight_[p * kStencil]; }
    double dt() const { return dt_; }
    const VecX& free_components() const { return free_; }

    /// Appends the PSD Hessian prepared last (as hessian_multiply() applies it) as
    /// triplets, rows and columns shifted by `offset`, for an assembled solve
    /// (MPM-FEM coupling). Node-pair blocks are summed first (in the colour
    /// order, so the result does not depend on the thread count): (2 dx + 1)^d
    /// neighbours per node, one triplet per entry.
    void add_hessian_triplets(std::vector<Eigen::Triplet<double>>& triplets, Eigen::Index offset) const;

    /// Assemble H at every Hessian pass (add_hessian_triplets()) so that hessian_matrix() gives it for
    /// a direct solve (NewtonOptions::LinearSolver::Cholesky); default off (matrix-free PCG).
    void set_assemble(bool assemble) { assemble_ = assemble; }
    const SparseMatrix* hessian_matrix() const override { return assemble_ ? &hessian_ : nullptr; }

    /// Project the particles' Hessians to PSD (default; false gives the exact
    /// Hessian of E, for derivative checks).
    void set_project_psd(bool project) { project_psd_ = project; }

    /// Seconds spent in the particle energies (evaluate) and in Hessian-vector
    /// products since the last begin_step().
    double energy_seconds() const { return energy_seconds_; }
    double multiply_seconds() const { return multiply_seconds_; }

private:
    double inertia(const VecX& v) const;
    /// gradient = M (v - v*) + sum_p V0 dt P_p F^E_p^T grad w_ip on the free components.
    void assemble_gradient(const VecX& v, VecX& gradient) const;
    /// K_p = V0 dt^2 T_p^T H_p T_p in place of the Hessians H_p.
    void transform_hessians();
    double potential_sum() const;

    ParticleEnergy<dim>& energy_;
    const Grid<dim>* grid_ = nullptr;
    const Particles<dim>* particles_ = nullptr;
    double dt_ = 0.0;       // the potential's step: dt (backward Euler), 2/3 dt (BDF2)
    double step_dt_ = 0.0;  // the time step
    bool bdf2_ = false;
    VecX offset_;           // BDF2: u / 2 on the free components (F_p(v) about G_p(offset + v))
    VecX rate_;             // displacement_rate()'s

    std::vector<int> node_dof_;                            // grid storage index -> dof (-1: not an unknown)
    std::vector<std::int64_t> dof_node_;                   // dof -> grid storage index
    VecX mass_;                                            // per component (m_i, or 1 for a massless node), kg
    VecX v_star_, free_, residual_scale_, residual_mass_;  // free_: 1 on free components, 0 on fixed ones
    std::vector<int> stencil_dof_;                         // particle p, node s: dof of node s of p's stencil
    std::vector<Vec<dim>> stencil_grad_;                   // grad w_ip, 1/m
    std::vector<double> stencil_weight_;                   // w_ip
    // add_hessian_triplets(): per node and neighbour offset, the neighbour's dof and the d x d block.
    mutable std::vector<int> pair_dof_;
    mutable std::vector<double> pair_block_;

    // Per particle, at the last evaluation.
    std::vector<Mat<dim>> F_, P_;
    std::vector<double> psi_;
    std::vector<Tensor4<dim>> K_;  // the Hessian of psi, then K_p (prepare_hessian)
    mutable VecX masked_;
    // hessian_multiply without colour passes: the stencil entries (p, s) of each unknown node, grouped
    // by node (CSR: node_entries_[node_entry_start_[k] .. node_entry_start_[k + 1]) = p * kStencil + s,
    // increasing), and each particle's K_p dG_p.
    std::vector<int> node_entry_start_, node_entries_;
    mutable std::vector<Eigen::Matrix<double, kM, 1>> particle_product_;
    bool project_psd_ = true;
    bool assemble_ = false;
    SparseMatrix hessian_;
    std::vector<Eigen::Triplet<double>> triplets_;
    double energy_seconds_ = 0.0;
    mutable double multiply_seconds_ = 0.0;
};

}  // namespace pnet
