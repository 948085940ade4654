#pragma once
// The IPC barrier as a form (docs/methods.md): B(x(v)) with x(v) = x^n + dt v, the nodal
// positions a step of velocities v reaches, over a ContactPotential (collisions/
// contact_potential.hpp: the mesh's pairs and the ground). Its gradient in v is dt dB/dx, its
// Hessian dt^2 d2B/dx2 (PSD-projected per pair), and max_step() the CCD filter on the motion
// x -> x + dt d, so that no iterate intersects. The pairs change with x, so its Hessian is
// summed apart from the fixed-pattern forms (Form::changing_pattern()).
#include <vector>

#include "pnet/contact/collisions/contact_potential.hpp"
#include "pnet/solver/triplet_hessian.hpp"

namespace pnet {

template <int dim>
class BarrierForm final : public TripletHessianForm {
public:
    explicit BarrierForm(const ContactPotential<dim>& contact) : TripletHessianForm(dim), contact_(contact) {}

    /// The step: positions x^n (referenced, as is `free`, the problem's 1 / 0 mask) and dt.
    void begin_step(const std::vector<Vec<dim>>& x_start, double dt, const VecX& free);
    /// x^n + dt v.
    void positions(const VecX& v, std::vector<Vec<dim>>& x) const;

    double value(const VecX& v) override;
    double add_gradient(const VecX& v, VecX& g) override;
    void prepare_hessian(const VecX& v) override;
    double max_step(const VecX& v, const VecX& d) override;

    /// Project the pairs' Hessians to PSD (default; false: exact, for derivative checks).
    void set_project_psd(bool project) { project_psd_ = project; }
    /// CCD queries of max_step() since begin_step(), and how many of them shortened the step.
    int ccd_queries() const { return ccd_queries_; }
    int ccd_limited() const { return ccd_limited_; }

private:
    const ContactPotential<dim>& contact_;
    const std::vector<Vec<dim>>* x_start_ = nullptr;
    const VecX* free_ = nullptr;
    double dt_ = 0.0;
    std::vector<Vec<dim>> x_, dx_;
    bool project_psd_ = true;
    int ccd_queries_ = 0, ccd_limited_ = 0;
};

}  // namespace pnet
