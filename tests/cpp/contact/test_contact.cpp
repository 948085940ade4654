// IPC contact in 2D: the barrier, the point-edge distances in every case and
// near the case boundaries, CCD on constructed motions, the contact potential's
// derivatives, and an elastic square dropped on the ground that comes to rest
// without ever touching it.
#include <gtest/gtest.h>

#include <cmath>

#include <Eigen/Eigenvalues>
#include <algorithm>

#include "pnet/contact/adaptive_stiffness.hpp"
#include "pnet/contact/ccd/point_edge.hpp"
#include "pnet/contact/distance/point_edge.hpp"
#include "pnet/contact/collisions/contact.hpp"
#include "pnet/fem/fem_potential.hpp"
#include "pnet/fem/gmsh_mesher.hpp"
#include "pnet/solver/newton.hpp"
#include "support/contact_checks.hpp"
#include "support/fem_systems.hpp"
#include "support/finite_difference.hpp"
#include "support/random.hpp"

namespace pnet {
namespace {

TEST(Barrier, DerivativesAndSmoothnessAtDhat) {
    const Barrier b{1e-6};
    test::FdStats fd;
    for (double s : {1e-9, 1e-8, 1e-7, 5e-7, 9.9e-7}) {
        Eigen::VectorXd x(1);
        x[0] = s;
        Eigen::VectorXd g(1), h(1);
        g[0] = b.first(s);
        h[0] = b.second(s);
        EXPECT_TRUE(test::check_gradient([&](const Eigen::VectorXd& y) { return b.value(y[0]); }, g, x, fd, 1e-4, 1e-5));
        EXPECT_TRUE(test::check_jacobian([&](const Eigen::VectorXd& y) { return Eigen::VectorXd::Constant(1, b.first(y[0])); },
                                         h, x, fd, 1e-4, 1e-5));
    }
    EXPECT_EQ(fd.checks, 10);
    EXPECT_EQ(b.value(1e-6), 0.0);
    EXPECT_EQ(b.first(1e-6), 0.0);
    EXPECT_EQ(b.second(1e-6), 0.0);
    EXPECT_NEAR(b.first(1e-6 * (1 - 1e-9)), 0.0, 1e-18) << "C1 at s_hat";
    EXPECT_TRUE(std::isinf(b.value(0.0)));
}

using Vec6d = Eigen::Matrix<double, 6, 1>;

Vec6d stack(const Vec<2>& p, const Vec<2>& a, const Vec<2>& b) {
    Vec6d q;
    q << p, a, b;
    return q;
}

TEST(PointEdgeDistance, DerivativesInEveryCaseAndNearTheCaseBoundaries) {
    const Vec<2> a(0.0, 0.0), b(1.0, 0.2);
    const Vec<2> along = (b - a).normalized(), normal(-along[1], along[0]);
    const double length = (b - a).norm();
    test::FdStats fd;
    int cases[3] = {0, 0, 0};
    // Points beside the edge at parameters t before a, inside (also just inside the ends) and past b.
    for (double t : {-0.5, -0.01, 0.01, 0.5, 0.99, 1.01, 1.5})
        for (double h : {0.3, -0.2, 0.05}) {
            const Vec<2> p = a + t * length * along + h * normal;
            const PointEdgeCase c = point_edge_case(p, a, b);
            ++cases[static_cast<int>(c)];
            const Vec6 g = point_edge_distance_sq_gradient(p, a, b, c);
            const Mat6 H = point_edge_distance_sq_hessian(p, a, b, c);
            auto f = [&](const Eigen::VectorXd& q) {
                return point_edge_distance_sq(q.segment<2>(0), q.segment<2>(2), q.segment<2>(4), c);
            };
            auto grad = [&](const Eigen::VectorXd& q) {
                return Eigen::VectorXd(point_edge_distance_sq_gradient(q.segment<2>(0), q.segment<2>(2), q.segment<2>(4), c));
            };
            const Eigen::VectorXd q = stack(p, a, b);
            EXPECT_TRUE(test::check_gradient(f, g, q, fd, 1e-7, 1e-6)) << "t " << t << " h " << h;
            EXPECT_TRUE(test::check_jacobian(grad, H, q, fd, 1e-7, 1e-6)) << "t " << t << " h " << h;
            // The case's value is the true distance to the segment.
            const double t_clamped = std::clamp((p - a).dot(b - a) / (b - a).squaredNorm(), 0.0, 1.0);
            EXPECT_NEAR(point_edge_distance_sq(p, a, b), (p - (a + t_clamped * (b - a))).squaredNorm(), 1e-14);
        }
    EXPECT_EQ(cases[0], 6);
    EXPECT_EQ(cases[1], 6);
    EXPECT_EQ(cases[2], 9);
    EXPECT_EQ(fd.checks, 21 * (6 + 36)) << "every entry of every case was compared";
}

TEST(Ccd, PointEdgeNeverLaterThanTheTrueImpactAndLeavesTheGapOpen) {
    const Vec<2> a(0.0, 0.0), b(1.0, 0.0);
    // A point falling straight onto the edge's inside: true impact at t* = 0.5.
    double t = point_edge_time_of_impact(Vec<2>(0.3, 0.5), a, b, Vec<2>(0.0, -1.0), Vec<2>::Zero(), Vec<2>::Zero());
    EXPECT_LE(t, 0.5);
    EXPECT_GT(t, 0.4) << "not needlessly conservative";
    EXPECT_GT(point_edge_distance_sq(Vec<2>(0.3, 0.5 - t), a, b), 0.0);
    // The edge rising to meet a point (both move): true impact at t* = 0.25.
    t = point_edge_time_of_impact(Vec<2>(0.5, 0.5), a, b, Vec<2>(0.0, -1.0), Vec<2>(0.0, 1.0), Vec<2>(0.0, 1.0));
    EXPECT_LE(t, 0.25);
    EXPECT_GT(t, 0.2);
    // An edge rotating about a onto a point: impact when the edge has turned to the point.
    const Vec<2> p(0.5, 0.25);
    const double angle = 0.9;  // over the motion (linearized: the endpoint moves on the chord)
    const Vec<2> b1(std::cos(angle), std::sin(angle));
    t = point_edge_time_of_impact(p, a, b, Vec<2>::Zero(), Vec<2>::Zero(), b1 - b);
    ASSERT_LT(t, 1.0);
    // Brute force: the first sampled time at which the edge's side of the point flips.
    double t_true = 1.0;
    for (int k = 1; k <= 100000; ++k) {
        const double s = k * 1e-5;
        const Vec<2> e = b + s * (b1 - b) - a;
        if (e[0] * (p - a)[1] - e[1] * (p - a)[0] <= 0.0) {
            t_true = s;
            break;
        }
    }
    EXPECT_LE(t, t_true);
    EXPECT_GT(t, 0.8 * t_true);
    // Sliding parallel, never closer: no impact; moving away: none either.
    EXPECT_EQ(point_edge_time_of_impact(Vec<2>(0.5, 0.1), a, b, Vec<2>(2.0, 0.0), Vec<2>::Zero(), Vec<2>::Zero()),
              kNoImpact);
    EXPECT_EQ(point_edge_time_of_impact(Vec<2>(0.5, 0.1), a, b, Vec<2>(0.0, 1.0), Vec<2>::Zero(), Vec<2>::Zero()),
              kNoImpact);
    // Repeated CCD: stepping to the returned time again and again never crosses the edge.
    Vec<2> q(0.3, 0.5);
    const Vec<2> dq(0.0, -1.0);
    double travelled = 0.0;
    for (int k = 0; k < 20; ++k) {
        const double step = point_edge_time_of_impact(q, a, b, (1.0 - travelled) * dq, Vec<2>::Zero(), Vec<2>::Zero());
        ASSERT_GE(step, 0.0);
        if (step == kNoImpact) break;
        q += step * (1.0 - travelled) * dq;
        travelled += step * (1.0 - travelled);
        ASSERT_GT(q[1], 0.0) << "repeat " << k;
    }
    EXPECT_GT(travelled, 0.49);
    // Point-plane.
    EXPECT_NEAR(point_plane_time_of_impact(Vec<2>(0, 1), Vec<2>(0, -2), Vec<2>::Zero(), Vec<2>(0, 1)), 0.9 * 0.5, 1e-15);
    EXPECT_EQ(point_plane_time_of_impact(Vec<2>(0, 1), Vec<2>(0, 2), Vec<2>::Zero(), Vec<2>(0, 1)), kNoImpact);
}

TEST(Contact2d, BarrierPotentialMatchesFiniteDifferences) {
    // Two edges of a "V" and a node of another edge near both, and the ground below.
    std::vector<Vec<2>> x = {Vec<2>(0.0, 0.002), Vec<2>(0.010, 0.0015), Vec<2>(0.020, 0.002),  // edges 0-1, 1-2
                             Vec<2>(0.0095, 0.0022), Vec<2>(0.0095, 0.012)};                  // edge 3-4
    Contact2d contact({{0, 1}, {1, 2}, {3, 4}}, 1e-3, 1e8);
    contact.add_half_space({Vec<2>(0.0, 0.0), Vec<2>(0.0, 1.0)});
    EXPECT_GE(contact.active_pairs(x), 3u);
    test::expect_barrier_derivatives<2>(contact, x);
    EXPECT_EQ(contact.first_intersection(x), "");
    x[3] = Vec<2>(0.0095, 0.0015);  // on edge 0-1... exactly on the line through it
    EXPECT_TRUE(std::isinf(contact.value(x)) || contact.value(x) > 0.0);
}

// An elastic square dropped on the ground (a half-space) bounces, settles and
// rests on it: no node ever reaches the ground, and at rest it floats within
// dhat of it.
TEST(Contact2d, ElasticSquareDroppedOnTheGroundComesToRestWithoutPenetration) {
    const Mesh<2> mesh = mesh_shape(test::box_shape<2>(Vec<2>(0.0, 0.05), Vec<2>(0.1, 0.15), 0.02), "square");
    const MaterialDescription jelly = test::elastic_material(ElasticityModel::NeoHookeanMetal, 1e5);
    const std::vector<Material<2>> materials = {Material<2>(jelly)};
    ElasticParticleEnergy<2> energy(materials);
    const ElementRest<2> rest(mesh, std::vector<double>(mesh.elements.size(), jelly.density));
    FemPotential<2> potential(mesh, rest, energy);
    const double dhat = 1e-3;
    Contact2d contact(mesh.boundary, dhat, 1e10);
    contact.add_half_space({Vec<2>(0.0, 0.0), Vec<2>(0.0, 1.0)});
    potential.set_contact(&contact);
    const std::size_t n = mesh.nodes();
    std::vector<Vec<2>> x = mesh.x;
    VecX v = VecX::Zero(2 * n);
    const std::vector<Mat<2>> identity(mesh.elements.size(), Mat<2>::Identity());
    const std::vector<int> object(mesh.elements.size(), 0);
    const std::vector<double> hardening(mesh.elements.size(), 0.0);
    NewtonOptions options;
    options.tolerance = 1e-6;
    options.linear_solver = NewtonOptions::LinearSolver::Cholesky;
    const double dt = 5e-3;
    double lowest = 1.0;
    int contact_steps = 0;
    for (int step = 0; step < 400; ++step) {
        VecX v_star = v;
        for (std::size_t i = 0; i < n; ++i) v_star[2 * i + 1] -= 9.8 * dt;
        potential.begin_step(x, v_star, dt, identity, {});
        potential.set_material_state(object, hardening);
        potential.set_reference({});
        options.residual_mass = potential.residual_mass();
        // The solve starts intersection-free: at v* as far as CCD allows from x^n (v = 0).
        v = potential.max_step(VecX::Zero(2 * n), v_star) * v_star;
        const NewtonStats s = minimize(potential, v, options, "step " + std::to_string(step));
        ASSERT_TRUE(s.converged) << "step " << step << " residual " << s.residual;
        for (std::size_t i = 0; i < n; ++i) x[i] += dt * v.segment<2>(2 * i);
        const double d = contact.min_distance(x);
        ASSERT_GT(d, 0.0) << "step " << step << ": a node reached the ground";
        lowest = std::min(lowest, d);
        contact_steps += contact.active_pairs(x) > 0;
    }
    EXPECT_GT(contact_steps, 100) << "the square lands (it falls 5 cm in ~0.1 s)";
    EXPECT_LT(contact.min_distance(x), dhat) << "resting within dhat of the ground";
    double speed = 0.0;
    for (Eigen::Index k = 0; k < v.size(); ++k) speed = std::max(speed, std::abs(v[k]));
    EXPECT_LT(speed, 1e-2) << "m/s: at rest";
    EXPECT_GT(lowest, 0.0);
}

}  // namespace
}  // namespace pnet

