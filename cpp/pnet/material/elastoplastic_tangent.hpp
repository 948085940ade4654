#pragma once
// The consistent tangent of the elastoplastic stress (docs/solver.md):
//
//   dPtilde/dF at F = U diag(Sigma) V^T, Ptilde(F, h) = U diag(tau(Z(Sigma, h))_i / Sigma_i) V^T,
//
// for any isotropic return mapping Z (the material library's or a learned one) and elasticity tau.
// The return-mapped Kirchhoff stress tau_Z(eps) = tau(Z(exp eps, h)) is differentiated in the
// principal log-strains by central differences (a return mapping has no closed-form derivative
// in general: Cam-Clay's scalar solve, a network); the rotational part comes from the difference
// quotients (tau_i - tau_j) / (Sigma_i - Sigma_j), exactly as for a hyperelastic energy
// (isotropic_dPdF). Non-associative flow (Drucker-Prager, Cam-Clay) makes dtau_Z/deps
// non-symmetric. Its symmetric part gives the tangent (projected to PSD on request); with keep_skew
// its skew part is added back, unprojected:
//
//   T = S + K,   S = [the tangent of sym(dtau_Z/deps)] (PSD when projected),   K = -K^T,
//
// which is the full Jacobian wherever the projection changed nothing, and positive real when S is
// PSD (x . T x = x . S x >= 0), so that a Newton direction solved with it still descends
// (docs/solver.md, "Which Hessian"). For StVK-Hencky with von Mises this is the Hessian of the ECI
// energy (AnalyticElastoplasticEnergy) up to the differencing error.
//
// It is what Newton needs on the true residual R(v) of an elastoplastic step (the learned energy's
// gradient at F = F0): a learned energy's own Hessian Hess N at F0 is never trained and is a
// smoothed secant of the stress over the training neighbourhood, so Newton steps with it converge
// only linearly (measured on metal_frame_2d: docs/solver.md).
#include <functional>

#include "pnet/material/elasticity.hpp"
#include "pnet/math/svd.hpp"
#include "pnet/math/types.hpp"

namespace pnet {

/// The singular values of Z(Sigma) for the particle's hardening state (the return mapping).
template <int dim>
using PrincipalReturnMap = std::function<Vec<dim>(const Vec<dim>& Sigma)>;

/// dPtilde/dF (row-major vec(F) basis) at the clamped polar SVD `svd`: its symmetric part,
/// projected to positive semi-definite when project_psd, plus its skew part when keep_skew. Costs
/// 2d + 1 return mappings.
template <int dim>
Tensor4<dim> elastoplastic_tangent(const PolarSVD<dim>& svd, const Elasticity<dim>& elasticity,
                                   const PrincipalReturnMap<dim>& return_map, bool project_psd, bool keep_skew = false);

/// The same in two halves, for return mappings evaluated in batches (a learned one): the 2d + 1
/// singular values at which the return mapping is needed (Sigma, then Sigma e^{+-delta} along each
/// axis), and the tangent from the returned ones, Z[k] = Z(stencil[k]).
template <int dim>
constexpr int kTangentStencil = 2 * dim + 1;
/// The stencil's central-difference step in log-strain: the truncation error (~delta^2 tau''') and the
/// round-off (~1e-16 |tau| / delta) balance near 1e-5; a return mapping's kink (the yield surface)
/// within delta of eps averages the two one-sided tangents.
inline constexpr double kTangentStencilStep = 1e-5;
template <int dim>
void tangent_stencil(const Vec<dim>& Sigma, Vec<dim>* stencil);
template <int dim>
Tensor4<dim> elastoplastic_tangent_from(const PolarSVD<dim>& svd, const Elasticity<dim>& elasticity, const Vec<dim>* Z,
                                        bool project_psd, bool keep_skew = false);

/// The same stencil in Hencky strain, log Sigma + (0, +-delta e_j), for return mappings that work
/// in strain (Material::elastoplastic_tangent: no log or exp per evaluation), and the tangent from
/// the return-mapped Kirchhoff stresses there, tau[k] = tau(Z(exp strain_stencil[k])).
template <int dim>
void tangent_strain_stencil(const Vec<dim>& eps, Vec<dim>* stencil);
template <int dim>
Tensor4<dim> elastoplastic_tangent_of_stress(const PolarSVD<dim>& svd, const Vec<dim>* tau, bool project_psd,
                                             bool keep_skew = false, const Mat<dim>* pair_quotient = nullptr);
/// The tangent from the return-mapped Kirchhoff stress tau and its derivative dtau/deps (not symmetric
/// for non-associative flow) where a return mapping gives them in closed form (the adjoint's exact
/// Drucker-Prager Jacobian, return_map_derivative.hpp); the stencil's version differences them and calls
/// this.
///
/// The rotational part takes the difference quotients (tau_i - tau_j) / (Sigma_i - Sigma_j); for singular
/// values within kCloseLog (1e-4 in log) of each other, where they cancel, `pair_quotient(i, j)` where the
/// caller gives it, formed without cancellation from what the return is, else their limit from dtau_deps.
/// That limit holds only where tau_Z is smooth across equal principal strains, and on Drucker-Prager's
/// cone it is not (the return scales the deviatoric strain by k = 1 - dgamma / |dev eps|, which depends on
/// the direction it comes from; the limit took the cone's derivative across its edge and was negative, and
/// near the cone's tip the stencil's points straddle the branches): the Drucker-Prager callers pass
/// 2 mu k (eps_i - eps_j) / (Sigma_i - Sigma_j).
/// The pair quotients of a return that scales the deviatoric Hencky strain by k, with StVK-Hencky elasticity
/// (Drucker-Prager, DruckerPrager::deviatoric_scale): (tau_i - tau_j) / (Sigma_i - Sigma_j) = k 2 mu (eps_i -
/// eps_j) / (Sigma_i - Sigma_j), exact for equal singular values too (zero on the diagonal).
template <int dim>
Mat<dim> deviatoric_scale_quotients(const Elasticity<dim>& elasticity, const Vec<dim>& Sigma, double k);

template <int dim>
Tensor4<dim> elastoplastic_tangent_of_derivative(const PolarSVD<dim>& svd, const Vec<dim>& tau, Mat<dim> dtau_deps,
                                                 bool project_psd, bool keep_skew = false,
                                                 const Mat<dim>* pair_quotient = nullptr);

}  // namespace pnet
