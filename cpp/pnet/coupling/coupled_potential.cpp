#include "pnet/coupling/coupled_potential.hpp"

namespace pnet {

void CoupledPotential2d::begin_step() {
    const Eigen::Index ng = mpm_.size(), nf = fem_.size();
    v_star_.resize(ng + nf);
    v_star_ << mpm_.v_star(), fem_.v_star();
    residual_mass_.resize(ng + nf);
    residual_mass_ << mpm_.residual_mass(), fem_.residual_mass();
    ccd_queries_ = ccd_limited_ = 0;
    pairs_.clear();
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

void CoupledPotential2d::assemble(const VecX& v) {
    const Eigen::Index ng = mpm_.size(), n = size();
    triplets_.clear();
    mpm_.add_hessian_triplets(triplets_, 0);
    const SparseMatrix& Hf = *fem_.hessian_matrix();
    for (Eigen::Index c = 0; c < Hf.outerSize(); ++c)
        for (SparseMatrix::InnerIterator it(Hf, c); it; ++it) triplets_.emplace_back(ng + it.row(), ng + c, it.value());
    positions(v, X_, x_);
    contact_.hessians(X_, x_, project_psd_, pairs_, pair_hessians_);
    const double dt2 = mpm_.dt() * mpm_.dt();
    constexpr int kStencil = IncrementalPotential<2>::kStencil;
    // The pair's unknown nodes: the particle's stencil (weights w_ip, slot 0 of the 6 x 6
    // Hessian) and the edge's two nodes (weight 1, slots 1 and 2).
    Eigen::Index index[kStencil + 2];
    double weight[kStencil + 2];
    int slot[kStencil + 2];
    for (std::size_t k = 0; k < pairs_.size(); ++k) {
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
            index[count] = ng + 2 * edge[e];
            weight[count] = 1.0;
            slot[count++] = 1 + e;
        }
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
}

void CoupledPotential2d::prepare_hessian(const VecX& v) {
    split(v);
    mpm_.prepare_hessian(vg_);
    fem_.prepare_hessian(vf_);
    assemble(v);
}

double CoupledPotential2d::value_gradient_hessian(const VecX& v, VecX& gradient) {
    split(v);
    const double em = mpm_.value_gradient_hessian(vg_, gg_);
    const double ef = fem_.value_gradient_hessian(vf_, gf_);
    gradient.resize(size());
    gradient << gg_, gf_;
    const double b = add_barrier_gradient(v, gradient);
    assemble(v);
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
