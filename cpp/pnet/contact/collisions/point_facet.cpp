#include "pnet/contact/collisions/point_facet.hpp"

#include <cmath>

#include <Eigen/Geometry>  // cross

namespace pnet {

bool inside_boundary(const Vec<2>& p, const std::vector<Vec<2>>& x, const std::vector<std::array<int, 2>>& facets,
                     int* facet_on) {
    bool in = false;
    for (std::size_t e = 0; e < facets.size(); ++e) {
        const Vec<2>& a = x[facets[e][0]];
        const Vec<2>& b = x[facets[e][1]];
        const double cross = (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]);
        if (cross == 0.0 && (p - a).dot(p - b) <= 0.0) {
            *facet_on = static_cast<int>(e);
            return true;
        }
        if ((a[1] > p[1]) != (b[1] > p[1])) {
            const double xc = a[0] + (p[1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1]);
            if (p[0] < xc) in = !in;
        }
    }
    *facet_on = -1;
    return in;
}

bool inside_boundary(const Vec<3>& p, const std::vector<Vec<3>>& x, const std::vector<std::array<int, 3>>& facets,
                     int* facet_on) {
    // Van Oosterom and Strackee's solid angle of each triangle seen from p.
    double solid_angle = 0.0;
    for (std::size_t t = 0; t < facets.size(); ++t) {
        const Vec<3> a = x[facets[t][0]] - p, b = x[facets[t][1]] - p, c = x[facets[t][2]] - p;
        if (point_triangle_distance_sq(p, x[facets[t][0]], x[facets[t][1]], x[facets[t][2]]) == 0.0) {
            *facet_on = static_cast<int>(t);
            return true;
        }
        const double la = a.norm(), lb = b.norm(), lc = c.norm();
        const double numerator = a.dot(b.cross(c));
        const double denominator = la * lb * lc + a.dot(b) * lc + a.dot(c) * lb + b.dot(c) * la;
        solid_angle += 2.0 * std::atan2(numerator, denominator);
    }
    *facet_on = -1;
    return std::abs(solid_angle) > 2.0 * M_PI;  // winding number above 1/2
}

}  // namespace pnet
