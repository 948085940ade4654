// Additive CCD of IPC's 3D primitives on constructed motions whose time of impact
// t* is known in closed form (point-triangle head-on, grazing, in the triangle's
// plane; edge-edge crossing, parallel; degenerate motions): the result is never
// later than t*, at least 0.5 eta t*, and the pair moved to it is apart. A random
// stress test certifies, with a Lipschitz bound on the distance over finely
// sampled intervals, that no pair touches before the time returned.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <functional>

#include "pnet/contact/ccd/point_triangle_edge_edge.hpp"
#include "pnet/contact/distance/point_triangle_edge_edge.hpp"
#include "support/random.hpp"

namespace pnet {
namespace {

using Quad = std::array<Vec<3>, 4>;

constexpr double kEta = 0.9;

double pt_distance(const Quad& x, const Quad& dx, double t) {
    return std::sqrt(
        point_triangle_distance_sq(x[0] + t * dx[0], x[1] + t * dx[1], x[2] + t * dx[2], x[3] + t * dx[3]));
}

double ee_distance(const Quad& x, const Quad& dx, double t) {
    return std::sqrt(edge_edge_distance_sq(x[0] + t * dx[0], x[1] + t * dx[1], x[2] + t * dx[2], x[3] + t * dx[3]));
}

double pt_toi(const Quad& x, const Quad& dx, double min_distance = 0.0, double t_max = 1.0) {
    return point_triangle_time_of_impact(x[0], x[1], x[2], x[3], dx[0], dx[1], dx[2], dx[3], min_distance, t_max, kEta);
}

double ee_toi(const Quad& x, const Quad& dx, double min_distance = 0.0, double t_max = 1.0) {
    return edge_edge_time_of_impact(x[0], x[1], x[2], x[3], dx[0], dx[1], dx[2], dx[3], min_distance, t_max, kEta);
}

/// The result t against the exact time of impact t_star: not later, not needlessly early,
/// and the pair at t is still apart (by more than min_distance).
void expect_safe_and_tight(double t, double t_star, double distance_at_t, double min_distance = 0.0) {
    EXPECT_LE(t, t_star);
    EXPECT_GE(t, 0.5 * kEta * t_star) << "needlessly conservative";
    EXPECT_GT(distance_at_t, min_distance);
}

const Quad kTriangleAtOrigin = {Vec<3>::Zero(), Vec<3>(0, 0, 0), Vec<3>(1, 0, 0), Vec<3>(0, 1, 0)};  // p set per case
const Vec<3> kZero = Vec<3>::Zero();

TEST(Ccd3d, PointTriangleConstructedMotions) {
    Quad x = kTriangleAtOrigin;
    // Head-on: a point falling onto the inside of a resting triangle, t* = 0.5.
    x[0] = Vec<3>(0.2, 0.3, 0.5);
    Quad dx = {Vec<3>(0, 0, -1), kZero, kZero, kZero};
    double t = pt_toi(x, dx);
    expect_safe_and_tight(t, 0.5, pt_distance(x, dx, t));
    EXPECT_GE(t, kEta * 0.5 - 1e-12) << "one exact step head-on";
    // The triangle rising to meet the point: t* = 0.25.
    dx = {Vec<3>(0, 0, -1), Vec<3>(0, 0, 1), Vec<3>(0, 0, 1), Vec<3>(0, 0, 1)};
    t = pt_toi(x, dx);
    expect_safe_and_tight(t, 0.25, pt_distance(x, dx, t));
    // Grazing: a point gliding over the triangle at a shallow angle, z = 0.05 - 0.1 t, reaching
    // the inside (0.6, 0.3, 0) at t* = 0.5.
    x[0] = Vec<3>(0.1, 0.3, 0.05);
    dx = {Vec<3>(1, 0, -0.1), kZero, kZero, kZero};
    t = pt_toi(x, dx);
    expect_safe_and_tight(t, 0.5, pt_distance(x, dx, t));
    // Gliding parallel to it, never closer: no impact.
    dx = {Vec<3>(2, 0, 0), kZero, kZero, kZero};
    EXPECT_EQ(pt_toi(x, dx), kNoImpact);
    // Moving away: none either.
    dx = {Vec<3>(0, 0, 1), kZero, kZero, kZero};
    EXPECT_EQ(pt_toi(x, dx), kNoImpact);
    // A point moving in the triangle's plane onto its edge x = 0 (the edge CA), t* = 0.5.
    x[0] = Vec<3>(-0.5, 0.3, 0.0);
    dx = {Vec<3>(1, 0, 0), kZero, kZero, kZero};
    t = pt_toi(x, dx);
    expect_safe_and_tight(t, 0.5, pt_distance(x, dx, t));
    // ... and onto its corner b = (1, 0, 0) along the x axis, t* = 0.5.
    x[0] = Vec<3>(2.0, 0.0, 0.0);
    dx = {Vec<3>(-2, 0, 0), kZero, kZero, kZero};
    t = pt_toi(x, dx);
    expect_safe_and_tight(t, 0.5, pt_distance(x, dx, t));
    // A triangle spinning about its corner a (the z axis) in its plane onto a point beside
    // it: the edge ab (then the corner b, linearized: b moves on the chord) sweeps it. t* by
    // bisection on the orientation of p against the edge ab.
    x[0] = Vec<3>(0.5, -0.25, 0.0);
    const double angle = -1.2;
    dx = {kZero, kZero, Vec<3>(std::cos(angle) - 1.0, std::sin(angle), 0.0),
          Vec<3>(-std::sin(angle), std::cos(angle) - 1.0, 0.0)};
    double lo = 0.0, hi = 1.0;
    const auto side = [&](double s) {
        const Vec<3> e = x[2] + s * dx[2] - x[1];
        return e[0] * x[0][1] - e[1] * x[0][0];  // cross(e, p - a), a = 0
    };
    ASSERT_LT(side(0.0) * side(1.0), 0.0);
    for (int k = 0; k < 100; ++k) (side(0.5 * (lo + hi)) * side(0.0) > 0.0 ? lo : hi) = 0.5 * (lo + hi);
    t = pt_toi(x, dx);
    expect_safe_and_tight(t, hi, pt_distance(x, dx, t));
    // A gap min_distance = 0.1: head-on from 0.5, t* = (0.5 - 0.1) / 1 = 0.4.
    x[0] = Vec<3>(0.2, 0.3, 0.5);
    dx = {Vec<3>(0, 0, -1), kZero, kZero, kZero};
    t = pt_toi(x, dx, 0.1);
    expect_safe_and_tight(t, 0.4, pt_distance(x, dx, t), 0.1);
    // t_max: nothing happens before 0.3 (kNoImpact), but before 0.6 it does.
    EXPECT_EQ(pt_toi(x, dx, 0.0, 0.3), kNoImpact);
    EXPECT_LE(pt_toi(x, dx, 0.0, 0.6), 0.5);
    // Repeated CCD: stepping to the returned time again and again never reaches the triangle.
    double travelled = 0.0;
    Quad y = x;
    for (int k = 0; k < 30; ++k) {
        Quad rest = dx;
        for (Vec<3>& v : rest) v *= 1.0 - travelled;
        const double step = pt_toi(y, rest);
        ASSERT_GE(step, 0.0);
        if (step == kNoImpact) break;
        for (int i = 0; i < 4; ++i) y[i] += step * rest[i];
        travelled += step * (1.0 - travelled);
        ASSERT_GT(y[0][2], 0.0) << "repeat " << k;
    }
    EXPECT_GT(travelled, 0.49);
}

TEST(Ccd3d, EdgeEdgeConstructedMotions) {
    // Crossing: edge b across edge a, 0.4 above it, falling: t* = 0.4.
    Quad x = {Vec<3>(0, 0, 0), Vec<3>(1, 0, 0), Vec<3>(0.5, -0.5, 0.4), Vec<3>(0.5, 0.5, 0.4)};
    Quad dx = {kZero, kZero, Vec<3>(0, 0, -1), Vec<3>(0, 0, -1)};
    double t = ee_toi(x, dx);
    expect_safe_and_tight(t, 0.4, ee_distance(x, dx, t));
    EXPECT_GE(t, kEta * 0.4 - 1e-12) << "one exact step head-on";
    // Both move toward each other, b also sliding along a: t* = 0.2.
    dx = {Vec<3>(0, 0, 1), Vec<3>(0, 0, 1), Vec<3>(0.3, 0, -1), Vec<3>(0.3, 0, -1)};
    t = ee_toi(x, dx);
    expect_safe_and_tight(t, 0.2, ee_distance(x, dx, t));
    // Passing beside each other (b moves along y past the end of a): no impact.
    x = {Vec<3>(0, 0, 0), Vec<3>(1, 0, 0), Vec<3>(1.2, -0.5, 0.1), Vec<3>(1.2, 0.5, -0.1)};
    dx = {kZero, kZero, Vec<3>(0, 1.5, 0), Vec<3>(0, 1.5, 0)};
    EXPECT_EQ(ee_toi(x, dx), kNoImpact);
    // Parallel edges, overlapping, approaching: t* = 0.3 (the case stays endpoint-edge).
    x = {Vec<3>(0, 0, 0), Vec<3>(1, 0, 0), Vec<3>(0.2, 0, 0.3), Vec<3>(1.2, 0, 0.3)};
    dx = {kZero, kZero, Vec<3>(0, 0, -1), Vec<3>(0, 0, -1)};
    t = ee_toi(x, dx);
    expect_safe_and_tight(t, 0.3, ee_distance(x, dx, t));
    // Parallel edges sliding along each other: no impact.
    dx = {kZero, kZero, Vec<3>(2, 0, 0), Vec<3>(2, 0, 0)};
    EXPECT_EQ(ee_toi(x, dx), kNoImpact);
    // Collinear edges, end to end, closing the gap a1 = (1, 0, 0) .. b0 = (1.5, 0, 0): t* = 0.25.
    x = {Vec<3>(0, 0, 0), Vec<3>(1, 0, 0), Vec<3>(1.5, 0, 0), Vec<3>(2.5, 0, 0)};
    dx = {kZero, kZero, Vec<3>(-2, 0, 0), Vec<3>(-2, 0, 0)};
    t = ee_toi(x, dx);
    expect_safe_and_tight(t, 0.25, ee_distance(x, dx, t));
    // Edge b, level at height z = 0.3 - 0.6 t, turning while it descends: its end b0 lands
    // on the inside of edge a (on the x axis) at t* = 0.5.
    x = {Vec<3>(0, 0, 0), Vec<3>(1, 0, 0), Vec<3>(0.5, 0.0, 0.3), Vec<3>(0.5, 1.0, 0.3)};
    dx = {kZero, kZero, Vec<3>(0, 0, -0.6), Vec<3>(0.4, -0.2, -0.6)};
    t = ee_toi(x, dx);
    expect_safe_and_tight(t, 0.5, ee_distance(x, dx, t));
    // A gap min_distance = 0.05 in the crossing: t* = 0.4 - 0.05.
    x = {Vec<3>(0, 0, 0), Vec<3>(1, 0, 0), Vec<3>(0.5, -0.5, 0.4), Vec<3>(0.5, 0.5, 0.4)};
    dx = {kZero, kZero, Vec<3>(0, 0, -1), Vec<3>(0, 0, -1)};
    t = ee_toi(x, dx, 0.05);
    expect_safe_and_tight(t, 0.35, ee_distance(x, dx, t), 0.05);
    EXPECT_EQ(ee_toi(x, dx, 0.0, 0.2), kNoImpact);
}

TEST(Ccd3d, DegenerateMotions) {
    Quad x = kTriangleAtOrigin;
    x[0] = Vec<3>(0.2, 0.3, 0.5);
    // No motion, and a common translation: nothing changes.
    EXPECT_EQ(pt_toi(x, {kZero, kZero, kZero, kZero}), kNoImpact);
    const Vec<3> drift(0.3, -2.0, 5.0);
    EXPECT_EQ(pt_toi(x, {drift, drift, drift, drift}), kNoImpact);
    const Quad edges = {Vec<3>(0, 0, 0), Vec<3>(1, 0, 0), Vec<3>(0.5, -0.5, 0.4), Vec<3>(0.5, 0.5, 0.4)};
    EXPECT_EQ(ee_toi(edges, {kZero, kZero, kZero, kZero}), kNoImpact);
    EXPECT_EQ(ee_toi(edges, {drift, drift, drift, drift}), kNoImpact);
    // Already touching (or within the gap): no motion is safe.
    x[0] = Vec<3>(0.2, 0.3, 0.0);
    EXPECT_EQ(pt_toi(x, {Vec<3>(0, 0, 1), kZero, kZero, kZero}), 0.0);
    x[0] = Vec<3>(0.2, 0.3, 0.01);
    EXPECT_EQ(pt_toi(x, {Vec<3>(0, 0, 1), kZero, kZero, kZero}, 0.02), 0.0);
    const Quad crossing = {Vec<3>(0, 0, 0), Vec<3>(1, 0, 0), Vec<3>(0.5, -0.5, 0), Vec<3>(0.5, 0.5, 0)};
    EXPECT_EQ(ee_toi(crossing, {kZero, kZero, Vec<3>(0, 0, 1), Vec<3>(0, 0, 1)}), 0.0);
    // A degenerate (collinear) triangle struck by a point: it still stops before it.
    const Quad flat = {Vec<3>(0.5, 0.5, 0.5), Vec<3>(0, 0, 0), Vec<3>(1, 1, 0), Vec<3>(0.25, 0.25, 0)};
    const Quad down = {Vec<3>(0, 0, -1), kZero, kZero, kZero};
    const double t = pt_toi(flat, down);
    expect_safe_and_tight(t, 0.5, pt_distance(flat, down, t));
    // Zero-length edge (a point) falling onto an edge.
    const Quad dot_and_edge = {Vec<3>(0.5, 0, 0.2), Vec<3>(0.5, 0, 0.2), Vec<3>(0, 0, 0), Vec<3>(1, 0, 0)};
    const Quad fall = {Vec<3>(0, 0, -1), Vec<3>(0, 0, -1), kZero, kZero};
    const double t2 = ee_toi(dot_and_edge, fall);
    expect_safe_and_tight(t2, 0.2, ee_distance(dot_and_edge, fall, t2));
}

TEST(Ccd3d, PointPlane) {
    const Vec<3> up(0, 0, 1);
    EXPECT_NEAR(point_plane_time_of_impact(Vec<3>(1, 2, 1), Vec<3>(3, 0, -2), Vec<3>::Zero(), up), 0.9 * 0.5, 1e-15);
    EXPECT_NEAR(point_plane_time_of_impact(Vec<3>(0, 0, 1), Vec<3>(0, 0, -4), Vec<3>(5, 5, 0), up, 1.0, 0.5),
                0.5 * 0.25, 1e-15);
    EXPECT_EQ(point_plane_time_of_impact(Vec<3>(0, 0, 1), Vec<3>(0, 0, 2), Vec<3>::Zero(), up), kNoImpact);
    EXPECT_EQ(point_plane_time_of_impact(Vec<3>(0, 0, 1), Vec<3>(1, 0, 0), Vec<3>::Zero(), up), kNoImpact);
    EXPECT_EQ(point_plane_time_of_impact(Vec<3>(0, 0, 1), Vec<3>(0, 0, -0.5), Vec<3>::Zero(), up), kNoImpact)
        << "the plane is reached only at t = 2 > t_max";
    EXPECT_EQ(point_plane_time_of_impact(Vec<3>(0, 0, -0.1), Vec<3>(0, 0, 1), Vec<3>::Zero(), up), 0.0);
    const Vec<3> n = Vec<3>(1, 1, 1).normalized();
    EXPECT_NEAR(point_plane_time_of_impact(n, -n, Vec<3>::Zero(), n), 0.9, 1e-15);
}

/// True when the distance d(t) (Lipschitz with constant L) stays positive on [t0, t1]: an
/// interval is safe when d(t0) + d(t1) > L (t1 - t0) (d cannot reach 0 inside it), else it
/// is bisected, to a depth of 40.
bool certified_apart(const std::function<double(double)>& d, double L, double t0, double t1, double d0, double d1,
                     int depth = 0) {
    if (!(d0 > 0.0) || !(d1 > 0.0)) return false;
    if (d0 + d1 > L * (t1 - t0)) return true;
    if (depth == 40) return false;
    const double tm = 0.5 * (t0 + t1), dm = d(tm);
    return certified_apart(d, L, t0, tm, d0, dm, depth + 1) && certified_apart(d, L, tm, t1, dm, d1, depth + 1);
}

/// The pair does not touch on [0, t] (t = 1 for kNoImpact), on 1000 samples and between them.
::testing::AssertionResult apart_until(const std::function<double(double)>& d, double L, double t) {
    const double end = t == kNoImpact ? 1.0 : t;
    constexpr int kSamples = 1000;
    double previous = d(0.0);
    for (int k = 1; k <= kSamples; ++k) {
        const double tk = end * k / kSamples, dk = d(tk);
        if (!certified_apart(d, L, end * (k - 1) / kSamples, tk, previous, dk))
            return ::testing::AssertionFailure() << "touching (or too close to certify) in ["
                                                 << end * (k - 1) / kSamples << ", " << tk << "], t = " << t;
        previous = dk;
    }
    return ::testing::AssertionSuccess();
}

/// CCD's times of impact t over random motions, against a sampled stand-in t*: the first of 4000
/// steps where the distance is below 1e-3 of its start.
struct ImpactTally {
    int hits = 0;       // motions with t != kNoImpact
    int true_hits = 0;  // ... that also have a t*
    double ratio = 0.0;  // sum of t / t* over those

