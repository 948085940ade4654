#pragma once
// Matrix-free preconditioned conjugate gradients for H d = b with H symmetric
// positive semi-definite (Objective::hessian_multiply) and a Jacobi
// preconditioner (1 / diag H).
#include "pnet/solver/objective.hpp"

namespace pnet {

struct PcgResult {
    int iterations = 0;
    double relative_residual = 0.0;  // |b - H d| / |b|
    bool converged = false;
    bool negative_curvature = false;  // d^T H d <= 0 met (H not PD along a search direction)
};

/// Solves H d = b from d = 0 until |b - H d| <= relative_tolerance |b| or
/// max_iterations. On negative curvature it stops and keeps the last iterate
/// (the first iterate, if any, is the preconditioned steepest descent step).
PcgResult solve_pcg(const Objective& objective, const VecX& b, const VecX& inverse_diagonal, VecX& d,
                    double relative_tolerance, int max_iterations);

}  // namespace pnet
