#pragma once
// The incremental potential of an implicit MPM step (docs/methods.md; Gast et al.
// 2015; paper sec. 3.1, 4.2), minimized over the grid velocities v: a Problem
// (solver/problem.hpp) of two forms,
//
//   E(v) = sum_i m_i/2 |v_i - v*_i|^2 + sum_p V0_p psi_p(F_p(v)),
//          (InertiaForm)              (ParticleEnergyForm, particle_energy_form.hpp)
//   F_p(v) = (I + dt G_p(v)) F^E_p,   G_p(v) = sum_i v_i grad w_ip^T.
//
// This class is the step's discretization the forms share: the particles'
// stencils on the grid (weights w_ip and their gradients), the unknowns and
// the fixed components. Unknowns: the velocities of the grid nodes that some
// particle's stencil reaches (dof k, component a at index dim k + a). Boundary
// conditions are fixed components (Grid::constrained_components) held at v*:
// their gradient is zeroed and their Hessian rows and columns replaced by m_i,
// so Newton never moves them.
#include <Eigen/SparseCore>
#include <cstdint>
#include <vector>

#include "pnet/energy/particle_energy.hpp"
#include "pnet/mpm/floor_friction_form.hpp"
#include "pnet/mpm/grid.hpp"
#include "pnet/mpm/particle_energy_form.hpp"
#include "pnet/mpm/particles.hpp"
#include "pnet/solver/inertia_form.hpp"
#include "pnet/solver/multigrid.hpp"
#include "pnet/solver/problem.hpp"

namespace pnet {

template <int dim>
class IncrementalPotential final : public Problem<dim> {
public:
    static constexpr int kStencil = dim == 2 ? 9 : 27;

    explicit IncrementalPotential(ParticleEnergy<dim>& energy)
        : inertia_(this->free_, dim), particle_energy_(*this, energy) {
        this->set_forms({&inertia_, &particle_energy_});
    }
    IncrementalPotential(const IncrementalPotential&) = delete;  // its forms refer to its members
    IncrementalPotential& operator=(const IncrementalPotential&) = delete;

    /// Sets up one step. `grid` holds this step's P2G (binning, node masses) and
    /// v* = momentum / mass + dt g with the boundary conditions applied, in
    /// Node::momentum (Grid::update_velocity()); both must outlive the step.
    void begin_step(const Grid<dim>& grid, const Particles<dim>& particles, double dt, const BoundaryConditions& bc);

    /// BDF2 (ImplicitOptions::time_integrator), after begin_step(): `u` the last step's grid displacement
    /// rate (x^n - x^{n-1}) / dt_prev and `v_previous` v^{n-1}, on the unknowns (grid_field()); `omega`
    /// the step ratio dt / dt_prev (1: constant steps). The variable-step BDF2 formulas, with
    /// beta = (1 + omega) / (1 + 2 omega) (2/3 at omega = 1):
    ///   v* = ((1 + omega)^2 v^n - omega^2 v^{n-1}) / (1 + 2 omega) + beta dt g,
    ///   F_p(v) = (I + beta dt G_p(omega u / (1 + omega) + v)) F^E_p
    /// on the free components (v^n = v*_BE - dt g; fixed ones keep their v* and move by beta dt v): the
    /// same potential with the step beta dt about the displacement BDF2 extrapolates,
    /// omega dt u / (1 + 2 omega) (dt u / 3 at constant steps).
    void use_bdf2(const VecX& u, const VecX& v_previous, const Vec<dim>& gravity, double omega = 1.0);
    /// momentum / mass of `grid`'s nodes on the unknowns (0 on massless ones): a P2G'd history field.
    void grid_field(const Grid<dim>& grid, VecX& out) const;
    /// The grid's displacement rate over the step, (x^{n+1} - x^n) / dt on the nodes: v for backward
    /// Euler, (omega u / (1 + omega) + v) beta for BDF2 (what moves the particles and their F).
    const VecX& displacement_rate(const VecX& v);

