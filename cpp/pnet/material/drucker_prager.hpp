#pragma once
// Drucker-Prager plasticity for sand with StVK-Hencky elasticity (Klar et al.
// 2016; paper appendix A.2.1, eq. 15-16; docs/physics.md). No hardening.
#include "pnet/material/elasticity.hpp"
#include "pnet/material/return_branch.hpp"

namespace pnet {

struct DruckerPragerParams {
    double friction_angle_deg = 30.0;  // phi_f, degrees, in (0, 90)

    /// alpha = sqrt(2/3) 2 sin(phi) / (3 - sin(phi)) (Klar et al.; the paper's
    /// typeset formula puts the square root over the whole product).
    double alpha() const;
    void validate() const;
};

template <int dim>
class DruckerPrager {
public:
    /// `elasticity` must be StVK-Hencky: the projection is exact in Hencky strain.
    DruckerPrager(const DruckerPragerParams& params, const Elasticity<dim>& elasticity);

    /// Z(Sigma): tr(eps) > 0 -> Z = 1 (apex); otherwise
    /// dgamma = ||dev eps|| + alpha (d lambda + 2 mu) tr(eps) / (2 mu) and
    /// Z = exp(eps - dgamma dev(eps)/||dev eps||) when dgamma > 0 (cone).
    /// The hardening argument is passed through unchanged.
    ReturnResult<dim> project(const Vec<dim>& Sigma, double hardening) const;
    /// The same projection in Hencky strain: log Z from eps = log Sigma (no log or exp: the
    /// consistent tangent evaluates it 2d + 1 times per point).
    Vec<dim> project_strain(const Vec<dim>& eps, ReturnBranch* branch = nullptr) const;
    /// k with dev(log Z) = k dev(eps) on the branch project_strain takes: 1 inside the cone, 1 - dgamma /
    /// ||dev eps|| on it, 0 at the apex. So tau_i - tau_j = k 2 mu (eps_i - eps_j), the rotational part of the
    /// consistent tangent without cancellation where principal strains nearly coincide.
    double deviatoric_scale(const Vec<dim>& eps) const;
    /// project_strain with its Jacobian d log Z / d eps on the branch it takes, that branch's
    /// deviatoric_scale, and `margin`: how far eps is from the branches' boundaries (tr eps = 0, the
    /// apex's; ||dev eps|| + c tr eps = 0, the cone's surface) in the largest change of one principal
    /// strain that could cross one, so that every point within `margin` of eps in each principal strain
    /// takes the same branch. On the cone, with n = dev(eps) / ||dev eps||, c = alpha (d lambda + 2 mu) /
    /// (2 mu) and k = -c tr(eps) / ||dev eps||,
    ///   log Z = tr(eps) / d 1 - c tr(eps) n,   d log Z / d eps = 1 1^T / d - c n 1^T + k (I - 1 1^T / d - n n^T).
    Vec<dim> project_strain(const Vec<dim>& eps, Mat<dim>& jacobian, double& deviatoric_scale, double& margin,
                            ReturnBranch* branch = nullptr) const;

    /// y(tau) = ||dev tau|| + alpha tr(tau), Pa; <= 0 inside the elastic cone.
    double yield_function(const Vec<dim>& tau) const;
    /// ||dev tau|| + alpha |tr tau|: the size of the terms that cancel on the
    /// surface, for relative tolerances on yield_function().
    double yield_scale(const Vec<dim>& tau) const;

    const DruckerPragerParams& params() const { return params_; }

private:
    DruckerPragerParams params_;
    double alpha_, mu_, lambda_;
};

}  // namespace pnet