    void add(const std::function<double(double)>& distance, double t) {
        double t_star = kNoImpact;
        for (int k = 1; k <= 4000 && t_star == kNoImpact; ++k)
            if (distance(k / 4000.0) < 1e-3 * distance(0.0)) t_star = k / 4000.0;
        if (t != kNoImpact) ++hits;
        if (t_star != kNoImpact && t != kNoImpact) {
            ++true_hits;
            ratio += t / t_star;
        }
    }
    double mean_ratio() const { return ratio / true_hits; }
};

TEST(Ccd3d, RandomMotionsNeverTouchBeforeTheReturnedTime) {
    test::Random random(61);
    constexpr int kTrials = 3000;
    ImpactTally pt, ee;
    for (int trial = 0; trial < kTrials; ++trial) {
        // Point-triangle: the point starts near the triangle and is thrown at (or past) it.
        Quad x, dx;
        for (int i = 1; i < 4; ++i) x[i] = random.uniform_vec<3>(-1.0, 1.0);
        Vec<3> w = random.uniform_vec<3>(0.05, 1.0);
        w /= w.sum();
        const Vec<3> target = w[0] * x[1] + w[1] * x[2] + w[2] * x[3] + random.uniform_vec<3>(-0.3, 0.3);
        x[0] = target + random.uniform_vec<3>(-1.0, 1.0);
        dx[0] = random.uniform(0.5, 2.5) * (target - x[0]);
        for (int i = 1; i < 4; ++i) dx[i] = random.uniform_vec<3>(-0.3, 0.3);
        // A valid Lipschitz constant of the distance, independent of the implementation's.
        const double L = dx[0].norm() + std::max({dx[1].norm(), dx[2].norm(), dx[3].norm()});
        const double t = pt_toi(x, dx);
        ASSERT_GE(t, 0.0);
        ASSERT_TRUE(apart_until([&](double s) { return pt_distance(x, dx, s); }, L, t)) << "point-triangle " << trial;
        pt.add([&](double s) { return pt_distance(x, dx, s); }, t);

        // Edge-edge: edge b starts near edge a and is thrown at (or past) it.
        Quad y, dy;
        y[0] = random.uniform_vec<3>(-1.0, 1.0);
        y[1] = random.uniform_vec<3>(-1.0, 1.0);
        const Vec<3> aim = y[0] + random.uniform(0.0, 1.0) * (y[1] - y[0]) + random.uniform_vec<3>(-0.3, 0.3);
        const Vec<3> half = random.uniform_vec<3>(-0.7, 0.7), start = aim + random.uniform_vec<3>(-1.0, 1.0);
        y[2] = start - half;
        y[3] = start + half;
        const double speed = random.uniform(0.5, 2.5);
        dy = {random.uniform_vec<3>(-0.3, 0.3), random.uniform_vec<3>(-0.3, 0.3),
              speed * (aim - start) + random.uniform_vec<3>(-0.3, 0.3),
              speed * (aim - start) + random.uniform_vec<3>(-0.3, 0.3)};
        const double Le = std::max(dy[0].norm(), dy[1].norm()) + std::max(dy[2].norm(), dy[3].norm());
        const double te = ee_toi(y, dy);
        ASSERT_GE(te, 0.0);
        ASSERT_TRUE(apart_until([&](double s) { return ee_distance(y, dy, s); }, Le, te)) << "edge-edge " << trial;
        ee.add([&](double s) { return ee_distance(y, dy, s); }, te);
    }
    // Enough of the motions collide for the test to mean something, and CCD is not
    // needlessly conservative on average (t against the first sampled near-contact).
    EXPECT_GT(pt.hits, kTrials / 4);
    EXPECT_GT(ee.hits, kTrials / 4);
    EXPECT_GT(pt.mean_ratio(), 0.7);
    EXPECT_GT(ee.mean_ratio(), 0.7);
    std::printf(
        "[          ] CCD stress: point-triangle %d of %d hit (%d sampled contacts, mean t/t* %.3f); "
        "edge-edge %d hit (%d, %.3f)\n",
        pt.hits, kTrials, pt.true_hits, pt.mean_ratio(), ee.hits, ee.true_hits, ee.mean_ratio());
}

}  // namespace
}  // namespace pnet
