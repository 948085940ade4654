#pragma once
// Closest points of IPC's contact primitives, as barycentric weights, and the tangent bases
// of a contact normal (docs/methods.md), in 2D and 3D: what lagged friction needs to turn a
// pair into a relative velocity (friction.hpp) and a plane to slide in.
#include <algorithm>
#include <array>
#include <utility>

#include <Eigen/Geometry>  // cross

#include "pnet/math/types.hpp"

namespace pnet {

// Inline: they sit in the contact loops (the same code as when they were local there).

/// Weights (of a, b) of the point of segment ab closest to p; a zero-length segment gives a.
template <int dim>
std::array<double, 2> closest_on_segment(const Vec<dim>& p, const Vec<dim>& a, const Vec<dim>& b) {
    const Vec<dim> e = b - a;
    const double length_sq = e.squaredNorm();
    if (!(length_sq > 0.0)) return {1.0, 0.0};
    const double t = std::clamp((p - a).dot(e) / length_sq, 0.0, 1.0);
    return {1.0 - t, t};
}

/// Barycentric weights (of a, b, c) of the point of triangle abc closest to p, by the
/// Voronoi regions of its corners and edges.
inline Vec<3> closest_on_triangle(const Vec<3>& p, const Vec<3>& a, const Vec<3>& b, const Vec<3>& c) {
    const Vec<3> ab = b - a, ac = c - a, ap = p - a;
    const double d1 = ab.dot(ap), d2 = ac.dot(ap);
    if (d1 <= 0.0 && d2 <= 0.0) return Vec<3>(1.0, 0.0, 0.0);
    const Vec<3> bp = p - b;
    const double d3 = ab.dot(bp), d4 = ac.dot(bp);
    if (d3 >= 0.0 && d4 <= d3) return Vec<3>(0.0, 1.0, 0.0);
    const double vc = d1 * d4 - d3 * d2;
    if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) {
        const double t = d1 / (d1 - d3);
        return Vec<3>(1.0 - t, t, 0.0);
    }
    const Vec<3> cp = p - c;
    const double d5 = ab.dot(cp), d6 = ac.dot(cp);
    if (d6 >= 0.0 && d5 <= d6) return Vec<3>(0.0, 0.0, 1.0);
    const double vb = d5 * d2 - d1 * d6;
    if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) {
        const double t = d2 / (d2 - d6);
        return Vec<3>(1.0 - t, 0.0, t);
    }
    const double va = d3 * d6 - d5 * d4;
    if (va <= 0.0 && d4 - d3 >= 0.0 && d5 - d6 >= 0.0) {
        const double t = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return Vec<3>(0.0, 1.0 - t, t);
    }
    const double sum = va + vb + vc;
    return Vec<3>(va / sum, vb / sum, vc / sum);
}

/// Parameters (s on a0a1, t on b0b1) of the closest points of two segments.
inline std::pair<double, double> closest_on_segments(const Vec<3>& a0, const Vec<3>& a1, const Vec<3>& b0, const Vec<3>& b1) {
    const Vec<3> d1 = a1 - a0, d2 = b1 - b0, r = a0 - b0;
    const double a = d1.squaredNorm(), e = d2.squaredNorm(), f = d2.dot(r), c = d1.dot(r), b = d1.dot(d2);
    const double denom = a * e - b * b;
    double s = denom > 1e-14 * a * e ? std::clamp((b * f - c * e) / denom, 0.0, 1.0) : 0.0;
    double t = (b * s + f) / e;
    if (t < 0.0) {
        t = 0.0;
        s = std::clamp(-c / a, 0.0, 1.0);
    } else if (t > 1.0) {
        t = 1.0;
        s = std::clamp((b - c) / a, 0.0, 1.0);
    }
    return {s, t};
}

/// dim - 1 unit vectors orthogonal to the unit vector n and to each other (the columns):
/// in 2D n turned by +90 degrees; in 3D two vectors built on the axis least aligned with n.
template <int dim>
Eigen::Matrix<double, dim, dim - 1> tangent_basis(const Vec<dim>& n);

template <>
inline Eigen::Matrix<double, 2, 1> tangent_basis<2>(const Vec<2>& n) {
    return Vec<2>(-n[1], n[0]);
}

template <>
inline Eigen::Matrix<double, 3, 2> tangent_basis<3>(const Vec<3>& n) {
    int axis = 0;  // the axis least aligned with n
    n.cwiseAbs().minCoeff(&axis);
    const Vec<3> e1 = n.cross(Vec<3>::Unit(axis)).normalized();
    Eigen::Matrix<double, 3, 2> T;
    T.col(0) = e1;
    T.col(1) = n.cross(e1);
    return T;
}

}  // namespace pnet
