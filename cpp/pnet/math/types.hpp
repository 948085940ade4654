#pragma once
// Small fixed-size linear-algebra types shared by the whole library.
//
// Flattening convention: a d x d matrix F is stored as the row-major vector
// vec(F)_{i*d+j} = F_ij (the layout of the network inputs, docs/physics.md, and of
// every fourth-order tensor such as dP/dF, whose entry ((i*d+j), (k*d+l)) is
// dP_ij / dF_kl).
#include <Eigen/Core>
#include <Eigen/LU>  // determinant(), inverse() of the small matrices

namespace pnet {

template <int dim>
using Vec = Eigen::Matrix<double, dim, 1>;

template <int dim>
using Mat = Eigen::Matrix<double, dim, dim>;

/// A linear map on d x d matrices in the row-major vec() basis (e.g. dP/dF).
template <int dim>
using Tensor4 = Eigen::Matrix<double, dim * dim, dim * dim>;

/// vec(F), row-major.
template <int dim>
Eigen::Matrix<double, dim * dim, 1> flatten(const Mat<dim>& F) {
    Eigen::Matrix<double, dim * dim, 1> v;
    for (int i = 0; i < dim; ++i)
        for (int j = 0; j < dim; ++j) v[i * dim + j] = F(i, j);
    return v;
}

/// Inverse of flatten().
template <int dim>
Mat<dim> unflatten(const Eigen::Matrix<double, dim * dim, 1>& v) {
    Mat<dim> F;
    for (int i = 0; i < dim; ++i)
        for (int j = 0; j < dim; ++j) F(i, j) = v[i * dim + j];
    return F;
}

}  // namespace pnet
