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
// energy + its own contact, fem/fem_potential.hpp) and B the particle / mesh
// boundary barrier (particle_contact.hpp), D the lagged particle-mesh friction
// (contact/friction.hpp: the particle's velocity relative to the closest point
// of the facet, c_kj its weights, frozen with the normal force lambda_k and the
// tangent basis T_k at the start of the step). A pair's gradient dB/dX_p reaches
// the particle's stencil nodes as dt w_ip dB/dX_p, and its Hessian
// dt^2 J^T H J (J: the weights of X_p on the stencil nodes and the identity on
// the facet's nodes) couples the stencil to the facet's nodes; a friction pair
// has the same shape with dt for dt^2. Every part is PSD (projected per particle,
// element and pair), and so is H. Two linear solves
// (set_linear_solve()): `Assembled`, H assembled (MPM node-pair blocks, the FEM
// matrix, the pairs) for CHOLMOD; `BlockPreconditioned`, matrix-free PCG whose
// preconditioner is Jacobi on the grid and an exact sparse Cholesky solve of
// the FEM block (with the pairs' FEM terms): the stiff FEM body makes the
// system too ill-conditioned for Jacobi alone, and the grid part is too large
// to factor at every Newton iteration. max_step() is the
// CCD of the particles' linear motion against the mesh's (and the FEM
// potential's own filter), so every iterate is intersection-free. The fixed
// point on F0 (plasticitynet) runs over the MPM particles; the FEM body is
// elastic (its energy has no reference).
#include <vector>

#include <memory>

#include <Eigen/SparseCore>

#include "pnet/coupling/particle_contact.hpp"
#include "pnet/fem/fem_potential.hpp"
#include "pnet/mpm/incremental_potential.hpp"
#include "pnet/solver/fixed_point.hpp"

namespace pnet {

template <int dim>
class CoupledPotential final : public ReferencedObjective<dim> {
public:
    using Contact = ParticleContact<dim>;
    using Pair = typename Contact::Pair;
    using Gradient = typename Contact::Gradient;
    using Hessian = typename Contact::Hessian;

    CoupledPotential(IncrementalPotential<dim>& mpm, FemPotential<dim>& fem, const Contact& contact);
    ~CoupledPotential() override;

    enum class LinearSolve { Assembled, BlockPreconditioned };
    /// Assembled: hessian_matrix() for Newton's CHOLMOD solve. BlockPreconditioned (default):
    /// hessian_matrix() is null, and PCG uses apply_preconditioner().
    void set_linear_solve(LinearSolve solve) { solve_ = solve; }
    LinearSolve linear_solve() const { return solve_; }

    /// After mpm.begin_step() and fem.begin_step() (with the FEM material state set). Clears the friction.
    void begin_step();
    /// Lagged particle-mesh friction for this step (after begin_step()): the pairs of
    /// Contact::lagged_pairs() at the step's start, the Coulomb coefficient mu >= 0 and the
    /// slip velocity eps_v > 0 (m/s) below which it is smoothed. mu = 0: none.
    void set_friction(std::vector<ParticleFrictionPair<dim>> pairs, double mu, double eps_v);
    std::size_t friction_pairs() const { return friction_pairs_.size(); }
    /// dt D(v), the friction's share of value(v) (J).
    double friction_value(const VecX& v) const;

    /// [v*_grid; v*_fem], the start of the solve.
    const VecX& v_star() const { return v_star_; }
    /// m_i on free components, 0 on fixed ones (NewtonOptions::residual_mass).
    const VecX& residual_mass() const { return residual_mass_; }
    Eigen::Index grid_size() const { return mpm_.size(); }

    /// The particles' and the mesh's positions at v.
    void positions(const VecX& v, std::vector<Vec<dim>>& X, std::vector<Vec<dim>>& x) const;

    // ReferencedObjective: the MPM particles (the FEM body is elastic).
    void deformation(const VecX& v, std::vector<Mat<dim>>& F) const override;
    void set_reference(const std::vector<Mat<dim>>& F0) override { mpm_.set_reference(F0); }
    bool set_damping(double lambda) override { return mpm_.set_damping(lambda); }

