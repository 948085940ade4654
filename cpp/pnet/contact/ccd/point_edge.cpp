#include "pnet/contact/ccd/point_edge.hpp"

#include <algorithm>
#include <cmath>

#include "pnet/contact/distance/point_edge.hpp"

namespace pnet {

double point_edge_time_of_impact(const Vec<2>& p, const Vec<2>& a, const Vec<2>& b, const Vec<2>& dp,
                                 const Vec<2>& da, const Vec<2>& db, double min_distance, double t_max, double eta) {
    // Relative motion: remove the pair's mean displacement (a common translation changes no distance).
    const Vec<2> mean = (dp + da + db) / 3.0;
    const Vec<2> up = dp - mean, ua = da - mean, ub = db - mean;
    const double l_p = up.norm() + std::sqrt(std::max(ua.squaredNorm(), ub.squaredNorm()));
    if (l_p == 0.0) return kNoImpact;
    Vec<2> xp = p, xa = a, xb = b;
    const double xi = min_distance, xi_sq = xi * xi;
    double d_sq = point_edge_distance_sq(xp, xa, xb);
    if (!(d_sq > xi_sq)) return 0.0;  // already in contact: no motion is safe
    double d = std::sqrt(d_sq);
    const double gap = (1.0 - eta) * (d_sq - xi_sq) / (d + xi);  // (1 - eta) (d - xi)
    double t = 0.0;
    for (int iteration = 0; iteration < 100000; ++iteration) {
        const double t_l = eta * (d_sq - xi_sq) / ((d + xi) * l_p);  // eta (d - xi) / l_p
        xp += t_l * up;
        xa += t_l * ua;
        xb += t_l * ub;
        d_sq = point_edge_distance_sq(xp, xa, xb);
        d = std::sqrt(d_sq);
        if (t > 0.0 && (d_sq - xi_sq) / (d + xi) < gap) return t;
        t += t_l;
        if (t > t_max) return kNoImpact;
    }
    return t;  // pathological slow approach: what was reached is safe
}

}  // namespace pnet
