#include "pnet/mpm/floor_friction_form.hpp"

namespace pnet {

namespace {

// The tangential axes: every axis but y, the floor's normal.
template <int dim>
constexpr int tangential_axis(int t) {
    return t == 0 ? 0 : 2;
}

}  // namespace

template <int dim>
double FloorFrictionForm<dim>::value(const VecX& v) {
    double e = 0.0;
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
    for (const Contact& c : contacts_)
        for (int t = 0; t < dim - 1; ++t) {
            const Eigen::Index i = dim * c.dof + tangential_axis<dim>(t);
            e += 0.5 * c.stiffness * v[i] * v[i];
            g[i] += c.stiffness * v[i];
        }
    return e;
}

template <int dim>
void FloorFrictionForm<dim>::prepare_hessian(const VecX& /*v*/) {
    std::vector<Triplet>& triplets = hessian_.triplets();
    triplets.clear();
    for (const Contact& c : contacts_)
        for (int t = 0; t < dim - 1; ++t) {
            const Eigen::Index i = dim * c.dof + tangential_axis<dim>(t);
            triplets.emplace_back(i, i, c.stiffness);
        }
    hessian_.keep_free(*free_);
}

template class FloorFrictionForm<2>;
template class FloorFrictionForm<3>;

}  // namespace pnet
