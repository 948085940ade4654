#pragma once
// A point against a boundary facet of a mesh, the one contact pair that 2D and 3D share
// (docs/methods.md): a facet is an edge (2 nodes) in 2D and a triangle (3 nodes) in 3D.
// PointFacet<dim> gathers, for that pair, what an IPC barrier needs: the closest-feature
// case, the squared distance with its gradient and Hessian in the stacked positions
// (p, facet nodes) in R^{dim (dim + 1)}, additive CCD, the closest point's barycentric
// weights (lagged friction) and whether a point lies inside a closed boundary. Code written
// once over PointFacet<dim> (Contact's point-facet pairs, a mesh's nodes and stand-alone points:
// contact.hpp) runs in both dimensions; each member forwards to the primitive's own file
// (distance/, ccd/).
#include <array>
#include <string>
#include <vector>

#include "pnet/contact/ccd/point_edge.hpp"
#include "pnet/contact/ccd/point_triangle_edge_edge.hpp"
#include "pnet/contact/distance/closest_point.hpp"
#include "pnet/contact/distance/point_edge.hpp"
#include "pnet/contact/distance/point_triangle_edge_edge.hpp"
#include "pnet/math/types.hpp"

namespace pnet {

template <int dim>
struct PointFacet;

template <>
struct PointFacet<2> {
    static constexpr int kNodes = 2;    // an edge
    static constexpr int kStacked = 6;  // (p, a, b)
    using Facet = std::array<int, 2>;
    using Case = PointEdgeCase;
    using Gradient = Vec6;
    using Hessian = Mat6;
    static constexpr const char* kFacetName = "edge";

    static Case classify(const Vec<2>& p, const std::vector<Vec<2>>& x, const Facet& f) {
        return point_edge_case(p, x[f[0]], x[f[1]]);
    }
    static double distance_sq(const Vec<2>& p, const std::vector<Vec<2>>& x, const Facet& f) {
        return point_edge_distance_sq(p, x[f[0]], x[f[1]]);
    }
    static double distance_sq(const Vec<2>& p, const std::vector<Vec<2>>& x, const Facet& f, Case c) {
        return point_edge_distance_sq(p, x[f[0]], x[f[1]], c);
    }
    static Gradient gradient(const Vec<2>& p, const std::vector<Vec<2>>& x, const Facet& f, Case c) {
        return point_edge_distance_sq_gradient(p, x[f[0]], x[f[1]], c);
    }
    static Hessian hessian(const Vec<2>& p, const std::vector<Vec<2>>& x, const Facet& f, Case c) {
        return point_edge_distance_sq_hessian(p, x[f[0]], x[f[1]], c);
    }
    static double time_of_impact(const Vec<2>& p, const Vec<2>& dp, const std::vector<Vec<2>>& x,
                                 const std::vector<Vec<2>>& dx, const Facet& f, double t_max) {
        return point_edge_time_of_impact(p, x[f[0]], x[f[1]], dp, dx[f[0]], dx[f[1]], 0.0, t_max);
    }
    static std::array<double, 2> closest_weights(const Vec<2>& p, const std::vector<Vec<2>>& x, const Facet& f) {
        return closest_on_segment<2>(p, x[f[0]], x[f[1]]);
    }
};

template <>
struct PointFacet<3> {
    static constexpr int kNodes = 3;     // a triangle
    static constexpr int kStacked = 12;  // (p, a, b, c)
    using Facet = std::array<int, 3>;
    using Case = PointTriangleCase;
    using Gradient = Vec12;
    using Hessian = Mat12;
    static constexpr const char* kFacetName = "triangle";

