#include "pnet/contact/friction.hpp"

#include <cmath>
#include <stdexcept>

namespace pnet {

double friction_f0(double x, double eps) {
    return x >= eps ? x : -x * x * x / (3.0 * eps * eps) + x * x / eps + eps / 3.0;
}

double friction_f1(double x, double eps) { return x >= eps ? 1.0 : -x * x / (eps * eps) + 2.0 * x / eps; }

double friction_f1_derivative(double x, double eps) { return x >= eps ? 0.0 : -2.0 * x / (eps * eps) + 2.0 / eps; }

double friction_f1_over_x(double x, double eps) { return x >= eps ? 1.0 / x : -x / (eps * eps) + 2.0 / eps; }

template <int dim>
Friction<dim>::Friction(double mu, double eps_v) : mu_(mu), eps_v_(eps_v) {
    if (!(mu >= 0.0) || !(eps_v > 0.0)) throw std::invalid_argument("Friction: mu must be >= 0 and eps_v > 0");
}

template <int dim>
void Friction<dim>::lag(const ContactPotential<dim>& contact, const std::vector<Vec<dim>>& x) {
    pairs_.clear();
    for (const Pair& p : contact.lagged_pairs(x))
        if (p.normal_force > 0.0) pairs_.push_back(p);
}

template <int dim>
typename Friction<dim>::Slip Friction<dim>::slip(const Pair& p, const Eigen::VectorXd& v) const {
    Vec<dim> relative = Vec<dim>::Zero();
    for (int k = 0; k < p.count; ++k) relative += p.weight[k] * v.template segment<dim>(dim * p.node[k]);
    return p.tangent.transpose() * relative;
}

template <int dim>
double Friction<dim>::value(const Eigen::VectorXd& v) const {
    double sum = 0.0;
    for (const Pair& p : pairs_) sum += mu_ * p.normal_force * friction_f0(slip(p, v).norm(), eps_v_);
    return sum;
}

template <int dim>
void Friction<dim>::add_gradient(const Eigen::VectorXd& v, double scale, Eigen::VectorXd& g) const {
    for (const Pair& p : pairs_) {
        const Slip u = slip(p, v);
        // dD/du = mu lambda f1(|u|) u / |u| (0 at u = 0).
        const Vec<dim> f = scale * mu_ * p.normal_force * friction_f1_over_x(u.norm(), eps_v_) * (p.tangent * u);
        for (int k = 0; k < p.count; ++k) g.template segment<dim>(dim * p.node[k]) += p.weight[k] * f;
    }
}

template <int dim>
void Friction<dim>::add_hessian(const Eigen::VectorXd& v, double scale,
                                std::vector<Eigen::Triplet<double>>& triplets) const {
    for (const Pair& p : pairs_) {
        const Slip u = slip(p, v);
        const double c = scale * mu_ * p.normal_force;
        const Mat<dim> H = c * p.tangent * friction_slip_hessian<dim - 1>(u, eps_v_) * p.tangent.transpose();
        if (H.cwiseAbs().maxCoeff() == 0.0) continue;
        for (int a = 0; a < p.count; ++a)
            for (int b = 0; b < p.count; ++b) {
                const Mat<dim> block = p.weight[a] * p.weight[b] * H;
                for (int r = 0; r < dim; ++r)
                    for (int q = 0; q < dim; ++q)
                        triplets.emplace_back(dim * p.node[a] + r, dim * p.node[b] + q, block(r, q));
            }
    }
}

template <int dim>
void Friction<dim>::apply_impulses(Eigen::VectorXd& v, double h, const std::vector<double>& inverse_mass) const {
    for (const Pair& p : pairs_) {
        Slip u = Slip::Zero();
        double w = 0.0;  // 1 / m_eff
        for (int k = 0; k < p.count; ++k) {
            u += p.weight[k] * (p.tangent.transpose() * v.template segment<dim>(dim * p.node[k]));
            w += p.weight[k] * p.weight[k] * inverse_mass[p.node[k]];
        }
        const double speed = u.norm();
        if (speed == 0.0 || !(w > 0.0)) continue;
        const double impulse = std::min(mu_ * p.normal_force * h, speed / w);
        const Vec<dim> direction = p.tangent * (u / speed);
        for (int k = 0; k < p.count; ++k)
            v.template segment<dim>(dim * p.node[k]) -= impulse * p.weight[k] * inverse_mass[p.node[k]] * direction;
    }
}

template class Friction<2>;
template class Friction<3>;

}  // namespace pnet
