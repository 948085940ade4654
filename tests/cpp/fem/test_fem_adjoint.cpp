// The adjoint of an implicit FEM rollout (fem/fem_adjoint.hpp; issue 57's first part): the gradient
// of a loss of the last state with respect to the start's positions and velocities and to Young's
// modulus against central finite differences of the whole rollout, on an elastic box that falls
// onto the ground and bounces on IPC's barrier (a contact pair appearing within the rollout); the
// forward solves tightened to 1e-10 m/s. Bad requests are refused naming what.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "pnet/fem/fem_adjoint.hpp"
#include "support/fem_systems.hpp"
#include "support/random.hpp"

namespace pnet {
namespace {

/// An elastic (neo-Hookean, E Pa) box 6 x 3 cm (2D) or 6 x 3 x 3 cm (3D), its bottom `gap` m above
/// the ground, falling at `speed` m/s; rest made.
template <int dim>
FemSystem<dim> falling_box(double E, double gap) {
    Vec<dim> lo = Vec<dim>::Zero(), hi = Vec<dim>::Constant(0.03);
    hi[0] = 0.06;
    lo[1] = gap;
    hi[1] = gap + 0.03;
    Mesh<dim> mesh = mesh_shape(test::box_shape<dim>(lo, hi, 0.015), "box");
    FemSystem<dim> system =
        test::falling_object<dim>(std::move(mesh), test::elastic_material(ElasticityModel::NeoHookeanMetal, E));
    system.make_rest();
    return system;
}

template <int dim>
struct Rollout {
    static constexpr double kGap = 0.002, kSpeed = 0.5, kDt = 2e-3;
    static constexpr int kSteps = 15;
    double E;
    std::string time_integrator;
    FemSystem<dim> system = falling_box<dim>(E, kGap);
    Contact<dim> contact{system.mesh.boundary, system.mesh.x, 1e-3, 1e8};
    ImplicitOptions options;
    FemAdjoint<dim> adjoint;

