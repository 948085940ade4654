#include "pnet/mpm/floor_friction_form.hpp"

#include <stdexcept>

#include "pnet/contact/friction.hpp"

namespace pnet {

namespace {

// The tangential axes: every axis but y, the floor's normal.
template <int dim>
constexpr int tangential_axis(int t) {
    return t == 0 ? 0 : 2;
}

}  // namespace

template <int dim>
void FloorFrictionForm<dim>::begin_newton(const std::vector<int>& dofs, const std::vector<double>& normal_velocity,
                                          const VecX& mass, double mu, double eps_v, const VecX& free,
                                          const VecX& held_product) {
    contacts_.clear();
    free_ = &free;
    newton_ = true;
    mu_ = mu;
    eps_v_ = eps_v;
    held_product_ = &held_product;
    newton_contacts_.clear();
    for (std::size_t c = 0; c < dofs.size(); ++c) {
        NewtonContact contact;
        contact.dof = dofs[c];
        contact.normal_momentum = mass[dim * dofs[c] + 1] * normal_velocity[c];
        contact.slip.setZero();
        contact.coupling.setZero();
        newton_contacts_.push_back(contact);
    }
    gradient_at_.resize(0);
}

template <int dim>
double FloorFrictionForm<dim>::value(const VecX& v) {
    double e = 0.0;
    if (newton_) {
        for (const NewtonContact& c : newton_contacts_) {
            Eigen::Matrix<double, dim - 1, 1> u;
            for (int t = 0; t < dim - 1; ++t) u[t] = v[dim * c.dof + tangential_axis<dim>(t)];
            if (c.held_impulse > 0.0) e += mu_ * c.held_impulse * friction_f0(u.norm(), eps_v_);
        }
        return e;
    }
    for (const Contact& c : contacts_)
        for (int t = 0; t < dim - 1; ++t) {
            const double u = v[dim * c.dof + tangential_axis<dim>(t)];
            e += 0.5 * c.stiffness * u * u;
        }
    return e;
}

template <int dim>
double FloorFrictionForm<dim>::add_gradient(const VecX& v, VecX& g) {
    double e = 0.0;
    if (newton_) {
        for (NewtonContact& c : newton_contacts_) {
            c.impulse = g[dim * c.dof + 1] - c.normal_momentum;
            for (int t = 0; t < dim - 1; ++t) c.slip[t] = v[dim * c.dof + tangential_axis<dim>(t)];
            if (!(c.impulse > 0.0)) continue;
            const double s = c.slip.norm();
            const double force = mu_ * c.impulse * friction_f1_over_x(s, eps_v_);
            if (c.held_impulse > 0.0) e += mu_ * c.held_impulse * friction_f0(s, eps_v_);
            for (int t = 0; t < dim - 1; ++t) g[dim * c.dof + tangential_axis<dim>(t)] += force * c.slip[t];
        }
        gradient_at_ = v;
        return e;
    }
    for (const Contact& c : contacts_)
        for (int t = 0; t < dim - 1; ++t) {
            const Eigen::Index i = dim * c.dof + tangential_axis<dim>(t);
            e += 0.5 * c.stiffness * v[i] * v[i];
            g[i] += c.stiffness * v[i];
        }
    return e;
}

template <int dim>
void FloorFrictionForm<dim>::prepare_hessian(const VecX& v) {
    std::vector<Triplet>& triplets = hessian_.triplets();
    triplets.clear();
    if (newton_) {
        if (gradient_at_.size() != v.size() || gradient_at_ != v)
            throw std::logic_error("FloorFrictionForm::prepare_hessian: the floor's impulses come from the gradient at "
                                   "the same v (call add_gradient there first)");
        for (NewtonContact& c : newton_contacts_) {
            c.coupling.setZero();
            c.held_impulse = c.impulse;
            if (!(c.impulse > 0.0)) continue;  // the floor pulls on nothing: no friction, one-sided in J
            // In the slip, the majorizer's curvature mu J f1(s) / s (not the friction's own, which is 0
            // along a 2D slip above eps_v: Newton then cycled between stick and slip, docs/solver.md).
            const double f1_over_s = friction_f1_over_x(c.slip.norm(), eps_v_);
            for (int t = 0; t < dim - 1; ++t) {
                const Eigen::Index i = dim * c.dof + tangential_axis<dim>(t);
                triplets.emplace_back(i, i, mu_ * c.impulse * f1_over_s);
            }
            c.coupling = mu_ * f1_over_s * c.slip;  // the force's derivative in J: mu f1 u / |u|
        }
        hessian_.keep_free(*free_);
        return;
    }
    for (const Contact& c : contacts_)
        for (int t = 0; t < dim - 1; ++t) {
            const Eigen::Index i = dim * c.dof + tangential_axis<dim>(t);
            triplets.emplace_back(i, i, c.stiffness);
        }
    hessian_.keep_free(*free_);
}

template <int dim>
double FloorFrictionForm<dim>::add_gradient_hessian(const VecX& v, VecX& g) {
    add_gradient(v, g);  // the impulses first: the Hessian's friction needs them
    prepare_hessian(v);  // and holds them for the value
    return value(v);
}

template <int dim>
void FloorFrictionForm<dim>::add_hessian_multiply(const VecX& d, VecX& out) const {
    hessian_.multiply(d, out);
    if (!newton_) return;
    const VecX& free = *free_;
    for (const NewtonContact& c : newton_contacts_) {
        const double dJ = (*held_product_)[dim * c.dof + 1];  // (H_psi d)_k,y: J's change along d
        for (int t = 0; t < dim - 1; ++t) {
            const Eigen::Index i = dim * c.dof + tangential_axis<dim>(t);
            out[i] += free[i] * c.coupling[t] * dJ;
        }
    }
}

template class FloorFrictionForm<2>;
template class FloorFrictionForm<3>;

}  // namespace pnet
