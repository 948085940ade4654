#pragma once
// von Mises plasticity with linear hardening for metal (paper appendix A.2.3
// and A.2.4; docs/physics.md). Hardening state h = tau_Y / (2 mu) >= 0, updated by
// h += xi dgamma (eq. 23).
//
// The yield surface ||dev tau|| = 2 mu h is the same for every elasticity; the
// projection follows the volume-preserving path eps - dgamma n,
// n = dev(eps)/||dev(eps)||. With StVK-Hencky ||dev tau|| = 2 mu ||dev eps||
// and dgamma is closed form (eq. 22); with any other model dgamma is the
// smallest root of y along the path, found by a scan and safeguarded Newton.
#include "pnet/material/elasticity.hpp"
#include "pnet/material/return_branch.hpp"

namespace pnet {

struct VonMisesParams {
    double hardening_coefficient = 0.1;  // xi in tau_Y += 2 mu xi dgamma, >= 0

    void validate() const;
};

template <int dim>
class VonMises {
public:
    VonMises(const VonMisesParams& params, const Elasticity<dim>& elasticity);

    /// Z(Sigma, h) and h_new = h + xi dgamma. Throws std::invalid_argument if h < 0.
    ReturnResult<dim> project(const Vec<dim>& Sigma, double h) const;
    /// log Z from eps = log Sigma, without the hardening update (the consistent tangent's
    /// 2d + 1 evaluations at a fixed h; no log or exp in the closed form). Requires h >= 0.
    Vec<dim> project_strain(const Vec<dim>& eps, double h) const;

    /// y(Sigma, h) = ||dev tau(Sigma)||^2 - (2 mu h)^2, Pa^2 (eq. 25).
    double yield_function(const Vec<dim>& Sigma, double h) const;
    /// ||dev tau||^2 + (2 mu h)^2, Pa^2, for relative tolerances.
    double yield_scale(const Vec<dim>& Sigma, double h) const;

    /// True when the projection is the closed form of StVK-Hencky.
    bool closed_form() const { return elasticity_.model() == ElasticityModel::StvkHencky; }

    const VonMisesParams& params() const { return params_; }

private:
    /// dgamma >= 0 of the projection of eps (0 inside the yield surface).
    double plastic_multiplier(const Vec<dim>& eps, const Vec<dim>& eps_hat, double L, double h) const;
    /// Smallest root in (0, L] of y along eps - dg n (y(0) > 0 >= y(L)).
    double solve_path(const Vec<dim>& eps, const Vec<dim>& n, double L, double h) const;

    VonMisesParams params_;
    Elasticity<dim> elasticity_;
};

}  // namespace pnet
