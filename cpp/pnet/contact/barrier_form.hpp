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

/// The CCD queries of a barrier form's max_step() since its step began, and how many of them
/// shortened the step.
struct CcdCount {
    int queries = 0, limited = 0;
    /// Counts one query that allowed the fraction t; returns t.
    double record(double t) {
        ++queries;
        limited += t < 1.0;
        return t;
    }
};

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
    const CcdCount& ccd() const { return ccd_; }

private:
    const ContactPotential<dim>& contact_;
    const std::vector<Vec<dim>>* x_start_ = nullptr;
    const VecX* free_ = nullptr;
    double dt_ = 0.0;
    std::vector<Vec<dim>> x_, dx_;
    bool project_psd_ = true;
    CcdCount ccd_;
};

}  // namespace pnet