    static Case classify(const Vec<3>& p, const std::vector<Vec<3>>& x, const Facet& f) {
        return point_triangle_case(p, x[f[0]], x[f[1]], x[f[2]]);
    }
    static double distance_sq(const Vec<3>& p, const std::vector<Vec<3>>& x, const Facet& f) {
        return point_triangle_distance_sq(p, x[f[0]], x[f[1]], x[f[2]]);
    }
    static double distance_sq(const Vec<3>& p, const std::vector<Vec<3>>& x, const Facet& f, Case c) {
        return point_triangle_distance_sq(p, x[f[0]], x[f[1]], x[f[2]], c);
    }
    static Gradient gradient(const Vec<3>& p, const std::vector<Vec<3>>& x, const Facet& f, Case c) {
        return point_triangle_distance_sq_gradient(p, x[f[0]], x[f[1]], x[f[2]], c);
    }
    static Hessian hessian(const Vec<3>& p, const std::vector<Vec<3>>& x, const Facet& f, Case c) {
        return point_triangle_distance_sq_hessian(p, x[f[0]], x[f[1]], x[f[2]], c);
    }
    static double time_of_impact(const Vec<3>& p, const Vec<3>& dp, const std::vector<Vec<3>>& x,
                                 const std::vector<Vec<3>>& dx, const Facet& f, double t_max) {
        return point_triangle_time_of_impact(p, x[f[0]], x[f[1]], x[f[2]], dp, dx[f[0]], dx[f[1]], dx[f[2]], 0.0,
                                             t_max);
    }
    static std::array<double, 3> closest_weights(const Vec<3>& p, const std::vector<Vec<3>>& x, const Facet& f) {
        const Vec<3> w = closest_on_triangle(p, x[f[0]], x[f[1]], x[f[2]]);
        return {w[0], w[1], w[2]};
    }
};

/// Whether p lies inside the region bounded by the closed boundary `facets` (positions x), or on
/// it. On the boundary: p on a facet exactly (*facet_on = its index); otherwise -1. 2D: the
/// crossing number of the ray along +x, with an exact collinearity test; 3D: the generalized
/// winding number (the facets' solid angles at p over 4 pi; 1 inside, 0 outside, either
/// orientation) with an exact test for p on a triangle (zero distance).
bool inside_boundary(const Vec<2>& p, const std::vector<Vec<2>>& x, const std::vector<std::array<int, 2>>& facets,
                     int* facet_on);
bool inside_boundary(const Vec<3>& p, const std::vector<Vec<3>>& x, const std::vector<std::array<int, 3>>& facets,
                     int* facet_on);

/// Calls f(k) for each point that may lie inside the region bounded by `facets` (positions x) or
/// on it: those within the facets' bounding box, in order; f returns false to stop.
template <int dim, typename F>
void for_each_point_in_box(const std::vector<Vec<dim>>& points, const std::vector<Vec<dim>>& x,
                           const std::vector<std::array<int, dim>>& facets, F&& f) {
    if (facets.empty()) return;
    Vec<dim> lo = x[facets[0][0]], hi = lo;
    for (const auto& facet : facets)
        for (int node : facet) {
            lo = lo.cwiseMin(x[node]);
            hi = hi.cwiseMax(x[node]);
        }
    for (std::size_t k = 0; k < points.size(); ++k) {
        if ((points[k].array() < lo.array()).any() || (points[k].array() > hi.array()).any()) continue;
        if (!f(k)) return;
    }
}

/// How many of the points lie inside the region bounded by `facets` (positions x), or on it
/// (inside_boundary for each).
template <int dim>
std::size_t count_inside(const std::vector<Vec<dim>>& points, const std::vector<Vec<dim>>& x,
                         const std::vector<std::array<int, dim>>& facets) {
    std::size_t inside = 0;
    for_each_point_in_box<dim>(points, x, facets, [&](std::size_t k) {
        int on = -1;
        inside += inside_boundary(points[k], x, facets, &on);
        return true;
    });
    return inside;
}

/// The first point inside the region bounded by `facets` (positions x) or on it, as text ("point
/// 12 inside the mesh", "point 12 on edge 3-4"; `name` in place of "point"), or "".
template <int dim>
std::string first_inside(const std::vector<Vec<dim>>& points, const std::vector<Vec<dim>>& x,
                         const std::vector<std::array<int, dim>>& facets, const std::string& name = "point") {
    std::string found;
    for_each_point_in_box<dim>(points, x, facets, [&](std::size_t k) {
        int on = -1;
        if (!inside_boundary(points[k], x, facets, &on)) return true;
        found = name + " " + std::to_string(k);
        if (on < 0) {
            found += " inside the mesh";
            return false;
        }
        found += std::string(" on ") + PointFacet<dim>::kFacetName + " ";
        for (int j = 0; j < dim; ++j) found += (j ? "-" : "") + std::to_string(facets[on][j]);
        return false;
    });
    return found;
}

}  // namespace pnet
