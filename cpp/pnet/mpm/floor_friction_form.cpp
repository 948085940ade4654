#include "pnet/mpm/floor_friction_form.hpp"

#include "pnet/contact/friction.hpp"

namespace pnet {

namespace {

// The tangential components of node `dof` (every axis but y, the floor's normal).
template <int dim>
Eigen::Matrix<double, dim - 1, 1> slip(const VecX& v, int dof) {
    Eigen::Matrix<double, dim - 1, 1> u;
    for (int a = 0, t = 0; a < dim; ++a)
        if (a != 1) u[t++] = v[dim * dof + a];
    return u;
}

template <int dim>
constexpr int axis_of(int t) {  // tangential index -> axis
    return t == 0 ? 0 : 2;
}

}  // namespace

template <int dim>
double FloorFrictionForm<dim>::value(const VecX& v) {
    double e = 0.0;
    for (const Contact& c : contacts_) e += c.weight * friction_f0(slip<dim>(v, c.dof).norm(), eps_v_);
    return e;
}

template <int dim>
double FloorFrictionForm<dim>::add_gradient(const VecX& v, VecX& g) {
    double e = 0.0;
    for (const Contact& c : contacts_) {
        const auto u = slip<dim>(v, c.dof);
        const double x = u.norm();
        e += c.weight * friction_f0(x, eps_v_);
        const double scale = c.weight * friction_f1_over_x(x, eps_v_);
        for (int t = 0; t < dim - 1; ++t) g[dim * c.dof + axis_of<dim>(t)] += scale * u[t];
    }
    return e;
}

template <int dim>
void FloorFrictionForm<dim>::prepare_hessian(const VecX& v) {
    std::vector<Triplet>& triplets = hessian_.triplets();
    triplets.clear();
    for (const Contact& c : contacts_) {
        const Eigen::Matrix<double, dim - 1, dim - 1> H = c.weight * friction_slip_hessian<dim - 1>(slip<dim>(v, c.dof), eps_v_);
        for (int s = 0; s < dim - 1; ++s)
            for (int t = 0; t < dim - 1; ++t)
                triplets.emplace_back(dim * c.dof + axis_of<dim>(s), dim * c.dof + axis_of<dim>(t), H(s, t));
    }
    hessian_.keep_free(*free_);
}

template class FloorFrictionForm<2>;
template class FloorFrictionForm<3>;

}  // namespace pnet
