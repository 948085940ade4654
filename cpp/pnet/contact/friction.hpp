#pragma once
// Lagged smoothed Coulomb friction of IPC (Li et al. 2020; docs/methods.md) in
// velocity form, in 2D and 3D: for every contact pair active at the start of
// the step, its normal force lambda_k = kappa |b'(s)| 2 d, its tangent basis
// T_k (dim x (dim - 1), orthonormal columns) and the weights of its relative
// velocity are frozen (lagged); the dissipative potential is
//   D(v) = sum_k mu lambda_k f0(|u_k|),   u_k = T_k^T sum_j w_kj v_j  (m/s),
//   f0(x) = -x^3 / (3 eps^2) + x^2 / eps + eps / 3 for x < eps, x otherwise,
// so that -dD/du = -mu lambda f1(|u|) u / |u|, f1 = f0' (a Coulomb force
// smoothed below the slip velocity eps_v). The incremental potential gets
// dt D(v). Its Hessian in u,
//   mu lambda [f1'(|u|) u u^T / |u|^2 + f1(|u|) / |u| (I - u u^T / |u|^2)],
// is PSD (f1' >= 0, f1 >= 0) and tends to 2 mu lambda / eps I as u -> 0.
#include <vector>

#include <Eigen/SparseCore>

#include "pnet/contact/collisions/contact_potential.hpp"
#include "pnet/math/types.hpp"

namespace pnet {

/// f0, f1 = f0' and f1' of the smoothed friction (eps > 0, x >= 0).
double friction_f0(double x, double eps);
double friction_f1(double x, double eps);
double friction_f1_derivative(double x, double eps);
/// f1(x) / x, continuous at 0 (2 / eps).
double friction_f1_over_x(double x, double eps);

/// The Hessian of f0(|u|) in the slip u (n = dim - 1 components):
///   f1'(|u|) u u^T / |u|^2 + f1(|u|) / |u| (I - u u^T / |u|^2),   (2 / eps) I at u = 0.
template <int n>
Eigen::Matrix<double, n, n> friction_slip_hessian(const Eigen::Matrix<double, n, 1>& u, double eps) {
    const double x = u.norm();
    Eigen::Matrix<double, n, n> inner = friction_f1_over_x(x, eps) * Eigen::Matrix<double, n, n>::Identity();
    if (x > 0.0) {
        const Eigen::Matrix<double, n, 1> direction = u / x;
        inner += (friction_f1_derivative(x, eps) - friction_f1_over_x(x, eps)) * direction * direction.transpose();
    }
    return inner;
}

template <int dim>
class Friction {
public:
    using Pair = FrictionPair<dim>;
    using Slip = Eigen::Matrix<double, dim - 1, 1>;

    /// mu: Coulomb coefficient; eps_v: the slip velocity below which friction is smoothed, m/s.
    Friction(double mu, double eps_v);

    /// Lags the pairs of `contact` active at positions x (the start of the step).
    void lag(const ContactPotential<dim>& contact, const std::vector<Vec<dim>>& x);
    std::size_t pairs() const { return pairs_.size(); }

    /// D(v), W (v: dim values per node).
    double value(const Eigen::VectorXd& v) const;
    /// g += scale dD/dv.
    void add_gradient(const Eigen::VectorXd& v, double scale, Eigen::VectorXd& g) const;
    /// Triplets of scale d2D/dv2.
    void add_hessian(const Eigen::VectorXd& v, double scale, std::vector<Eigen::Triplet<double>>& triplets) const;

    const std::vector<Pair>& lagged() const { return pairs_; }
    double mu() const { return mu_; }

    /// Explicit integration (the ground truth): Coulomb friction as impulses on velocities v
    /// (dim values per node) over a step h, pair by pair in order (Gauss-Seidel), each
    /// opposing its tangential slip u and at most mu lambda h, and at most what stops the slip
    /// (m_eff |u|, 1 / m_eff = sum_j w_j^2 / m_j over the nodes with mass > 0): sticking is
    /// exact and no step overshoots, whatever h. inverse_mass: 1/m per node, 0 for kinematic.
    void apply_impulses(Eigen::VectorXd& v, double h, const std::vector<double>& inverse_mass) const;

private:
    Slip slip(const Pair& p, const Eigen::VectorXd& v) const;
    double mu_, eps_v_;
    std::vector<Pair> pairs_;
};

using Friction2d = Friction<2>;
using Friction3d = Friction<3>;

}  // namespace pnet
