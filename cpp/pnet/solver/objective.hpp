#pragma once
// The one face every energy shows the optimization integrators
// (docs/architecture.md): an objective E(x) on a flat vector of unknowns with
// value, gradient and the product of a positive semi-definite approximation
// of its Hessian with a vector. Newton (newton.hpp) only ever sees this
// interface, so the MPM incremental potential, FEM and coupling share it.
#include <Eigen/Core>
#include <Eigen/SparseCore>

namespace pnet {

using VecX = Eigen::VectorXd;
using SparseMatrix = Eigen::SparseMatrix<double>;  // column-major

class Objective {
public:
    virtual ~Objective() = default;

    /// Number of unknowns.
    virtual Eigen::Index size() const = 0;

    /// E(x).
    virtual double value(const VecX& x) = 0;

    /// E(x), and its gradient into `gradient` (resized by the caller to size()).
    virtual double value_gradient(const VecX& x, VecX& gradient) = 0;

    /// Prepares hessian_multiply() and hessian_diagonal() at x (for example,
    /// per-particle PSD-projected Hessians). Called once per Newton iteration,
    /// after value_gradient(x).
    virtual void prepare_hessian(const VecX& x) = 0;

    /// value_gradient(x) and prepare_hessian(x) in one call, for energies whose
    /// Hessian pass also yields the value and gradient (a learned energy's fused
    /// kernel): Newton evaluates trial points with it, so that an accepted step
    /// costs one energy pass.
    virtual double value_gradient_hessian(const VecX& x, VecX& gradient) {
        const double e = value_gradient(x, gradient);
        prepare_hessian(x);
        return e;
    }

    /// out = H d with H the PSD Hessian prepared at the last prepare_hessian() (where
    /// hessian_symmetric() is false: H = S + K with S symmetric PSD and K skew).
    virtual void hessian_multiply(const VecX& d, VecX& out) const = 0;

    /// Whether H is symmetric. An objective whose H keeps a skew part (the Jacobian of a residual
    /// that is not a gradient: non-associative plastic flow) says false; Newton then solves H d = -g
    /// with GMRES or BiCGSTAB (NewtonOptions::nonsymmetric_solver) instead of PCG or Cholesky. d . H d = d . S d >= 0
    /// still, so the exact solution is a descent direction (g . d = -y . S y with y = H^-1 g).
    virtual bool hessian_symmetric() const { return true; }

    /// diag(H), for the Jacobi preconditioner; entries must be > 0.
    virtual void hessian_diagonal(VecX& diagonal) const = 0;

    /// Size b of the diagonal blocks hessian_block_diagonal() gives (1: none;
    /// MPM: the d velocity components of a grid node).
    virtual int hessian_block_size() const { return 1; }

    /// The size()/b diagonal b x b blocks of H, consecutive, each row-major,
    /// for the block-Jacobi preconditioner (only called when b > 1).
    virtual void hessian_block_diagonal(VecX& blocks) const { hessian_diagonal(blocks); }

    /// The objective's own PCG preconditioner z = M^-1 r (M symmetric positive definite, built from
    /// the Hessian prepared last), for systems whose parts Jacobi cannot balance (MPM-FEM coupling:
    /// a stiff FEM body solved exactly beside the grid's Jacobi). False: it has none, and PCG uses
    /// Jacobi or block Jacobi.
    virtual bool has_preconditioner() const { return false; }
    virtual void apply_preconditioner(const VecX& r, VecX& z) const { z = r; }

    /// H assembled (symmetric, both triangles stored) at the last
    /// prepare_hessian(), for a direct solve (NewtonOptions::linear_solver);
    /// null for matrix-free objectives (MPM).
    virtual const SparseMatrix* hessian_matrix() const { return nullptr; }

    /// The largest step fraction in (0, 1] that x + t d may take (the line
    /// search's filter: for contact, what CCD allows, so that no iterate
    /// intersects); E must be finite on [x, x + max_step d]. Default 1.
    virtual double max_step(const VecX& /*x*/, const VecX& /*d*/) { return 1.0; }

    /// For an energy defined about an expansion point (the learned energy about its reference F0,
    /// exact in value slope only there): moves the point to x, so that the gradient at x becomes the
    /// exact one (NewtonOptions::rebase). Returns whether the objective changed; value, gradient and
    /// Hessian must then be evaluated anew. Default: nothing to move.
    virtual bool rebase(const VecX& /*x*/) { return false; }

    /// An extra proximal weight lambda about the expansion point (the learned energy: lambda mu/2
    /// |F - F0|^2, in value, gradient and Hessian from the next evaluation on), Newton's damping
    /// of a rebased solve that stopped contracting (NewtonOptions::rebase). Returns whether the
    /// objective supports it. Default: it does not.
    virtual bool set_damping(double /*lambda*/) { return false; }
};

}  // namespace pnet
