#include "pnet/material/cam_clay.hpp"

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
    return K_ * std::sinh(params_.xi * std::max(-a, 0.0));
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
    const double beta = params_.beta;
    const double J = Sigma.prod();
    const double p = -0.5 * K_ * (J * J - 1.0);
    const double p_0 = p0(a);
    const Vec<dim> ones = Vec<dim>::Ones();

    // Tips of the ellipse: purely volumetric states, Z = J_new^{1/d} 1.
    auto tip = [&](double J_new, ReturnBranch branch) {
        return ReturnResult<dim>{std::pow(J_new, 1.0 / dim) * ones, a + std::log(J / J_new), branch};
    };
    // p > p0 can only happen when p0 < p < K/2, so the square roots are real.
    if (p > p_0) return tip(std::sqrt(1.0 - 2.0 * p_0 / K_), ReturnBranch::CompressionTip);
    if (p < -beta * p_0) return tip(std::sqrt(1.0 + 2.0 * beta * p_0 / K_), ReturnBranch::TensionTip);

    const Vec<dim> b = Sigma.cwiseProduct(Sigma);
    const Vec<dim> dev_b = b - b.sum() / dim * ones;
    const double J_iso = std::pow(J, -2.0 / dim);  // J^{-2/d}
    const Vec<dim> s = mu_ * J_iso * dev_b;
    const double q2_factor = 0.5 * (6.0 - dim) * (1.0 + 2.0 * beta);  // y = q2_factor ||s||^2 + ...
    const double pressure_term = M_ * M_ * (p + beta * p_0) * (p - p_0);  // <= 0 between the tips
    if (q2_factor * s.squaredNorm() + pressure_term <= 0.0) return {Sigma, a, ReturnBranch::Elastic};

    // Ellipse: scale s at fixed p onto y = 0. y > 0 with pressure_term <= 0
    // implies ||s|| > 0.
    const double s_norm = s.norm();
    const Vec<dim> s_new = std::sqrt(-pressure_term / q2_factor) / s_norm * s;
    Vec<dim> Z;
    if (params_.variant == CamClayVariant::Exact) {
        // bbar_new = c 1 + s_new/mu with prod(bbar_new) = 1 (isochoric), J kept.
        const Vec<dim> t = s_new / mu_;
        double c;
        if constexpr (dim == 2) {
            c = std::sqrt(1.0 + t[0] * t[0]);  // (c + t0)(c - t0) = 1
        } else {
            // f(c) = prod(c + t_i) - 1 is increasing and convex for c > -min t,
            // and f(1 + max|t|) >= 0: Newton from there decreases monotonically.
            c = 1.0 + t.cwiseAbs().maxCoeff();
            for (int it = 0; it < 100; ++it) {
                const Vec<dim> ct = c * ones + t;
                const double f = ct.prod() - 1.0;
                const double df = ct[1] * ct[2] + ct[0] * ct[2] + ct[0] * ct[1];
                const double step = f / df;
                c -= step;
                if (std::abs(step) <= 1e-15 * c) break;
            }
        }
        Z = std::pow(J, 1.0 / dim) * (c * ones + t).cwiseSqrt();
    } else {
        // eq. 20 with consistent signs: b_new = J^{2/d}/mu s_new + tr(b)/d 1.
        Z = (s_new / (mu_ * J_iso) + b.sum() / dim * ones).cwiseSqrt();
    }

    // CD-MPM hardening: J_x is where the ray from the ellipse centre
    // (pc, 0) through the trial state (p, q) meets the ellipse. With u = p - pc
    // and R the ellipse's half-width, y = (1+2beta) q^2 + M^2 (u^2 - R^2).
    const double pc = 0.5 * (1.0 - beta) * p_0;
    const double R = 0.5 * (1.0 + beta) * p_0;
    const double u = p - pc;
    const double q2 = 0.5 * (6.0 - dim) * s.squaredNorm();
    const double t_ray = M_ * R / std::sqrt((1.0 + 2.0 * beta) * q2 + M_ * M_ * u * u);
    const double p_x = pc + t_ray * u;
    const double J_x = std::sqrt(std::max(1.0 - 2.0 * p_x / K_, 1e-12));
    return {Z, a + std::log(J / J_x), ReturnBranch::Ellipse};
}

namespace {

/// J - 1 = prod(1 + a_i) - 1 with a_i = Sigma_i - 1 (exact for Sigma_i near 1), expanded: as accurate near
/// F = I as the stress through the Hencky strain (expm1), without its log and exp.
template <int dim>
double j_minus_one(const Vec<dim>& Sigma) {
    const Vec<dim> a = Sigma.array() - 1.0;
    if constexpr (dim == 2) return a[0] + a[1] + a[0] * a[1];
    else return a[0] + a[1] + a[2] + a[0] * a[1] + a[0] * a[2] + a[1] * a[2] + a[0] * a[1] * a[2];
}

/// dev(b) with b = Sigma^2, from the differences b_i - b_j = (Sigma_i - Sigma_j)(Sigma_i + Sigma_j): accurate
/// where the singular values are close.
template <int dim>
Vec<dim> deviatoric_b(const Vec<dim>& Sigma) {
    Vec<dim> out = Vec<dim>::Zero();
    for (int i = 0; i < dim; ++i)
        for (int j = 0; j < dim; ++j)
            if (j != i) out[i] += (Sigma[i] - Sigma[j]) * (Sigma[i] + Sigma[j]);
    return out / dim;
}

}  // namespace

template <int dim>
Vec<dim> CamClay<dim>::project_tau(const Vec<dim>& Sigma, double p_0) const {
    if (params_.variant != CamClayVariant::Exact)
        throw std::logic_error("CamClay::project_tau: only the exact variant keeps J");
    const double beta = params_.beta;
    const double J_m1 = j_minus_one<dim>(Sigma);
    const double J = 1.0 + J_m1;
    const double p = -0.5 * K_ * J_m1 * (J_m1 + 2.0);
    const Vec<dim> ones = Vec<dim>::Ones();
    // The branches and their tests as in project().
    if (p > p_0) return -p_0 * ones;              // J_new^2 - 1 = -2 p0 / K
    if (p < -beta * p_0) return beta * p_0 * ones;  // J_new^2 - 1 = 2 beta p0 / K
    const double J_iso = dim == 2 ? 1.0 / J : std::pow(J, -2.0 / dim);
    const Vec<dim> s = mu_ * J_iso * deviatoric_b<dim>(Sigma);
    const double q2_factor = 0.5 * (6.0 - dim) * (1.0 + 2.0 * beta);
    const double pressure_term = M_ * M_ * (p + beta * p_0) * (p - p_0);
    if (q2_factor * s.squaredNorm() + pressure_term <= 0.0) return s - p * ones;
    return std::sqrt(-pressure_term / q2_factor) / s.norm() * s - p * ones;
}

template class CamClay<2>;
template class CamClay<3>;

}  // namespace pnet