    /// The Coulomb floor (BoundaryConditions::floor_friction; begin_step() must get v* without the
    /// floor's projection): the nodes of the floor layer moving into it have their normal velocity
    /// held at 0, and their friction is a form of the potential (floor_friction_form.hpp), one
    /// majorize-minimize pass per solve. Without `v`, the first pass: the normal impulses J_k of the
    /// start-of-step stress (set the reference state to the particles' F^E first, so that the energy's
    /// gradient there is the elastic stress) and the slips of v*; with `v`, those of that solution.
    /// Returns the nodes in contact. No-op without a Coulomb floor, and in the one-solve mode
    /// (set_floor_friction_newton), where the friction follows every iterate by itself.
    std::size_t floor_friction_contacts(const VecX* v = nullptr);
    const FloorFrictionForm<dim>& floor_friction_form() const { return floor_friction_form_; }
    /// The Coulomb floor's friction itself in the solve (FloorFrictionForm::begin_newton: one solve,
    /// no passes) from the next begin_step(); floor_friction_contacts() is then a no-op.
    void set_floor_friction_newton(bool on) { floor_friction_newton_ = on; }
    /// Leaves the one solve for the passes within this step (its solve failed, solve_on_coulomb_floor):
    /// the floor's friction form starts again without contacts, for floor_friction_contacts() to set the
    /// first pass's, and the multigrid (whose operator held the one solve's friction) is built anew.
    void floor_friction_to_passes();
    bool floor_friction_newton() const { return floor_friction_newton_; }

    /// v* on the unknowns: where the solve starts (plus the last step's velocity change: step_predictor.hpp).
    const VecX& v_star() const { return inertia_.target(); }
    /// 1 / m_i on free components, 0 on fixed ones.
    const VecX& residual_scale() const { return residual_scale_; }
    /// m_i on free components, 0 on fixed ones: Newton's mass-weighted
    /// velocity residual (NewtonOptions::residual_mass), m/s.
    const VecX& residual_mass() const { return residual_mass_; }
    /// Nodes that are unknowns.
    std::size_t nodes() const { return dof_node_.size(); }
    /// The grid storage index of unknown node k (its components dim k + a).
    std::int64_t dof_node(std::size_t k) const { return dof_node_[k]; }
    /// The unknown node at grid storage index `node`, or -1 (not an unknown this step, or off the grid).
    int node_dof(std::int64_t node) const {
        return node >= 0 && node < static_cast<std::int64_t>(node_dof_.size()) ? node_dof_[node] : -1;
    }

    /// F_p(v) of every particle.
    void deformation(const VecX& v, std::vector<Mat<dim>>& F) const override;

    /// The energy's reference state (plasticitynet: F0 of eq. 10, with the
    /// particles' start-of-step hardening).
    void set_reference(const std::vector<Mat<dim>>& F0) override;
    bool set_damping(double lambda) override { return particle_energy_.energy().set_damping(lambda); }

    /// Writes v into the grid's Node::momentum (velocities) for G2P.
    void write_velocity(const VecX& v, Grid<dim>& grid) const;

    /// The particles' end-of-step positions X_p(v) = x_p^n + dt sum_i w_ip v_i
    /// (what G2P's advection gives; linear in v; BDF2: the step and offset of use_bdf2()). With
    /// `displacement`, the motion dt sum_i w_ip d_i of a change d instead (no x_p^n).
    void particle_positions(const VecX& v, std::vector<Vec<dim>>& X, bool displacement = false) const;
    /// Particle p's stencil: kStencil dofs, weights w_ip and their gradients (at x_p^n).
    const int* stencil_dofs(std::size_t p) const { return &stencil_dof_[p * kStencil]; }
    const double* stencil_weights(std::size_t p) const { return &stencil_weight_[p * kStencil]; }
    const Vec<dim>* stencil_gradients(std::size_t p) const { return &stencil_grad_[p * kStencil]; }
    /// The stencil entries (p, s) of each unknown node, grouped by node (CSR: entries
    /// node_entry_start()[k] .. node_entry_start()[k + 1], increasing in p * kStencil + s): the
    /// order in which a node's gathers (the Hessian product, the gradient's scatter, the diagonal)
    /// sum its terms, the same for every thread count. Each entry's particle p and weight gradient
    /// grad w_ip, in that order, so that a node reads them in sequence.
    const int* node_entry_start() const { return node_entry_start_.data(); }
    const int* node_entry_particles() const { return node_entry_particle_.data(); }
    const Vec<dim>* node_entry_gradients() const { return node_entry_grad_.data(); }
    /// The potential's step: dt (backward Euler), beta dt (BDF2; 2/3 dt at constant steps).
    double dt() const { return dt_; }
    const Grid<dim>& grid() const { return *grid_; }
    const Particles<dim>& particles() const { return *particles_; }

