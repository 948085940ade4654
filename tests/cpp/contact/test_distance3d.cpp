// IPC's 3D distances: for each of the 7 point-triangle and 9 edge-edge cases,
// random configurations built to lie in that case (the closest point put on the
// feature, the offset in the feature's normal cone) check the case selector, the
// value against an independent brute-force minimization, and the gradient and
// Hessian against finite differences; across every case boundary the distance is
// C1 (neighbouring cases agree in value and gradient); degenerate triangles and
// (nearly) parallel edges stay finite and exact; the mollifier's derivatives, and
// m = 1 above its threshold.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <functional>

#include "pnet/contact/distance/point_triangle_edge_edge.hpp"
#include "support/finite_difference.hpp"
#include "support/random.hpp"

namespace pnet {
namespace {

using Quad = std::array<Vec<3>, 4>;

Eigen::VectorXd stack(const Quad& x) {
    Eigen::VectorXd q(12);
    for (int i = 0; i < 4; ++i) q.segment<3>(3 * i) = x[i];
    return q;
}

Quad unstack(const Eigen::VectorXd& q) {
    return {q.segment<3>(0), q.segment<3>(3), q.segment<3>(6), q.segment<3>(9)};
}

/// The minimum of a convex function on [0, 1] by golden-section search.
double golden_minimum(const std::function<double(double)>& g) {
    const double ratio = 0.5 * (std::sqrt(5.0) - 1.0);
    double lo = 0.0, hi = 1.0;
    double x1 = hi - ratio * (hi - lo), x2 = lo + ratio * (hi - lo), g1 = g(x1), g2 = g(x2);
    for (int iteration = 0; iteration < 200 && hi - lo > 1e-15; ++iteration) {
        if (g1 < g2) {
            hi = x2;
            x2 = x1;
            g2 = g1;
            x1 = hi - ratio * (hi - lo);
            g1 = g(x1);
        } else {
            lo = x1;
            x1 = x2;
            g1 = g2;
            x2 = lo + ratio * (hi - lo);
            g2 = g(x2);
        }
    }
    return std::min({g(0.0), g(1.0), g1, g2, g(0.5 * (lo + hi))});
}

/// Brute force, independent of the case analysis: min over the triangle {a + u e1 + v e2 :
/// u, v >= 0, u + v <= 1} of |p - x|^2, exactly over v for each u (a clamped 1D quadratic) and
/// by golden section over u (the partial minimum of a convex function is convex).
double brute_point_triangle(const Vec<3>& p, const Vec<3>& a, const Vec<3>& b, const Vec<3>& c) {
    const Vec<3> e1 = b - a, e2 = c - a;
    return golden_minimum([&](double u) {
        const Vec<3> r = p - a - u * e1;
        const double l = e2.squaredNorm();
        const double v = l > 0.0 ? std::clamp(r.dot(e2) / l, 0.0, 1.0 - u) : 0.0;
        return (r - v * e2).squaredNorm();
    });
}

/// Brute force: min over s, t in [0, 1] of |a0 + s ea - b0 - t eb|^2 likewise.
double brute_edge_edge(const Vec<3>& a0, const Vec<3>& a1, const Vec<3>& b0, const Vec<3>& b1) {
    const Vec<3> ea = a1 - a0, eb = b1 - b0;
    return golden_minimum([&](double s) {
        const Vec<3> r = a0 + s * ea - b0;
        const double l = eb.squaredNorm();
        const double t = l > 0.0 ? std::clamp(r.dot(eb) / l, 0.0, 1.0) : 0.0;
        return (r - t * eb).squaredNorm();
    });
}

/// A unit vector orthogonal to n (unit), at a random angle.
Vec<3> random_tangent(test::Random& random, const Vec<3>& n) {
    for (;;) {
        const Vec<3> v = random.uniform_vec<3>(-1.0, 1.0);
        const Vec<3> t = v - v.dot(n) * n;
        if (t.norm() > 0.1) return t.normalized();
    }
}

Vec<3> random_unit(test::Random& random) {
    for (;;) {
        const Vec<3> v = random.uniform_vec<3>(-1.0, 1.0);
        if (v.norm() > 0.1 && v.norm() < 1.0) return v.normalized();
    }
}

// ---------------------------------------------------------------------------
// Point-triangle configurations.

/// A random well-shaped triangle (every corner angle's sine above 0.3) with its unit
/// normal and the in-plane outward unit normals of its edges AB, BC, CA.
struct Triangle {
    Vec<3> a, b, c, n;
    std::array<Vec<3>, 3> outward;  // AB, BC, CA

