// The adjoint of an implicit MPM rollout (mpm/mpm_adjoint.hpp) against central differences of the whole
// rollout: an elastic disk dropped onto the slip floor (so that the walls' projection acts in the last
// steps), a random linear loss of the last state's positions and velocities, its gradient with respect to
// E and along random directions of the start's velocities, positions, APIC matrices and F. The forward
// solves are tightened to 1e-11 m/s for the check.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <functional>

#include <nlohmann/json.hpp>

#include "pnet/energy/return_mapping_energy.hpp"
#include "pnet/material/material_json.hpp"
#include "pnet/mpm/mpm_adjoint.hpp"
#include "pnet/scene/sampler.hpp"
#include "pnet/scene/scene.hpp"
#include "pnet/sim/mpm_simulation.hpp"
#include "support/random.hpp"

namespace pnet {
namespace {

Scene disk_scene(double E, const char* plasticity = "none") {
    return scene_from_json(nlohmann::json::parse(std::string(R"({
        "dim": 2, "domain": {"min": [0, 0], "max": [1, 1]}, "dx": 0.03125, "gravity": [0, -9.8],
        "particles_per_cell": 2, "boundary": {"walls": "slip", "sticky_floor_cells": 0},
        "integrator": {"name": "lagged", "dt": 2e-3},
        "objects": [{"shape": "disk", "center": [0.5, 0.25], "radius": 0.1, "velocity": [0.3, -2],
                     "material": {"name": "rubber", "density": 1000,
                                  "elasticity": {"model": "stvk_hencky", "E": )") +
                                                 std::to_string(E) + R"(, "nu": 0.3},
                                  "plasticity": {"model": ")" +
                                                 plasticity + R"("}}}]
    })"),
                           "<disk>", ".");
}

ImplicitOptions tight() {
    ImplicitOptions o;
    o.newton_tolerance = 1e-11;
    o.newton_acceleration_tolerance = 0.0;
    o.max_newton_iterations = 200;
    o.cg_tolerance = 1e-6;
    return o;
}

/// Per particle, in this order from Random(seed): the loss's weights a_p and b_p (linear_loss) and a direction
/// dv_p of the start's velocities, each uniform in [-1, 1] per component.
template <int dim>
void loss_directions(std::size_t n, unsigned seed, std::vector<Vec<dim>>& a, std::vector<Vec<dim>>& b,
                     std::vector<Vec<dim>>& dv) {
    test::Random random(seed);
    a.resize(n);
    b.resize(n);
    dv.resize(n);
    for (std::size_t p = 0; p < n; ++p) {
        a[p] = random.uniform_vec<dim>(-1.0, 1.0);
        b[p] = random.uniform_vec<dim>(-1.0, 1.0);
        dv[p] = random.uniform_vec<dim>(-1.0, 1.0);
    }
}

/// L = sum_p a_p . x_p + b_p . v_p of a state.
template <int dim>
double linear_loss(const Particles<dim>& state, const std::vector<Vec<dim>>& a, const std::vector<Vec<dim>>& b) {
    double L = 0.0;
    for (std::size_t p = 0; p < state.size(); ++p) L += a[p].dot(state.x[p]) + b[p].dot(state.v[p]);
    return L;
}

/// Central differences of loss(start with v_p + h dv_p) along the velocity direction dv.
template <int dim, typename Loss>
double along_velocities(const Loss& loss, const Particles<dim>& start, const std::vector<Vec<dim>>& dv, double h) {
    Particles<dim> plus = start, minus = start;
    for (std::size_t p = 0; p < start.size(); ++p) {
        plus.v[p] += h * dv[p];
        minus.v[p] -= h * dv[p];
    }
    return (loss(plus) - loss(minus)) / (2.0 * h);
}

/// The disk's system at E, with AFLIP transfers where flip_relaxation_time > 0 (APIC otherwise).
MpmSystem<2> disk_system(double E, double flip_relaxation_time) {
    MpmSystem<2> system = make_mpm_system<2>(disk_scene(E));
    system.flip_relaxation_time = flip_relaxation_time;
    return system;
}

// APIC, and AFLIP (the velocity residual r_p = v_p - sum_i w_ip q_i / m_i of P2G's grid, a fraction
// alpha = exp(-dt / 0.01) = 0.82 of it added back after G2P: its adjoint through v_p, x_p and the grid).
class MpmAdjointTransfers : public ::testing::TestWithParam<double> {};

TEST_P(MpmAdjointTransfers, ElasticRolloutGradientMatchesCentralDifferences) {
    const double E = 1e5, dt = 2e-3, flip = GetParam();
    const int steps = 20;
    const Scene scene = disk_scene(E);
    const MpmSystem<2> system = disk_system(E, flip);
    const Particles<2> start = sample_particles<2>(scene);
    const std::size_t n = start.size();
    test::Random random(71);
    std::vector<Vec<2>> a(n), b(n), dv(n), dx(n);
    std::vector<Mat<2>> dC(n), dF(n);
    for (std::size_t p = 0; p < n; ++p) {
        a[p] = random.uniform_vec<2>(-1.0, 1.0);
        b[p] = random.uniform_vec<2>(-1.0, 1.0);
        dv[p] = random.uniform_vec<2>(-1.0, 1.0);
        dx[p] = random.uniform_vec<2>(-1.0, 1.0) * system.dx;
        for (int i = 0; i < 2; ++i)
            for (int j = 0; j < 2; ++j) {
                dC[p](i, j) = random.uniform(-10.0, 10.0);
                dF[p](i, j) = random.uniform(-1.0, 1.0);
            }
    }
    const MpmOptions mpm;
    auto loss = [&](const MpmSystem<2>& s, const Particles<2>& from) {
        MpmAdjoint<2> adjoint(s, tight(), mpm);
        return linear_loss(adjoint.forward(from, dt, steps), a, b);
    };

    MpmAdjoint<2> adjoint(system, tight(), mpm);
    const Particles<2> last = adjoint.forward(start, dt, steps);
    double lowest = 1.0;
    for (const Vec<2>& x : last.x) lowest = std::min(lowest, x[1]);
    ASSERT_LT(lowest, 3 * system.dx) << "the disk must reach the floor's wall nodes";
    const MpmRolloutGradient<2> g = adjoint.backward(a, b);

    // Central differences of the rollout along `direction` in one field of every particle's start.
    auto along = [&](auto field, const auto& direction, double h) {
        Particles<2> plus = start, minus = start;
        for (std::size_t p = 0; p < n; ++p) {
            (plus.*field)[p] += h * direction[p];
            (minus.*field)[p] -= h * direction[p];
        }
        return (loss(system, plus) - loss(system, minus)) / (2.0 * h);
    };
    double g_v = 0.0, g_x = 0.0, g_C = 0.0, g_F = 0.0;
    for (std::size_t p = 0; p < n; ++p) {
        g_v += g.v[p].dot(dv[p]);
        g_x += g.x[p].dot(dx[p]);
        g_C += g.C[p].cwiseProduct(dC[p]).sum();
        g_F += g.F[p].cwiseProduct(dF[p]).sum();
    }
    const double fd_v = along(&Particles<2>::v, dv, 1e-4);
    const double fd_x = along(&Particles<2>::x, dx, 1e-4);
    const double fd_C = along(&Particles<2>::C, dC, 1e-4);
    const double fd_F = along(&Particles<2>::F_elastic, dF, 1e-6);
    const double hE = 1e-4 * E;
    const double fd_E =
        (loss(disk_system(E + hE, flip), start) - loss(disk_system(E - hE, flip), start)) / (2.0 * hE);
    std::printf(
        "MPM rollout (%s), %zu particles, %d steps: dL/dv0 %.10g vs %.10g, dL/dx0 %.10g vs %.10g, dL/dC0 %.10g vs "
        "%.10g, dL/dF0 %.10g vs %.10g, dL/dE %.10g vs %.10g\n",
        flip > 0.0 ? "AFLIP" : "APIC", n, steps, g_v, fd_v, g_x, fd_x, g_C, fd_C, g_F, fd_F, g.youngs_modulus, fd_E);
    EXPECT_NEAR(g_v, fd_v, 1e-4 * std::abs(fd_v));
    EXPECT_NEAR(g_x, fd_x, 1e-4 * std::abs(fd_x));
    EXPECT_NEAR(g_C, fd_C, 1e-4 * std::abs(fd_C));
    EXPECT_NEAR(g_F, fd_F, 1e-4 * std::abs(fd_F));
    EXPECT_NEAR(g.youngs_modulus, fd_E, 1e-4 * std::abs(fd_E));
}

INSTANTIATE_TEST_SUITE_P(MpmAdjoint2d, MpmAdjointTransfers, ::testing::Values(0.0, 0.01),
                         [](const ::testing::TestParamInfo<double>& info) {
                             return info.param > 0.0 ? std::string("Aflip") : std::string("Apic");
                         });

// A loss of an intermediate state and the last: the cotangents enter the backward pass at their states.
TEST(MpmAdjoint2d, ALossOfSeveralStatesGetsItsGradientAtEach) {
    const double dt = 2e-3;
    const int steps = 12;
    const Scene scene = disk_scene(1e5);
    const MpmSystem<2> system = make_mpm_system<2>(scene);
    const Particles<2> start = sample_particles<2>(scene);
    const std::size_t n = start.size();
    std::vector<Vec<2>> a, b, dv;
    loss_directions<2>(n, 73, a, b, dv);
    auto loss = [&](const Particles<2>& from) {
        MpmAdjoint<2> adjoint(system, tight(), MpmOptions{});
        double L = 0.0;
        adjoint.forward(from, dt, steps, [&](int k, const Particles<2>& s) {
            for (std::size_t p = 0; p < n; ++p) {
                if (k == 5) L += a[p].dot(s.x[p]);
                if (k == steps) L += b[p].dot(s.v[p]);
            }
        });
        return L;
    };
    MpmAdjoint<2> adjoint(system, tight(), MpmOptions{});
    adjoint.forward(start, dt, steps);
    EXPECT_EQ(adjoint.steps(), steps);
    std::vector<std::vector<Vec<2>>> xs(steps + 1), vs(steps + 1);
    xs[5] = a;
    vs[steps] = b;
    const MpmRolloutGradient<2> g = adjoint.backward(xs, vs);
    double g_v = 0.0;
    for (std::size_t p = 0; p < n; ++p) g_v += g.v[p].dot(dv[p]);
    const double fd = along_velocities<2>(loss, start, dv, 1e-4);
    EXPECT_NEAR(g_v, fd, 1e-4 * std::abs(fd));
    // Every state kept (checkpoint_every 1) or a checkpoint every 5 steps with the segments recomputed:
    // the same gradient to the last bit.
    for (const int every : {1, 5}) {
        MpmAdjoint<2> other(system, tight(), MpmOptions{});
        other.forward(start, dt, steps, {}, every);
        const MpmRolloutGradient<2> h = other.backward(xs, vs);
        EXPECT_EQ(h.youngs_modulus, g.youngs_modulus) << every;
        for (std::size_t p = 0; p < n; ++p) {
            EXPECT_EQ(h.x[p], g.x[p]) << every;
            EXPECT_EQ(h.v[p], g.v[p]) << every;
            EXPECT_EQ(h.F[p], g.F[p]) << every;
        }
        if (every == 5) {
            EXPECT_LE(other.peak_states(), 4u + 5u);  // checkpoints 0, 5, 10, 12 and a segment
        }
    }
    xs[5].resize(3);
    EXPECT_THROW(adjoint.backward(xs, vs), std::invalid_argument);
}

// 3D: an elastic sphere (neo-Hookean snow elasticity, dx 1/16) dropped onto the slip floor.
TEST(MpmAdjoint3d, ElasticRolloutGradientMatchesCentralDifferences) {
    const double E = 2e5, dt = 2e-3;
    const int steps = 12;
    auto sphere = [](double youngs) {
        return scene_from_json(nlohmann::json::parse(R"({
            "dim": 3, "domain": {"min": [0, 0, 0], "max": [1, 1, 1]}, "dx": 0.0625, "gravity": [0, -9.8, 0],
            "particles_per_cell": 2, "boundary": {"walls": "slip", "sticky_floor_cells": 0},
            "integrator": {"name": "lagged", "dt": 2e-3},
            "objects": [{"shape": "sphere", "center": [0.5, 0.3, 0.5], "radius": 0.12, "velocity": [0.2, -2, 0.1],
                         "material": {"name": "snowy", "density": 400,
                                      "elasticity": {"model": "neo_hookean_snow", "E": )" +
                                                     std::to_string(youngs) + R"(, "nu": 0.2},
                                      "plasticity": {"model": "none"}}}]
        })"),
                               "<sphere>", ".");
    };
    for (double flip : {0.0, 0.01}) {  // APIC and AFLIP transfers
        auto make = [&](double youngs) {
            MpmSystem<3> system = make_mpm_system<3>(sphere(youngs));
            system.flip_relaxation_time = flip;
            return system;
        };
        const MpmSystem<3> system = make(E);
        const Particles<3> start = sample_particles<3>(sphere(E));
        const std::size_t n = start.size();
        std::vector<Vec<3>> a, b, dv;
        loss_directions<3>(n, 79, a, b, dv);
        auto loss = [&](const MpmSystem<3>& s, const Particles<3>& from) {
            MpmAdjoint<3> adjoint(s, tight(), MpmOptions{});
            return linear_loss(adjoint.forward(from, dt, steps), a, b);
        };
        MpmAdjoint<3> adjoint(system, tight(), MpmOptions{});
        const Particles<3> last = adjoint.forward(start, dt, steps);
        double lowest = 1.0;
        for (const Vec<3>& x : last.x) lowest = std::min(lowest, x[1]);
        ASSERT_LT(lowest, 3 * system.dx) << "the sphere must reach the floor's wall nodes";
        const MpmRolloutGradient<3> g = adjoint.backward(a, b);
        double g_v = 0.0;
        for (std::size_t p = 0; p < n; ++p) g_v += g.v[p].dot(dv[p]);
        const double fd_v =
            along_velocities<3>([&](const Particles<3>& from) { return loss(system, from); }, start, dv, 1e-4);
        const double hE = 1e-4 * E;
        const double fd_E = (loss(make(E + hE), start) - loss(make(E - hE), start)) / (2.0 * hE);
        std::printf("MPM rollout 3D (%s), %zu particles, %d steps: dL/dv0 %.10g vs %.10g, dL/dE %.10g vs %.10g\n",
                    flip > 0.0 ? "AFLIP" : "APIC", n, steps, g_v, fd_v, g.youngs_modulus, fd_E);
        EXPECT_NEAR(g_v, fd_v, 1e-4 * std::abs(fd_v));
        EXPECT_NEAR(g.youngs_modulus, fd_E, 1e-4 * std::abs(fd_E));
    }
}

// Sand (Drucker-Prager, the friction angle 30 degrees) dropped onto the slip floor, under `return_map` (the
// return-mapped stress and its non-symmetric tangent in the solve) and `lagged` (the elastic solve, the
// return mapping after): dL/dv0, dL/dE and dL/dphi against central differences.
Scene sand_scene(double E, double angle) {
    return scene_from_json(nlohmann::json::parse(std::string(R"({
        "dim": 2, "domain": {"min": [0, 0], "max": [1, 1]}, "dx": 0.03125, "gravity": [0, -9.8],
        "particles_per_cell": 2, "boundary": {"walls": "slip", "sticky_floor_cells": 0},
        "integrator": {"name": "return_map", "dt": 2e-3},
        "objects": [{"shape": "box", "min": [0.42, 0.12], "max": [0.58, 0.3], "velocity": [0.2, -1.5],
                     "material": {"name": "sand", "density": 2200,
                                  "elasticity": {"model": "stvk_hencky", "E": )") +
                                                 std::to_string(E) + R"(, "nu": 0.3},
                                  "plasticity": {"model": "drucker_prager", "friction_angle_deg": )" +
                                                 std::to_string(angle) + R"(}}}]
    })"),
                           "<sand>", ".");
}

void check_sand(Method method) {
    const double E = 3.5e5, angle = 30.0, dt = 2e-3;
    const int steps = 20;
    const MpmSystem<2> system = make_mpm_system<2>(sand_scene(E, angle));
    // Compressed 1% to start with: F = I is the cone's tip, where Drucker-Prager's projection has no
    // derivative (a free fall's trial F sits there, and tension of round-off size takes the apex branch).
    Particles<2> start = sample_particles<2>(sand_scene(E, angle));
    for (Mat<2>& F : start.F_elastic) F = 0.99 * Mat<2>::Identity();
    const std::size_t n = start.size();
    std::vector<Vec<2>> a, b, dv;
    loss_directions<2>(n, 83, a, b, dv);
    auto loss = [&](const MpmSystem<2>& s, const Particles<2>& from) {
        MpmAdjoint<2> adjoint(s, tight(), MpmOptions{}, method);
        return linear_loss(adjoint.forward(from, dt, steps), a, b);
    };
    MpmAdjoint<2> adjoint(system, tight(), MpmOptions{}, method);
    const Particles<2> last = adjoint.forward(start, dt, steps);
    const Material<2>& sand = system.materials[0];
    int yielded = 0;  // on the cone (not at its tip)
    for (const Mat<2>& Fe : last.F_elastic) {
        const Vec<2> eps = clamped_svd<2>(Fe).Sigma.array().log().matrix();
        yielded += std::abs(eps[0] - eps[1]) > 1e-6 &&
                   sand.yield_function(clamped_svd<2>(Fe).Sigma, 0.0) > -1e-6 * sand.description().elastic.E;
    }
    ASSERT_GT(yielded, static_cast<int>(n) / 10) << "the sand must flow";
    const MpmRolloutGradient<2> g = adjoint.backward(a, b);
    double g_v = 0.0;
    for (std::size_t p = 0; p < n; ++p) g_v += g.v[p].dot(dv[p]);
    const double fd_v =
        along_velocities<2>([&](const Particles<2>& from) { return loss(system, from); }, start, dv, 1e-4);
    const double hE = 1e-4 * E, hphi = 1e-3;
    const double fd_E = (loss(make_mpm_system<2>(sand_scene(E + hE, angle)), start) -
                         loss(make_mpm_system<2>(sand_scene(E - hE, angle)), start)) /
                        (2.0 * hE);
    const double fd_phi = (loss(make_mpm_system<2>(sand_scene(E, angle + hphi)), start) -
                           loss(make_mpm_system<2>(sand_scene(E, angle - hphi)), start)) /
                          (2.0 * hphi);
    std::printf(
        "MPM sand rollout (%s), %zu particles (%d yielding at the end), %d steps: dL/dv0 %.10g vs %.10g, "
        "dL/dE %.10g vs %.10g, dL/dphi %.10g vs %.10g\n",
        to_string(method), n, yielded, steps, g_v, fd_v, g.youngs_modulus, fd_E, g.friction_angle, fd_phi);
    EXPECT_NEAR(g_v, fd_v, 1e-4 * std::abs(fd_v));
    EXPECT_NEAR(g.youngs_modulus, fd_E, 1e-4 * std::abs(fd_E));
    EXPECT_NEAR(g.friction_angle, fd_phi, 1e-4 * std::abs(fd_phi));
}

TEST(MpmAdjoint2d, DruckerPragerRolloutGradientMatchesCentralDifferences) {
    check_sand(Method::ReturnMap);
    check_sand(Method::Lagged);
}

// A sand column (330 particles) standing on the slip floor from F = I, under `return_map`, as scripts/identify.py
// friction_angle fits it: its free surface sits at the cone's tip, strains of 1e-5 with principal strains closer
// than the consistent tangent's kCloseLog, where the tangent's limit quotient was negative and the adjoint grew
// 1.8x per step (dL/dv0 -219 after 12 steps against central differences' 0.2-0.4). dL/dphi of the positions
// after 60 steps against central differences; dL/dv0 of a loss of positions and velocities stays within the
// spread of central differences at two steps (the free surface's particles change branch under any
// perturbation of the velocities, so differences of different size disagree by tens of percent).
Scene column_scene(double angle) {
    return scene_from_json(nlohmann::json::parse(std::string(R"({
        "dim": 2, "domain": {"min": [0, 0], "max": [1, 1]}, "dx": 0.015625, "gravity": [0, -9.8],
        "particles_per_cell": 2, "boundary": {"walls": "slip", "sticky_floor_cells": 0},
        "integrator": {"name": "return_map", "dt": 1e-3},
        "objects": [{"shape": "box", "min": [0.45, 0.046875], "max": [0.55, 0.25],
                     "material": {"name": "sand", "density": 2200,
                                  "elasticity": {"model": "stvk_hencky", "E": 3.537e5, "nu": 0.3},
                                  "plasticity": {"model": "drucker_prager", "friction_angle_deg": )") +
                                                 std::to_string(angle) + R"(}}}]})"),
                           "<column>", ".");
}

TEST(MpmAdjoint2d, ASandColumnAtRestFromTheConesTipHasItsFrictionAngleGradient) {
    const double angle = 30.0, dt = 1e-3;
    const MpmSystem<2> system = make_mpm_system<2>(column_scene(angle));
    const Particles<2> start = sample_particles<2>(column_scene(angle));
    const std::size_t n = start.size();
    std::vector<Vec<2>> a, b, dv;
    loss_directions<2>(n, 83, a, b, dv);
    std::vector<Vec<2>> none(n, Vec<2>::Zero());
    auto rollout = [&](const MpmSystem<2>& s, const Particles<2>& from, int steps) {
        MpmAdjoint<2> adjoint(s, tight(), MpmOptions{}, Method::ReturnMap);
        return adjoint.forward(from, dt, steps);
    };
    auto positions = [&](const Particles<2>& last) {
        double L = 0.0;
        for (std::size_t p = 0; p < n; ++p) L += a[p].dot(last.x[p]);
        return L;
    };
    const int steps = 60;
    MpmAdjoint<2> adjoint(system, tight(), MpmOptions{}, Method::ReturnMap);
    adjoint.forward(start, dt, steps);
    const double g_phi = adjoint.backward(a, none).friction_angle;
    const double hphi = 1e-3;
    const double fd_phi = (positions(rollout(make_mpm_system<2>(column_scene(angle + hphi)), start, steps)) -
                           positions(rollout(make_mpm_system<2>(column_scene(angle - hphi)), start, steps))) /
                          (2.0 * hphi);
    std::printf("sand column at rest, %zu particles, %d steps: dL/dphi %.10g vs %.10g\n", n, steps, g_phi, fd_phi);
    EXPECT_GT(std::abs(fd_phi), 1e-5);
    EXPECT_NEAR(g_phi, fd_phi, 1e-4 * std::abs(fd_phi));

    const int short_steps = 12;
    MpmAdjoint<2> short_adjoint(system, tight(), MpmOptions{}, Method::ReturnMap);
    short_adjoint.forward(start, dt, short_steps);
    const MpmRolloutGradient<2> g = short_adjoint.backward(a, b);
    double g_v = 0.0;
    for (std::size_t p = 0; p < n; ++p) g_v += g.v[p].dot(dv[p]);
    auto loss = [&](const Particles<2>& from) {
        const Particles<2> last = rollout(system, from, short_steps);
        double L = positions(last);
        for (std::size_t p = 0; p < n; ++p) L += b[p].dot(last.v[p]);
        return L;
    };
    const double fd_coarse = along_velocities<2>(loss, start, dv, 1e-4), fd_fine = along_velocities<2>(loss, start, dv, 1e-6);
    std::printf("the same, %d steps: dL/dv0 %.10g vs %.10g (h 1e-4) and %.10g (h 1e-6)\n", short_steps, g_v, fd_coarse,
                fd_fine);
    const double low = std::min(fd_coarse, fd_fine), high = std::max(fd_coarse, fd_fine), spread = high - low;
    EXPECT_GT(g_v, low - spread);
    EXPECT_LT(g_v, high + spread);
}

// A block of a plastic material with hardening (snow: Cam-Clay, a = -0.1; metal: von Mises with StVK-Hencky)
// thrown onto the slip floor, under `return_map` and `lagged`: dL/dv0, dL/dE, dL/d of each plasticity parameter
// and dL/dh0 along a random direction against central differences of the whole rollout. The hardening's
// cotangent carries each step's return mapping back (h' = h'(F_trial, h), and return_map's stress in h).
Scene hardening_block_scene(const MaterialDescription& material, int sticky_floor_cells = 0,
                            double flip_relaxation_time = 0.0, double floor_friction = -1.0) {
    nlohmann::json scene = nlohmann::json::parse(R"({
        "dim": 2, "domain": {"min": [0, 0], "max": [1, 1]}, "dx": 0.03125, "gravity": [0, -9.8],
        "particles_per_cell": 2, "boundary": {"walls": "slip", "sticky_floor_cells": 0},
        "integrator": {"name": "return_map", "dt": 2e-3},
        "objects": [{"shape": "box", "min": [0.42, 0.12], "max": [0.58, 0.26], "velocity": [0.4, -2.5]}]
    })");
    scene["objects"][0]["material"] = material_to_json(material);
    scene["boundary"]["sticky_floor_cells"] = sticky_floor_cells;
    if (floor_friction >= 0.0) {  // a Coulomb floor, the block sliding along it
        scene["boundary"]["floor_friction"] = floor_friction;
        scene["objects"][0]["velocity"] = {1.5, -2.0};
    }
    if (flip_relaxation_time > 0.0) scene["transfer"] = {{"flip_relaxation_time", flip_relaxation_time}};
    return scene_from_json(scene, "<block>", ".");
}

/// The hardening rollout's check: scene_of(material) (its particles and material) for `steps` steps of 2e-3 s under
/// `method`, a random linear loss of the last positions and velocities; dL/dv0 and dL/dh0 along random
/// directions and dL/d of each field ("elasticity.E", a plasticity parameter) against central differences.
template <int dim>
void check_hardening_rollout(const std::function<Scene(const MaterialDescription&)>& scene_of,
                             const MaterialDescription& material, Method method, const std::vector<std::string>& fields,
                             int steps, const ImplicitOptions& options, const std::string& label) {
    const double dt = 2e-3;
    const Scene scene = scene_of(material);
    const MpmSystem<dim> system = make_mpm_system<dim>(scene);
    const Particles<dim> start = sample_particles<dim>(scene);
    const std::size_t n = start.size();
    test::Random random(89);
    std::vector<Vec<dim>> a(n), b(n), dv(n);
    std::vector<double> dh(n);
    for (std::size_t p = 0; p < n; ++p) {
        a[p] = random.uniform_vec<dim>(-1.0, 1.0);
        b[p] = random.uniform_vec<dim>(-1.0, 1.0);
        dv[p] = random.uniform_vec<dim>(-1.0, 1.0);
        dh[p] = random.uniform(-1.0, 1.0);
    }
    auto loss = [&](const MaterialDescription& m, const Particles<dim>& from) {
        MpmSystem<dim> s = system;
        s.materials[0] = Material<dim>(m);
        MpmAdjoint<dim> adjoint(s, options, MpmOptions{}, method);
        return linear_loss(adjoint.forward(from, dt, steps), a, b);
    };
    MpmAdjoint<dim> adjoint(system, options, MpmOptions{}, method);
    const Particles<dim> last = adjoint.forward(start, dt, steps);
    ASSERT_EQ(adjoint.unconverged_steps(), 0) << "the gradient is of converged steps";
    int hardened = 0;
    for (std::size_t p = 0; p < n; ++p) hardened += last.hardening[p] != start.hardening[p];
    ASSERT_GT(hardened, static_cast<int>(n) / 5) << "the body must yield";
    // Every field but E through the material-field gradients too (MpmAdjoint::set_parameter_fields: central
    // differences of each particle's stress and return mapping), beside the written-out derivatives where any.
    std::vector<std::string> material_fields;
    for (const std::string& field : fields)
        if (field != "elasticity.E") material_fields.push_back(field);
    adjoint.set_parameter_fields(material_fields);
    const MpmRolloutGradient<dim> g = adjoint.backward(a, b);
    double g_v = 0.0, g_h = 0.0;
    for (std::size_t p = 0; p < n; ++p) {
        g_v += g.v[p].dot(dv[p]);
        g_h += g.hardening[p] * dh[p];
    }
    // Differences of 1e-5 m/s, 1e-6 in h and 1e-6 relative in the parameters: at 10 times these, particles that
    // change branch (yield onset, the ellipse's tips) within the step move them by up to 10% (the metal's dL/dh0).
    const double fd_v =
        along_velocities<dim>([&](const Particles<dim>& from) { return loss(material, from); }, start, dv, 1e-5);
    const double step_h = 1e-6;
    Particles<dim> plus = start, minus = start;
    for (std::size_t p = 0; p < n; ++p) {
        plus.hardening[p] += step_h * dh[p];
        minus.hardening[p] -= step_h * dh[p];
    }
    const double fd_h = (loss(material, plus) - loss(material, minus)) / (2.0 * step_h);
    std::printf("MPM %s rollout %dD (%s%s), %zu particles (%d hardened), %d steps: dL/dv0 %.10g vs %.10g, dL/dh0 %.10g "
                "vs %.10g\n",
                material.name.c_str(), dim, to_string(method), label.c_str(), n, hardened, steps, g_v, fd_v, g_h, fd_h);
    EXPECT_NEAR(g_v, fd_v, 1e-4 * std::abs(fd_v));
    EXPECT_NEAR(g_h, fd_h, 1e-4 * std::abs(fd_h));
    for (const std::string& field : fields) {
        MaterialDescription up = material, down = material;
        double *value_up, *value_down, adjoint_value;
        bool written = true;  // a closed-form derivative beside the material-field one
        if (field == "elasticity.E") {
            value_up = &up.elastic.E;
            value_down = &down.elastic.E;
            adjoint_value = g.youngs_modulus;
        } else {
            value_up = material_parameter(up, field);
            value_down = material_parameter(down, field);
            const std::size_t f = static_cast<std::size_t>(
                std::find(material_fields.begin(), material_fields.end(), field) - material_fields.begin());
            adjoint_value = g.fields[f];
            written =
                field == "plasticity.xi" || field == "plasticity.beta" || field == "plasticity.friction_angle_deg";
            if (written) {
                const double closed = field == "plasticity.xi"     ? g.xi
                                      : field == "plasticity.beta" ? g.beta
                                                                   : g.friction_angle;
                std::printf("  dL/d%s written out %.10g, by the material's differences %.10g\n", field.c_str(), closed,
                            adjoint_value);
                // Within the differences' error: Cam-Clay's projection solves for its scale iteratively, and its
                // difference quotient in xi carries that solve's tolerance (9e-5 relative under return_map).
                EXPECT_NEAR(closed, adjoint_value, 1e-3 * std::abs(closed)) << field;
                adjoint_value = closed;
            }
        }
        const double h = 1e-6 * *value_up;
        *value_up += h;
        *value_down -= h;
        const double fd = (loss(up, start) - loss(down, start)) / (2.0 * h);
        std::printf("  dL/d%s %.10g vs %.10g\n", field.c_str(), adjoint_value, fd);
        EXPECT_NEAR(adjoint_value, fd, 1e-4 * std::abs(fd)) << field;
    }
}

void check_hardening_block(const MaterialDescription& material, Method method, const std::vector<std::string>& fields,
                           int sticky_floor_cells = 0, double flip_relaxation_time = 0.0, double floor_friction = -1.0,
                           const ImplicitOptions& options = tight()) {
    check_hardening_rollout<2>(
        [&](const MaterialDescription& m) {
            return hardening_block_scene(m, sticky_floor_cells, flip_relaxation_time, floor_friction);
        },
        material, method, fields, 20, options,
        floor_friction >= 0.0 ? ", Coulomb floor" : sticky_floor_cells > 0 ? ", sticky floor, AFLIP" : "");
}

TEST(MpmAdjoint2d, CamClayRolloutGradientMatchesCentralDifferences) {
    const std::vector<std::string> fields = {"elasticity.E", "elasticity.nu", "plasticity.friction_angle_deg",
                                             "plasticity.xi", "plasticity.beta"};
    check_hardening_block(material_preset("snow"), Method::ReturnMap, fields);
    check_hardening_block(material_preset("snow"), Method::Lagged, fields);
}

TEST(MpmAdjoint2d, VonMisesRolloutGradientMatchesCentralDifferences) {
    MaterialDescription metal = material_preset("metal");
    metal.elastic.E = 2e6;
    metal.initial_hardening = 0.02;
    const std::vector<std::string> fields = {"elasticity.E", "elasticity.nu", "plasticity.hardening_coefficient"};
    check_hardening_block(metal, Method::ReturnMap, fields);
    check_hardening_block(metal, Method::Lagged, fields);
}

// The snowball's boundary and transfers: a sticky floor (its three cells of nodes held at 0 by the solve)
// and AFLIP.
TEST(MpmAdjoint2d, CamClayOnTheStickyFloorWithAflipMatchesCentralDifferences) {
    const std::vector<std::string> fields = {"elasticity.E", "plasticity.xi"};
    check_hardening_block(material_preset("snow"), Method::ReturnMap, fields, 3, 0.01);
    check_hardening_block(material_preset("snow"), Method::Lagged, fields, 3, 0.01);
}

// The Coulomb floor (mu 0.3, and 0) in return_map's one solve (its friction in the residual, J_k the floor's
// normal impulse at v), the block sliding along it: the friction's Jacobian (mu J_k f1'(|u|) in the slip, and
// its coupling through J_k to the held normal rows) in J^T, the held rows' cotangent to v*_y and the particles,
// and the floor's projection after the solve (a node still moving into the layer loses its normal velocity and
// mu |v_y| of its tangential speed). Newton's cap at 2000: on the sliding nodes the one solve converges
// linearly, and at 200 three of the 20 steps stop short of 1e-11 m/s.
TEST(MpmAdjoint2d, CamClayOnTheCoulombFloorMatchesCentralDifferences) {
    const std::vector<std::string> fields = {"elasticity.E", "plasticity.xi"};
    ImplicitOptions options = tight();
    options.max_newton_iterations = 2000;
    check_hardening_block(material_preset("snow"), Method::ReturnMap, fields, 3, 0.0, 0.3, options);
    check_hardening_block(material_preset("snow"), Method::ReturnMap, fields, 3, 0.0, 0.0, options);  // held normals
}

// 3D snow (Cam-Clay, the snow preset) thrown onto the sticky floor (snowball_3d's), under `return_map`: dL/dv0,
// dL/dh0 and dL/dxi against central differences.
Scene snow_sphere_scene(const MaterialDescription& material) {
    nlohmann::json scene = nlohmann::json::parse(R"({
        "dim": 3, "domain": {"min": [0, 0, 0], "max": [1, 1, 1]}, "dx": 0.0625, "gravity": [0, -9.8, 0],
        "particles_per_cell": 2, "boundary": {"walls": "slip", "sticky_floor_cells": 3},
        "integrator": {"name": "return_map", "dt": 2e-3},
        "objects": [{"shape": "sphere", "center": [0.5, 0.32, 0.5], "radius": 0.12, "velocity": [0.3, -3, 0.1]}]
    })");
    scene["objects"][0]["material"] = material_to_json(material);
    return scene_from_json(scene, "<snow sphere>", ".");
}

TEST(MpmAdjoint3d, CamClayOnTheStickyFloorMatchesCentralDifferences) {
    check_hardening_rollout<3>(snow_sphere_scene, material_preset("snow"), Method::ReturnMap, {"plasticity.xi"}, 10,
                               tight(), ", sticky floor");
}

TEST(MpmAdjoint2d, RefusesWhatItDoesNotCover) {
    MpmSystem<2> snow = make_mpm_system<2>(disk_scene(1e5));
    MaterialDescription paper = material_preset("snow");
    paper.cam_clay.variant = CamClayVariant::Paper;
    snow.materials[0] = Material<2>(paper);
    try {
        MpmAdjoint<2>(snow, tight(), MpmOptions{});
        FAIL() << "expected std::invalid_argument";
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("materials[0].plasticity.variant 'paper'"), std::string::npos) << e.what();
    }
    MpmSystem<2> coulomb = make_mpm_system<2>(disk_scene(1e5));
    coulomb.boundary.sticky_floor_cells = 3;
    coulomb.boundary.floor_friction = 0.3;
    try {
        MpmAdjoint<2>(coulomb, tight(), MpmOptions{}, Method::Lagged);
        FAIL() << "expected std::invalid_argument";
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("boundary.floor_friction with integrator 'lagged'"), std::string::npos)
            << e.what();
    }
    MpmSystem<2> metal_nh = make_mpm_system<2>(disk_scene(1e5));
    metal_nh.materials[0] = Material<2>(material_preset("metal_nh"));
    try {
        MpmAdjoint<2>(metal_nh, tight(), MpmOptions{});
        FAIL() << "expected std::invalid_argument";
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("materials[0].elasticity"), std::string::npos) << e.what();
    }
    EXPECT_THROW(MpmAdjoint<2>(make_mpm_system<2>(disk_scene(1e5)), tight(), MpmOptions{}, Method::PlasticityNet),
                 std::invalid_argument);
    // A material field no material has (the elastic disk has no plasticity), or no such field, named.
    const MpmSystem<2> elastic = make_mpm_system<2>(disk_scene(1e5));
    MpmAdjoint<2> adjoint(elastic, tight(), MpmOptions{});
    for (const char* field : {"plasticity.xi", "elasticity.poisson"}) {
        try {
            adjoint.set_parameter_fields({"elasticity.nu", field});
            FAIL() << "expected std::invalid_argument for " << field;
        } catch (const std::invalid_argument& e) {
            EXPECT_NE(std::string(e.what()).find(std::string("parameter field '") + field + "'"), std::string::npos)
                << e.what();
        }
    }
}

}  // namespace
}  // namespace pnet
