// Lagged smoothed friction: f0/f1 and the potential's derivatives against
// finite differences, and a block on a slope that sticks below the friction
// angle and slides above it with the analytic acceleration g (sin a - mu cos a).
#include <gtest/gtest.h>

#include <cmath>
#include <memory>

#include <Eigen/Geometry>

#include "pnet/contact/friction.hpp"
#include "pnet/contact/collisions/contact.hpp"
#include "pnet/fem/fem_integrator.hpp"
#include "pnet/fem/gmsh_mesher.hpp"
#include "support/contact_checks.hpp"
#include "support/fem_systems.hpp"
#include "support/finite_difference.hpp"

namespace pnet {
namespace {

TEST(Friction, SmoothedCoulombDerivatives) {
    const double eps = 1e-3;
    test::FdStats fd;
    for (double x : {1e-5, 3e-4, 9.9e-4, 2e-3}) {
        Eigen::VectorXd p(1), g(1), h(1);
        p[0] = x;
        g[0] = friction_f1(x, eps);
        h[0] = friction_f1_derivative(x, eps);
        EXPECT_TRUE(test::check_gradient([&](const Eigen::VectorXd& y) { return friction_f0(y[0], eps); }, g, p, fd,
                                         1e-9, 1e-5));
        if (h[0] != 0.0) {
            EXPECT_TRUE(test::check_jacobian(
                [&](const Eigen::VectorXd& y) { return Eigen::VectorXd::Constant(1, friction_f1(y[0], eps)); }, h, p,
                fd, 1e-9, 1e-5));
        }
    }
    EXPECT_EQ(fd.checks, 7);
    EXPECT_NEAR(friction_f0(eps, eps), eps, 1e-18) << "C1 at eps";
    EXPECT_NEAR(friction_f1(eps, eps), 1.0, 1e-15);
    EXPECT_EQ(friction_f1(0.0, eps), 0.0) << "no force without slip";
}

TEST(Friction, PotentialMatchesFiniteDifferences) {
    // A node over an edge's inside and a node on the ground, both in contact.
    const std::vector<Vec<2>> x = {Vec<2>(0.0, 0.0015), Vec<2>(0.02, 0.0015), Vec<2>(0.01, 0.0021),
                                   Vec<2>(0.01, 0.012), Vec<2>(0.03, 0.0004)};
    Contact2d contact({{0, 1}, {2, 3}, {4, 3}}, 1e-3, 1e8);
    contact.add_half_space({Vec<2>(0.0, 0.0), Vec<2>(0.0, 1.0)});
    Friction2d friction(0.3, 1e-3);
    friction.lag(contact, x);
    ASSERT_GE(friction.pairs(), 2u);
    test::expect_friction_derivatives<2>(friction, x.size());
}

/// A stiff 2 x 2 cm block resting on a slope of angle `degrees`, friction mu; returns the block's
/// mean velocity along the slope (down-slope positive) at t1 and t2.
std::pair<double, double> slope_velocities(double degrees, double mu, double t1, double t2, bool explicit_ = false) {
    const double angle = degrees * M_PI / 180.0, dhat = 1e-4;
    const Eigen::Matrix2d R = Eigen::Rotation2Dd(angle).toRotationMatrix();
    const Vec<2> along(std::cos(angle), std::sin(angle)), normal(-std::sin(angle), std::cos(angle));
    const FemSystem<2> system = test::block_on_slope<2>(R, normal, 0.02, 0.01, dhat);
    // kappa: the weight's normal part, 0.4 kg/m g cos, held at about dhat / 2 by the few bottom nodes.
    Contact2d contact(system.mesh.boundary, dhat, 1e13);
    contact.add_half_space({Vec<2>(0.0, 0.0), normal});
    Friction2d friction(mu, 1e-4);
    FemImplicitIntegrator<2> implicit = test::lagged_integrator<2>(system, &contact, 1e-7);
    implicit.set_friction(&friction, &contact);
    FemExplicitIntegrator<2> explicit_integrator(system, &contact);
    explicit_integrator.set_friction(&friction, &contact);
    FemState<2> state = FemState<2>::at_rest(system);
    const double dt = explicit_ ? 0.5 * explicit_integrator.cfl_time_step(0.5) : 1e-3;
    auto slope_speed = [&] {
        double u = 0.0;
        for (const Vec<2>& v : state.v) u -= v.dot(along);  // down the slope
        return u / state.v.size();
    };
    std::pair<double, double> out{0.0, 0.0};
    const int n1 = static_cast<int>(std::lround(t1 / dt)), n2 = static_cast<int>(std::lround(t2 / dt));
    for (int step = 0; step < n2; ++step) {
        if (explicit_) {
            explicit_integrator.step(state, dt, step);
        } else {
            const FemStepStats s = implicit.step(state, dt, step);
            EXPECT_TRUE(s.converged) << "step " << step;
        }
        EXPECT_GT(contact.min_distance(state.x), 0.0) << "step " << step;
        if (step + 1 == n1) out.first = slope_speed();
    }
    out.second = slope_speed();
    return out;
}

TEST(Friction, BlockOnASlopeSticksBelowTheFrictionAngleAndSlidesAbove) {
    const double mu = 0.3;  // friction angle 16.7 degrees
    const auto [stick1, stick2] = slope_velocities(10.0, mu, 0.1, 0.2);
    EXPECT_LT(std::abs(stick2), 2e-4) << "m/s: sticks (creeps below the smoothing velocity)";
    const auto [v1, v2] = slope_velocities(30.0, mu, 0.1, 0.2);
    const double a = (v2 - v1) / 0.1, expected = 9.8 * (std::sin(M_PI / 6) - mu * std::cos(M_PI / 6));
    EXPECT_NEAR(a, expected, 0.02 * expected) << "m/s^2 down the slope";
    // The explicit integrator (the ground truth's) applies Coulomb friction as an impulse that
    // at most stops each pair's sliding within the step. Measured: a creep of 0.0115 m/s where
    // it should stick (0.0031 with whole CFL steps rather than half-size substeps) and 2.295
    // m/s^2 sliding (2.5% slow): the lagged normal force follows the block's undamped bouncing
    // on the barrier, and it slips where the force dips. A guard on that limitation. (The smoothed force of
    // the implicit potential at the start-of-step velocity crept at 0.034 m/s, slid at 2.271,
    // and is unstable once mu lambda dt / (m eps_v) > 2: metal_frame_2d's nodes chattered up to
    // 10 m/s.)
    const auto [es1, es2] = slope_velocities(10.0, mu, 0.1, 0.2, true);
    EXPECT_LT(std::abs(es2), 0.02) << "m/s: the explicit block (nearly) sticks (sliding: ~0.5 m/s by then)";
    const auto [e1, e2] = slope_velocities(30.0, mu, 0.1, 0.2, true);
    const double a_explicit = (e2 - e1) / 0.1;
    EXPECT_NEAR(a_explicit, expected, 0.03 * expected) << "m/s^2 down the slope, explicit";
    (void)es1;
    RecordProperty("acceleration", std::to_string(a) + " (explicit " + std::to_string(a_explicit) + ") vs " +
                                       std::to_string(expected));
    (void)stick1;
}

}  // namespace
}  // namespace pnet