namespace pnet {
namespace {

TEST(AdaptiveStiffness, InitialValueBalancesTheGradientsWithinIpcBounds) {
    const double diag = 0.2, dhat = 2e-4, mass = 0.01, dt = 1e-2;
    Eigen::VectorXd gE(2), gB(2);
    gB << 0.0, -1.0;
    // No contact force to balance: the lower bound. IPC's kappa_min = 1e11 m / (4 d0 b''(d0)), d0 = (1e-8 diag)^2.
    const Barrier b{dhat * dhat};
    const double d0 = 1e-8 * diag * 1e-8 * diag;
    const double kappa_min = 1e11 * mass / (4.0 * d0 * b.second(d0)) / (dt * dt);
    gE << 0.0, 0.0;
    BarrierStiffness k = initial_barrier_stiffness(diag, dhat, mass, dt, gE, gB);
    EXPECT_NEAR(k.kappa, kappa_min, 1e-12 * kappa_min);
    EXPECT_NEAR(k.kappa_max, 100.0 * kappa_min, 1e-12 * kappa_min);
    // Gravity pushing into the barrier: kappa = -gB.gE / |gB|^2 when inside the bounds.
    gE << 0.0, 5.0 * kappa_min;
    EXPECT_NEAR(initial_barrier_stiffness(diag, dhat, mass, dt, gE, gB).kappa, 5.0 * kappa_min, 1e-9 * kappa_min);
    gE << 0.0, 1e6 * kappa_min;
    EXPECT_NEAR(initial_barrier_stiffness(diag, dhat, mass, dt, gE, gB).kappa, 100.0 * kappa_min, 1e-9 * kappa_min);
    // Doubling: only while the smallest distance is below 1e-9 diag and still shrinking.
    const double eps = 1e-9 * diag;
    EXPECT_EQ(update_barrier_stiffness(k, 0.5 * eps, 0.4 * eps, diag), 2.0 * k.kappa);
    EXPECT_EQ(update_barrier_stiffness(k, 0.5 * eps, 0.6 * eps, diag), k.kappa);
    EXPECT_EQ(update_barrier_stiffness(k, 2.0 * eps, 0.4 * eps, diag), k.kappa);
    BarrierStiffness top{k.kappa_max, k.kappa_max};
    EXPECT_EQ(update_barrier_stiffness(top, 0.5 * eps, 0.4 * eps, diag), k.kappa_max);
    EXPECT_THROW(initial_barrier_stiffness(0.0, dhat, mass, dt, gE, gB), std::invalid_argument);
}

}  // namespace
}  // namespace pnet