    explicit Triangle(test::Random& random) {
        for (;;) {
            a = random.uniform_vec<3>(-1.0, 1.0);
            b = random.uniform_vec<3>(-1.0, 1.0);
            c = random.uniform_vec<3>(-1.0, 1.0);
            const auto sine = [](const Vec<3>& u, const Vec<3>& v) {
                return u.cross(v).norm() / (u.norm() * v.norm());
            };
            if ((b - a).norm() > 0.5 && (c - b).norm() > 0.5 && (a - c).norm() > 0.5 && sine(b - a, c - a) > 0.3 &&
                sine(a - b, c - b) > 0.3 && sine(a - c, b - c) > 0.3)
                break;
        }
        n = (b - a).cross(c - a).normalized();
        const std::array<Vec<3>, 3> from = {a, b, c}, to = {b, c, a}, opposite = {c, a, b};
        for (int i = 0; i < 3; ++i) {
            Vec<3> m = (to[i] - from[i]).cross(n).normalized();
            if (m.dot(opposite[i] - from[i]) > 0.0) m = -m;
            outward[i] = m;
        }
    }
    const Vec<3>& corner(int i) const { return i == 0 ? a : i == 1 ? b : c; }
};

/// p in the region of case k: the closest point q on the feature and p = q + an offset
/// strictly inside the feature's normal cone (the cone spanned by the adjacent edges'
/// outward normals at a corner, the edge's outward normal on an edge, both +-n).
Vec<3> point_in_case(test::Random& random, const Triangle& T, PointTriangleCase k) {
    const double h = random.uniform(-1.0, 1.0);
    switch (k) {
        case PointTriangleCase::VertexA:
        case PointTriangleCase::VertexB:
        case PointTriangleCase::VertexC: {
            const int i = static_cast<int>(k);  // corner i joins edges i (starting there) and i - 1
            const double along_first = random.uniform(0.05, 1.0), along_second = random.uniform(0.05, 1.0);
            return T.corner(i) + along_first * T.outward[i] + along_second * T.outward[(i + 2) % 3] + h * T.n;
        }
        case PointTriangleCase::EdgeAB:
        case PointTriangleCase::EdgeBC:
        case PointTriangleCase::EdgeCA: {
            const int i = static_cast<int>(k) - 3;
            const double t = random.uniform(0.05, 0.95), out = random.uniform(0.05, 1.0);
            return T.corner(i) + t * (T.corner((i + 1) % 3) - T.corner(i)) + out * T.outward[i] + h * T.n;
        }
        case PointTriangleCase::Interior: {
            Vec<3> w = random.uniform_vec<3>(0.1, 1.0);
            w /= w.sum();
            const double side = random.uniform(0.05, 1.0) * (h < 0.0 ? -1.0 : 1.0);
            return w[0] * T.a + w[1] * T.b + w[2] * T.c + side * T.n;
        }
    }
    return Vec<3>::Zero();
}

constexpr PointTriangleCase kPointTriangleCases[7] = {
    PointTriangleCase::VertexA, PointTriangleCase::VertexB, PointTriangleCase::VertexC, PointTriangleCase::EdgeAB,
    PointTriangleCase::EdgeBC,  PointTriangleCase::EdgeCA,  PointTriangleCase::Interior};

/// The functions of one kind of primitive pair, point-triangle or edge-edge (four points x and
/// a case k), for the checks the two kinds share.
template <typename Case>
struct PairDistance {
    template <typename Result, typename... Extra>
    using Function = Result (*)(const Vec<3>&, const Vec<3>&, const Vec<3>&, const Vec<3>&, Extra...);
    Function<Case> select;                  // the case
    Function<double, Case> value;           // the case's squared distance
    Function<Vec12, Case> gradient;         // ... its gradient
    Function<Mat12, Case> hessian;          // ... its Hessian
    Function<double> distance_sq;           // the squared distance, case chosen by select
    Function<double> brute_force;           // the same, by brute force (no cases)

