#pragma once
// Matrix-free preconditioned conjugate gradients for H d = b with H symmetric
// positive semi-definite (Objective::hessian_multiply), and GMRES or BiCGSTAB for an H with a
// skew part (Objective::hessian_symmetric()), preconditioned by the
// inverse of diag(H) (Jacobi) or of its b x b diagonal blocks (block Jacobi:
// for MPM the d x d coupling of a node's velocity components), or an
// incomplete Cholesky factorization of the assembled Hessian.
#include <memory>

#include <Eigen/IterativeLinearSolvers>

#include "pnet/solver/objective.hpp"

namespace pnet {

/// M^-1 of PCG: an inverse diagonal or inverse diagonal blocks.
class Preconditioner {
public:
    /// 1 / H_ii (entries <= 0 are taken as 1).
    static Preconditioner jacobi(const VecX& diagonal);
    /// The inverses of the b x b blocks (consecutive, row-major, as
    /// Objective::hessian_block_diagonal gives them); a block that is not
    /// positive definite falls back to the inverse of its diagonal.
    static Preconditioner block_jacobi(const VecX& blocks, int block);

    /// The objective's own (Objective::apply_preconditioner; not owned).
    static Preconditioner of(const Objective& objective);

    /// The same, in place: the storage is kept from one Newton iteration to the next.
    void set_jacobi(const VecX& diagonal);
    void set_block_jacobi(const VecX& blocks, int block);
    void set_objective(const Objective& objective) { objective_ = &objective; }
    /// Incomplete Cholesky with threshold dropping (Eigen's IncompleteCholesky, AMD ordering, the
    /// diagonal shifted until the factorization succeeds) of the assembled H (both triangles or the
    /// lower one); the ordering is kept while H's pattern size is unchanged.
    void set_incomplete_cholesky(const SparseMatrix& H);

    int block() const { return block_; }
    /// z = M^-1 r.
    void apply(const VecX& r, VecX& z) const;

private:
    int block_ = 1;
    const Objective* objective_ = nullptr;  // set: the objective's own preconditioner
    VecX inverse_;                          // block 1: the inverse diagonal; else the inverse blocks, row-major
    using IncompleteCholesky = Eigen::IncompleteCholesky<double, Eigen::Lower, Eigen::AMDOrdering<int>>;
    std::shared_ptr<IncompleteCholesky> ichol_;  // set: incomplete Cholesky
    bool use_ichol_ = false;
};

struct PcgResult {
    int iterations = 0;
    double relative_residual = 0.0;  // |b - H d| / |b|
    bool converged = false;
    bool negative_curvature = false;  // d^T H d <= 0 met (H not PD along a search direction)
};

/// PCG's work vectors, kept between solves so that a Newton loop allocates
/// them once.
struct PcgWorkspace {
    VecX r, z, p, Hp;
};

/// Solves H d = b from d = 0 until |b - H d| <= relative_tolerance |b| or
/// max_iterations. On negative curvature it stops and keeps the last iterate
/// (the first iterate, if any, is the preconditioned steepest descent step).
PcgResult solve_pcg(const Objective& objective, const VecX& b, const Preconditioner& preconditioner, VecX& d,
                    double relative_tolerance, int max_iterations, PcgWorkspace& work);
PcgResult solve_pcg(const Objective& objective, const VecX& b, const Preconditioner& preconditioner, VecX& d,
                    double relative_tolerance, int max_iterations);

/// BiCGSTAB's work vectors (van der Vorst 1992), kept between solves.
struct BicgstabWorkspace {
    VecX r, r0, p, v, s, t, y, z;
};

/// Solves H d = b for an H that is not symmetric (Objective::hessian_symmetric() false: S + K, S
/// symmetric PSD, K skew) by right-preconditioned BiCGSTAB, from d = 0 until |b - H d| <=
/// relative_tolerance |b| or max_iterations. Each iteration costs two products with H, and
/// PcgResult::iterations counts the products, so that the statistics compare with PCG's. A breakdown
/// (a vanishing inner product) stops it with the last iterate (the first iterate, if none, is the
/// preconditioned residual step M^-1 b scaled as PCG's first one).
PcgResult solve_bicgstab(const Objective& objective, const VecX& b, const Preconditioner& preconditioner, VecX& d,
                         double relative_tolerance, int max_iterations, BicgstabWorkspace& work);

/// GMRES's work: the Krylov basis and the Hessenberg least-squares problem, kept between solves.
struct GmresWorkspace {
    Eigen::MatrixXd basis;       // n x (m + 1), the orthonormal Arnoldi vectors
    Eigen::MatrixXd hessenberg;  // (m + 1) x m, rotated to upper triangular as it grows
    Eigen::VectorXd cosines, sines, rhs;
    VecX w, z;
};

/// Solves H d = b for any H by right-preconditioned GMRES(m) (Saad and Schultz 1986): each iteration
/// one product with H and the Krylov iterate that minimizes |b - H d|_W over the basis built so far
/// (modified Gram-Schmidt in the inner product u . W v, Givens rotations), restarted every `restart`
/// products, from d = 0 until |b - H d|_W <= relative_tolerance |b|_W or max_iterations products.
/// W = diag(`weight`), the identity when null; Newton passes 1 / diag(H), so that the linear solve is
/// judged in the norm its own residual is (the mass-weighted residual, NewtonOptions::residual_mass).
/// PcgResult::iterations counts the products, relative_residual is in the W norm.
PcgResult solve_gmres(const Objective& objective, const VecX& b, const Preconditioner& preconditioner, VecX& d,
                      double relative_tolerance, int max_iterations, GmresWorkspace& work, int restart = 30,
                      const VecX* weight = nullptr);

}  // namespace pnet