    explicit Rollout(double E_, std::string integrator = "backward_euler")
        : E(E_), time_integrator(std::move(integrator)), adjoint(make_adjoint()) {}
    FemAdjoint<dim> make_adjoint() {
        contact.add_half_space(HalfSpace<dim>{});
        options.newton_tolerance = 1e-10;
        options.max_newton_iterations = 500;
        options.time_integrator = time_integrator;
        return FemAdjoint<dim>(system, &contact, options);
    }
    FemState<dim> start() const {
        FemState<dim> s = FemState<dim>::at_rest(system);
        for (Vec<dim>& v : s.v) v = -kSpeed * Vec<dim>::Unit(1);
        return s;
    }
    /// Every state of kSteps steps from s (0: s), checkpoints every `every` steps (0: sqrt).
    std::vector<FemState<dim>> run(const FemState<dim>& s, int every = 0, int steps = kSteps) {
        std::vector<FemState<dim>> states;
        adjoint.forward(s, kDt, steps, every, [&](int, const FemState<dim>& state) { states.push_back(state); });
        return states;
    }
};

/// L = a . x^N + b . v^N + c . x^(N/2): the last state's positions and velocities and a middle state's
/// positions.
template <int dim>
double loss(const std::vector<FemState<dim>>& states, const std::vector<Vec<dim>>& a, const std::vector<Vec<dim>>& b,
            const std::vector<Vec<dim>>& c) {
    const FemState<dim>& last = states.back();
    const FemState<dim>& middle = states[states.size() / 2];
    double L = 0.0;
    for (std::size_t i = 0; i < a.size(); ++i) L += a[i].dot(last.x[i]) + b[i].dot(last.v[i]) + c[i].dot(middle.x[i]);
    return L;
}

template <int dim>
void check_rollout_gradient(const std::string& time_integrator = "backward_euler") {
    Rollout<dim> r(1e5, time_integrator);
    test::Random rng(7);
    const std::size_t nodes = r.system.mesh.nodes();
    std::vector<Vec<dim>> a(nodes), b(nodes), c(nodes);
    for (std::size_t i = 0; i < nodes; ++i) {
        a[i] = rng.template uniform_vec<dim>(-1.0, 1.0);
        b[i] = rng.template uniform_vec<dim>(-1.0, 1.0);
        c[i] = rng.template uniform_vec<dim>(-1.0, 1.0);
    }
    const FemState<dim> start = r.start();
    const std::vector<FemState<dim>> states_run = r.run(start);
    double min_distance = 1e9;
    for (const FemState<dim>& s : states_run) min_distance = std::min(min_distance, r.contact.min_distance(s.x));
    ASSERT_LT(min_distance, 1e-3) << "the box never came within dhat of the ground";
    const std::size_t states = states_run.size();
    std::vector<std::vector<Vec<dim>>> dL_dx(states), dL_dv(states);
    dL_dx.back() = a;
    dL_dv.back() = b;
    dL_dx[states / 2] = c;
    const FemRolloutGradient<dim> g = r.adjoint.backward(dL_dx, dL_dv);

    auto run = [&](double E, const FemState<dim>& s) {
        Rollout<dim> q(E, time_integrator);
        return loss<dim>(q.run(s), a, b, c);
    };
    // Young's modulus.
    const double hE = 1e-4 * r.E;
    const double fd_E = (run(r.E + hE, start) - run(r.E - hE, start)) / (2.0 * hE);
    EXPECT_NEAR(g.youngs_modulus, fd_E, 1e-4 * std::abs(fd_E)) << "dL/dE";
    std::printf("%dD %s, %d steps, closest %.3g m: dL/dE adjoint %.10g, finite differences %.10g (%.2g relative)\n",
                dim, time_integrator.c_str(), r.kSteps, min_distance, g.youngs_modulus, fd_E,
                std::abs(g.youngs_modulus - fd_E) / std::abs(fd_E));
    // The start's velocities and positions along random directions (every node at once: a single
    // node's component moves L too little to rise above the solver's noise).
    for (const bool velocity : {true, false}) {
        std::vector<Vec<dim>> d(nodes);
        double slope = 0.0;
        for (std::size_t i = 0; i < nodes; ++i) {
            d[i] = rng.template uniform_vec<dim>(-1.0, 1.0);
            slope += d[i].dot(velocity ? g.v[i] : g.x[i]);
        }
        const double h = velocity ? 1e-4 : 1e-6;  // m/s, m (the closest gap is a few microns)
        FemState<dim> plus = start, minus = start;
        for (std::size_t i = 0; i < nodes; ++i) {
            (velocity ? plus.v : plus.x)[i] += h * d[i];
            (velocity ? minus.v : minus.x)[i] -= h * d[i];
        }
        const double fd = (run(r.E, plus) - run(r.E, minus)) / (2.0 * h);
        EXPECT_NEAR(slope, fd, 1e-4 * std::abs(fd))
            << (velocity ? "dL/dv^0" : "dL/dx^0") << " along a random direction";
        std::printf("  along a random direction: %s adjoint %.10g, finite differences %.10g (%.2g relative)\n",
                    velocity ? "dL/dv^0" : "dL/dx^0", slope, fd, std::abs(slope - fd) / std::abs(fd));
    }
}

TEST(FemAdjoint2d, RolloutGradientMatchesFiniteDifferencesThroughAContact) {
    check_rollout_gradient<2>();
}
TEST(FemAdjoint2d, Bdf2RolloutGradientMatchesFiniteDifferencesThroughAContact) {
    check_rollout_gradient<2>("bdf2");
}
TEST(FemAdjoint3d, RolloutGradientMatchesFiniteDifferencesThroughAContact) {
    check_rollout_gradient<3>();
}

// A metal box (von Mises, StVK-Hencky; the preset, E 1e7 Pa, but yielding at 0.5% deviatoric strain) hits the
// ground at 4 m/s and yields: the gradient through the return mapping's state update and the
// residual's dependence on (F^P)^-1, against central differences of the whole rollout, with respect
// to the initial hardening (the yield stress, tau_Y = 2 mu h), E and the start's velocities.
template <int dim>
void check_plastic_rollout_gradient(FemMethod method) {
    const MaterialDescription preset = material_preset("metal");
    const double nu0 = preset.elastic.nu, xi0 = preset.von_mises.hardening_coefficient;
    auto make = [&](double E, double h0, double nu = -1.0, double xi = -1.0) {
        Vec<dim> lo = Vec<dim>::Zero(), hi = Vec<dim>::Constant(0.03);
        hi[0] = 0.06;
        lo[1] = 0.002;
        hi[1] = 0.032;
        MaterialDescription metal = preset;
        metal.elastic.E = E;
        metal.initial_hardening = h0;
        metal.elastic.nu = nu >= 0.0 ? nu : nu0;
        metal.von_mises.hardening_coefficient = xi >= 0.0 ? xi : xi0;
        FemSystem<dim> system =
            test::falling_object<dim>(mesh_shape(test::box_shape<dim>(lo, hi, 0.015), "box"), metal);
        system.make_rest();
        return system;
    };
    const double E = 1e7, h0 = 0.005, dt = 1e-3, speed = 4.0;
    const int steps = 12;
    ImplicitOptions options;
    options.newton_tolerance = 1e-10;
    options.max_newton_iterations = 500;
    FemSystem<dim> system = make(E, h0);
    Contact<dim> contact(system.mesh.boundary, system.mesh.x, 1e-3, 1e10);
    contact.add_half_space(HalfSpace<dim>{});
    FemAdjoint<dim> adjoint(system, &contact, options, method);
    test::Random rng(5);
    const std::size_t nodes = system.mesh.nodes();
    std::vector<Vec<dim>> a(nodes), b(nodes), d(nodes);
    for (std::size_t i = 0; i < nodes; ++i) {
        a[i] = rng.template uniform_vec<dim>(-1.0, 1.0);
        b[i] = rng.template uniform_vec<dim>(-1.0, 1.0);
        d[i] = rng.template uniform_vec<dim>(-1.0, 1.0);
    }
    // L = a . x^N + b . v^N of a rollout of the system (E, h0) from v0 + eps d.
    auto loss = [&](double E_, double h0_, double eps, FemState<dim>* last_state = nullptr, double nu = -1.0,
                    double xi = -1.0) {
        FemSystem<dim> s = make(E_, h0_, nu, xi);
        Contact<dim> c(s.mesh.boundary, s.mesh.x, 1e-3, 1e10);
        c.add_half_space(HalfSpace<dim>{});
        FemAdjoint<dim> r(s, &c, options, method);
        FemState<dim> start = FemState<dim>::at_rest(s);
        for (std::size_t i = 0; i < nodes; ++i) start.v[i] = -speed * Vec<dim>::Unit(1) + eps * d[i];
        const FemState<dim> last = r.forward(start, dt, steps);
        if (last_state) *last_state = last;
        double L = 0.0;
        for (std::size_t i = 0; i < nodes; ++i) L += a[i].dot(last.x[i]) + b[i].dot(last.v[i]);
        return L;
    };
    FemState<dim> start = FemState<dim>::at_rest(system);
    for (Vec<dim>& v : start.v) v = -speed * Vec<dim>::Unit(1);
    const FemState<dim> last = adjoint.forward(start, dt, steps);
    double yielded = 0.0;
    for (double h : last.hardening) yielded = std::max(yielded, h - h0);
    ASSERT_GT(yielded, 1e-4) << "no element yielded";
    adjoint.set_parameter_fields({"elasticity.nu", "plasticity.hardening_coefficient"});
    const FemRolloutGradient<dim> g = adjoint.backward(a, b);
    double g_h0 = 0.0;
    for (double h : g.hardening) g_h0 += h;
    const double fd_h0 = (loss(E, h0 + 1e-6, 0.0) - loss(E, h0 - 1e-6, 0.0)) / 2e-6;
    const double fd_E = (loss(E * (1 + 1e-4), h0, 0.0) - loss(E * (1 - 1e-4), h0, 0.0)) / (2e-4 * E);
    const double fd_v = (loss(E, h0, 1e-5) - loss(E, h0, -1e-5)) / 2e-5;
    double g_v = 0.0;
    for (std::size_t i = 0; i < nodes; ++i) g_v += g.v[i].dot(d[i]);
    std::printf(
        "%dD plastic (%s), %d steps, largest hardening growth %.3g: dL/dh0 %.10g vs %.10g (%.2g), dL/dE %.10g vs "
        "%.10g (%.2g), dL/dv0 along a direction %.10g vs %.10g (%.2g)\n",
        dim, integrator_info(method).name, steps, yielded, g_h0, fd_h0, std::abs(g_h0 - fd_h0) / std::abs(fd_h0),
        g.youngs_modulus, fd_E, std::abs(g.youngs_modulus - fd_E) / std::abs(fd_E), g_v, fd_v,
        std::abs(g_v - fd_v) / std::abs(fd_v));
    EXPECT_NEAR(g_h0, fd_h0, 1e-4 * std::abs(fd_h0)) << "dL/dh0";
    EXPECT_NEAR(g.youngs_modulus, fd_E, 1e-4 * std::abs(fd_E)) << "dL/dE";
    EXPECT_NEAR(g_v, fd_v, 1e-4 * std::abs(fd_v)) << "dL/dv0";
    // Poisson's ratio and the hardening coefficient (FemAdjoint::set_parameter_fields).
    // 1e-3 relative: the loss moves by about 1e-4 there, against the solves' noise (1e-10 m/s), which made central
    // differences at 1e-6 scatter by 1e-2.
    const double h_nu = 1e-3 * nu0, h_xi = 1e-3 * xi0;
    const double fd_nu = (loss(E, h0, 0.0, nullptr, nu0 + h_nu) - loss(E, h0, 0.0, nullptr, nu0 - h_nu)) / (2.0 * h_nu);
    const double fd_xi =
        (loss(E, h0, 0.0, nullptr, -1.0, xi0 + h_xi) - loss(E, h0, 0.0, nullptr, -1.0, xi0 - h_xi)) / (2.0 * h_xi);
    std::printf("  dL/dnu %.10g vs %.10g (%.2g), dL/d(hardening coefficient) %.10g vs %.10g (%.2g)\n", g.fields[0],
                fd_nu, std::abs(g.fields[0] - fd_nu) / std::abs(fd_nu), g.fields[1], fd_xi,
                std::abs(g.fields[1] - fd_xi) / std::abs(fd_xi));
    EXPECT_NEAR(g.fields[0], fd_nu, 1e-4 * std::abs(fd_nu)) << "dL/dnu";
    EXPECT_NEAR(g.fields[1], fd_xi, 1e-4 * std::abs(fd_xi)) << "dL/d(hardening coefficient)";
}

TEST(FemAdjoint2d, PlasticRolloutGradientMatchesFiniteDifferences) {
    check_plastic_rollout_gradient<2>(FemMethod::Lagged);
    check_plastic_rollout_gradient<2>(FemMethod::ReturnMap);
}
TEST(FemAdjoint3d, PlasticRolloutGradientMatchesFiniteDifferences) {
    check_plastic_rollout_gradient<3>(FemMethod::Lagged);
    check_plastic_rollout_gradient<3>(FemMethod::ReturnMap);
}

// A cantilever: a metal bar (yielding at 0.5% deviatoric strain) 10 x 1 cm clamped at its left end
// (fixed nodes at rest) sags under gravity and yields at its root; no contact. The gradient with
// respect to the yield stress, E and the free nodes' start velocities against central differences.
void check_cantilever(FemMethod method) {
    auto make = [](double E, double h0) {
        MaterialDescription metal = material_preset("metal");
        metal.elastic.E = E;
        metal.initial_hardening = h0;
        FemSystem<2> s = test::falling_object<2>(
            mesh_shape(test::box_shape<2>(Vec<2>(0.0, 0.05), Vec<2>(0.1, 0.06), 0.005), "bar"), metal);
        s.fixed_node.assign(s.mesh.nodes(), 0);
        s.prescribed_velocity.assign(s.mesh.nodes(), Vec<2>::Zero());
        for (std::size_t i = 0; i < s.mesh.nodes(); ++i) s.fixed_node[i] = s.mesh.x[i][0] < 1e-9;
        s.make_rest();
        return s;
    };
    const double E = 1e7, h0 = 0.005, dt = 2e-3;
    const int steps = 15;
    ImplicitOptions options;
    options.newton_tolerance = 1e-10;
    options.max_newton_iterations = 500;
    FemSystem<2> system = make(E, h0);
    const std::size_t nodes = system.mesh.nodes();
    test::Random rng(9);
    std::vector<Vec<2>> a(nodes), d(nodes);
    for (std::size_t i = 0; i < nodes; ++i) {
        a[i] = rng.template uniform_vec<2>(-1.0, 1.0);
        d[i] = system.fixed_node[i] ? Vec<2>::Zero() : rng.template uniform_vec<2>(-1.0, 1.0);
    }
    auto loss = [&](double E_, double h0_, double eps, FemState<2>* last_state = nullptr) {
        FemSystem<2> s = make(E_, h0_);
        FemAdjoint<2> r(s, nullptr, options, method);
        FemState<2> start = FemState<2>::at_rest(s);
        for (std::size_t i = 0; i < nodes; ++i) start.v[i] = eps * d[i];
        const FemState<2> last = r.forward(start, dt, steps);
        if (last_state) *last_state = last;
        double L = 0.0;
        for (std::size_t i = 0; i < nodes; ++i) L += a[i].dot(last.x[i]);
        return L;
    };
    FemAdjoint<2> adjoint(system, nullptr, options, method);
    const FemState<2> last = adjoint.forward(FemState<2>::at_rest(system), dt, steps);
    double yielded = 0.0, sag = 0.0;
    for (double h : last.hardening) yielded = std::max(yielded, h - h0);
    for (std::size_t i = 0; i < nodes; ++i) sag = std::max(sag, system.mesh.x[i][1] - last.x[i][1]);
    ASSERT_GT(yielded, 1e-5) << "the root did not yield";
    const FemRolloutGradient<2> g = adjoint.backward(a, std::vector<Vec<2>>(nodes, Vec<2>::Zero()));
    double g_h0 = 0.0, g_v = 0.0;
    for (double h : g.hardening) g_h0 += h;
    for (std::size_t i = 0; i < nodes; ++i) g_v += g.v[i].dot(d[i]);
    const double fd_h0 = (loss(E, h0 + 1e-6, 0.0) - loss(E, h0 - 1e-6, 0.0)) / 2e-6;
    const double fd_E =
        (loss(E * (1 + 1e-4), h0, 0.0) - loss(E * (1 - 1e-4), h0, 0.0)) / (2e-4 * E);  // L moves little with E
    const double fd_v = (loss(E, h0, 1e-5) - loss(E, h0, -1e-5)) / 2e-5;
    std::printf(
        "cantilever (%s), %d steps, sag %.3g m, largest hardening growth %.3g: dL/dh0 %.10g vs %.10g (%.2g), "
        "dL/dE %.10g vs %.10g (%.2g), dL/dv0 %.10g vs %.10g (%.2g)\n",
        integrator_info(method).name, steps, sag, yielded, g_h0, fd_h0, std::abs(g_h0 - fd_h0) / std::abs(fd_h0),
        g.youngs_modulus, fd_E, std::abs(g.youngs_modulus - fd_E) / std::abs(fd_E), g_v, fd_v,
        std::abs(g_v - fd_v) / std::abs(fd_v));
    EXPECT_NEAR(g_h0, fd_h0, 1e-4 * std::abs(fd_h0)) << "dL/dh0";
    EXPECT_NEAR(g.youngs_modulus, fd_E, 1e-4 * std::abs(fd_E)) << "dL/dE";
    EXPECT_NEAR(g_v, fd_v, 1e-4 * std::abs(fd_v)) << "dL/dv0";
    for (std::size_t i = 0; i < nodes; ++i) {
        if (system.fixed_node[i]) {
            EXPECT_EQ(g.v[i], Vec<2>::Zero()) << "clamp " << i;
        }
    }
}

TEST(FemAdjoint2d, ClampedCantileverYieldsAndItsGradientMatchesFiniteDifferences) {
    check_cantilever(FemMethod::Lagged);
    check_cantilever(FemMethod::ReturnMap);
}

// Lagged friction, held at its lagged values: a box creeping on the ground at 5e-5 m/s (within eps_v, where
// friction has curvature; a 2D slide beyond eps_v has none along its slip) under Coulomb
// friction (mu 0.3). One step's lagged pairs depend on the start's positions only, so central
// differences of one step with respect to the start's velocities and E hold them, as the adjoint does;
// so does a horizontal translation of the whole start (the ground is flat). Over several steps the
// lags move with the path, which the adjoint holds: that gap is printed, not asserted.
TEST(FemAdjoint2d, LaggedFrictionHeldMatchesFiniteDifferencesOfOneStep) {
    auto rollout = [](double E, const std::vector<Vec<2>>& dx, const std::vector<Vec<2>>& dv, double eps, int steps,
                      const std::vector<Vec<2>>& a, const std::vector<Vec<2>>& b, FemRolloutGradient<2>* g) {
        FemSystem<2> s = falling_box<2>(E, 0.0005);
        Contact<2> c(s.mesh.boundary, s.mesh.x, 1e-3, 1e8);
        c.add_half_space(HalfSpace<2>{});
        ImplicitOptions options;
        options.newton_tolerance = 1e-10;
        options.max_newton_iterations = 500;
        FemAdjoint<2> adjoint(s, &c, options);
        adjoint.set_friction(0.3, 1e-4);
        FemState<2> start = FemState<2>::at_rest(s);
        for (std::size_t i = 0; i < start.x.size(); ++i) {
            start.x[i] += eps * dx[i];
            start.v[i] = Vec<2>(5e-5, 0.0) + eps * dv[i];  // within eps_v: the smoothed, stiff friction
        }
        const FemState<2> last = adjoint.forward(start, 2e-3, steps);
        if (g) *g = adjoint.backward(a, b);
        double L = 0.0;
        for (std::size_t i = 0; i < a.size(); ++i) L += a[i].dot(last.x[i]) + b[i].dot(last.v[i]);
        return L;
    };
    const std::size_t nodes = falling_box<2>(1e5, 0.0005).mesh.nodes();
    test::Random rng(13);
    std::vector<Vec<2>> a(nodes), b(nodes), d(nodes), zero(nodes, Vec<2>::Zero()), shift(nodes, Vec<2>(1.0, 0.0));
    for (std::size_t i = 0; i < nodes; ++i) {
        a[i] = rng.template uniform_vec<2>(-1.0, 1.0);
        b[i] = rng.template uniform_vec<2>(-1.0, 1.0);
        d[i] = rng.template uniform_vec<2>(-1.0, 1.0);
    }
    for (const int steps : {1, 10}) {
        FemRolloutGradient<2> g;
        rollout(1e5, zero, zero, 0.0, steps, a, b, &g);
        double g_v = 0.0, g_x = 0.0;
        for (std::size_t i = 0; i < nodes; ++i) {
            g_v += g.v[i].dot(d[i]);
            g_x += g.x[i][0];
        }
        const double fd_v =
            (rollout(1e5, zero, d, 1e-5, steps, a, b, nullptr) - rollout(1e5, zero, d, -1e-5, steps, a, b, nullptr)) /
            2e-5;
        const double fd_x = (rollout(1e5, shift, zero, 1e-6, steps, a, b, nullptr) -
                             rollout(1e5, shift, zero, -1e-6, steps, a, b, nullptr)) /
                            2e-6;
        const double fd_E = (rollout(1e5 * (1 + 1e-4), zero, zero, 0.0, steps, a, b, nullptr) -
                             rollout(1e5 * (1 - 1e-4), zero, zero, 0.0, steps, a, b, nullptr)) /
                            (2e-4 * 1e5);
        std::printf(
            "friction, %d step(s): dL/dv0 %.10g vs %.10g (%.2g), dL/dx0 along a translation %.10g vs %.10g "
            "(%.2g), dL/dE %.10g vs %.10g (%.2g)\n",
            steps, g_v, fd_v, std::abs(g_v - fd_v) / std::abs(fd_v), g_x, fd_x, std::abs(g_x - fd_x) / std::abs(fd_x),
            g.youngs_modulus, fd_E, std::abs(g.youngs_modulus - fd_E) / std::abs(fd_E));
        if (steps == 1) {
            EXPECT_NEAR(g_v, fd_v, 1e-4 * std::abs(fd_v)) << "dL/dv0";
            EXPECT_NEAR(g_x, fd_x, 1e-4 * std::abs(fd_x)) << "dL/dx0 along a translation";
            EXPECT_NEAR(g.youngs_modulus, fd_E, 1e-4 * std::abs(fd_E)) << "dL/dE";
        }
    }
}

// Checkpoints every ~sqrt(N) steps and the segments recomputed give the gradient of the stored tape
// to the last bit (a recomputed step is the same step), holding about 2 sqrt(N) states: 1000 steps.
TEST(FemAdjoint2d, CheckpointedAndStoredTapeGradientsAreIdentical) {
    Rollout<2> r(1e5);
    const int steps = 1000;
    const FemState<2> start = r.start();
    std::vector<Vec<2>> a(r.system.mesh.nodes(), Vec<2>(0.3, -0.7));
    std::vector<FemRolloutGradient<2>> g;
    std::vector<std::size_t> peak;
    for (const int every : {1, 0, 7}) {
        r.adjoint.forward(start, 1e-4, steps, every);
        g.push_back(r.adjoint.backward(a, a));
        peak.push_back(r.adjoint.peak_states());
    }
    EXPECT_EQ(peak[0], static_cast<std::size_t>(steps + 1 + 2));  // every state, and a step's two
    EXPECT_LE(peak[1], static_cast<std::size_t>(2 * std::sqrt(steps) + 3)) << "sqrt checkpoints";
    for (std::size_t k = 1; k < g.size(); ++k) {
        EXPECT_EQ(g[k].youngs_modulus, g[0].youngs_modulus);
        for (std::size_t i = 0; i < a.size(); ++i) {
            EXPECT_EQ(g[k].x[i], g[0].x[i]) << "node " << i;
            EXPECT_EQ(g[k].v[i], g[0].v[i]) << "node " << i;
        }
    }
    std::printf("1000 steps: %zu / %zu / %zu states held (every state / sqrt checkpoints / every 7)\n", peak[0],
                peak[1], peak[2]);
}

TEST(FemAdjoint, RefusesWhatItDoesNotDifferentiate) {
    ImplicitOptions options;
    FemSystem<2> elastic_box = falling_box<2>(1e5, 0.01);
    try {
        FemAdjoint<2> adjoint(elastic_box, nullptr, options, FemMethod::PlasticityNet);
        ADD_FAILURE() << "plasticitynet was accepted";
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("return_map"), std::string::npos) << e.what();
    }
    // von Mises with neo-Hookean elasticity (its return mapping a root find: no derivative written).
    FemSystem<2> metal_nh =
        test::falling_object<2>(mesh_shape(test::box_shape<2>(Vec<2>(0.0, 0.01), Vec<2>(0.06, 0.04), 0.015), "box"),
                                material_preset("metal_nh"));
    metal_nh.make_rest();
    try {
        FemAdjoint<2> adjoint(metal_nh, nullptr, options);
        ADD_FAILURE() << "metal_nh was accepted";
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("plasticity"), std::string::npos) << e.what();
    }
    FemSystem<2> crushed = test::crushed_bar(0.05);  // von Mises with StVK-Hencky, but a moving plate
    try {
        FemAdjoint<2> adjoint(crushed, nullptr, options);
        ADD_FAILURE() << "moving kinematic nodes were accepted";
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("fixed_node"), std::string::npos) << e.what();
    }
    FemSystem<2> box = falling_box<2>(1e5, 0.01);
    FemAdjoint<2> adjoint(box, nullptr, options);
    EXPECT_THROW(adjoint.backward(std::vector<Vec<2>>{}, std::vector<Vec<2>>{}), std::logic_error);  // forward() first
    adjoint.forward(FemState<2>::at_rest(box), 1e-3, 2);
    EXPECT_THROW(adjoint.backward({Vec<2>::Zero()}, {Vec<2>::Zero()}), std::invalid_argument);
}

}  // namespace
}  // namespace pnet
