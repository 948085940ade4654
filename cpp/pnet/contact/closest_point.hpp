#pragma once
// Closest points of IPC's contact primitives, as barycentric weights, and the tangent bases
// of a contact normal (docs/methods.md), in 2D and 3D: what lagged friction needs to turn a
// pair into a relative velocity (friction.hpp) and a plane to slide in.
#include <array>
#include <utility>

#include "pnet/math/types.hpp"

namespace pnet {

/// Weights (of a, b) of the point of segment ab closest to p; a zero-length segment gives a.
template <int dim>
std::array<double, 2> closest_on_segment(const Vec<dim>& p, const Vec<dim>& a, const Vec<dim>& b);

/// Barycentric weights (of a, b, c) of the point of triangle abc closest to p, by the
/// Voronoi regions of its corners and edges.
Vec<3> closest_on_triangle(const Vec<3>& p, const Vec<3>& a, const Vec<3>& b, const Vec<3>& c);

/// Parameters (s on a0a1, t on b0b1) of the closest points of two segments.
std::pair<double, double> closest_on_segments(const Vec<3>& a0, const Vec<3>& a1, const Vec<3>& b0, const Vec<3>& b1);

/// dim - 1 unit vectors orthogonal to the unit vector n and to each other (the columns):
/// in 2D n turned by +90 degrees; in 3D two vectors built on the axis least aligned with n.
template <int dim>
Eigen::Matrix<double, dim, dim - 1> tangent_basis(const Vec<dim>& n);

}  // namespace pnet
