#pragma once
// One term of an incremental potential (docs/architecture.md, "Forms"): inertia, a material
// energy on particles or elements, the IPC barrier, lagged friction, the particle-mesh barrier.
// A Problem (problem.hpp) sums its forms, in a fixed order, into the one Objective Newton
// minimizes; MPM, FEM and coupling are problems that differ only in which forms they hold.
//
// A form sees the problem's whole vector of unknowns x and adds its share: its value, its
// gradient, its Hessian (PSD-projected, or with a PSD symmetric part where symmetric_hessian() is
// false) as a matrix-free product, a diagonal, d x d node blocks and triplets for an assembled
// solve, and the largest step its own constraints allow (CCD).
// Components the problem holds fixed (Dirichlet) get no gradient (the problem masks it); each
// form leaves their Hessian rows and columns out itself, except inertia, which keeps its mass
// there, so that a fixed component's row is m_i d_i and Newton never moves it.
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

namespace pnet {

using VecX = Eigen::VectorXd;
using Triplet = Eigen::Triplet<double>;

class Form {
public:
    virtual ~Form() = default;

    /// E_f(x).
    virtual double value(const VecX& x) = 0;
    /// g += dE_f/dx; returns E_f(x), found in the same pass.
    virtual double add_gradient(const VecX& x, VecX& g) = 0;
    /// Prepares the Hessian products below at x (per-point PSD projections, contact pairs).
    virtual void prepare_hessian(const VecX& x) = 0;
    /// prepare_hessian(x), then add_gradient(x, g): for a form whose Hessian pass also yields its
    /// value and gradient (the learned energy's fused kernel), one pass instead of two.
    virtual double add_gradient_hessian(const VecX& x, VecX& g) {
        prepare_hessian(x);
        return add_gradient(x, g);
    }

    /// out += H d.
    virtual void add_hessian_multiply(const VecX& d, VecX& out) const = 0;
    /// diagonal += diag(H).
    virtual void add_hessian_diagonal(VecX& diagonal) const = 0;
    /// blocks += the dim x dim diagonal blocks of H (one per node, consecutive, row-major).
    virtual void add_hessian_block_diagonal(VecX& blocks) const = 0;
    /// Appends H as triplets (duplicates are summed in order).
    virtual void add_hessian_triplets(std::vector<Triplet>& triplets) const = 0;
    /// values[slots[k]] += the value of the k-th triplet of add_hessian_triplets(), in that order:
    /// how the problem refills a pattern it built from the triplets once. The default makes the
    /// triplets; a form with a fixed pattern writes its values straight into the slots.
    virtual void add_hessian_values(double* values, const int* slots) const {
        std::vector<Triplet> triplets;
        add_hessian_triplets(triplets);
        for (std::size_t k = 0; k < triplets.size(); ++k) values[slots[k]] += triplets[k].value();
    }
    /// Whether H is symmetric (a learned energy's tangent of non-associative flow is not:
    /// ParticleEnergy::symmetric_hessian()). Its symmetric part is always PSD.
    virtual bool symmetric_hessian() const { return true; }
    /// Whether the triplets' pattern changes from one Newton iterate to the next (contact pairs
    /// come and go): the problem keeps a fixed pattern for the others and adds these apart.
    virtual bool changing_pattern() const { return false; }

    /// The largest fraction in (0, 1] of the step x -> x + d that keeps this form finite.
    virtual double max_step(const VecX& /*x*/, const VecX& /*d*/) { return 1.0; }
};

}  // namespace pnet
