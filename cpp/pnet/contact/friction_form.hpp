#pragma once
// Lagged friction as a form (friction.hpp, docs/methods.md): dt D(v), with the pairs, their
// normal forces and tangent bases frozen at the start of the step. Its gradient is dt dD/dv and
// its Hessian dt d2D/dv2 (PSD); the pairs are fixed over the step, but they differ from step to
// step, so the Hessian is summed apart from the fixed-pattern forms.
#include "pnet/contact/friction.hpp"
#include "pnet/solver/triplet_hessian.hpp"

namespace pnet {

template <int dim>
class FrictionForm final : public TripletHessianForm {
public:
    explicit FrictionForm(const Friction<dim>& friction) : TripletHessianForm(dim), friction_(friction) {}

    /// The step's dt and the problem's 1 / 0 mask of free components (referenced).
    void begin_step(double dt, const VecX& free) {
        dt_ = dt;
        free_ = &free;
    }

    double value(const VecX& v) override { return dt_ * friction_.value(v); }
    double add_gradient(const VecX& v, VecX& g) override;
    void prepare_hessian(const VecX& v) override;

private:
    const Friction<dim>& friction_;
    const VecX* free_ = nullptr;
    double dt_ = 0.0;
};

}  // namespace pnet
