#pragma once
// Seeded random deformations for the property tests.
#include <Eigen/Core>
#include <Eigen/QR>
#include <cmath>
#include <random>

#include "pnet/math/types.hpp"

namespace pnet::test {

class Random {
public:
    explicit Random(unsigned seed) : engine_(seed) {}

    double uniform(double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(engine_); }

    template <int dim>
    Vec<dim> uniform_vec(double lo, double hi) {
        Vec<dim> v;
        for (int i = 0; i < dim; ++i) v[i] = uniform(lo, hi);
        return v;
    }

    /// A rows x cols matrix of entries ~ U[lo, hi], drawn row by row.
    Eigen::MatrixXd uniform_matrix(Eigen::Index rows, Eigen::Index cols, double lo, double hi) {
        Eigen::MatrixXd M(rows, cols);
        for (Eigen::Index i = 0; i < rows; ++i)
            for (Eigen::Index j = 0; j < cols; ++j) M(i, j) = uniform(lo, hi);
        return M;
    }

    /// A vector of n entries ~ U[lo, hi].
    Eigen::VectorXd uniform_vector(Eigen::Index n, double lo, double hi) {
        Eigen::VectorXd v(n);
        for (Eigen::Index i = 0; i < n; ++i) v[i] = uniform(lo, hi);
        return v;
    }

    /// Haar-random rotation (QR of a Gaussian matrix with the sign fix of Mezzadri 2007).
    template <int dim>
    Mat<dim> rotation() {
        std::normal_distribution<double> normal;
        Mat<dim> A;
        for (int i = 0; i < dim; ++i)
            for (int j = 0; j < dim; ++j) A(i, j) = normal(engine_);
        Eigen::HouseholderQR<Mat<dim>> qr(A);
        Mat<dim> Q = qr.householderQ();
        const Mat<dim> R = qr.matrixQR().template triangularView<Eigen::Upper>();
        for (int i = 0; i < dim; ++i)
            if (R(i, i) < 0) Q.col(i) *= -1.0;
        if (Q.determinant() < 0) Q.col(0) *= -1.0;
        return Q;
    }

    /// R1 diag(exp(eps)) R2 with eps ~ U[-magnitude, magnitude]^d.
    template <int dim>
    Mat<dim> deformation(double magnitude) {
        const Vec<dim> Sigma = uniform_vec<dim>(-magnitude, magnitude).array().exp().matrix();
        return rotation<dim>() * Sigma.asDiagonal() * rotation<dim>();
    }

private:
    std::mt19937_64 engine_;
};

}  // namespace pnet::test
