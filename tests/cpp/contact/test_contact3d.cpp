// IPC contact in 3D: the hash-grid broad phase against brute force, the
// barrier potential's derivatives over point-triangle, edge-edge and
// point-plane pairs, the CCD filter, the exact intersection test, 3D lagged
// friction's derivatives, and a tetrahedral cube dropped on the ground that
// rests on it without penetration; a box on a slope sticks below the friction
// angle and slides above it.
#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "pnet/contact/collisions/contact.hpp"
#include "pnet/contact/friction.hpp"
#include "pnet/contact/broad_phase/hash_grid.hpp"
#include "pnet/fem/fem_integrator.hpp"
#include "pnet/fem/gmsh_mesher.hpp"
#include "support/contact_checks.hpp"
#include "support/fem_systems.hpp"
#include "support/random.hpp"

namespace pnet {
namespace {

TEST(HashGrid, QueriesFindExactlyTheOverlappingBoxesInAscendingOrder) {
    test::Random random(5);
    std::vector<Vec<3>> lo, hi;
    for (int k = 0; k < 400; ++k) {
        const Vec<3> c = random.uniform_vec<3>(-1.0, 1.0), half = random.uniform_vec<3>(0.0, 0.15);
        lo.push_back(c - half);
        hi.push_back(c + half);
    }
    HashGrid<3> grid;
    grid.build(lo, hi, HashGrid<3>::suggested_cell(lo, hi, 1e-9));
    std::vector<int> found;
    int hits = 0;
    for (int q = 0; q < 200; ++q) {
        const Vec<3> c = random.uniform_vec<3>(-1.2, 1.2), half = random.uniform_vec<3>(0.0, 0.3);
        grid.query(c - half, c + half, found);
        std::vector<int> expected;
        for (int k = 0; k < 400; ++k)
            if (!((c + half).array() < lo[k].array()).any() && !((c - half).array() > hi[k].array()).any())
                expected.push_back(k);
        ASSERT_EQ(found, expected) << "query " << q;
        hits += static_cast<int>(found.size());
    }
    EXPECT_GT(hits, 200) << "the queries overlap boxes";
}

/// Two triangles: a horizontal one at y = 0 and a tilted one whose corner hangs over it at
/// height `gap`; and a third whose edge 6-7 passes 0.8 mm above the first (node 7 over its
/// inside, clear of its case boundaries, so that finite differences stay in one case).
struct TwoTriangles {
    std::vector<Vec<3>> x;
    std::vector<std::array<int, 3>> faces;
};

TwoTriangles near_pair(double gap) {
    TwoTriangles t;
    t.x = {Vec<3>(0.0, 0.0, 0.0), Vec<3>(0.02, 0.0, 0.0), Vec<3>(0.0, 0.0, 0.02),           // lower
           Vec<3>(0.004, gap, 0.004), Vec<3>(0.012, 0.012, 0.003), Vec<3>(0.003, 0.011, 0.013),  // upper, corner down
           Vec<3>(0.011, 0.0008, -0.004), Vec<3>(0.011, 0.0008, 0.0075)};                    // a crossing edge
    t.faces = {{0, 2, 1}, {3, 4, 5}, {6, 7, 4}};
    return t;
}

TEST(Contact3d, BarrierPotentialMatchesFiniteDifferences) {
    const TwoTriangles t = near_pair(0.0006);
    Contact3d contact(t.faces, t.x, 1e-3, 1e8);
    contact.add_half_space({Vec<3>(0.0, -0.0007, 0.0), Vec<3>(0.0, 1.0, 0.0)});
    const std::vector<Vec<3>>& x = t.x;
    ASSERT_GE(contact.active_pairs(x), 4u) << "point-triangle, edge-edge and point-plane pairs within dhat";
    const double b = test::expect_barrier_derivatives<3>(contact, x);
    EXPECT_DOUBLE_EQ(b, contact.value(x));
    EXPECT_EQ(contact.first_intersection(x), "");
    EXPECT_GT(contact.min_distance(x), 0.0);
    EXPECT_LT(contact.min_distance(x), 1e-3);
}

TEST(Contact3d, MaxStepKeepsEveryPairApartAndTheIntersectionTestFindsCrossings) {
    TwoTriangles t = near_pair(0.004);
    Contact3d contact(t.faces, t.x, 1e-4, 1e8);
    contact.add_half_space({Vec<3>(0.0, -0.001, 0.0), Vec<3>(0.0, 1.0, 0.0)});
    // The upper triangle falls 1 cm: through the lower one and the ground.
    std::vector<Vec<3>> dx(t.x.size(), Vec<3>::Zero());
    for (int i = 3; i < 6; ++i) dx[i] = Vec<3>(0.0, -0.01, 0.0);
    const double step = contact.max_step(t.x, dx);
    EXPECT_GT(step, 0.0);
    EXPECT_LT(step, 0.4) << "the corner reaches the lower triangle after 0.4 of the motion";
    std::vector<Vec<3>> y = t.x;
    for (std::size_t i = 0; i < y.size(); ++i) y[i] += step * dx[i];
    EXPECT_EQ(contact.first_intersection(y), "");
    EXPECT_GT(contact.min_distance(y), 0.0);
    EXPECT_LT(contact.max_step(y, dx), 0.5) << "CCD from the returned point still stops short";
    // The whole motion crosses: the exact test names a pair.
    for (std::size_t i = 0; i < y.size(); ++i) y[i] = t.x[i] + dx[i];
    const std::string crossing = contact.first_intersection(y);
    EXPECT_FALSE(crossing.empty());
    EXPECT_TRUE(crossing.find("triangle") != std::string::npos || crossing.find("half-space") != std::string::npos)
        << crossing;
}

TEST(Friction3d, PotentialMatchesFiniteDifferences) {
    const TwoTriangles t = near_pair(0.0006);
    Contact3d contact(t.faces, t.x, 1e-3, 1e8);
    contact.add_half_space({Vec<3>(0.0, -0.0007, 0.0), Vec<3>(0.0, 1.0, 0.0)});
    Friction<3> friction(0.3, 1e-3);
    friction.lag(contact, t.x);
    ASSERT_GE(friction.pairs(), 3u);
    for (const auto& p : friction.lagged()) {
        EXPECT_NEAR((p.tangent.transpose() * p.tangent - Eigen::Matrix2d::Identity()).norm(), 0.0, 1e-12);
        double sum = 0.0;
        for (int k = 0; k < p.count; ++k) sum += p.weight[k];
        // Between two primitives a rigid translation does not slip; against the ground the node does.
        EXPECT_NEAR(sum, p.count == 1 ? 1.0 : 0.0, 1e-12);
    }
    const Eigen::MatrixXd Hd = test::expect_friction_derivatives<3>(friction, t.x.size());
    EXPECT_GE(Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(Hd).eigenvalues().minCoeff(), -1e-9 * Hd.norm());
}

/// A stiff tetrahedral box (2 cm) on the ground: with the ground tilted by `degrees` and
/// friction mu, its mean speed down the slope after t (s).
double slope_speed(double degrees, double mu, double t) {
    const double angle = degrees * M_PI / 180.0, dhat = 1e-4;
    const Eigen::Matrix3d R = Eigen::AngleAxisd(angle, Vec<3>::UnitZ()).toRotationMatrix();
    const Vec<3> along = R * Vec<3>::UnitX(), normal = R * Vec<3>::UnitY();
    const FemSystem<3> system = test::block_on_slope<3>(R, normal, 0.02, 0.02, dhat);
    // kappa: the weight, 0.08 N, held by the 4 bottom nodes at about dhat / 2, where
    // kappa |b'(s)| 2 d = kappa 4.3e-12 m^3 (1e15 put 4 kN on each node and Newton stalled).
    Contact3d contact(system.mesh.boundary, system.mesh.x, dhat, 5e9);
    contact.add_half_space({Vec<3>(0.0, 0.0, 0.0), normal});
    Friction<3> friction(mu, 1e-4);
    FemImplicitIntegrator<3> implicit = test::lagged_integrator<3>(system, &contact, 1e-7);
    implicit.set_friction(&friction, &contact);
    FemState<3> state = FemState<3>::at_rest(system);
    const double dt = 2e-3;
    const int steps = static_cast<int>(std::lround(t / dt));
    for (int step = 0; step < steps; ++step) {
        const FemStepStats s = implicit.step(state, dt, step);
        EXPECT_TRUE(s.converged) << "step " << step << ": residual " << s.residual << " m/s after "
                                 << s.newton_iterations << " Newton iterations";
        EXPECT_EQ(contact.first_intersection(state.x), "") << "step " << step;
    }
    double u = 0.0;
    for (const Vec<3>& v : state.v) u -= v.dot(along);  // down the slope
    return u / state.v.size();
}

TEST(Friction3d, BoxOnASlopeSticksBelowTheFrictionAngleAndSlidesAbove) {
    // tan(atan(0.3)) = 0.3: 16.7 degrees. Below, it stays (to the smoothing's creep); above,
    // it accelerates at g (sin - mu cos).
    const double mu = 0.3, t = 0.1;
    const double below = slope_speed(12.0, mu, t), above = slope_speed(22.0, mu, t);
    const double a = 9.8 * (std::sin(22.0 * M_PI / 180.0) - mu * std::cos(22.0 * M_PI / 180.0));
    EXPECT_LT(std::abs(below), 2e-3) << "m/s: sticks";
    EXPECT_NEAR(above, a * t, 0.15 * a * t) << "slides at g (sin - mu cos)";
}

TEST(Contact3d, TetrahedralCubeDroppedOnTheGroundRestsWithoutPenetration) {
    const Shape3d cube = test::box_shape<3>(Vec<3>(0.0, 0.02, 0.0), Vec<3>(0.04, 0.06, 0.04), 0.02);
    const MaterialDescription jelly = test::elastic_material(ElasticityModel::NeoHookeanMetal, 1e5);
    FemSystem<3> system = test::falling_object<3>(mesh_shape(cube, "cube"), jelly);
    system.make_rest();
    const double dhat = 1e-3;
    Contact3d contact(system.mesh.boundary, system.mesh.x, dhat, 1e10);
    contact.add_half_space({Vec<3>::Zero(), Vec<3>::UnitY()});
    FemImplicitIntegrator<3> implicit = test::lagged_integrator<3>(system, &contact, 1e-6);
    FemState<3> state = FemState<3>::at_rest(system);
    int contact_steps = 0;
    double lowest = 1.0;
    for (int step = 0; step < 150; ++step) {
        const FemStepStats s = implicit.step(state, 5e-3, step);
        ASSERT_TRUE(s.converged) << "step " << step;
        const double d = contact.min_distance(state.x);
        ASSERT_GT(d, 0.0) << "step " << step;
        lowest = std::min(lowest, d);
        contact_steps += contact.active_pairs(state.x) > 0;
    }
    EXPECT_GT(contact_steps, 50) << "it lands (2 cm fall: ~0.064 s)";
    EXPECT_LT(contact.min_distance(state.x), dhat) << "resting within dhat of the ground";
    double speed = 0.0;
    for (const Vec<3>& v : state.v) speed = std::max(speed, v.norm());
    EXPECT_LT(speed, 1e-2) << "m/s: at rest";
}

}  // namespace
}  // namespace pnet
