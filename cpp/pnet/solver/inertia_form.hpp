#pragma once
// The inertia form of an incremental potential over velocities v (docs/methods.md):
//
//   E(v) = sum_i s_i m_i / 2 (v_i - v*_i)^2   over the free components,
//   dE/dv_i = s_i m_i (v_i - v*_i),   H = diag(h),  h_i = s_i m_i (free) or m_i (fixed),
//
// with m_i the mass per velocity component (MPM grid node, FEM node), v* the velocity the step
// would reach without forces, and s_i a weight, 1 except on soft kinematic constraints (FEM:
// components driven to their target under contact, s >> 1). A fixed component keeps m_i on the
// diagonal, so that Newton, whose gradient there is 0, never moves it.
#include "pnet/solver/form.hpp"

namespace pnet {

class InertiaForm final : public Form {
public:
    /// `free`: the problem's 1 / 0 mask of free components (referenced); `block`: the unknowns per node.
    InertiaForm(const VecX& free, int block) : free_(free), block_(block) {}

    /// The step's masses m_i, targets v*_i and weights s_i (set by the problem; s = 1 by default).
    VecX& mass() { return mass_; }
    VecX& target() { return target_; }
    VecX& weight() { return weight_; }
    const VecX& mass() const { return mass_; }
    const VecX& target() const { return target_; }

    double value(const VecX& v) override;
    double add_gradient(const VecX& v, VecX& g) override;
    void prepare_hessian(const VecX& v) override;
    void add_hessian_multiply(const VecX& d, VecX& out) const override;
    void add_hessian_diagonal(VecX& diagonal) const override;
    void add_hessian_block_diagonal(VecX& blocks) const override;
    void add_hessian_triplets(std::vector<Triplet>& triplets) const override;
    void add_hessian_values(double* values, const int* slots) const override;

private:
    const VecX& free_;
    const int block_;
    VecX mass_, target_, weight_, hessian_;
};

}  // namespace pnet
