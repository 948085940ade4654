#include "pnet/contact/friction.hpp"

#include <cmath>
#include <stdexcept>

#include "pnet/contact/ipc_contact.hpp"

namespace pnet {

double friction_f0(double x, double eps) {
    return x >= eps ? x : -x * x * x / (3.0 * eps * eps) + x * x / eps + eps / 3.0;
}

double friction_f1(double x, double eps) { return x >= eps ? 1.0 : -x * x / (eps * eps) + 2.0 * x / eps; }

double friction_f1_derivative(double x, double eps) { return x >= eps ? 0.0 : -2.0 * x / (eps * eps) + 2.0 / eps; }

Friction2d::Friction2d(double mu, double eps_v) : mu_(mu), eps_v_(eps_v) {
    if (!(mu >= 0.0) || !(eps_v > 0.0)) throw std::invalid_argument("Friction2d: mu must be >= 0 and eps_v > 0");
}

void Friction2d::lag(const Contact2d& contact, const std::vector<Vec<2>>& x) {
    pairs_.clear();
    for (const Contact2d::LaggedPair& c : contact.lagged_pairs(x)) {
        Pair p;
        p.count = c.count;
        for (int k = 0; k < c.count; ++k) {
            p.node[k] = c.node[k];
            p.weight[k] = c.weight[k];
        }
        p.tangent = c.tangent;
        p.normal_force = c.normal_force;
        if (p.normal_force > 0.0) pairs_.push_back(p);
    }
}

double Friction2d::slip(const Pair& p, const Eigen::VectorXd& v) const {
    Vec<2> relative = Vec<2>::Zero();
    for (int k = 0; k < p.count; ++k) relative += p.weight[k] * v.segment<2>(2 * p.node[k]);
    return p.tangent.dot(relative);
}

double Friction2d::value(const Eigen::VectorXd& v) const {
    double sum = 0.0;
    for (const Pair& p : pairs_) sum += mu_ * p.normal_force * friction_f0(std::abs(slip(p, v)), eps_v_);
    return sum;
}

void Friction2d::add_gradient(const Eigen::VectorXd& v, double scale, Eigen::VectorXd& g) const {
    for (const Pair& p : pairs_) {
        const double u = slip(p, v);
        const double f = scale * mu_ * p.normal_force * friction_f1(std::abs(u), eps_v_) * (u > 0.0 ? 1.0 : u < 0.0 ? -1.0 : 0.0);
        for (int k = 0; k < p.count; ++k) g.segment<2>(2 * p.node[k]) += f * p.weight[k] * p.tangent;
    }
}

void Friction2d::add_hessian(const Eigen::VectorXd& v, double scale,
                             std::vector<Eigen::Triplet<double>>& triplets) const {
    for (const Pair& p : pairs_) {
        const double h = scale * mu_ * p.normal_force * friction_f1_derivative(std::abs(slip(p, v)), eps_v_);
        if (h == 0.0) continue;
        for (int a = 0; a < p.count; ++a)
            for (int b = 0; b < p.count; ++b) {
                const Eigen::Matrix2d block = h * p.weight[a] * p.weight[b] * p.tangent * p.tangent.transpose();
                for (int r = 0; r < 2; ++r)
                    for (int c = 0; c < 2; ++c) triplets.emplace_back(2 * p.node[a] + r, 2 * p.node[b] + c, block(r, c));
            }
    }
}

void Friction2d::apply_impulses(Eigen::VectorXd& v, double h, const std::vector<double>& inverse_mass) const {
    for (const Pair& p : pairs_) {
        double u = 0.0, w = 0.0;  // slip and 1 / m_eff
        for (int k = 0; k < p.count; ++k) {
            u += p.weight[k] * p.tangent.dot(v.segment<2>(2 * p.node[k]));
            w += p.weight[k] * p.weight[k] * inverse_mass[p.node[k]];
        }
        if (u == 0.0 || !(w > 0.0)) continue;
        const double impulse = std::min(mu_ * p.normal_force * h, std::abs(u) / w);
        const double sign = u > 0.0 ? 1.0 : -1.0;
        for (int k = 0; k < p.count; ++k)
            v.segment<2>(2 * p.node[k]) -= sign * impulse * p.weight[k] * inverse_mass[p.node[k]] * p.tangent;
    }
}

}  // namespace pnet