    template <typename Result, typename... Extra>
    static Result at(Function<Result, Extra...> f, const Quad& x, Extra... k) {
        return f(x[0], x[1], x[2], x[3], k...);
    }
};

const PairDistance<PointTriangleCase> kPointTriangle{point_triangle_case,
                                                     point_triangle_distance_sq,
                                                     point_triangle_distance_sq_gradient,
                                                     point_triangle_distance_sq_hessian,
                                                     point_triangle_distance_sq,
                                                     brute_point_triangle};

/// Compares the case's gradient and Hessian with central differences (its value / its
/// gradient), the case held fixed.
template <typename Case>
void check_case_derivatives(const PairDistance<Case>& d, const Quad& x, Case k, test::FdStats& fd) {
    using D = PairDistance<Case>;
    auto f = [&](const Eigen::VectorXd& q) { return D::at(d.value, unstack(q), k); };
    auto grad = [&](const Eigen::VectorXd& q) { return Eigen::VectorXd(D::at(d.gradient, unstack(q), k)); };
    const Vec12 g = D::at(d.gradient, x, k);
    const Mat12 H = D::at(d.hessian, x, k);
    EXPECT_TRUE(test::check_gradient(f, g, stack(x), fd, 1e-6, 1e-6)) << "case " << static_cast<int>(k);
    EXPECT_TRUE(test::check_jacobian(grad, H, stack(x), fd, 1e-6, 1e-6)) << "case " << static_cast<int>(k);
    EXPECT_LE((H - H.transpose()).cwiseAbs().maxCoeff(), 1e-12 * (1.0 + H.cwiseAbs().maxCoeff()));
}

/// x, built to lie in case k, does: the selector picks k, the case's value is the brute-force
/// distance and the case-free one, and its derivatives match finite differences.
template <typename Case>
void expect_in_case(const PairDistance<Case>& d, const Quad& x, Case k, test::FdStats& fd, int trial) {
    using D = PairDistance<Case>;
    ASSERT_EQ(D::at(d.select, x), k) << "trial " << trial;
    const double s = D::at(d.value, x, k);
    const double reference = D::at(d.brute_force, x);
    EXPECT_NEAR(s, reference, 1e-12 * (1.0 + reference)) << "case " << static_cast<int>(k);
    EXPECT_EQ(D::at(d.distance_sq, x), s);
    check_case_derivatives(d, x, k, fd);
}

/// x lies on the boundary between cases `minus` and `plus`, x_minus and x_plus just off it on
/// either side: on it both formulas give the (brute-force) distance and the same gradient; off
/// it the selector picks each side's case and the gradients differ by O(delta) only. Returns
/// the distance on the boundary.
template <typename Case>
double expect_c1_across(const PairDistance<Case>& d, const Quad& x, Case minus, Case plus, const Quad& x_minus,
                        const Quad& x_plus) {
    using D = PairDistance<Case>;
    const double s_minus = D::at(d.value, x, minus), s_plus = D::at(d.value, x, plus);
    EXPECT_NEAR(s_minus, s_plus, 1e-13 * (1.0 + s_plus));
    EXPECT_NEAR(s_plus, D::at(d.brute_force, x), 1e-12 * (1.0 + s_plus));
    const Vec12 g_minus = D::at(d.gradient, x, minus), g_plus = D::at(d.gradient, x, plus);
    EXPECT_LE((g_minus - g_plus).norm(), 1e-11 * (1.0 + g_plus.norm()))
        << "cases " << static_cast<int>(minus) << " / " << static_cast<int>(plus);
    EXPECT_EQ(D::at(d.select, x_minus), minus);
    EXPECT_EQ(D::at(d.select, x_plus), plus);
    const Vec12 g0 = D::at(d.gradient, x_minus, minus), g1 = D::at(d.gradient, x_plus, plus);
    EXPECT_LE((g0 - g1).norm(), 1e-5 * (1.0 + g1.norm()));
    return s_plus;
}

TEST(PointTriangleDistance, EveryCaseMatchesBruteForceAndFiniteDifferences) {
    test::Random random(31);
    test::FdStats fd;
    constexpr int kPerCase = 25;
    for (PointTriangleCase k : kPointTriangleCases)
        for (int trial = 0; trial < kPerCase; ++trial) {
            const Triangle T(random);
            const Vec<3> p = point_in_case(random, T, k);
            ASSERT_NO_FATAL_FAILURE(expect_in_case(kPointTriangle, {p, T.a, T.b, T.c}, k, fd, trial));
        }
    EXPECT_EQ(fd.checks, 7 * kPerCase * (12 + 144)) << "every entry of every case was compared";
}

/// The boundary between two neighbouring cases: p on it, and the direction that
/// crosses it from case `minus` to case `plus`.
struct Boundary {
    Vec<3> p, across;
    PointTriangleCase minus, plus;
};

/// The 9 boundaries of the point-triangle cases: the interior against each edge (p over
/// the edge, crossing along its outward normal), each edge against its two corners (p in
/// the plane through the corner perpendicular to the edge, crossing along the edge).
std::vector<Boundary> point_triangle_boundaries(test::Random& random, const Triangle& T) {
    using K = PointTriangleCase;
    const K edges[3] = {K::EdgeAB, K::EdgeBC, K::EdgeCA}, corners[3] = {K::VertexA, K::VertexB, K::VertexC};
    std::vector<Boundary> out;
    for (int i = 0; i < 3; ++i) {
        const Vec<3>&from = T.corner(i), &to = T.corner((i + 1) % 3);
        const Vec<3> along = (to - from).normalized();
        const double t = random.uniform(0.1, 0.9), height = random.uniform(-1.0, 1.0);
        out.push_back({from + t * (to - from) + height * T.n, T.outward[i], K::Interior, edges[i]});
        const double out_of_edge = random.uniform(0.1, 1.0), out_of_plane = random.uniform(-1.0, 1.0);
        const Vec<3> beside = out_of_edge * T.outward[i] + out_of_plane * T.n;
        out.push_back({from + beside, along, corners[i], edges[i]});
        out.push_back({to + beside, -along, corners[(i + 1) % 3], edges[i]});
    }
    return out;
}

TEST(PointTriangleDistance, IsC1AcrossCaseBoundaries) {
    test::Random random(32);
    int boundaries = 0;
    for (int trial = 0; trial < 20; ++trial) {
        const Triangle T(random);
        for (const Boundary& B : point_triangle_boundaries(random, T)) {
            ++boundaries;
            const double delta = 1e-7;
            const Vec<3> p_minus = B.p - delta * B.across, p_plus = B.p + delta * B.across;
            const double s_plus = expect_c1_across(kPointTriangle, {B.p, T.a, T.b, T.c}, B.minus, B.plus,
                                                   {p_minus, T.a, T.b, T.c}, {p_plus, T.a, T.b, T.c});
            EXPECT_NEAR(point_triangle_distance_sq(p_minus, T.a, T.b, T.c),
                        point_triangle_distance_sq(p_plus, T.a, T.b, T.c), 1e-5 * (1.0 + s_plus));
        }
    }
    EXPECT_EQ(boundaries, 20 * 9);
}

TEST(PointTriangleDistance, DegenerateTrianglesAreFiniteAndExact) {
    test::Random random(33);
    test::FdStats fd;
    int checked = 0;
    for (int trial = 0; trial < 50; ++trial) {
        const Vec<3> a = random.uniform_vec<3>(-1.0, 1.0), b = random.uniform_vec<3>(-1.0, 1.0);
        const Vec<3> off = random_tangent(random, (b - a).normalized());
        const Vec<3> p = random.uniform_vec<3>(-1.5, 1.5);
        // Collinear corners, a corner repeated, all three equal, and nearly collinear ones.
        const double lambda = trial % 2 == 0 ? random.uniform(0.1, 0.9) : random.uniform(1.1, 1.5);
        const std::array<Vec<3>, 3> cs = {a + lambda * (b - a), a, a + 0.5 * (b - a) + 1e-13 * off};
        for (int variant = 0; variant < 4; ++variant) {
            const Vec<3> bb = variant == 3 ? a : b;  // all three equal: b = c = a
            const Vec<3> c = variant == 3 ? a : cs[variant];
            const PointTriangleCase k = point_triangle_case(p, a, bb, c);
            EXPECT_NE(k, PointTriangleCase::Interior) << "variant " << variant;
            const double s = point_triangle_distance_sq(p, a, bb, c, k);
            ASSERT_TRUE(std::isfinite(s));
            EXPECT_NEAR(s, brute_point_triangle(p, a, bb, c), 1e-11 * (1.0 + s)) << "variant " << variant;
            EXPECT_TRUE(point_triangle_distance_sq_gradient(p, a, bb, c, k).allFinite());
            EXPECT_TRUE(point_triangle_distance_sq_hessian(p, a, bb, c, k).allFinite());
            // The chosen case's formula never divides by a vanishing length: its derivatives are exact.
            if (variant != 3) check_case_derivatives(kPointTriangle, {p, a, bb, c}, k, fd);
            ++checked;
        }
    }
    EXPECT_EQ(checked, 200);
    EXPECT_EQ(fd.checks, 150 * (12 + 144));
}

// ---------------------------------------------------------------------------
// Edge-edge configurations.

/// Where the closest point lies on one segment: its start (0), its end (1), or inside.
enum class Param { Start, End, Inside };

struct EdgePair {
    Vec<3> a0, a1, b0, b1;
};

/// Segments whose closest points are a0 + s ea and b0 + t eb with s, t of the given kinds
/// and w = (a0 + s ea) - (b0 + t eb) satisfying the optimality conditions of the convex
/// quadratic |w(s, t)|^2 on [0, 1]^2: w.ea > 0 at s = 0, < 0 at s = 1, = 0 inside, and
/// w.eb < 0 at t = 0, > 0 at t = 1, = 0 inside (strict margins, so the minimum is unique);
/// `on_boundary_a` / `_b` put w.ea (w.eb) = 0 with s (t) at an end: the configuration then
/// lies on the boundary between the endpoint case and the edge case.
EdgePair edges_in_case(test::Random& random, Param s_kind, Param t_kind, bool on_boundary_a = false,
                       bool on_boundary_b = false) {
    for (;;) {
        const Vec<3> w_dir = random_unit(random);
        const Vec<3> w = random.uniform(0.05, 1.0) * w_dir;
        auto edge = [&](Param kind, bool on_boundary, double sign_at_start) {
            const double along_w = kind == Param::Inside || on_boundary ? 0.0
                                   : kind == Param::Start               ? sign_at_start * random.uniform(0.2, 1.0)
                                                                        : -sign_at_start * random.uniform(0.2, 1.0);
            const double length = random.uniform(0.3, 1.5);
            return Vec<3>(length * random_tangent(random, w_dir) + along_w * w_dir);
        };
        const Vec<3> ea = edge(s_kind, on_boundary_a, 1.0), eb = edge(t_kind, on_boundary_b, -1.0);
        // Nearly parallel edges: the line-line case needs an angle (the others do not).
        if (ea.cross(eb).norm() < 0.3 * ea.norm() * eb.norm() &&
            (s_kind == Param::Inside || t_kind == Param::Inside || on_boundary_a || on_boundary_b))
            continue;
        auto param = [&](Param kind) {
            return kind == Param::Start ? 0.0 : kind == Param::End ? 1.0 : random.uniform(0.1, 0.9);
        };
        const Vec<3> qa = random.uniform_vec<3>(-1.0, 1.0), qb = qa - w;
        EdgePair e;
        e.a0 = qa - param(s_kind) * ea;
        e.a1 = e.a0 + ea;
        e.b0 = qb - param(t_kind) * eb;
        e.b1 = e.b0 + eb;
        return e;
    }
}

struct EdgeEdgeCaseSpec {
    EdgeEdgeCase k;
    Param s, t;
};

constexpr EdgeEdgeCaseSpec kEdgeEdgeCases[9] = {
    {EdgeEdgeCase::A0B0, Param::Start, Param::Start},      {EdgeEdgeCase::A0B1, Param::Start, Param::End},
    {EdgeEdgeCase::A1B0, Param::End, Param::Start},        {EdgeEdgeCase::A1B1, Param::End, Param::End},
    {EdgeEdgeCase::A0EdgeB, Param::Start, Param::Inside},  {EdgeEdgeCase::A1EdgeB, Param::End, Param::Inside},
    {EdgeEdgeCase::B0EdgeA, Param::Inside, Param::Start},  {EdgeEdgeCase::B1EdgeA, Param::Inside, Param::End},
    {EdgeEdgeCase::Interior, Param::Inside, Param::Inside}};

const PairDistance<EdgeEdgeCase> kEdgeEdge{edge_edge_case,
                                           edge_edge_distance_sq,
                                           edge_edge_distance_sq_gradient,
                                           edge_edge_distance_sq_hessian,
                                           edge_edge_distance_sq,
                                           brute_edge_edge};

TEST(EdgeEdgeDistance, EveryCaseMatchesBruteForceAndFiniteDifferences) {
    test::Random random(41);
    test::FdStats fd;
    constexpr int kPerCase = 25;
    for (const EdgeEdgeCaseSpec& spec : kEdgeEdgeCases)
        for (int trial = 0; trial < kPerCase; ++trial) {
            const EdgePair e = edges_in_case(random, spec.s, spec.t);
            ASSERT_NO_FATAL_FAILURE(expect_in_case(kEdgeEdge, {e.a0, e.a1, e.b0, e.b1}, spec.k, fd, trial));
        }
    EXPECT_EQ(fd.checks, 9 * kPerCase * (12 + 144)) << "every entry of every case was compared";
}

/// A boundary between two neighbouring edge-edge cases: the configuration (s, t kinds with
/// one optimality condition at equality), which edge is translated along itself to cross
/// it, and the cases reached by translating forward (plus) and backward (minus).
struct EdgeBoundarySpec {
    Param s, t;
    bool on_boundary_a, on_boundary_b;
    int moved;  // 0: edge a, 1: edge b
    EdgeEdgeCase minus, plus;
};

TEST(EdgeEdgeDistance, IsC1AcrossCaseBoundaries) {
    using K = EdgeEdgeCase;
    // Translating a segment along itself leaves its line in place and shifts the
    // parameter of the closest point by -delta / |e|.
    const EdgeBoundarySpec specs[12] = {
        {Param::Start, Param::Inside, true, false, 0, K::Interior, K::A0EdgeB},
        {Param::End, Param::Inside, true, false, 0, K::A1EdgeB, K::Interior},
        {Param::Inside, Param::Start, false, true, 1, K::Interior, K::B0EdgeA},
        {Param::Inside, Param::End, false, true, 1, K::B1EdgeA, K::Interior},
        {Param::Start, Param::Start, false, true, 1, K::A0EdgeB, K::A0B0},
        {Param::Start, Param::End, false, true, 1, K::A0B1, K::A0EdgeB},
        {Param::End, Param::Start, false, true, 1, K::A1EdgeB, K::A1B0},
        {Param::End, Param::End, false, true, 1, K::A1B1, K::A1EdgeB},
        {Param::Start, Param::Start, true, false, 0, K::B0EdgeA, K::A0B0},
        {Param::End, Param::Start, true, false, 0, K::A1B0, K::B0EdgeA},
        {Param::Start, Param::End, true, false, 0, K::B1EdgeA, K::A0B1},
        {Param::End, Param::End, true, false, 0, K::A1B1, K::B1EdgeA},
    };
    test::Random random(42);
    int boundaries = 0;
    for (int trial = 0; trial < 20; ++trial)
        for (const EdgeBoundarySpec& spec : specs) {
            ++boundaries;
            const EdgePair e = edges_in_case(random, spec.s, spec.t, spec.on_boundary_a, spec.on_boundary_b);
            const double delta = 1e-7;
            auto shifted = [&](double sign) {
                EdgePair f = e;
                if (spec.moved == 0) {
                    const Vec<3> shift = sign * delta * (e.a1 - e.a0).normalized();
                    f.a0 += shift;
                    f.a1 += shift;
                } else {
                    const Vec<3> shift = sign * delta * (e.b1 - e.b0).normalized();
                    f.b0 += shift;
                    f.b1 += shift;
                }
                return f;
            };
            const EdgePair m = shifted(-1.0), p = shifted(1.0);
            expect_c1_across(kEdgeEdge, {e.a0, e.a1, e.b0, e.b1}, spec.minus, spec.plus, {m.a0, m.a1, m.b0, m.b1},
                             {p.a0, p.a1, p.b0, p.b1});
        }
    EXPECT_EQ(boundaries, 20 * 12);
}

TEST(EdgeEdgeDistance, ParallelAndDegenerateEdgesAreFiniteAndExact) {
    test::Random random(43);
    test::FdStats fd;
    int checked = 0;
    for (int trial = 0; trial < 50; ++trial) {
        const Vec<3> a0 = random.uniform_vec<3>(-1.0, 1.0), dir = random_unit(random);
        const Vec<3> a1 = a0 + random.uniform(0.3, 1.5) * dir, side = random_tangent(random, dir);
        const double shift = random.uniform(-1.0, 1.0), apart = random.uniform(0.01, 0.5);
        const Vec<3> b0 = a0 + shift * dir + apart * side;
        const double length = random.uniform(0.3, 1.5);
        const Vec<3> tilt = random_tangent(random, dir);
        const std::array<EdgePair, 5> variants = {
            EdgePair{a0, a1, b0, b0 + length * dir},                        // parallel
            EdgePair{a0, a1, b0, b0 - length * dir},                        // antiparallel
            EdgePair{a0, a1, b0, b0 + length * (dir + 1e-10 * tilt)},       // parallel to 1e-10 rad
            EdgePair{a0, a0, b0, b0 + length * (dir + 0.5 * tilt)},         // edge a of zero length
            EdgePair{a0, a1, a0 + 0.3 * (a1 - a0), a0 + 2.0 * (a1 - a0)}};  // collinear, overlapping
        for (int variant = 0; variant < 5; ++variant) {
            const EdgePair& e = variants[variant];
            const EdgeEdgeCase k = edge_edge_case(e.a0, e.a1, e.b0, e.b1);
            EXPECT_NE(k, EdgeEdgeCase::Interior) << "variant " << variant;
            const double s = edge_edge_distance_sq(e.a0, e.a1, e.b0, e.b1, k);
            ASSERT_TRUE(std::isfinite(s));
            const double reference = brute_edge_edge(e.a0, e.a1, e.b0, e.b1);
            // Nearly parallel: the endpoint/edge cases overestimate by at most |ea| sin(angle).
            const double tolerance = variant == 2 ? 4.0 * std::sqrt(reference) * 1.5e-10 + 1e-12 : 1e-12;
            EXPECT_NEAR(s, reference, tolerance) << "variant " << variant;
            EXPECT_GE(s, reference - 1e-12) << "the segments' distance is the smallest";
            EXPECT_TRUE(edge_edge_distance_sq_gradient(e.a0, e.a1, e.b0, e.b1, k).allFinite());
            EXPECT_TRUE(edge_edge_distance_sq_hessian(e.a0, e.a1, e.b0, e.b1, k).allFinite());
            if (variant < 4) check_case_derivatives(kEdgeEdge, {e.a0, e.a1, e.b0, e.b1}, k, fd);
            if (variant == 4) {
                EXPECT_LE(s, 1e-28) << "collinear overlapping segments touch";
            }
            ++checked;
        }
    }
    EXPECT_EQ(checked, 250);
    EXPECT_EQ(fd.checks, 200 * (12 + 144));
}

// ---------------------------------------------------------------------------
// The mollifier.

/// Two edges at an angle whose sin^2 is `sin_sq`, and their rest positions (the same).
EdgePair edges_at_angle(test::Random& random, double sin_sq) {
    const Vec<3> dir = random_unit(random), tilt = random_tangent(random, dir);
    const double angle = std::asin(std::sqrt(sin_sq));
    const Vec<3> a0 = random.uniform_vec<3>(-1.0, 1.0);
    const Vec<3> b0 = a0 + random.uniform_vec<3>(-0.3, 0.3);
    const double la = random.uniform(0.3, 1.5), lb = random.uniform(0.3, 1.5);
    return {a0, a0 + la * dir, b0, b0 + lb * (std::cos(angle) * dir + std::sin(angle) * tilt)};
}

TEST(EdgeEdgeMollifier, DerivativesMatchFiniteDifferencesBelowTheThreshold) {
    test::Random random(51);
    test::FdStats fd;
    constexpr int kTrials = 40;
    for (int trial = 0; trial < kTrials; ++trial) {
        // c / eps = sin^2 / 1e-3 in (0.05, 0.95) with the rest shape the current one.
        const EdgePair e = edges_at_angle(random, 1e-3 * random.uniform(0.05, 0.95));
        // Rest positions rotated and translated: the same threshold.
        const Mat<3> R = random.rotation<3>();
        const double eps =
            edge_edge_mollifier_threshold(R * e.a0, R * e.a1, R * e.b0 + Vec<3>::Ones(), R * e.b1 + Vec<3>::Ones());
        EXPECT_NEAR(eps, 1e-3 * (e.a1 - e.a0).squaredNorm() * (e.b1 - e.b0).squaredNorm(), 1e-15);
        const double m = edge_edge_mollifier(e.a0, e.a1, e.b0, e.b1, eps);
        EXPECT_GT(m, 0.0);
        EXPECT_LT(m, 1.0);
        auto f = [eps](const Eigen::VectorXd& q) {
            const Quad y = unstack(q);
            return edge_edge_mollifier(y[0], y[1], y[2], y[3], eps);
        };
        auto grad = [eps](const Eigen::VectorXd& q) {
            const Quad y = unstack(q);
            return Eigen::VectorXd(edge_edge_mollifier_gradient(y[0], y[1], y[2], y[3], eps));
        };
        const Eigen::VectorXd q = stack({e.a0, e.a1, e.b0, e.b1});
        const Vec12 g = edge_edge_mollifier_gradient(e.a0, e.a1, e.b0, e.b1, eps);
        const Mat12 H = edge_edge_mollifier_hessian(e.a0, e.a1, e.b0, e.b1, eps);
        EXPECT_TRUE(test::check_gradient(f, g, q, fd, 1e-7, 1e-6)) << "trial " << trial;
        EXPECT_TRUE(test::check_jacobian(grad, H, q, fd, 1e-7, 1e-6)) << "trial " << trial;
    }
    EXPECT_EQ(fd.checks, kTrials * (12 + 144));
}

TEST(EdgeEdgeMollifier, IsOneAboveTheThresholdAndC1AtIt) {
    test::Random random(52);
    for (int trial = 0; trial < 40; ++trial) {
        const EdgePair e = edges_at_angle(random, random.uniform(1.1e-3, 1.0));
        const double eps = edge_edge_mollifier_threshold(e.a0, e.a1, e.b0, e.b1);
        EXPECT_EQ(edge_edge_mollifier(e.a0, e.a1, e.b0, e.b1, eps), 1.0);
        EXPECT_TRUE(edge_edge_mollifier_gradient(e.a0, e.a1, e.b0, e.b1, eps).isZero(0.0));
        EXPECT_TRUE(edge_edge_mollifier_hessian(e.a0, e.a1, e.b0, e.b1, eps).isZero(0.0));
        // Parallel edges: m = 0.
        const EdgePair p = edges_at_angle(random, 0.0);
        EXPECT_NEAR(edge_edge_mollifier(p.a0, p.a1, p.b0, p.b1, edge_edge_mollifier_threshold(p.a0, p.a1, p.b0, p.b1)),
                    0.0, 1e-12);
        // C1 at the threshold: with eps just above c, m -> 1 and its gradient -> 0, against the
        // same edges' gradient with eps = 2c (m' = 2 (1 - c / eps) / eps: a ratio of 4e-8).
        const double c = (e.a1 - e.a0).cross(e.b1 - e.b0).squaredNorm();
        EXPECT_NEAR(edge_edge_mollifier(e.a0, e.a1, e.b0, e.b1, c * (1.0 + 1e-8)), 1.0, 1e-14);
        const double g_tight = edge_edge_mollifier_gradient(e.a0, e.a1, e.b0, e.b1, c * (1.0 + 1e-8)).norm();
        const double g_wide = edge_edge_mollifier_gradient(e.a0, e.a1, e.b0, e.b1, 2.0 * c).norm();
        EXPECT_GT(g_wide, 0.0);
        EXPECT_NEAR(g_tight / g_wide, 4e-8, 1e-10);
        EXPECT_EQ(edge_edge_mollifier(e.a0, e.a1, e.b0, e.b1, c * (1.0 - 1e-12)), 1.0);
    }
}

}  // namespace
}  // namespace pnet
