#pragma once
// Non-associative Cam-Clay plasticity for snow with the neo-Hookean snow
// elasticity (Wolper et al. 2019, CD-MPM; paper appendix A.2.2, eq. 17-20;
// docs/physics.md). Hardening state a = log of the plastic volume ratio (a < 0
// hardens); the networks see h = min(a, 0).
#include <string>

#include "pnet/material/elasticity.hpp"
#include "pnet/material/return_branch.hpp"

namespace pnet {

enum class CamClayVariant {
    /// Keep J (hence p) and project the deviatoric stress exactly onto the
    /// ellipse: the result lies on the yield surface and Z is idempotent.
    Exact,
    /// The paper's eq. 20 (as in Ziran): keeps tr(b) instead of J, on the
    /// surface only to first order, not idempotent.
    Paper,
};

std::string to_string(CamClayVariant variant);
CamClayVariant cam_clay_variant_from_string(const std::string& name);

struct CamClayParams {
    double friction_angle_deg = 45.0;  // phi_f, degrees, in (0, 90)
    double xi = 0.5;                   // hardening factor: p0 = K sinh(xi max(-a, 0))
    double beta = 0.3;                 // cohesion: tension tip at -beta p0
    CamClayVariant variant = CamClayVariant::Exact;

    void validate() const;
};

/// The directions Cam-Clay's derivatives are taken in (return_map_derivative.cpp, on math/dual2.hpp's Dual1):
/// the singular values, then the hardening a, xi, beta and M.
template <int dim>
constexpr int kCamClayDirections = dim + 4;

template <int dim>
class CamClay {
public:
    /// `elasticity` must be the neo-Hookean snow form (the projection keeps its
    /// pressure p = -K/2 (J^2 - 1) and deviatoric stress s = mu J^{-2/d} dev(b)).
    CamClay(const CamClayParams& params, const Elasticity<dim>& elasticity);

    /// Z(Sigma, a) and the CD-MPM hardening update a += log(J_trial / J_x).
    ReturnResult<dim> project(const Vec<dim>& Sigma, double a) const;
    /// The return-mapped principal Kirchhoff stress tau(Z(Sigma)) of the exact variant, given
    /// p0 = p0(a), without forming Z: the projection keeps J (hence tau's volumetric part -p) and
    /// scales the deviatoric stress s onto the ellipse, so tau = s_new - p 1 there, s - p 1 inside, and
    /// -p0 1 / beta p0 1 at the compression / tension tip. What the consistent tangent's stencil
    /// evaluates 2d + 1 times per yielding point (Material::elastoplastic_tangent): no exp, log or
    /// expm1. Throws std::logic_error for the paper's variant (it does not keep J).
    Vec<dim> project_tau(const Vec<dim>& Sigma, double p0) const;

    /// y = (6-d)/2 (1 + 2 beta) ||s||^2 + M^2 (p + beta p0)(p - p0), Pa^2;
    /// the elastic region is y <= 0 with -beta p0 <= p <= p0.
    double yield_function(const Vec<dim>& Sigma, double a) const;
    /// (6-d)/2 (1+2 beta) ||s||^2 + M^2 (|p| + beta p0)(|p| + p0), Pa^2: the
    /// size of the terms of y, for relative tolerances.
    double yield_scale(const Vec<dim>& Sigma, double a) const;

    /// p0 = K sinh(xi max(-a, 0)), Pa.
    double p0(double a) const;

    /// What project() and project_tau() compute, on any scalar type S (double, or the forward-mode dual
    /// numbers their derivatives are taken with: material/return_map_derivative.cpp), with the parameters
    /// xi, beta and M as arguments. `scale` is the factor the projection scales the deviatoric stress by
    /// (1 inside, 0 at the tips, ||s_new|| / ||s|| on the ellipse): Z_i - Z_j = scale (Sigma_i^2 - Sigma_j^2) /
    /// (Z_i + Z_j) and tau_i - tau_j = scale mu J^{-2/d} (Sigma_i^2 - Sigma_j^2), the pair quotients without
    /// cancellation. Instantiated for double and for return_map_derivative.cpp's dual numbers.
    template <typename S>
    struct Projected {
        Eigen::Matrix<S, dim, 1> Z;
        S hardening, scale;
        ReturnBranch branch;
    };
    template <typename S>
    Projected<S> project_with(const Eigen::Matrix<S, dim, 1>& Sigma, const S& a, const S& xi, const S& beta,
                              const S& M) const;
    template <typename S>
    Eigen::Matrix<S, dim, 1> project_tau_with(const Eigen::Matrix<S, dim, 1>& Sigma, const S& p0, const S& beta,
                                              const S& M, S* scale = nullptr) const;
    /// p0 on any scalar type, xi an argument.
    template <typename S>
    S p0_with(const S& a, const S& xi) const;
    /// M = sqrt(2/3) 2 sin(phi)/(3 - sin(phi)) d / sqrt(2/(6-d)).
    double M() const { return M_; }

    const CamClayParams& params() const { return params_; }

private:
    CamClayParams params_;
    double mu_, K_, M_;
};

}  // namespace pnet
