#include "pnet/material/von_mises.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace pnet {

void VonMisesParams::validate() const {
    if (!std::isfinite(hardening_coefficient) || hardening_coefficient < 0.0) {
        std::ostringstream msg;
        msg << "von_mises parameter hardening_coefficient = " << hardening_coefficient << " must be finite and >= 0";
        throw std::invalid_argument(msg.str());
    }
}

template <int dim>
VonMises<dim>::VonMises(const VonMisesParams& params, const Elasticity<dim>& elasticity)
    : params_(params), elasticity_(elasticity) {
    params_.validate();
}

template <int dim>
double VonMises<dim>::yield_function(const Vec<dim>& Sigma, double h) const {
    const Vec<dim> t = elasticity_.tau(Sigma);
    const double radius = 2.0 * elasticity_.mu() * h;
    return (t - t.sum() / dim * Vec<dim>::Ones()).squaredNorm() - radius * radius;
}

template <int dim>
double VonMises<dim>::yield_scale(const Vec<dim>& Sigma, double h) const {
    const Vec<dim> t = elasticity_.tau(Sigma);
    const double radius = 2.0 * elasticity_.mu() * h;
    return (t - t.sum() / dim * Vec<dim>::Ones()).squaredNorm() + radius * radius;
}

template <int dim>
double VonMises<dim>::solve_path(const Vec<dim>& eps, const Vec<dim>& n, double L, double h) const {
    const double radius = 2.0 * elasticity_.mu() * h;
    const Vec<dim> ones = Vec<dim>::Ones();
    // g(dg) = ||dev tau||^2 - r^2 and dg/d(dg) = -2 dev(tau) . (dtau/deps n).
    auto g = [&](double dg, double* slope) {
        const Vec<dim> Sigma = (eps - dg * n).array().exp().matrix();
        const Vec<dim> t = elasticity_.tau(Sigma);
        const Vec<dim> dev_t = t - t.sum() / dim * ones;
        if (slope) *slope = -2.0 * dev_t.dot(elasticity_.dtau_deps(Sigma) * n);
        return dev_t.squaredNorm() - radius * radius;
    };

    // Bracket the first sign change on a uniform scan; y(L) <= 0 always holds
    // in exact arithmetic (dev tau = 0 on the hydrostatic axis), so the last
    // interval is taken if no earlier one changes sign.
    constexpr int kScan = 16;
    double lo = 0.0, hi = L;
    for (int k = 1; k <= kScan; ++k) {
        const double dg = (k == kScan) ? L : L * k / kScan;
        if (k == kScan || g(dg, nullptr) <= 0.0) {
            lo = L * (k - 1) / kScan;
            hi = dg;
            break;
        }
    }
    // Safeguarded Newton: g(lo) > 0 >= g(hi); fall back to bisection whenever
    // the Newton iterate leaves the bracket.
    double x = 0.5 * (lo + hi);
    for (int it = 0; it < 200 && hi - lo > 1e-15 * L; ++it) {
        double slope = 0.0;
        const double value = g(x, &slope);
        if (value == 0.0) return x;
        (value > 0.0 ? lo : hi) = x;
        const double newton = (slope != 0.0) ? x - value / slope : lo - 1.0;
        const double next = (newton > lo && newton < hi) ? newton : 0.5 * (lo + hi);
        if (std::abs(next - x) <= 1e-15 * L) return next;
        x = next;
    }
    return x;
}

template <int dim>
double VonMises<dim>::plastic_multiplier(const Vec<dim>& eps, const Vec<dim>& eps_hat, double L, double h) const {
    if (closed_form()) return std::max(L - h, 0.0);  // eq. 22
    if (L == 0.0 || yield_function(eps.array().exp().matrix(), h) <= 0.0) return 0.0;
    return solve_path(eps, eps_hat / L, L, h);
}

template <int dim>
ReturnResult<dim> VonMises<dim>::project(const Vec<dim>& Sigma, double h) const {
    if (!(h >= 0.0)) {
        std::ostringstream msg;
        msg << "von_mises hardening state h = " << h << " must be >= 0 (h = tau_Y / (2 mu))";
        throw std::invalid_argument(msg.str());
    }
    const Vec<dim> eps = Sigma.array().log().matrix();
    const Vec<dim> eps_hat = eps - eps.sum() / dim * Vec<dim>::Ones();
    const double L = eps_hat.norm();
    const double dgamma = plastic_multiplier(eps, eps_hat, L, h);
    if (dgamma <= 0.0) return {Sigma, h, ReturnBranch::Elastic, true, eps};
    const Vec<dim> eps_Z = eps - dgamma / L * eps_hat;
    return {eps_Z.array().exp().matrix(), h + params_.hardening_coefficient * dgamma, ReturnBranch::Yield, true, eps_Z};
}

template <int dim>
Vec<dim> VonMises<dim>::project_strain(const Vec<dim>& eps, double h) const {
    const Vec<dim> eps_hat = eps - eps.sum() / dim * Vec<dim>::Ones();
    const double L = eps_hat.norm();
    const double dgamma = plastic_multiplier(eps, eps_hat, L, h);
    return dgamma > 0.0 ? Vec<dim>(eps - dgamma / L * eps_hat) : eps;
}

template class VonMises<2>;
template class VonMises<3>;

}  // namespace pnet
