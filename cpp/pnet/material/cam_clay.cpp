#include "pnet/material/cam_clay.hpp"

#include "pnet/math/dual2.hpp"

#include <cmath>
#include <sstream>
#include <stdexcept>

namespace pnet {

std::string to_string(CamClayVariant variant) {
    return variant == CamClayVariant::Exact ? "exact" : "paper";
}

CamClayVariant cam_clay_variant_from_string(const std::string& name) {
    if (name == "exact") return CamClayVariant::Exact;
    if (name == "paper") return CamClayVariant::Paper;
    throw std::invalid_argument("unknown cam_clay variant '" + name + "' (expected exact or paper)");
}

void CamClayParams::validate() const {
    auto fail = [](const char* field, double value, const char* expected) {
        std::ostringstream msg;
        msg << "cam_clay parameter " << field << " = " << value << " must be " << expected;
        throw std::invalid_argument(msg.str());
    };
    if (!std::isfinite(friction_angle_deg) || friction_angle_deg <= 0.0 || friction_angle_deg >= 90.0)
        fail("friction_angle_deg", friction_angle_deg, "in (0, 90) degrees");
    if (!std::isfinite(xi) || xi < 0.0) fail("xi", xi, "finite and >= 0");
    if (!std::isfinite(beta) || beta < 0.0) fail("beta", beta, "finite and >= 0");
}

template <int dim>
CamClay<dim>::CamClay(const CamClayParams& params, const Elasticity<dim>& elasticity)
    : params_(params), mu_(elasticity.mu()), K_(elasticity.K()) {
    params_.validate();
    if (elasticity.model() != ElasticityModel::NeoHookeanSnow)
        throw std::invalid_argument("plasticity 'cam_clay' requires elasticity 'neo_hookean_snow', got '" +
                                    to_string(elasticity.model()) + "'");
    const double s = std::sin(params_.friction_angle_deg * M_PI / 180.0);
    M_ = std::sqrt(2.0 / 3.0) * 2.0 * s / (3.0 - s) * dim / std::sqrt(2.0 / (6.0 - dim));
}

template <int dim>
double CamClay<dim>::p0(double a) const {
    return p0_with<double>(a, params_.xi);
}

template <int dim>
template <typename S>
S CamClay<dim>::p0_with(const S& a, const S& xi) const {
    using std::sinh;
    return K_ * sinh(xi * (-a < 0.0 ? S(0.0) : S(-a)));  // K sinh(xi max(-a, 0))
}

template <int dim>
double CamClay<dim>::yield_function(const Vec<dim>& Sigma, double a) const {
    const double J = Sigma.prod();
    const Vec<dim> b = Sigma.cwiseProduct(Sigma);
    const Vec<dim> s = mu_ * std::pow(J, -2.0 / dim) * (b - b.sum() / dim * Vec<dim>::Ones());
    const double p = -0.5 * K_ * (J * J - 1.0);  // compression positive
    const double p_0 = p0(a);
    const double beta = params_.beta;
    return 0.5 * (6.0 - dim) * (1.0 + 2.0 * beta) * s.squaredNorm() + M_ * M_ * (p + beta * p_0) * (p - p_0);
}

template <int dim>
double CamClay<dim>::yield_scale(const Vec<dim>& Sigma, double a) const {
    const double J = Sigma.prod();
    const Vec<dim> b = Sigma.cwiseProduct(Sigma);
    const Vec<dim> s = mu_ * std::pow(J, -2.0 / dim) * (b - b.sum() / dim * Vec<dim>::Ones());
    const double p = std::abs(0.5 * K_ * (J * J - 1.0));
    const double p_0 = p0(a);
    const double beta = params_.beta;
    return 0.5 * (6.0 - dim) * (1.0 + 2.0 * beta) * s.squaredNorm() + M_ * M_ * (p + beta * p_0) * (p + p_0);
}

template <int dim>
ReturnResult<dim> CamClay<dim>::project(const Vec<dim>& Sigma, double a) const {
    const Projected<double> r = project_with<double>(Sigma, a, params_.xi, params_.beta, M_);
    return {r.Z, r.hardening, r.branch};
}

template <int dim>
template <typename S>
typename CamClay<dim>::template Projected<S> CamClay<dim>::project_with(const Eigen::Matrix<S, dim, 1>& Sigma,
                                                                         const S& a, const S& xi, const S& beta,
                                                                         const S& M) const {
    using std::log;
    using std::pow;
    using std::sqrt;
    using Vector = Eigen::Matrix<S, dim, 1>;
    const S J = Sigma.prod();
    const S p = -0.5 * K_ * (J * J - 1.0);
    const S p_0 = p0_with<S>(a, xi);
    const Vector ones = Vector::Ones();

    // Tips of the ellipse: purely volumetric states, Z = J_new^{1/d} 1.
    auto tip = [&](const S& J_new, ReturnBranch branch) {
        return Projected<S>{S(pow(J_new, 1.0 / dim)) * ones, a + log(J / J_new), S(0.0), branch};
    };
    // p > p0 can only happen when p0 < p < K/2, so the square roots are real.
    if (p > p_0) return tip(sqrt(1.0 - 2.0 * p_0 / K_), ReturnBranch::CompressionTip);
    if (p < -beta * p_0) return tip(sqrt(1.0 + 2.0 * beta * p_0 / K_), ReturnBranch::TensionTip);

    const Vector b = Sigma.cwiseProduct(Sigma);
    const Vector dev_b = b - S(b.sum() / dim) * ones;
    const S J_iso = pow(J, -2.0 / dim);  // J^{-2/d}
    const Vector s = S(mu_ * J_iso) * dev_b;
    const S q2_factor = 0.5 * (6.0 - dim) * (1.0 + 2.0 * beta);  // y = q2_factor ||s||^2 + ...
    const S pressure_term = M * M * (p + beta * p_0) * (p - p_0);  // <= 0 between the tips
    if (q2_factor * s.squaredNorm() + pressure_term <= 0.0) return {Sigma, a, S(1.0), ReturnBranch::Elastic};

    // Ellipse: scale s at fixed p onto y = 0. y > 0 with pressure_term <= 0
    // implies ||s|| > 0.
    const S s_norm = sqrt(s.squaredNorm());
    const S scale = sqrt(-pressure_term / q2_factor) / s_norm;
    const Vector s_new = scale * s;
    Vector Z;
    if (params_.variant == CamClayVariant::Exact) {
        // bbar_new = c 1 + s_new/mu with prod(bbar_new) = 1 (isochoric), J kept.
        const Vector t = s_new / mu_;
        S c;
        if constexpr (dim == 2) {
            c = sqrt(1.0 + t[0] * t[0]);  // (c + t0)(c - t0) = 1
        } else {
            // f(c) = prod(c + t_i) - 1 is increasing and convex for c > -min t,
            // and f(1 + max|t|) >= 0: Newton from there decreases monotonically. (Its dual part converges
            // with its value: at the root the iteration's derivative in t is the implicit function's.)
            S largest = t[0] < 0.0 ? S(-t[0]) : t[0];
            for (int i = 1; i < dim; ++i) {
                const S magnitude = t[i] < 0.0 ? S(-t[i]) : t[i];
                if (largest < magnitude) largest = magnitude;
            }
            c = 1.0 + largest;
            for (int it = 0; it < 100; ++it) {
                const Vector ct = c * ones + t;
                const S f = ct.prod() - 1.0;
                const S df = ct[1] * ct[2] + ct[0] * ct[2] + ct[0] * ct[1];
                const S step = f / df;
                c -= step;
                if ((step < 0.0 ? S(-step) : step) <= 1e-15 * c) break;
            }
        }
        const S root = pow(J, 1.0 / dim);
        for (int i = 0; i < dim; ++i) Z[i] = root * sqrt(c + t[i]);
    } else {
        // eq. 20 with consistent signs: b_new = J^{2/d}/mu s_new + tr(b)/d 1.
        const Vector b_new = s_new / (mu_ * J_iso) + S(b.sum() / dim) * ones;
        for (int i = 0; i < dim; ++i) Z[i] = sqrt(b_new[i]);
    }

    // CD-MPM hardening: J_x is where the ray from the ellipse centre
    // (pc, 0) through the trial state (p, q) meets the ellipse. With u = p - pc
    // and R the ellipse's half-width, y = (1+2beta) q^2 + M^2 (u^2 - R^2).
    const S pc = 0.5 * (1.0 - beta) * p_0;
    const S R = 0.5 * (1.0 + beta) * p_0;
    const S u = p - pc;
    const S q2 = 0.5 * (6.0 - dim) * s.squaredNorm();
    const S t_ray = M * R / sqrt((1.0 + 2.0 * beta) * q2 + M * M * u * u);
    const S p_x = pc + t_ray * u;
    const S J_x2 = 1.0 - 2.0 * p_x / K_;
    const S J_x = sqrt(J_x2 < 1e-12 ? S(1e-12) : J_x2);  // sqrt(max(1 - 2 p_x / K, 1e-12))
    return {Z, a + log(J / J_x), scale, ReturnBranch::Ellipse};
}

namespace {

/// J - 1 = prod(1 + a_i) - 1 with a_i = Sigma_i - 1 (exact for Sigma_i near 1), expanded: as accurate near
/// F = I as the stress through the Hencky strain (expm1), without its log and exp.
template <int dim, typename S>
S j_minus_one(const Eigen::Matrix<S, dim, 1>& Sigma) {
    const Eigen::Matrix<S, dim, 1> a = Sigma.array() - S(1.0);
    if constexpr (dim == 2) return a[0] + a[1] + a[0] * a[1];
    else return a[0] + a[1] + a[2] + a[0] * a[1] + a[0] * a[2] + a[1] * a[2] + a[0] * a[1] * a[2];
}

/// dev(b) with b = Sigma^2, from the differences b_i - b_j = (Sigma_i - Sigma_j)(Sigma_i + Sigma_j): accurate
/// where the singular values are close.
template <int dim, typename S>
Eigen::Matrix<S, dim, 1> deviatoric_b(const Eigen::Matrix<S, dim, 1>& Sigma) {
    Eigen::Matrix<S, dim, 1> out = Eigen::Matrix<S, dim, 1>::Zero();
    for (int i = 0; i < dim; ++i)
        for (int j = 0; j < dim; ++j)
            if (j != i) out[i] += (Sigma[i] - Sigma[j]) * (Sigma[i] + Sigma[j]);
    return out / S(dim);
}

}  // namespace

template <int dim>
Vec<dim> CamClay<dim>::project_tau(const Vec<dim>& Sigma, double p_0) const {
    if (params_.variant != CamClayVariant::Exact)
        throw std::logic_error("CamClay::project_tau: only the exact variant keeps J");
    return project_tau_with<double>(Sigma, p_0, params_.beta, M_);
}

template <int dim>
template <typename S>
Eigen::Matrix<S, dim, 1> CamClay<dim>::project_tau_with(const Eigen::Matrix<S, dim, 1>& Sigma, const S& p_0,
                                                         const S& beta, const S& M, S* scale) const {
    using std::pow;
    using std::sqrt;
    using Vector = Eigen::Matrix<S, dim, 1>;
    const S J_m1 = j_minus_one<dim, S>(Sigma);
    const S J = 1.0 + J_m1;
    const S p = -0.5 * K_ * J_m1 * (J_m1 + 2.0);
    const Vector ones = Vector::Ones();
    S k(1.0);
    Vector tau;
    // The branches and their tests as in project().
    if (p > p_0) {
        k = 0.0;
        tau = S(-p_0) * ones;  // J_new^2 - 1 = -2 p0 / K
    } else if (p < -beta * p_0) {
        k = 0.0;
        tau = S(beta * p_0) * ones;  // J_new^2 - 1 = 2 beta p0 / K
    } else {
        const S J_iso = dim == 2 ? S(1.0 / J) : S(pow(J, -2.0 / dim));
        const Vector s = S(mu_ * J_iso) * deviatoric_b<dim, S>(Sigma);
        const S q2_factor = 0.5 * (6.0 - dim) * (1.0 + 2.0 * beta);
        const S pressure_term = M * M * (p + beta * p_0) * (p - p_0);
        const S s2 = s.squaredNorm();
        const bool inside = q2_factor * s2 + pressure_term <= 0.0;  // tested once: one branch for tau and k
        if (!inside) k = sqrt(-pressure_term / q2_factor) / sqrt(s2);
        tau = (inside ? s : Vector(k * s)) - S(p) * ones;
    }
    if (scale) *scale = k;
    return tau;
}

template class CamClay<2>;
template class CamClay<3>;
template CamClay<2>::Projected<double> CamClay<2>::project_with<double>(const Vec<2>&, const double&, const double&,
                                                                         const double&, const double&) const;
template CamClay<3>::Projected<double> CamClay<3>::project_with<double>(const Vec<3>&, const double&, const double&,
                                                                         const double&, const double&) const;
// Their dual instantiations, for the derivatives (return_map_derivative.cpp).
#define PNET_CAM_CLAY_DUAL(dim)                                                                                     \
    template CamClay<dim>::Projected<Dual1<kCamClayDirections<dim>>>                                                 \
    CamClay<dim>::project_with<Dual1<kCamClayDirections<dim>>>(                                                      \
        const Eigen::Matrix<Dual1<kCamClayDirections<dim>>, dim, 1>&, const Dual1<kCamClayDirections<dim>>&,           \
        const Dual1<kCamClayDirections<dim>>&, const Dual1<kCamClayDirections<dim>>&,                                  \
        const Dual1<kCamClayDirections<dim>>&) const;                                                                \
    template Eigen::Matrix<Dual1<kCamClayDirections<dim>>, dim, 1>                                                   \
    CamClay<dim>::project_tau_with<Dual1<kCamClayDirections<dim>>>(                                                  \
        const Eigen::Matrix<Dual1<kCamClayDirections<dim>>, dim, 1>&, const Dual1<kCamClayDirections<dim>>&,           \
        const Dual1<kCamClayDirections<dim>>&, const Dual1<kCamClayDirections<dim>>&,                                  \
        Dual1<kCamClayDirections<dim>>*) const;                                                               \
    template Dual1<kCamClayDirections<dim>> CamClay<dim>::p0_with<Dual1<kCamClayDirections<dim>>>(                   \
        const Dual1<kCamClayDirections<dim>>&, const Dual1<kCamClayDirections<dim>>&) const;
PNET_CAM_CLAY_DUAL(2)
PNET_CAM_CLAY_DUAL(3)
#undef PNET_CAM_CLAY_DUAL

}  // namespace pnet
