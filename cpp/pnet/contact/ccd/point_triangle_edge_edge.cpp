#include "pnet/contact/ccd/point_triangle_edge_edge.hpp"

#include <algorithm>
#include <array>
#include <cmath>

#include "pnet/contact/distance/point_triangle_edge_edge.hpp"

namespace pnet {

namespace {

using Quad = std::array<Vec<3>, 4>;

/// Additive CCD (Li, Kaufman, Jiang 2021) of the four points x moving by u
/// (mean displacement removed), whose relative motion shrinks distance_sq(x)^(1/2) by at
/// most l_p per unit t. The pair is evaluated at x + t u for each candidate t (not by
/// accumulating steps), so the returned t is checked at the configuration the caller
/// moves to.
template <class DistanceSq>
double additive_ccd(const Quad& x, const Quad& u, double l_p, const DistanceSq& distance_sq, double min_distance,
                    double t_max, double eta) {
    const double xi = min_distance, xi_sq = xi * xi;
    // d - xi, written (d^2 - xi^2) / (d + xi) against the cancellation of d - xi; 0 in contact.
    const auto clearance = [&](const Quad& y) {
        const double d_sq = distance_sq(y);
        return d_sq > xi_sq ? (d_sq - xi_sq) / (std::sqrt(d_sq) + xi) : 0.0;
    };
    double c = clearance(x);
    if (!(c > 0.0)) return 0.0;        // already in contact: no motion is safe
    if (l_p == 0.0) return kNoImpact;  // a rigid translation changes no distance
    const double gap = (1.0 - eta) * c;
    double t = 0.0;
    double t_l = eta * c / l_p;
    Quad y;
    for (int iteration = 0; iteration < 100000; ++iteration) {
        const double t_next = t + t_l;
        for (int i = 0; i < 4; ++i) y[i] = x[i] + t_next * u[i];
        c = clearance(y);
        // The first step keeps c >= gap by the bound on l_p; below it only by round-off,
        // and then t_next is still taken unless the pair touches there.
        if (c < gap && (t > 0.0 || !(c > 0.0))) return t;
        t = t_next;
        if (t > t_max) return kNoImpact;
        t_l = eta * c / l_p;
    }
    return t;  // a slow grazing approach: what was reached is safe
}

/// The displacements relative to their mean.
Quad relative(const Quad& dx) {
    const Vec<3> mean = 0.25 * (dx[0] + dx[1] + dx[2] + dx[3]);
    return {dx[0] - mean, dx[1] - mean, dx[2] - mean, dx[3] - mean};
}

}  // namespace

double point_triangle_time_of_impact(const Vec<3>& p, const Vec<3>& a, const Vec<3>& b, const Vec<3>& c,
                                     const Vec<3>& dp, const Vec<3>& da, const Vec<3>& db, const Vec<3>& dc,
                                     double min_distance, double t_max, double eta) {
    const Quad u = relative({dp, da, db, dc});
    const double l_p = u[0].norm() + std::sqrt(std::max({u[1].squaredNorm(), u[2].squaredNorm(), u[3].squaredNorm()}));
    return additive_ccd(
        {p, a, b, c}, u, l_p, [](const Quad& y) { return point_triangle_distance_sq(y[0], y[1], y[2], y[3]); },
        min_distance, t_max, eta);
}

double edge_edge_time_of_impact(const Vec<3>& a0, const Vec<3>& a1, const Vec<3>& b0, const Vec<3>& b1,
                                const Vec<3>& da0, const Vec<3>& da1, const Vec<3>& db0, const Vec<3>& db1,
                                double min_distance, double t_max, double eta) {
    const Quad u = relative({da0, da1, db0, db1});
    const double l_p = std::sqrt(std::max(u[0].squaredNorm(), u[1].squaredNorm())) +
                       std::sqrt(std::max(u[2].squaredNorm(), u[3].squaredNorm()));
    return additive_ccd(
        {a0, a1, b0, b1}, u, l_p, [](const Quad& y) { return edge_edge_distance_sq(y[0], y[1], y[2], y[3]); },
        min_distance, t_max, eta);
}

}  // namespace pnet
