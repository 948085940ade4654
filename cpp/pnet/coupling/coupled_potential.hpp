#pragma once
// The incremental potential of an MPM-FEM coupled step (BFEMP, Li, Fang, Li,
// Jiang 2021; docs/methods.md), over v = [MPM grid velocities; FEM nodal
// velocities] (m/s, both):
//
//   E(v) = E_mpm(v_g) + E_fem(v_f) + B(X(v_g), x(v_f)),
//   X_p(v_g) = X_p^n + dt sum_i w_ip v_i,   x_a(v_f) = x_a^n + dt v_a,
//
// E_mpm the MPM incremental potential (inertia + learned or elastic particle
// energy, mpm/incremental_potential.hpp), E_fem the FEM one (inertia + element
// energy + its own contact, fem/fem_potential.hpp) and B the particle / mesh
// boundary barrier (particle_contact.hpp). A pair's gradient dB/dX_p reaches
// the particle's stencil nodes as dt w_ip dB/dX_p, and its Hessian
// dt^2 J^T H J (J: the weights of X_p on the stencil nodes and the identity on
// the edge's nodes) couples the stencil to the edge's nodes. Every part is PSD
// (projected per particle, element and pair), and so is H. Two linear solves
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

class CoupledPotential2d final : public ReferencedObjective<2> {
public:
    CoupledPotential2d(IncrementalPotential<2>& mpm, FemPotential<2>& fem, const ParticleContact2d& contact);
    ~CoupledPotential2d() override;

    enum class LinearSolve { Assembled, BlockPreconditioned };
    /// Assembled: hessian_matrix() for Newton's CHOLMOD solve. BlockPreconditioned (default):
    /// hessian_matrix() is null, and PCG uses apply_preconditioner().
    void set_linear_solve(LinearSolve solve) { solve_ = solve; }
    LinearSolve linear_solve() const { return solve_; }

    /// After mpm.begin_step() and fem.begin_step() (with the FEM material state set).
    void begin_step();

    /// [v*_grid; v*_fem], the start of the solve.
    const VecX& v_star() const { return v_star_; }
    /// m_i on free components, 0 on fixed ones (NewtonOptions::residual_mass).
    const VecX& residual_mass() const { return residual_mass_; }
    Eigen::Index grid_size() const { return mpm_.size(); }

    /// The particles' and the mesh's positions at v.
    void positions(const VecX& v, std::vector<Vec<2>>& X, std::vector<Vec<2>>& x) const;

    // ReferencedObjective: the MPM particles (the FEM body is elastic).
    void deformation(const VecX& v, std::vector<Mat<2>>& F) const override;
    void set_reference(const std::vector<Mat<2>>& F0) override { mpm_.set_reference(F0); }
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
    std::size_t pairs() const { return pairs_.size(); }

private:
    void split(const VecX& v) const;
    /// g += dB/dv over the active pairs at v (gradients_ and pairs_ set); returns B.
    double add_barrier_gradient(const VecX& v, VecX& g);
    /// The pairs' Hessians at v, then the assembled H (Assembled) or the diagonal and the FEM
    /// block's factorization (BlockPreconditioned).
    void prepare(const VecX& v);
    void assemble();
    void prepare_blocks();
    /// The pair's unknown components: the particle's stencil (weight w_ip, slot 0 of its 6 x 6
    /// Hessian) and the edge's nodes (weight 1, slots 1 and 2); returns how many.
    int pair_nodes(std::size_t k, Eigen::Index* index, double* weight, int* slot) const;

    IncrementalPotential<2>& mpm_;
    FemPotential<2>& fem_;
    const ParticleContact2d& contact_;
    VecX v_star_, residual_mass_;
    mutable VecX vg_, vf_;
    VecX gg_, gf_;
    mutable std::vector<Vec<2>> X_, x_, dX_, dx_;
    std::vector<ParticleContact2d::Pair> pairs_;
    std::vector<Vec6> gradients_;
    std::vector<Mat6> pair_hessians_;
    std::vector<Eigen::Triplet<double>> triplets_;
    SparseMatrix hessian_, fem_block_, pair_block_;
    VecX diagonal_, inverse_grid_diagonal_;
    mutable VecX work_in_, work_out_;
    struct FemFactor;
    std::unique_ptr<FemFactor> fem_factor_;
    std::vector<ParticleContact2d::Pair> factor_pairs_;  // the pairs of the FEM block's factorization
    bool factorized_this_step_ = false;
    LinearSolve solve_ = LinearSolve::BlockPreconditioned;
    bool project_psd_ = true;
    int ccd_queries_ = 0, ccd_limited_ = 0;
};

}  // namespace pnet
