#include "pnet/contact/barrier_form.hpp"

#include <algorithm>

namespace pnet {

template <int dim>
void BarrierForm<dim>::begin_step(const std::vector<Vec<dim>>& x_start, double dt, const VecX& free) {
    x_start_ = &x_start;
    dt_ = dt;
    free_ = &free;
    ccd_ = CcdCount{};
}

template <int dim>
void BarrierForm<dim>::positions(const VecX& v, std::vector<Vec<dim>>& x) const {
    const std::vector<Vec<dim>>& x_start = *x_start_;
    x.resize(x_start.size());
    for (std::size_t i = 0; i < x.size(); ++i) x[i] = x_start[i] + dt_ * v.template segment<dim>(dim * i);
}

template <int dim>
double BarrierForm<dim>::value(const VecX& v) {
    positions(v, x_);
    return contact_.value(x_);
}

template <int dim>
double BarrierForm<dim>::add_gradient(const VecX& v, VecX& g) {
    positions(v, x_);
    return contact_.add_gradient(x_, dt_, g);
}

template <int dim>
void BarrierForm<dim>::prepare_hessian(const VecX& v) {
    positions(v, x_);
    hessian_.triplets().clear();
    contact_.add_hessian(x_, dt_ * dt_, hessian_.triplets(), project_psd_);
    hessian_.keep_free(*free_);  // fixed components keep only their mass
}

template <int dim>
double BarrierForm<dim>::max_step(const VecX& v, const VecX& d) {
    positions(v, x_);
    dx_.resize(x_.size());
    for (std::size_t i = 0; i < x_.size(); ++i) dx_[i] = dt_ * d.template segment<dim>(dim * i);
    return ccd_.record(contact_.max_step(x_, dx_));
}

template class BarrierForm<2>;
template class BarrierForm<3>;

}  // namespace pnet
