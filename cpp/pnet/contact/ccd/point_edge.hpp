#pragma once
// Continuous collision detection for the line search (docs/methods.md): the
// largest fraction t of a linear motion x0 -> x0 + dx that a pair can take
// without touching.
//
// Point-edge: additive CCD (Li, Kaufman, Jiang 2021): advance by the
// conservative bound t_l = eta (d - xi) / l_p (l_p bounds the relative motion
// of the pair per unit t, after removing its mean) until the distance has
// fallen below (1 - eta) of its start; the result never exceeds the true time
// of impact, and a pair stepped to it keeps a positive distance.
// Point-plane: closed form, scaled by eta.
#include <limits>
#include <type_traits>

#include "pnet/math/types.hpp"

namespace pnet {

constexpr double kNoImpact = std::numeric_limits<double>::infinity();

/// Time of impact in [0, t_max] of point p and edge ab moving by dp, da, db, or
/// kNoImpact if none before t_max; min_distance xi >= 0 is kept as a gap. eta:
/// the conservative rescaling in (0, 1).
double point_edge_time_of_impact(const Vec<2>& p, const Vec<2>& a, const Vec<2>& b, const Vec<2>& dp,
                                 const Vec<2>& da, const Vec<2>& db, double min_distance = 0.0, double t_max = 1.0,
                                 double eta = 0.9);

/// Time of impact of point x moving by dx with the plane (2D: line) n.(y - origin) = 0 (n unit,
/// the point on its positive side): eta times the exact time, or kNoImpact if it does not reach
/// the plane before t_max; 0 if it is not above the plane. In 2D and 3D.
/// (The dimension is taken from x alone, so the other arguments may be Eigen expressions such as
/// Vec<2>::Zero().)
template <int dim>
double point_plane_time_of_impact(const Vec<dim>& x, const std::enable_if_t<true, Vec<dim>>& dx,
                                  const std::enable_if_t<true, Vec<dim>>& origin,
                                  const std::enable_if_t<true, Vec<dim>>& normal, double t_max = 1.0,
                                  double eta = 0.9) {
    const double d = normal.dot(x - origin), rate = normal.dot(dx);
    if (!(d > 0.0)) return 0.0;
    if (rate >= 0.0) return kNoImpact;
    const double t = d / -rate;
    return t > t_max ? kNoImpact : eta * t;
}

}  // namespace pnet
