#include "pnet/coupling/coupled_potential.hpp"

#include <algorithm>

#include <Eigen/SparseCholesky>

#include "pnet/contact/friction.hpp"
#include "pnet/solver/newton.hpp"  // NewtonError

namespace pnet {

template <int dim>
struct CoupledPotential<dim>::FemFactor {
    Eigen::SimplicialLLT<SparseMatrix, Eigen::Lower> llt;
    std::vector<SparseMatrix::StorageIndex> outer, inner;  // the pattern analysed
};

template <int dim>
CoupledPotential<dim>::CoupledPotential(IncrementalPotential<dim>& mpm, FemPotential<dim>& fem,
                                        const ContactPotential<dim>& contact)
    : mpm_(mpm),
      fem_(fem),
      mpm_form_(mpm),
      fem_form_(fem),
      vertices_(mpm, fem),
      barrier_(contact, vertices_, this->free_),
      friction_(vertices_, this->free_),
      fem_factor_(std::make_unique<FemFactor>()) {
    contact_.set_forms({&barrier_, &friction_});
    this->set_forms({&mpm_form_, &fem_form_, &contact_});
}

template <int dim>
CoupledPotential<dim>::~CoupledPotential() = default;

template <int dim>
void CoupledPotential<dim>::begin_step() {
    const Eigen::Index ng = mpm_.size(), nf = fem_.size();
    v_star_.resize(ng + nf);
    v_star_ << mpm_.v_star(), fem_.v_star();
    residual_mass_.resize(ng + nf);
    residual_mass_ << mpm_.residual_mass(), fem_.residual_mass();
    this->free_.resize(ng + nf);
    this->free_ << mpm_.free_components(), fem_.free_components();
    fem_form_.set_offset(ng);
    barrier_.begin_step();
    friction_.set_pairs({}, 0.0, 1e-4);
    this->invalidate_pattern();  // a new grid
    factorized_this_step_ = false;
}

template <int dim>
void CoupledPotential<dim>::deformation(const VecX& v, std::vector<Mat<dim>>& F) const {
    vg_ = v.head(mpm_.size());
    mpm_.deformation(vg_, F);
}

template <int dim>
void CoupledPotential<dim>::hessian_diagonal(VecX& diagonal) const {
    if (solve_ == LinearSolve::Assembled)
        Problem<dim>::hessian_diagonal(diagonal);
    else
        diagonal = diagonal_;
}

template <int dim>
void CoupledPotential<dim>::hessian_prepared(const VecX& /*v*/) {
    if (solve_ == LinearSolve::Assembled) return;
    const Eigen::Index ng = mpm_.size(), nf = fem_.size();
    // The grid's diagonal and the FEM block, each with the pairs' terms on its own unknowns.
    VecX grid_diagonal;
    mpm_.hessian_diagonal(grid_diagonal);
    const SparseMatrix& Hf = *fem_.hessian_matrix();
    triplets_.clear();  // the pairs' FEM terms, added to Hf below
    using Hessian = typename BarrierForm<dim>::Hessian;
    const auto add_pair = [&](const Hessian& H, double scale, int count, const Eigen::Index* index,
                              const double* weight, const int* slot) {
        for (int i = 0; i < count; ++i) {
            if (index[i] < ng) {
                for (int a = 0; a < dim; ++a)
                    if (residual_mass_[index[i] + a] > 0.0)
                        grid_diagonal[index[i] + a] +=
                            scale * weight[i] * weight[i] * H(dim * slot[i] + a, dim * slot[i] + a);
                continue;
            }
            for (int j = 0; j < count; ++j) {
                if (index[j] < ng) continue;
                for (int a = 0; a < dim; ++a)
                    for (int b = 0; b < dim; ++b) {
                        const Eigen::Index row = index[i] + a, col = index[j] + b;
                        if (residual_mass_[row] > 0.0 && residual_mass_[col] > 0.0)
                            triplets_.emplace_back(row - ng, col - ng, scale * H(dim * slot[i] + a, dim * slot[j] + b));
                    }
            }
        }
    };
    barrier_.for_each_pair_hessian(add_pair);
    friction_.for_each_pair_hessian(add_pair);
    if (triplets_.empty()) {
        fem_block_ = Hf;
    } else {
        pair_block_.resize(nf, nf);
        pair_block_.setFromTriplets(triplets_.begin(), triplets_.end());
        fem_block_ = Hf + pair_block_;
    }
    FemFactor& f = *fem_factor_;
    // The FEM block only preconditions PCG: its factorization is kept through the step's Newton
    // iterations while the barrier's pairs are the same ones (the stiff body's Hessian hardly
    // changes; the pairs' terms do, and a new pair set gets a new factorization).
    const std::vector<ContactPairTerms<dim>>& pairs = barrier_.hessian_pairs();
    const bool same_pairs = factorized_this_step_ && pairs.size() == factor_pairs_.size() &&
                            std::equal(pairs.begin(), pairs.end(), factor_pairs_.begin(),
                                       [](const auto& a, const auto& b) { return a.node == b; });
    inverse_grid_diagonal_ = grid_diagonal.unaryExpr([](double h) { return h > 0.0 ? 1.0 / h : 1.0; });
    diagonal_.resize(ng + nf);
    diagonal_ << grid_diagonal, fem_block_.diagonal();
    if (same_pairs) return;
    factorized_this_step_ = true;
    factor_pairs_.clear();
    for (const ContactPairTerms<dim>& t : pairs) factor_pairs_.push_back(t.node);
    const bool same = static_cast<Eigen::Index>(f.outer.size()) == nf + 1 &&
                      static_cast<Eigen::Index>(f.inner.size()) == fem_block_.nonZeros() &&
                      std::equal(f.outer.begin(), f.outer.end(), fem_block_.outerIndexPtr()) &&
                      std::equal(f.inner.begin(), f.inner.end(), fem_block_.innerIndexPtr());
    if (!same) {
        f.llt.analyzePattern(fem_block_);
        f.outer.assign(fem_block_.outerIndexPtr(), fem_block_.outerIndexPtr() + nf + 1);
        f.inner.assign(fem_block_.innerIndexPtr(), fem_block_.innerIndexPtr() + fem_block_.nonZeros());
    }
    f.llt.factorize(fem_block_);
    if (f.llt.info() != Eigen::Success)
        throw NewtonError("the FEM block of the coupled Hessian is not positive definite");
}

template <int dim>
void CoupledPotential<dim>::apply_preconditioner(const VecX& r, VecX& z) const {
    const Eigen::Index ng = mpm_.size(), nf = fem_.size();
    z.resize(ng + nf);
    z.head(ng) = inverse_grid_diagonal_.cwiseProduct(r.head(ng));
    z.tail(nf) = fem_factor_->llt.solve(r.tail(nf));
}

template class CoupledPotential<2>;
template class CoupledPotential<3>;

}  // namespace pnet
