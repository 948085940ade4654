#include "pnet/solver/inertia_form.hpp"

namespace pnet {

double InertiaForm::value(const VecX& v) {
    return 0.5 * (v - target_).cwiseAbs2().dot(mass_.cwiseProduct(free_).cwiseProduct(weight_));
}

double InertiaForm::add_gradient(const VecX& v, VecX& g) {
    g += mass_.cwiseProduct(weight_).cwiseProduct(v - target_);
    return value(v);
}

void InertiaForm::prepare_hessian(const VecX& /*v*/) {
    hessian_.resize(mass_.size());
    for (Eigen::Index i = 0; i < mass_.size(); ++i) hessian_[i] = mass_[i] * (free_[i] > 0.0 ? weight_[i] : 1.0);
}

void InertiaForm::add_hessian_multiply(const VecX& d, VecX& out) const {
    out += hessian_.cwiseProduct(d);
}

void InertiaForm::add_hessian_diagonal(VecX& diagonal) const {
    diagonal += hessian_;
}

void InertiaForm::add_hessian_block_diagonal(VecX& blocks) const {
    for (Eigen::Index i = 0; i < hessian_.size(); ++i) blocks[(i / block_) * block_ * block_ + (i % block_) * (block_ + 1)] += hessian_[i];
}

void InertiaForm::add_hessian_triplets(std::vector<Triplet>& triplets) const {
    for (Eigen::Index i = 0; i < hessian_.size(); ++i) triplets.emplace_back(i, i, hessian_[i]);
}

void InertiaForm::add_hessian_values(double* values, const int* slots) const {
    for (Eigen::Index i = 0; i < hessian_.size(); ++i) values[slots[i]] += hessian_[i];
}

}  // namespace pnet
