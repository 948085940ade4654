#pragma once
// Derivative checks of the contact tests (tests/cpp/contact/), 2D and 3D alike: the barrier
// potential's and the lagged friction's gradient and Hessian against finite differences.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/SparseCore>
#include <cmath>
#include <vector>

#include "pnet/contact/collisions/contact_potential.hpp"
#include "pnet/contact/friction.hpp"
#include "support/finite_difference.hpp"

namespace pnet::test {

/// Node positions stacked into one vector (dim entries a node).
template <int dim>
Eigen::VectorXd pack(const std::vector<Vec<dim>>& x) {
    Eigen::VectorXd q(dim * x.size());
    for (std::size_t i = 0; i < x.size(); ++i) q.template segment<dim>(dim * i) = x[i];
    return q;
}

/// The inverse of pack().
template <int dim>
std::vector<Vec<dim>> unpack(const Eigen::VectorXd& q) {
    std::vector<Vec<dim>> y(q.size() / dim);
    for (std::size_t i = 0; i < y.size(); ++i) y[i] = q.template segment<dim>(dim * i);
    return y;
}

/// The barrier potential's gradient and Hessian at x against central differences of its value and
/// gradient (every entry compared), and its projected Hessian positive semi-definite (every pair's
/// is, so the sum is). Returns what add_gradient() returned.
template <int dim>
double expect_barrier_derivatives(const ContactPotential<dim>& contact, const std::vector<Vec<dim>>& x) {
    const Eigen::VectorXd q = pack<dim>(x);
    Eigen::VectorXd g = Eigen::VectorXd::Zero(q.size());
    const double b = contact.add_gradient(x, 1.0, g);
    FdStats fd;
    EXPECT_TRUE(check_gradient([&](const Eigen::VectorXd& y) { return contact.value(unpack<dim>(y)); }, g, q, fd,
                               1e-9, 1e-5, 1e-6 * g.cwiseAbs().maxCoeff()));
    std::vector<Eigen::Triplet<double>> triplets;
    contact.add_hessian(x, 1.0, triplets, /*project_psd=*/false);
    Eigen::SparseMatrix<double> H(q.size(), q.size());
    H.setFromTriplets(triplets.begin(), triplets.end());
    const Eigen::MatrixXd Hd(H);
    auto grad = [&](const Eigen::VectorXd& y) {
        Eigen::VectorXd gy = Eigen::VectorXd::Zero(y.size());
        contact.add_gradient(unpack<dim>(y), 1.0, gy);
        return gy;
    };
    EXPECT_TRUE(check_jacobian(grad, Hd, q, fd, 1e-9, 1e-4, 1e-6 * Hd.cwiseAbs().maxCoeff()));
    EXPECT_EQ(fd.checks, static_cast<int>(q.size() + q.size() * q.size()));
    triplets.clear();
    contact.add_hessian(x, 1.0, triplets, /*project_psd=*/true);
    H.setFromTriplets(triplets.begin(), triplets.end());
    EXPECT_GE(Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(Eigen::MatrixXd(H)).eigenvalues().minCoeff(),
              -1e-9 * Hd.cwiseAbs().maxCoeff());
    return b;
}

/// The lagged friction potential's gradient and Hessian against central differences of its value
/// and gradient (every entry compared), at velocities of `nodes` nodes that slip below and above
/// 1e-3 m/s. Returns the (dense) Hessian.
template <int dim>
Eigen::MatrixXd expect_friction_derivatives(const Friction<dim>& friction, std::size_t nodes) {
    Eigen::VectorXd v(dim * nodes);
    for (Eigen::Index k = 0; k < v.size(); ++k) v[k] = 1e-3 * std::sin(1.7 * k + 0.3);
    Eigen::VectorXd g = Eigen::VectorXd::Zero(v.size());
    friction.add_gradient(v, 1.0, g);
    FdStats fd;
    EXPECT_TRUE(check_gradient([&](const Eigen::VectorXd& y) { return friction.value(y); }, g, v, fd, 1e-9, 1e-5,
                               1e-6 * g.cwiseAbs().maxCoeff()));
    std::vector<Eigen::Triplet<double>> triplets;
    friction.add_hessian(v, 1.0, triplets);
    Eigen::SparseMatrix<double> H(v.size(), v.size());
    H.setFromTriplets(triplets.begin(), triplets.end());
    const Eigen::MatrixXd Hd(H);
    auto grad = [&](const Eigen::VectorXd& y) {
        Eigen::VectorXd gy = Eigen::VectorXd::Zero(y.size());
        friction.add_gradient(y, 1.0, gy);
        return gy;
    };
    EXPECT_TRUE(check_jacobian(grad, Hd, v, fd, 1e-10, 1e-4, 1e-6 * Hd.cwiseAbs().maxCoeff()));
    EXPECT_EQ(fd.checks, static_cast<int>(v.size() + v.size() * v.size()));
    return Hd;
}

}  // namespace pnet::test
