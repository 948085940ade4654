#pragma once
// Polar singular value decomposition F = U diag(Sigma) V^T with U, V proper
// rotations (det = +1). Singular values are sorted Sigma_0 >= ... >= |Sigma_{d-1}|
// and an inverted F (det F < 0) is marked by a negative last singular value,
// the convention of Irving et al. 2004 used by every isotropic model here.
#include "pnet/math/types.hpp"

namespace pnet {

template <int dim>
struct PolarSVD {
    Mat<dim> U;
    Vec<dim> Sigma;
    Mat<dim> V;

    /// U diag(values) V^T: maps a diagonal-space quantity back to F space.
    Mat<dim> compose(const Vec<dim>& values) const {
        return U * values.asDiagonal() * V.transpose();
    }
};

/// Polar SVD of a d x d matrix (d = 2: closed form; d = 3: Jacobi eigenvectors of
/// F^T F, then Givens QR of F V; see svd.cpp).
template <int dim>
PolarSVD<dim> polar_svd(const Mat<dim>& F);

/// The same, started from a rotation V_start near F's V (a nearby F's: the previous Newton iterate's,
/// the previous step's), which spares the 3x3 Jacobi sweeps most of their work; V_start is
/// re-orthonormalized first, so a start carried over many calls does not drift. Any start gives
/// the same decomposition to round-off. d = 2: the closed form, V_start unused.
template <int dim>
PolarSVD<dim> polar_svd(const Mat<dim>& F, const Mat<dim>& V_start);

}  // namespace pnet
