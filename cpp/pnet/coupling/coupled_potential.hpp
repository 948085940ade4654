#pragma once
// The incremental potential of an MPM-FEM coupled step (BFEMP, Li, Fang, Li,
// Jiang 2021; docs/methods.md), in 2D and 3D, over v = [MPM grid velocities; FEM
// nodal velocities] (m/s, both):
//
//   E(v) = E_mpm(v_g) + E_fem(v_f) + B(X(v_g), x(v_f)) + dt D(v),
//   X_p(v_g) = X_p^n + dt sum_i w_ip v_i,   x_a(v_f) = x_a^n + dt v_a,
//   D(v) = sum_k mu lambda_k f0(|T_k^T (sum_i w_ip v_i - sum_j c_kj v_j)|),
//
// E_mpm the MPM incremental potential (inertia + learned or elastic particle
// energy, mpm/incremental_potential.hpp), E_fem the FEM one (inertia + element
// energy + its own contact, fem/fem_potential.hpp), B the particle / mesh boundary
// barrier (the one barrier form, contact/barrier_form.hpp, over a Contact whose
// stand-alone points are the particles, moved by CoupledVertices) and D the lagged
// particle-mesh friction (particle_mesh_forms.hpp).
// The coupled step is a Problem (solver/problem.hpp) of three forms: the MPM and
// FEM problems, each as one form on its part of v (ProblemForm), and the
// particle-mesh contact (barrier + friction, summed as one). Every part is PSD
// (projected per particle, element and pair), and so is H. Two linear solves
// (set_linear_solve()): `Assembled`, H assembled for CHOLMOD; `BlockPreconditioned`,
// matrix-free PCG whose preconditioner is Jacobi on the grid and an exact sparse
// Cholesky solve of the FEM block (with the pairs' FEM terms): the stiff FEM body
// makes the system too ill-conditioned for Jacobi alone, and the grid part is too
// large to factor at every Newton iteration. max_step() is the CCD of the
// particles' linear motion against the mesh's (and the FEM problem's own filter),
// so every iterate is intersection-free. The fixed point on F0 (plasticitynet)
// runs over the MPM particles; the FEM body is elastic (its energy has no reference).
#include <memory>
#include <vector>

#include <Eigen/SparseCore>

#include "pnet/contact/collisions/contact.hpp"
#include "pnet/coupling/particle_mesh_forms.hpp"
#include "pnet/solver/form_sum.hpp"
#include "pnet/solver/problem.hpp"

namespace pnet {

template <int dim>
class CoupledPotential final : public Problem<dim> {
public:
    /// contact: the mesh's boundary facets with the particles as stand-alone points after its
    /// nodes (ContactPoints{nodes, true}), positions as CoupledVertices orders them.
    CoupledPotential(IncrementalPotential<dim>& mpm, FemPotential<dim>& fem, const ContactPotential<dim>& contact);
    ~CoupledPotential() override;
    CoupledPotential(const CoupledPotential&) = delete;  // its forms refer to its members
    CoupledPotential& operator=(const CoupledPotential&) = delete;

    enum class LinearSolve { Assembled, BlockPreconditioned };
    /// Assembled: hessian_matrix() for Newton's CHOLMOD solve. BlockPreconditioned (default):
    /// hessian_matrix() is null, and PCG uses apply_preconditioner().
    void set_linear_solve(LinearSolve solve) {
        solve_ = solve;
        this->set_assemble(solve == LinearSolve::Assembled);
    }
    LinearSolve linear_solve() const { return solve_; }

    /// After mpm.begin_step() and fem.begin_step() (with the FEM material state set). Clears the friction.
    void begin_step();
    /// Lagged particle-mesh friction for this step (after begin_step()): the pairs of
    /// Contact::lagged_pairs() at the step's start, the Coulomb coefficient mu >= 0 and the
    /// slip velocity eps_v > 0 (m/s) below which it is smoothed. mu = 0: none.
    void set_friction(std::vector<FrictionPair<dim>> pairs, double mu, double eps_v) {
        friction_.set_pairs(std::move(pairs), mu, eps_v);
    }
    std::size_t friction_pairs() const { return friction_.size(); }
    /// dt D(v), the friction's share of value(v) (J).
    double friction_value(const VecX& v) { return friction_.value(v); }

    /// [v*_grid; v*_fem], the start of the solve.
    const VecX& v_star() const { return v_star_; }
    /// m_i on free components, 0 on fixed ones (NewtonOptions::residual_mass).
    const VecX& residual_mass() const { return residual_mass_; }
    Eigen::Index grid_size() const { return mpm_.size(); }

    /// The contact's positions at v: the mesh's nodes, then the particles.
    void positions(const VecX& v, std::vector<Vec<dim>>& x) const { vertices_.positions(v, x); }

    // ReferencedObjective: the MPM particles (the FEM body is elastic).
    void deformation(const VecX& v, std::vector<Mat<dim>>& F) const override;
    void set_reference(const std::vector<Mat<dim>>& F0) override { mpm_.set_reference(F0); }
    bool set_damping(double lambda) override { return mpm_.set_damping(lambda); }

    void hessian_diagonal(VecX& diagonal) const override;
    bool has_preconditioner() const override { return solve_ == LinearSolve::BlockPreconditioned; }
    void apply_preconditioner(const VecX& r, VecX& z) const override;

    /// Project the pair Hessians to PSD (default; false: exact, for derivative checks; the
    /// MPM and FEM parts follow their own set_project_psd()).
    void set_project_psd(bool project) { barrier_.set_project_psd(project); }

    /// CCD queries since begin_step() and how many shortened a step; the pairs at the last evaluation.
    int ccd_queries() const { return barrier_.ccd().queries; }
    int ccd_limited() const { return barrier_.ccd().limited; }
    std::size_t pairs() const { return barrier_.pairs(); }

private:
    /// BlockPreconditioned: the diagonal and the FEM block's factorization.
    void hessian_prepared(const VecX& x) override;

    IncrementalPotential<dim>& mpm_;
    FemPotential<dim>& fem_;
    ProblemForm<dim> mpm_form_, fem_form_;
    CoupledVertices<dim> vertices_;
    BarrierForm<dim> barrier_;
    ParticleFrictionForm<dim> friction_;
    FormSum contact_;  // barrier + friction
    VecX v_star_, residual_mass_;
    mutable VecX vg_;
    std::vector<Eigen::Triplet<double>> triplets_;
    SparseMatrix fem_block_, pair_block_;
    VecX diagonal_, inverse_grid_diagonal_;
    struct FemFactor;
    std::unique_ptr<FemFactor> fem_factor_;
    std::vector<std::array<int, dim + 1>> factor_pairs_;  // the pairs of the FEM block's factorization
    bool factorized_this_step_ = false;
    LinearSolve solve_ = LinearSolve::BlockPreconditioned;
};

using CoupledPotential2d = CoupledPotential<2>;
using CoupledPotential3d = CoupledPotential<3>;

}  // namespace pnet
