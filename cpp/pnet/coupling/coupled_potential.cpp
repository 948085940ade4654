#include "pnet/coupling/coupled_potential.hpp"

#include <algorithm>

#include <Eigen/SparseCholesky>

#include "pnet/solver/newton.hpp"  // NewtonError

namespace pnet {

void CoupledPotential2d::begin_step() {
    const Eigen::Index ng = mpm_.size(), nf = fem_.size();
    v_star_.resize(ng + nf);
    v_star_ << mpm_.v_star(), fem_.v_star();
    residual_mass_.resize(ng + nf);
    residual_mass_ << mpm_.residual_mass(), fem_.residual_mass();
    ccd_queries_ = ccd_limited_ = 0;
    pairs_.clear();
    factorized_this_step_ = false;
}

void CoupledPotential2d::split(const VecX& v) const {
    vg_ = v.head(mpm_.size());
    vf_ = v.tail(fem_.size());
}

void CoupledPotential2d::positions(const VecX& v, std::vector<Vec<2>>& X, std::vector<Vec<2>>& x) const {
    split(v);
    mpm_.particle_positions(vg_, X);
    fem_.positions(vf_, x);
}

void CoupledPotential2d::deformation(const VecX& v, std::vector<Mat<2>>& F) const {
    split(v);
    mpm_.deformation(vg_, F);
}

double CoupledPotential2d::value(const VecX& v) {
    split(v);
    const double e = mpm_.value(vg_) + fem_.value(vf_);
    positions(v, X_, x_);
    return e + contact_.value(X_, x_);
}

double CoupledPotential2d::add_barrier_gradient(const VecX& v, VecX& g) {
    positions(v, X_, x_);
    const double b = contact_.gradient(X_, x_, pairs_, gradients_);
    const double dt = mpm_.dt();
    const Eigen::Index ng = mpm_.size();
    constexpr int kStencil = IncrementalPotential<2>::kStencil;
    for (std::size_t k = 0; k < pairs_.size(); ++k) {
        const int p = pairs_[k].particle;
        const int* dof = mpm_.stencil_dofs(p);
        const double* w = mpm_.stencil_weights(p);
        for (int s = 0; s < kStencil; ++s) g.segment<2>(2 * dof[s]) += (dt * w[s]) * gradients_[k].head<2>();
        const auto& edge = contact_.edges()[pairs_[k].edge];
        g.segment<2>(ng + 2 * edge[0]) += dt * gradients_[k].segment<2>(2);
        g.segment<2>(ng + 2 * edge[1]) += dt * gradients_[k].segment<2>(4);
    }
    // Fixed components (sticky floor, kinematic nodes) are held: no gradient.
    g.array() *= (residual_mass_.array() > 0.0).cast<double>();
    return b;
}

double CoupledPotential2d::value_gradient(const VecX& v, VecX& gradient) {
    split(v);
    const double em = mpm_.value_gradient(vg_, gg_);
    const double ef = fem_.value_gradient(vf_, gf_);
    gradient.resize(size());
    gradient << gg_, gf_;
    return em + ef + add_barrier_gradient(v, gradient);
}

int CoupledPotential2d::pair_nodes(std::size_t k, Eigen::Index* index, double* weight, int* slot) const {
    constexpr int kStencil = IncrementalPotential<2>::kStencil;
    const int p = pairs_[k].particle;
    const int* dof = mpm_.stencil_dofs(p);
    const double* w = mpm_.stencil_weights(p);
    int count = 0;
    for (int s = 0; s < kStencil; ++s)
        if (w[s] != 0.0) {
            index[count] = 2 * dof[s];
            weight[count] = w[s];
            slot[count++] = 0;
        }
    const auto& edge = contact_.edges()[pairs_[k].edge];
    for (int e = 0; e < 2; ++e) {
        index[count] = mpm_.size() + 2 * edge[e];
        weight[count] = 1.0;
        slot[count++] = 1 + e;
    }
    return count;
}

namespace {
constexpr int kPairNodes = IncrementalPotential<2>::kStencil + 2;
}  // namespace

struct CoupledPotential2d::FemFactor {
    Eigen::SimplicialLLT<SparseMatrix, Eigen::Lower> llt;
    std::vector<SparseMatrix::StorageIndex> outer, inner;  // the pattern analysed
};

CoupledPotential2d::CoupledPotential2d(IncrementalPotential<2>& mpm, FemPotential<2>& fem,
                                       const ParticleContact2d& contact)
    : mpm_(mpm), fem_(fem), contact_(contact), fem_factor_(std::make_unique<FemFactor>()) {}

CoupledPotential2d::~CoupledPotential2d() = default;

void CoupledPotential2d::prepare(const VecX& v) {
    positions(v, X_, x_);
    contact_.hessians(X_, x_, project_psd_, pairs_, pair_hessians_);
    if (solve_ == LinearSolve::Assembled)
        assemble();
    else
        prepare_blocks();
}

void CoupledPotential2d::assemble() {
    const Eigen::Index ng = mpm_.size(), n = size();
    triplets_.clear();
    mpm_.add_hessian_triplets(triplets_, 0);
    const SparseMatrix& Hf = *fem_.hessian_matrix();
    for (Eigen::Index c = 0; c < Hf.outerSize(); ++c)
        for (SparseMatrix::InnerIterator it(Hf, c); it; ++it) triplets_.emplace_back(ng + it.row(), ng + c, it.value());
    const double dt2 = mpm_.dt() * mpm_.dt();
    Eigen::Index index[kPairNodes];
    double weight[kPairNodes];
    int slot[kPairNodes];
    for (std::size_t k = 0; k < pairs_.size(); ++k) {
        const int count = pair_nodes(k, index, weight, slot);
        const Mat6& H = pair_hessians_[k];
        for (int i = 0; i < count; ++i)
            for (int j = 0; j < count; ++j) {
                const double scale = dt2 * weight[i] * weight[j];
                for (int a = 0; a < 2; ++a)
                    for (int b = 0; b < 2; ++b) {
                        const Eigen::Index row = index[i] + a, col = index[j] + b;
                        if (residual_mass_[row] > 0.0 && residual_mass_[col] > 0.0)
                            triplets_.emplace_back(row, col, scale * H(2 * slot[i] + a, 2 * slot[j] + b));
                    }
            }
    }
    hessian_.resize(n, n);
    hessian_.setFromTriplets(triplets_.begin(), triplets_.end());  // duplicates summed in triplet order
    diagonal_ = hessian_.diagonal();
}

void CoupledPotential2d::prepare_blocks() {
    const Eigen::Index ng = mpm_.size(), nf = fem_.size();
    // The grid's diagonal and the FEM block, each with the pairs' terms on its own unknowns.
    VecX grid_diagonal;
    mpm_.hessian_diagonal(grid_diagonal);
    const SparseMatrix& Hf = *fem_.hessian_matrix();
    triplets_.clear();  // the pairs' FEM terms, added to Hf below
    const double dt2 = mpm_.dt() * mpm_.dt();
    Eigen::Index index[kPairNodes];
    double weight[kPairNodes];
    int slot[kPairNodes];
    for (std::size_t k = 0; k < pairs_.size(); ++k) {
        const int count = pair_nodes(k, index, weight, slot);
        const Mat6& H = pair_hessians_[k];
        for (int i = 0; i < count; ++i) {
            if (index[i] < ng) {
                for (int a = 0; a < 2; ++a)
                    if (residual_mass_[index[i] + a] > 0.0)
                        grid_diagonal[index[i] + a] +=
                            dt2 * weight[i] * weight[i] * H(2 * slot[i] + a, 2 * slot[i] + a);
                continue;
            }
            for (int j = 0; j < count; ++j) {
                if (index[j] < ng) continue;
                for (int a = 0; a < 2; ++a)
                    for (int b = 0; b < 2; ++b) {
                        const Eigen::Index row = index[i] + a, col = index[j] + b;
                        if (residual_mass_[row] > 0.0 && residual_mass_[col] > 0.0)
                            triplets_.emplace_back(row - ng, col - ng, dt2 * H(2 * slot[i] + a, 2 * slot[j] + b));
                    }
            }
        }
    }
    if (triplets_.empty()) {
        fem_block_ = Hf;
    } else {
        pair_block_.resize(nf, nf);
        pair_block_.setFromTriplets(triplets_.begin(), triplets_.end());
        fem_block_ = Hf + pair_block_;
    }
    FemFactor& f = *fem_factor_;
    // The FEM block only preconditions PCG: its factorization is kept through the step's Newton
    // iterations while the pairs are the same ones (the stiff body's Hessian hardly changes; the
    // pairs' terms do, and a new pair set gets a new factorization).
    const bool same_pairs =
        factorized_this_step_ && pairs_.size() == factor_pairs_.size() &&
        std::equal(pairs_.begin(), pairs_.end(), factor_pairs_.begin(),
                   [](const auto& a, const auto& b) { return a.particle == b.particle && a.edge == b.edge; });
    inverse_grid_diagonal_ = grid_diagonal.unaryExpr([](double h) { return h > 0.0 ? 1.0 / h : 1.0; });
    diagonal_.resize(ng + nf);
    diagonal_ << grid_diagonal, fem_block_.diagonal();
    if (same_pairs) return;
    factorized_this_step_ = true;
    factor_pairs_ = pairs_;
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

void CoupledPotential2d::hessian_multiply(const VecX& d, VecX& out) const {
    if (solve_ == LinearSolve::Assembled) {
        out.noalias() = hessian_ * d;
        return;
    }
    const Eigen::Index ng = mpm_.size(), nf = fem_.size();
    out.resize(ng + nf);
    work_in_ = d.head(ng);
    mpm_.hessian_multiply(work_in_, work_out_);
    out.head(ng) = work_out_;
    out.tail(nf).noalias() = *fem_.hessian_matrix() * d.tail(nf);
    const double dt2 = mpm_.dt() * mpm_.dt();
    Eigen::Index index[kPairNodes];
    double weight[kPairNodes];
    int slot[kPairNodes];
    for (std::size_t k = 0; k < pairs_.size(); ++k) {
        const int count = pair_nodes(k, index, weight, slot);
        // u = J d (the pair's positions' motion per dt), y = H u, out += J^T y dt^2.
        Vec6 u = Vec6::Zero();
        for (int i = 0; i < count; ++i)
            for (int a = 0; a < 2; ++a)
                if (residual_mass_[index[i] + a] > 0.0) u[2 * slot[i] + a] += weight[i] * d[index[i] + a];
        const Vec6 y = dt2 * (pair_hessians_[k] * u);
        for (int i = 0; i < count; ++i)
            for (int a = 0; a < 2; ++a)
                if (residual_mass_[index[i] + a] > 0.0) out[index[i] + a] += weight[i] * y[2 * slot[i] + a];
    }
}

void CoupledPotential2d::apply_preconditioner(const VecX& r, VecX& z) const {
    const Eigen::Index ng = mpm_.size(), nf = fem_.size();
    z.resize(ng + nf);
    z.head(ng) = inverse_grid_diagonal_.cwiseProduct(r.head(ng));
    z.tail(nf) = fem_factor_->llt.solve(r.tail(nf));
}

void CoupledPotential2d::prepare_hessian(const VecX& v) {
    split(v);
    mpm_.prepare_hessian(vg_);
    fem_.prepare_hessian(vf_);
    prepare(v);
}

double CoupledPotential2d::value_gradient_hessian(const VecX& v, VecX& gradient) {
    split(v);
    const double em = mpm_.value_gradient_hessian(vg_, gg_);
    const double ef = fem_.value_gradient_hessian(vf_, gf_);
    gradient.resize(size());
    gradient << gg_, gf_;
    const double b = add_barrier_gradient(v, gradient);
    prepare(v);
    return em + ef + b;
}

double CoupledPotential2d::max_step(const VecX& v, const VecX& d) {
    split(d);
    const VecX dg = vg_, df = vf_;
    double t = std::min(1.0, fem_.max_step(v.tail(fem_.size()), df));
    positions(v, X_, x_);
    mpm_.particle_positions(dg, dX_, true);
    dx_.resize(x_.size());
    for (std::size_t a = 0; a < x_.size(); ++a) dx_[a] = mpm_.dt() * df.segment<2>(2 * a);
    t = std::min(t, contact_.max_step(X_, dX_, x_, dx_));
    ++ccd_queries_;
    ccd_limited_ += t < 1.0;
    return t;
}

}  // namespace pnet