    // Objective
    Eigen::Index size() const override { return mpm_.size() + fem_.size(); }
    double value(const VecX& v) override;
    double value_gradient(const VecX& v, VecX& gradient) override;
    void prepare_hessian(const VecX& v) override;
    double value_gradient_hessian(const VecX& v, VecX& gradient) override;
    void hessian_multiply(const VecX& d, VecX& out) const override;
    void hessian_diagonal(VecX& diagonal) const override { diagonal = diagonal_; }
    const SparseMatrix* hessian_matrix() const override {
        return solve_ == LinearSolve::Assembled ? &hessian_ : nullptr;
    }
    bool has_preconditioner() const override { return solve_ == LinearSolve::BlockPreconditioned; }
    void apply_preconditioner(const VecX& r, VecX& z) const override;
    double max_step(const VecX& v, const VecX& d) override;

    /// Project the pair Hessians to PSD (default; false: exact, for derivative checks; the
    /// MPM and FEM parts follow their own set_project_psd()).
    void set_project_psd(bool project) { project_psd_ = project; }

    /// CCD queries since begin_step() and how many shortened a step; the pairs at the last evaluation.
    int ccd_queries() const { return ccd_queries_; }
    int ccd_limited() const { return ccd_limited_; }
    std::size_t pairs() const { return barrier_.pairs.size(); }

private:
    /// Per-pair terms in the stacked (X_p, facet nodes) of each pair, and the factor of their
    /// Hessian in v (dt^2 for the barrier, whose terms are in positions; dt for friction).
    struct PairTerms {
        std::vector<Pair> pairs;
        std::vector<Gradient> gradients;
        std::vector<Hessian> hessians;
        double hessian_scale = 0.0;
    };

    void split(const VecX& v) const;
    /// g += dB/dv + dt dD/dv over the active pairs at v (barrier_ and friction_ gradients set);
    /// returns B + dt D.
    double add_contact_gradient(const VecX& v, VecX& g);
    /// g += dt J^T gradient of each pair of `terms`.
    void scatter_gradient(const PairTerms& terms, VecX& g) const;
    /// The friction pairs' slip T^T (v_p - sum_j c_j v_j) at v (split into vg_, vf_).
    Eigen::Matrix<double, dim - 1, 1> slip(std::size_t k) const;
    void friction_hessians();
    /// The pairs' Hessians at v, then the assembled H (Assembled) or the diagonal and the FEM
    /// block's factorization (BlockPreconditioned).
    void prepare(const VecX& v);
    void assemble();
    void prepare_blocks();
    /// The pair's unknown components: the particle's stencil (weight w_ip, slot 0 of its stacked
    /// Hessian) and the facet's nodes (weight 1, slots 1 .. dim); returns how many.
    int pair_nodes(const Pair& pair, Eigen::Index* index, double* weight, int* slot) const;
    /// f(H, scale, count, index, weight, slot) for every barrier pair, then every friction pair:
    /// its stacked Hessian, the factor of its Hessian in v and its unknown components (pair_nodes()).
    template <typename F>
    void for_each_pair_hessian(F&& f) const;

    IncrementalPotential<dim>& mpm_;
    FemPotential<dim>& fem_;
    const Contact& contact_;
    VecX v_star_, residual_mass_;
    mutable VecX vg_, vf_;
    VecX gg_, gf_;
    mutable std::vector<Vec<dim>> X_, x_, dX_, dx_;
    PairTerms barrier_, friction_;
    std::vector<ParticleFrictionPair<dim>> friction_pairs_;
    double mu_ = 0.0, eps_v_ = 1e-4;
    std::vector<Eigen::Triplet<double>> triplets_;
    SparseMatrix hessian_, fem_block_, pair_block_;
    VecX diagonal_, inverse_grid_diagonal_;
    mutable VecX work_in_, work_out_;
    struct FemFactor;
    std::unique_ptr<FemFactor> fem_factor_;
    std::vector<Pair> factor_pairs_;  // the pairs of the FEM block's factorization
    bool factorized_this_step_ = false;
    LinearSolve solve_ = LinearSolve::BlockPreconditioned;
    bool project_psd_ = true;
    int ccd_queries_ = 0, ccd_limited_ = 0;
};

using CoupledPotential2d = CoupledPotential<2>;
using CoupledPotential3d = CoupledPotential<3>;

}  // namespace pnet
