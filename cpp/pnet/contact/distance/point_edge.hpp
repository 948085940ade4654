#pragma once
// Squared distances of IPC's 2D contact primitives with their gradients and
// Hessians (docs/methods.md): point-point, point-edge (three cases: the point is
// closest to endpoint a, to endpoint b, or to the inside of the edge) and
// point-plane. Derivatives are with respect to the stacked positions: (p, a)
// for point-point, (p, a, b) for point-edge, p for point-plane.
#include <Eigen/Core>

#include "pnet/math/types.hpp"

namespace pnet {

using Vec4 = Eigen::Matrix<double, 4, 1>;
using Mat4 = Eigen::Matrix<double, 4, 4>;
using Vec6 = Eigen::Matrix<double, 6, 1>;
using Mat6 = Eigen::Matrix<double, 6, 6>;

/// Which part of edge ab is closest to p.
enum class PointEdgeCase { EndpointA, EndpointB, Interior };

/// t = (p - a).(b - a) / |b - a|^2 <= 0: endpoint a; >= 1: endpoint b; else the interior.
PointEdgeCase point_edge_case(const Vec<2>& p, const Vec<2>& a, const Vec<2>& b);

/// |p - a|^2 and its derivatives in (p, a).
double point_point_distance_sq(const Vec<2>& p, const Vec<2>& a);
Vec4 point_point_distance_sq_gradient(const Vec<2>& p, const Vec<2>& a);
Mat4 point_point_distance_sq_hessian();

/// The squared distance from p to segment ab (the case's formula: |p - a|^2,
/// |p - b|^2, or cross(b - a, p - a)^2 / |b - a|^2) and its derivatives in
/// (p, a, b), of the given case (so that a caller evaluates all three with the
/// case chosen once; derivatives are exact within a case).
double point_edge_distance_sq(const Vec<2>& p, const Vec<2>& a, const Vec<2>& b, PointEdgeCase c);
Vec6 point_edge_distance_sq_gradient(const Vec<2>& p, const Vec<2>& a, const Vec<2>& b, PointEdgeCase c);
Mat6 point_edge_distance_sq_hessian(const Vec<2>& p, const Vec<2>& a, const Vec<2>& b, PointEdgeCase c);

/// The squared distance to the segment, case chosen by point_edge_case().
inline double point_edge_distance_sq(const Vec<2>& p, const Vec<2>& a, const Vec<2>& b) {
    return point_edge_distance_sq(p, a, b, point_edge_case(p, a, b));
}

}  // namespace pnet