    /// Project the particles' Hessians to PSD (default; false gives the exact
    /// Hessian of E, for derivative checks).
    void set_project_psd(bool project) { particle_energy_.set_project_psd(project); }
    /// The particles' energy Hessians d^2 psi / dF^2 given (ParticleEnergyForm::set_hessians) instead of a Hessian
    /// pass at v: the products and diagonal of the Hessian there (the inertia's prepared as a pass would).
    void set_particle_hessians(const VecX& v, const std::vector<Tensor4<dim>>& hessians) {
        inertia_.prepare_hessian(v);
        particle_energy_.set_hessians(hessians);
    }
    /// The particles' term of the Hessian prepared last, as node-pair block entries on the free components, rows and
    /// columns shifted by `offset` (without the inertia).
    void add_particle_hessian_triplets(std::vector<Eigen::Triplet<double>>& triplets, Eigen::Index offset) const {
        const std::size_t first = triplets.size();
        particle_energy_.add_hessian_triplets(triplets);
        for (std::size_t k = first; k < triplets.size(); ++k)
            triplets[k] = Eigen::Triplet<double>(offset + triplets[k].row(), offset + triplets[k].col(), triplets[k].value());
    }

    /// The linear solve's preconditioner: Galerkin multigrid on the grid's nodes (solver/multigrid.hpp)
    /// built from the Hessian assembled when a step's first linear solve applies it (the Hessian
    /// prepared last) and kept for the step's solves (`per_hessian`: rebuilt after every Hessian
    /// pass), or none of its own (off: Newton's Jacobi or block Jacobi). A step that needs no linear
    /// solve builds none. Hessian products stay matrix-free.
    void set_multigrid(bool on, bool per_hessian = false, const MultigridOptions& options = {}) {
        multigrid_on_ = on;
        multigrid_per_hessian_ = per_hessian;
        multigrid_built_ = multigrid_stale_ = false;
        multigrid_ = GridMultigrid(options);
    }
    bool has_preconditioner() const override { return multigrid_on_; }
    void apply_preconditioner(const VecX& r, VecX& z) const override;
    const GridMultigrid& multigrid() const { return multigrid_; }

    /// Seconds spent in the particle energies (evaluate) and in Hessian-vector
    /// products since the last begin_step().
    double energy_seconds() const { return particle_energy_.energy_seconds(); }
    double multiply_seconds() const { return particle_energy_.multiply_seconds(); }

    /// The Hessian prepared last, assembled node by node from the particles' pair blocks (no
    /// triplets): H^T in column-major storage (H's rows as columns; H itself where it is symmetric).
    void assemble_by_nodes(SparseMatrix& out) const;

protected:
    void hessian_prepared(const VecX& x) override;

private:
    InertiaForm inertia_;
    ParticleEnergyForm<dim> particle_energy_;
    const Grid<dim>* grid_ = nullptr;
    const Particles<dim>* particles_ = nullptr;
    double dt_ = 0.0;       // the potential's step: dt (backward Euler), beta dt (BDF2)
    double step_dt_ = 0.0;  // the time step
    bool bdf2_ = false;
    VecX offset_;           // BDF2: omega u / (1 + omega) on the free components (F_p(v) about G_p(offset + v))
    VecX rate_;             // displacement_rate()'s

    std::vector<int> node_dof_;              // grid storage index -> dof (-1: not an unknown)
    std::vector<std::int64_t> dof_node_;     // dof -> grid storage index
    VecX residual_scale_, residual_mass_;
    std::vector<int> stencil_dof_;           // particle p, node s: dof of node s of p's stencil
    std::vector<Vec<dim>> stencil_grad_;     // grad w_ip, 1/m
    std::vector<double> stencil_weight_;     // w_ip
    std::vector<int> node_entry_start_;
    std::vector<int> node_entry_particle_;   // entry (p, s) -> p, in node order
    std::vector<Vec<dim>> node_entry_grad_;  // entry (p, s) -> grad w_ip, in node order
    double floor_friction_ = -1.0;           // the Coulomb floor's mu (< 0: none)
    std::vector<int> floor_dofs_;            // nodes held on the Coulomb floor (normal component)
    std::vector<double> floor_normal_velocity_;  // their v*_y before it was held at 0
    FloorFrictionForm<dim> floor_friction_form_;
    bool floor_friction_newton_ = false;
    bool multigrid_on_ = false, multigrid_per_hessian_ = false;
    // The hierarchy, built on demand from const apply_preconditioner (a cache of the Hessian).
    void build_multigrid() const;
    mutable bool multigrid_built_ = false;  // this step's hierarchy is built
    mutable bool multigrid_stale_ = false;  // rebuild at the next application (per_hessian)
    mutable GridMultigrid multigrid_;
    mutable SparseMatrix multigrid_matrix_;
    mutable std::vector<int> assembly_start_;
};

}  // namespace pnet
