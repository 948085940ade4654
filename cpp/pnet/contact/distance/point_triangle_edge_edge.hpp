#pragma once
// Squared distances of IPC's 3D contact primitives with their gradients and
// Hessians (Li et al. 2020; docs/methods.md): point-triangle and edge-edge, each
// piecewise over the feature pair that is closest, and IPC's mollifier of nearly
// parallel edges.
//
// Point-triangle (p; triangle abc), derivatives in the stacked (p, a, b, c) in R^12:
//   VertexA/B/C        |p - a|^2 (or b, c)
//   EdgeAB/BC/CA       |(p - a) x (b - a)|^2 / |b - a|^2   (p against the line through the edge)
//   Interior           ((p - a).n)^2 / |n|^2, n = (b - a) x (c - a)   (p against the plane)
// Edge-edge (segments a0a1, b0b1), derivatives in the stacked (a0, a1, b0, b1) in R^12:
//   A0B0, A0B1, A1B0, A1B1   the two endpoints, |a0 - b0|^2 etc.
//   A0EdgeB, A1EdgeB         an endpoint of a against the line through b
//   B0EdgeA, B1EdgeA         an endpoint of b against the line through a
//   Interior                 line against line, ((b0 - a0).n)^2 / |n|^2, n = (a1 - a0) x (b1 - b0)
// Each case's formula is the squared distance to a superset (a line, a plane) of the
// closest feature, so where the cases meet the true distance is C1: the two formulas
// agree there in value and gradient. The case is chosen once by the *_case function
// and passed to value, gradient and Hessian, which are exact (not finite
// differences) within the case; the Hessian is not projected to PSD.
//
// Degenerate inputs: a triangle with |n|^2 <= 1e-20 |b - a|^2 |c - a|^2 (collinear
// or repeated corners) never selects Interior, and edges with |n|^2 <= 1e-16 |ea|^2 |eb|^2
// (parallel to round-off) never select Interior (line-line): the nearest of the
// endpoint/edge pairs is used instead (exact for parallel edges; for nearly parallel
// ones it overestimates the distance by at most |ea| sin(angle) <= 1e-8 |ea|). A zero-
// length edge selects its endpoint. No case formula is evaluated where its
// denominator vanishes.
#include <Eigen/Core>

#include "pnet/math/types.hpp"

namespace pnet {

using Vec12 = Eigen::Matrix<double, 12, 1>;
using Mat12 = Eigen::Matrix<double, 12, 12>;

/// Which feature of triangle abc is closest to p.
enum class PointTriangleCase { VertexA, VertexB, VertexC, EdgeAB, EdgeBC, EdgeCA, Interior };

/// Interior when p projects strictly inside a non-degenerate triangle; otherwise the
/// nearest of the three edges (or of their endpoints).
PointTriangleCase point_triangle_case(const Vec<3>& p, const Vec<3>& a, const Vec<3>& b, const Vec<3>& c);

/// The case's squared distance (table above) and its derivatives in (p, a, b, c).
double point_triangle_distance_sq(const Vec<3>& p, const Vec<3>& a, const Vec<3>& b, const Vec<3>& c,
                                  PointTriangleCase k);
Vec12 point_triangle_distance_sq_gradient(const Vec<3>& p, const Vec<3>& a, const Vec<3>& b, const Vec<3>& c,
                                          PointTriangleCase k);
Mat12 point_triangle_distance_sq_hessian(const Vec<3>& p, const Vec<3>& a, const Vec<3>& b, const Vec<3>& c,
                                         PointTriangleCase k);

/// The squared distance from p to the triangle, case chosen by point_triangle_case().
inline double point_triangle_distance_sq(const Vec<3>& p, const Vec<3>& a, const Vec<3>& b, const Vec<3>& c) {
    return point_triangle_distance_sq(p, a, b, c, point_triangle_case(p, a, b, c));
}

/// Which features of segments a0a1 and b0b1 are closest (table above).
enum class EdgeEdgeCase { A0B0, A0B1, A1B0, A1B1, A0EdgeB, A1EdgeB, B0EdgeA, B1EdgeA, Interior };

/// Interior when the closest points of the two lines, s a0a1 and t b0b1, lie strictly
/// inside both segments (0 < s, t < 1) and the edges are not parallel; otherwise the
/// minimum lies on the boundary of the parameter square: the nearest of the four
/// endpoint-against-segment pairs.
EdgeEdgeCase edge_edge_case(const Vec<3>& a0, const Vec<3>& a1, const Vec<3>& b0, const Vec<3>& b1);

/// The case's squared distance (table above) and its derivatives in (a0, a1, b0, b1).
double edge_edge_distance_sq(const Vec<3>& a0, const Vec<3>& a1, const Vec<3>& b0, const Vec<3>& b1, EdgeEdgeCase k);
Vec12 edge_edge_distance_sq_gradient(const Vec<3>& a0, const Vec<3>& a1, const Vec<3>& b0, const Vec<3>& b1,
                                     EdgeEdgeCase k);
Mat12 edge_edge_distance_sq_hessian(const Vec<3>& a0, const Vec<3>& a1, const Vec<3>& b0, const Vec<3>& b1,
                                    EdgeEdgeCase k);

/// The squared distance between the segments, case chosen by edge_edge_case().
inline double edge_edge_distance_sq(const Vec<3>& a0, const Vec<3>& a1, const Vec<3>& b0, const Vec<3>& b1) {
    return edge_edge_distance_sq(a0, a1, b0, b1, edge_edge_case(a0, a1, b0, b1));
}

/// IPC's mollifier threshold from the rest positions (Li et al. 2020):
/// eps_x = 1e-3 |a1 - a0|^2 |b1 - b0|^2 (m^4).
double edge_edge_mollifier_threshold(const Vec<3>& a0_rest, const Vec<3>& a1_rest, const Vec<3>& b0_rest,
                                     const Vec<3>& b1_rest);

/// IPC's edge-edge mollifier of c = |(a1 - a0) x (b1 - b0)|^2:
///   m = (2 - c / eps) c / eps for c < eps, 1 otherwise,
/// C1 at c = eps and 0 for parallel edges, so that the barrier of nearly parallel
/// edges fades out smoothly where their case changes (point-triangle pairs hold
/// them apart there). Derivatives in (a0, a1, b0, b1); zero for c >= eps.
double edge_edge_mollifier(const Vec<3>& a0, const Vec<3>& a1, const Vec<3>& b0, const Vec<3>& b1, double eps);
Vec12 edge_edge_mollifier_gradient(const Vec<3>& a0, const Vec<3>& a1, const Vec<3>& b0, const Vec<3>& b1, double eps);
Mat12 edge_edge_mollifier_hessian(const Vec<3>& a0, const Vec<3>& a1, const Vec<3>& b0, const Vec<3>& b1, double eps);

}  // namespace pnet
