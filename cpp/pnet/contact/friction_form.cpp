#include "pnet/contact/friction_form.hpp"

namespace pnet {

template <int dim>
double FrictionForm<dim>::add_gradient(const VecX& v, VecX& g) {
    const double e = dt_ * friction_.value(v);
    friction_.add_gradient(v, dt_, g);
    return e;
}

template <int dim>
void FrictionForm<dim>::prepare_hessian(const VecX& v) {
    hessian_.triplets().clear();
    friction_.add_hessian(v, dt_, hessian_.triplets());
    hessian_.keep_free(*free_);
}

template class FrictionForm<2>;
template class FrictionForm<3>;

}  // namespace pnet
