#include "pnet/contact/distance/point_triangle_edge_edge.hpp"

#include <Eigen/Geometry>  // cross()
#include <array>
#include <type_traits>

#include "pnet/math/dual2.hpp"

namespace pnet {

namespace {

// Below these ratios |n|^2 / (|e1|^2 |e2|^2) = sin^2(angle) a triangle is degenerate
// and two edges are parallel (header): the plane and line-line formulas divide by |n|^2.
constexpr double kDegenerateTriangle = 1e-20;
constexpr double kParallelEdges = 1e-16;

// ---------------------------------------------------------------------------
// The case formulas, written once for any scalar T (double, Dual1, Dual2) in the
// translation-invariant differences v[i] of the points (a distance does not change
// under a common translation, so 3 x (number of differences) variables suffice).

template <typename T>
using Vec3T = std::array<T, 3>;

template <typename T>
T dot(const Vec3T<T>& u, const Vec3T<T>& v) {
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
}

template <typename T>
Vec3T<T> cross(const Vec3T<T>& u, const Vec3T<T>& v) {
    return {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
}

/// |v0|^2.
struct PointPoint {
    static constexpr int differences = 1;
    template <typename T>
    static T eval(const std::array<Vec3T<T>, 1>& v) {
        return dot(v[0], v[0]);
    }
};

/// |v0 x v1|^2 / |v1|^2: v0 from a point of the line to the point, v1 along the line.
struct PointLine {
    static constexpr int differences = 2;
    template <typename T>
    static T eval(const std::array<Vec3T<T>, 2>& v) {
        const Vec3T<T> m = cross(v[0], v[1]);
        return dot(m, m) / dot(v[1], v[1]);
    }
};

/// (v0.n)^2 / |n|^2, n = v1 x v2: v0 from a point of the plane (or of one line) to the
/// point (or to the other line), v1, v2 spanning the plane (or along the two lines).
struct PointPlane {
    static constexpr int differences = 3;
    template <typename T>
    static T eval(const std::array<Vec3T<T>, 3>& v) {
        const Vec3T<T> n = cross(v[1], v[2]);
        const T u = dot(v[0], n);
        return u * u / dot(n, n);
    }
};

/// |v0 x v1|^2: the mollifier's argument c.
struct CrossSq {
    static constexpr int differences = 2;
    template <typename T>
    static T eval(const std::array<Vec3T<T>, 2>& v) {
        const Vec3T<T> m = cross(v[0], v[1]);
        return dot(m, m);
    }
};

// ---------------------------------------------------------------------------
// A case as its formula's differences x[plus] - x[minus] of the four stacked points
// (0..3: p, a, b, c or a0, a1, b0, b1), and the chain rule back to the 12 coordinates.

struct Stencil {
    int differences;                         // 1: PointPoint, 2: PointLine, 3: PointPlane
    std::array<std::array<int, 2>, 3> diff;  // (plus, minus) of each difference
};

using Points = std::array<const Vec<3>*, 4>;

template <typename T, int nd>
std::array<Vec3T<T>, nd> differences(const Stencil& s, const Points& x) {
    std::array<Vec3T<T>, nd> v;
    for (int d = 0; d < nd; ++d) {
        const Vec<3> w = *x[s.diff[d][0]] - *x[s.diff[d][1]];
        for (int i = 0; i < 3; ++i) {
            if constexpr (std::is_same_v<T, double>)
                v[d][i] = w[i];
            else
                v[d][i] = T::variable(3 * d + i, w[i]);
        }
    }
    return v;
}

template <class F>
double value(const Stencil& s, const Points& x) {
    return F::eval(differences<double, F::differences>(s, x));
}

/// A gradient in the differences, scattered to +plus and -minus of each.
template <int nd>
Vec12 scatter(const Stencil& s, const Eigen::Matrix<double, 3 * nd, 1>& gv) {
    Vec12 g = Vec12::Zero();
    for (int d = 0; d < nd; ++d) {
        g.segment<3>(3 * s.diff[d][0]) += gv.template segment<3>(3 * d);
        g.segment<3>(3 * s.diff[d][1]) -= gv.template segment<3>(3 * d);
    }
    return g;
}

/// A Hessian in the differences, pulled back to the 12 coordinates: J^T Hv J with J the
/// constant map (blocks of +-identity) from the coordinates to the differences.
template <int nd>
Mat12 scatter(const Stencil& s, const Eigen::Matrix<double, 3 * nd, 3 * nd>& Hv) {
    Mat12 H = Mat12::Zero();
    for (int d = 0; d < nd; ++d)
        for (int e = 0; e < nd; ++e) {
            const Eigen::Matrix3d B = Hv.template block<3, 3>(3 * d, 3 * e);
            const int dp = 3 * s.diff[d][0], dm = 3 * s.diff[d][1], ep = 3 * s.diff[e][0], em = 3 * s.diff[e][1];
            H.block<3, 3>(dp, ep) += B;
            H.block<3, 3>(dp, em) -= B;
            H.block<3, 3>(dm, ep) -= B;
            H.block<3, 3>(dm, em) += B;
        }
    return H;
}

template <class F>
Vec12 gradient(const Stencil& s, const Points& x) {
    constexpr int nd = F::differences;
    return scatter<nd>(s, F::eval(differences<Dual1<3 * nd>, nd>(s, x)).gradient);
}

template <class F>
Mat12 hessian(const Stencil& s, const Points& x) {
    constexpr int nd = F::differences;
    return scatter<nd>(s, F::eval(differences<Dual2<3 * nd>, nd>(s, x)).hessian);
}

double distance_value(const Stencil& s, const Points& x) {
    switch (s.differences) {
        case 1:
            return value<PointPoint>(s, x);
        case 2:
            return value<PointLine>(s, x);
        default:
            return value<PointPlane>(s, x);
    }
}

Vec12 distance_gradient(const Stencil& s, const Points& x) {
    switch (s.differences) {
        case 1:
            return gradient<PointPoint>(s, x);
        case 2:
            return gradient<PointLine>(s, x);
        default:
            return gradient<PointPlane>(s, x);
    }
}

Mat12 distance_hessian(const Stencil& s, const Points& x) {
    switch (s.differences) {
        case 1:
            return hessian<PointPoint>(s, x);
        case 2:
            return hessian<PointLine>(s, x);
        default:
            return hessian<PointPlane>(s, x);
    }
}

// Points p = 0, a = 1, b = 2, c = 3, in PointTriangleCase order.
constexpr Stencil kPointTriangle[7] = {
    {1, {{{0, 1}}}},                  // VertexA: p - a
    {1, {{{0, 2}}}},                  // VertexB
    {1, {{{0, 3}}}},                  // VertexC
    {2, {{{0, 1}, {2, 1}}}},          // EdgeAB: p - a along b - a
    {2, {{{0, 2}, {3, 2}}}},          // EdgeBC: p - b along c - b
    {2, {{{0, 3}, {1, 3}}}},          // EdgeCA: p - c along a - c
    {3, {{{0, 1}, {2, 1}, {3, 1}}}},  // Interior: p - a against the plane of b - a, c - a
};

// Points a0 = 0, a1 = 1, b0 = 2, b1 = 3, in EdgeEdgeCase order.
constexpr Stencil kEdgeEdge[9] = {
    {1, {{{0, 2}}}},                  // A0B0
    {1, {{{0, 3}}}},                  // A0B1
    {1, {{{1, 2}}}},                  // A1B0
    {1, {{{1, 3}}}},                  // A1B1
    {2, {{{0, 2}, {3, 2}}}},          // A0EdgeB: a0 - b0 along b1 - b0
    {2, {{{1, 2}, {3, 2}}}},          // A1EdgeB
    {2, {{{2, 0}, {1, 0}}}},          // B0EdgeA: b0 - a0 along a1 - a0
    {2, {{{3, 0}, {1, 0}}}},          // B1EdgeA
    {3, {{{2, 0}, {1, 0}, {3, 2}}}},  // Interior: b0 - a0 against a1 - a0, b1 - b0
};

constexpr Stencil kMollifier = {2, {{{1, 0}, {3, 2}}}};  // (a1 - a0) x (b1 - b0)

const Stencil& stencil(PointTriangleCase k) {
    return kPointTriangle[static_cast<int>(k)];
}
const Stencil& stencil(EdgeEdgeCase k) {
    return kEdgeEdge[static_cast<int>(k)];
}

// ---------------------------------------------------------------------------
// Case selection.

/// The feature of segment ab nearest to p (0: a, 1: b, 2: the inside) and the squared
/// distance to it by that feature's formula. A zero-length segment is its endpoint a.
struct SegmentFeature {
    int feature;
    double distance_sq;
};

SegmentFeature nearest_on_segment(const Vec<3>& p, const Vec<3>& a, const Vec<3>& b) {
    const Vec<3> e = b - a, r = p - a;
    const double t = r.dot(e), length_sq = e.squaredNorm();  // t: the parameter times |e|^2
    if (t <= 0.0 || length_sq == 0.0) return {0, r.squaredNorm()};
    if (t >= length_sq) return {1, (p - b).squaredNorm()};
    return {2, r.cross(e).squaredNorm() / length_sq};
}

}  // namespace

PointTriangleCase point_triangle_case(const Vec<3>& p, const Vec<3>& a, const Vec<3>& b, const Vec<3>& c) {
    const Vec<3> ab = b - a, ac = c - a, n = ab.cross(ac);
    if (n.squaredNorm() > kDegenerateTriangle * ab.squaredNorm() * ac.squaredNorm()) {
        // p projects strictly inside when it is on the inner side of each edge (seen along n).
        if (ab.cross(p - a).dot(n) > 0.0 && (c - b).cross(p - b).dot(n) > 0.0 && (a - c).cross(p - c).dot(n) > 0.0)
            return PointTriangleCase::Interior;
    }
    // Otherwise the closest point of the (convex) triangle lies on its boundary.
    using K = PointTriangleCase;
    constexpr K kEdgeCases[3][3] = {
        {K::VertexA, K::VertexB, K::EdgeAB}, {K::VertexB, K::VertexC, K::EdgeBC}, {K::VertexC, K::VertexA, K::EdgeCA}};
    const SegmentFeature f[3] = {nearest_on_segment(p, a, b), nearest_on_segment(p, b, c), nearest_on_segment(p, c, a)};
    int best = 0;
    for (int i = 1; i < 3; ++i)
        if (f[i].distance_sq < f[best].distance_sq) best = i;
    return kEdgeCases[best][f[best].feature];
}

double point_triangle_distance_sq(const Vec<3>& p, const Vec<3>& a, const Vec<3>& b, const Vec<3>& c,
                                  PointTriangleCase k) {
    return distance_value(stencil(k), {&p, &a, &b, &c});
}

Vec12 point_triangle_distance_sq_gradient(const Vec<3>& p, const Vec<3>& a, const Vec<3>& b, const Vec<3>& c,
                                          PointTriangleCase k) {
    return distance_gradient(stencil(k), {&p, &a, &b, &c});
}

Mat12 point_triangle_distance_sq_hessian(const Vec<3>& p, const Vec<3>& a, const Vec<3>& b, const Vec<3>& c,
                                         PointTriangleCase k) {
    return distance_hessian(stencil(k), {&p, &a, &b, &c});
}

EdgeEdgeCase edge_edge_case(const Vec<3>& a0, const Vec<3>& a1, const Vec<3>& b0, const Vec<3>& b1) {
    const Vec<3> ea = a1 - a0, eb = b1 - b0, w = a0 - b0;
    const double A = ea.squaredNorm(), B = ea.dot(eb), C = eb.squaredNorm(), D = ea.dot(w), E = eb.dot(w);
    const double det = ea.cross(eb).squaredNorm();  // A C - B^2, without its cancellation
    if (det > kParallelEdges * A * C) {
        // The lines' closest points a0 + s ea, b0 + t eb: s = (B E - C D) / det, t = (A E - B D) / det.
        const double s = B * E - C * D, t = A * E - B * D;
        if (s > 0.0 && s < det && t > 0.0 && t < det) return EdgeEdgeCase::Interior;
    }
    // The convex quadratic |a0 + s ea - b0 - t eb|^2 has its minimum over [0, 1]^2 on the
    // square's boundary: an endpoint of one segment against the other segment.
    using K = EdgeEdgeCase;
    constexpr K kCases[4][3] = {{K::A0B0, K::A0B1, K::A0EdgeB},
                                {K::A1B0, K::A1B1, K::A1EdgeB},
                                {K::A0B0, K::A1B0, K::B0EdgeA},
                                {K::A0B1, K::A1B1, K::B1EdgeA}};
    const SegmentFeature f[4] = {nearest_on_segment(a0, b0, b1), nearest_on_segment(a1, b0, b1),
                                 nearest_on_segment(b0, a0, a1), nearest_on_segment(b1, a0, a1)};
    int best = 0;
    for (int i = 1; i < 4; ++i)
        if (f[i].distance_sq < f[best].distance_sq) best = i;
    return kCases[best][f[best].feature];
}

double edge_edge_distance_sq(const Vec<3>& a0, const Vec<3>& a1, const Vec<3>& b0, const Vec<3>& b1, EdgeEdgeCase k) {
    return distance_value(stencil(k), {&a0, &a1, &b0, &b1});
}

Vec12 edge_edge_distance_sq_gradient(const Vec<3>& a0, const Vec<3>& a1, const Vec<3>& b0, const Vec<3>& b1,
                                     EdgeEdgeCase k) {
    return distance_gradient(stencil(k), {&a0, &a1, &b0, &b1});
}

Mat12 edge_edge_distance_sq_hessian(const Vec<3>& a0, const Vec<3>& a1, const Vec<3>& b0, const Vec<3>& b1,
                                    EdgeEdgeCase k) {
    return distance_hessian(stencil(k), {&a0, &a1, &b0, &b1});
}

double edge_edge_mollifier_threshold(const Vec<3>& a0_rest, const Vec<3>& a1_rest, const Vec<3>& b0_rest,
                                     const Vec<3>& b1_rest) {
    return 1e-3 * (a1_rest - a0_rest).squaredNorm() * (b1_rest - b0_rest).squaredNorm();
}

// m(c) = (2 - c / eps) c / eps: m' = 2 (1 - c / eps) / eps, m'' = -2 / eps^2; by the chain
// rule dm = m' dc and d2m = m'' dc dc^T + m' d2c.

double edge_edge_mollifier(const Vec<3>& a0, const Vec<3>& a1, const Vec<3>& b0, const Vec<3>& b1, double eps) {
    const double c = value<CrossSq>(kMollifier, {&a0, &a1, &b0, &b1});
    if (!(c < eps)) return 1.0;
    const double x = c / eps;
    return (2.0 - x) * x;
}

Vec12 edge_edge_mollifier_gradient(const Vec<3>& a0, const Vec<3>& a1, const Vec<3>& b0, const Vec<3>& b1, double eps) {
    const Dual1<6> c = CrossSq::eval(differences<Dual1<6>, 2>(kMollifier, {&a0, &a1, &b0, &b1}));
    if (!(c.value < eps)) return Vec12::Zero();
    const double dm = 2.0 * (1.0 - c.value / eps) / eps;
    return scatter<2>(kMollifier, Eigen::Matrix<double, 6, 1>(dm * c.gradient));
}

Mat12 edge_edge_mollifier_hessian(const Vec<3>& a0, const Vec<3>& a1, const Vec<3>& b0, const Vec<3>& b1, double eps) {
    const Dual2<6> c = CrossSq::eval(differences<Dual2<6>, 2>(kMollifier, {&a0, &a1, &b0, &b1}));
    if (!(c.value < eps)) return Mat12::Zero();
    const double dm = 2.0 * (1.0 - c.value / eps) / eps, d2m = -2.0 / (eps * eps);
    return scatter<2>(kMollifier,
                      Eigen::Matrix<double, 6, 6>(d2m * c.gradient * c.gradient.transpose() + dm * c.hessian));
}

}  // namespace pnet
