// The adjoint of an implicit MPM-FEM coupled rollout (coupling/coupled_adjoint.hpp) against central differences
// of the whole rollout: the tiny coupling scenes' stiff disk (2D) and sphere (3D) pressed into their sand beds
// (within the barrier's reach from the first step; no friction), a random linear loss of the last state's
// particle and node positions and velocities, its gradient with respect to both Young's moduli and along random
// directions of the particles' start velocities and positions and the nodes' start positions and velocities;
// elastic sand and Drucker-Prager sand (lagged, return_map). The forward solves are tightened (Newton to 1e-10
// m/s, the assembled coupled solve) for the check.
#include <gtest/gtest.h>

#include <cstdio>
#include <functional>

#include <nlohmann/json.hpp>

#include "pnet/contact/collisions/contact.hpp"
#include "pnet/coupling/coupled_adjoint.hpp"
#include "pnet/scene/sampler.hpp"
#include "pnet/sim/coupled_simulation.hpp"
#include "support/random.hpp"

namespace pnet {
namespace {

/// The tiny coupling scene of `dim`, its mesh (a disk, a sphere) a quarter cell above the bed's top particles
/// (within the barrier's dhat = dx / 2) and moving at (0.1, vy), without friction, the particles' material
/// `plasticity` ("none": elastic sand) and both E.
template <int dim>
Scene pressed_scene(double vy, const char* plasticity, double sand_E = 3.537e5, double mesh_E = 1e7,
                    double friction_angle = 30.0) {
    const std::string file =
        std::string(PNET_SCENES_DIR "/tiny/sand_fem_coupling_") + (dim == 2 ? "2d" : "3d") + ".json";
    const Scene tiny = load_scene(file);
    double top = -1.0;
    for (const Vec<dim>& x : sample_particles<dim>(tiny).x) top = std::max(top, x[1]);
    nlohmann::json j = scene_to_json(tiny);
    const double radius = j["meshes"][0]["radius"];
    j["meshes"][0]["center"][1] = top + radius + 0.25 * tiny.dx;
    j["meshes"][0]["velocity"][0] = 0.1;
    j["meshes"][0]["velocity"][1] = vy;
    j["meshes"][0]["material"]["elasticity"]["E"] = mesh_E;
    j["objects"][0]["material"]["elasticity"]["E"] = sand_E;
    if (std::string(plasticity) == "none")
        j["objects"][0]["material"]["plasticity"] = {{"model", "none"}};
    else
        j["objects"][0]["material"]["plasticity"]["friction_angle_deg"] = friction_angle;
    j["contact"]["friction"] = 0.0;
    return scene_from_json(j, "pressed.json", PNET_SCENES_DIR "/tiny");
}

ImplicitOptions tight() {
    ImplicitOptions o;
    o.newton_tolerance = 1e-10;
    o.newton_acceleration_tolerance = 0.0;
    o.max_newton_iterations = 2000;
    o.cg_tolerance = 1e-8;
    return o;
}

/// What a coupled rollout needs, from a scene: the MPM and FEM systems and the particle / mesh barrier.
template <int dim>
struct Coupled {
    Scene scene;
    MpmSystem<dim> mpm;
    FemSceneSystem<dim> fem;
    Contact<dim> contact;
    CoupledState<dim> start;

    explicit Coupled(Scene s, double kappa = 1e3)
        : scene(std::move(s)),
          mpm(make_mpm_system<dim>(scene)),
          fem(make_fem_system<dim>(scene)),
          contact(fem.system.mesh.boundary, {}, 0.5 * scene.dx, kappa,
                  ContactPoints{static_cast<int>(fem.system.mesh.nodes()), true}) {
        start.particles = sample_particles<dim>(scene);
        start.mesh = FemState<dim>::at_rest(fem.system);
        for (Vec<dim>& v : start.mesh.v) v = scene.meshes[0].velocity.template head<dim>();
    }

    CoupledAdjoint<dim> adjoint(Method method, double mu = 0.0) const {
        CouplingOptions coupling;
        coupling.coupled_solver = "cholesky";
        CoupledAdjoint<dim> a(mpm, fem.system, nullptr, contact, tight(), MpmOptions{}, coupling, method);
        if (mu > 0.0) a.set_friction(mu, 0.2);  // eps_v 0.2 m/s: the disk's slip (0.1 m/s) within the smoothed range
        return a;
    }
};

/// L = sum_p a_p . x_p + b_p . v_p + sum_a c_a . x_a + d_a . v_a of a state.
template <int dim>
struct LinearLoss {
    std::vector<Vec<dim>> a, b, c, d;
    LinearLoss(std::size_t particles, std::size_t nodes, test::Random& random) {
        for (auto* w : {&a, &b}) {
            w->resize(particles);
            for (Vec<dim>& e : *w) e = random.uniform_vec<dim>(-1.0, 1.0);
        }
        for (auto* w : {&c, &d}) {
            w->resize(nodes);
            for (Vec<dim>& e : *w) e = random.uniform_vec<dim>(-1.0, 1.0);
        }
    }
    double operator()(const CoupledState<dim>& s) const {
        double L = 0.0;
        for (std::size_t p = 0; p < a.size(); ++p) L += a[p].dot(s.particles.x[p]) + b[p].dot(s.particles.v[p]);
        for (std::size_t i = 0; i < c.size(); ++i) L += c[i].dot(s.mesh.x[i]) + d[i].dot(s.mesh.v[i]);
        return L;
    }
};

/// The rollout's gradient against central differences along random directions of the start and of both E.
template <int dim>
void check_coupled_gradient(const char* plasticity, Method method, int steps, double tolerance,
                            double compression = 0.0, bool disk_E_check = true, double mu = 0.0) {
    const double dt = 1e-3, sand_E = 3.537e5, disk_E = 1e7;
    // With friction, a stiffer barrier (kappa 1e6), so that the lagged normal forces, and the friction, matter.
    const double kappa = mu > 0.0 ? 1e6 : 1e3;
    Coupled<dim> base(pressed_scene<dim>(-0.5, plasticity, sand_E, disk_E), kappa);
    // Sand at rest from F = I sits at Drucker-Prager's cone tip, where the return mapping has no derivative (a
    // central difference there averages two one-sided ones: docs/adjoint.md): the bed starts compressed by
    // `compression`, inside the cone.
    for (Mat<dim>& F : base.start.particles.F_elastic) F = (1.0 - compression) * Mat<dim>::Identity();
    const std::size_t n = base.start.particles.size(), nodes = base.start.mesh.x.size();
    test::Random random(11);
    const LinearLoss<dim> loss(n, nodes, random);
    std::vector<Vec<dim>> dv(n), dx(n), dxa(nodes), dva(nodes);
    for (std::size_t p = 0; p < n; ++p) {
        dv[p] = random.uniform_vec<dim>(-1.0, 1.0);
        dx[p] = random.uniform_vec<dim>(-1.0, 1.0);
    }
    for (std::size_t i = 0; i < nodes; ++i) {
        dxa[i] = random.uniform_vec<dim>(-1.0, 1.0);
        dva[i] = random.uniform_vec<dim>(-1.0, 1.0);
    }

    CoupledAdjoint<dim> adjoint = base.adjoint(method, mu);
    std::size_t pairs_seen = 0;
    const CoupledState<dim> last = adjoint.forward(base.start, dt, steps, [&](int, const CoupledState<dim>& s) {
        std::vector<Vec<dim>> x;
        CoupledVertices<dim>::join(s.mesh.x, s.particles.x, x);
        pairs_seen = std::max(pairs_seen, base.contact.active_pairs(x));
    });
    ASSERT_EQ(adjoint.unconverged_steps(), 0);
    ASSERT_GT(pairs_seen, 0u) << "the disk never came within the barrier's reach of the bed";
    std::vector<std::vector<Vec<dim>>> px(steps + 1), pv(steps + 1), nx(steps + 1), nv(steps + 1);
    px.back() = loss.a;
    pv.back() = loss.b;
    nx.back() = loss.c;
    nv.back() = loss.d;
    const CoupledRolloutGradient<dim> g = adjoint.backward(px, pv, nx, nv);

    auto rollout_loss = [&](const Coupled<dim>& system, const CoupledState<dim>& start) {
        CoupledAdjoint<dim> a = system.adjoint(method, mu);
        return loss(a.forward(start, dt, steps));
    };
    auto along = [&](const std::function<void(CoupledState<dim>&, double)>& move, double h) {
        CoupledState<dim> plus = base.start, minus = base.start;
        move(plus, h);
        move(minus, -h);
        return (rollout_loss(base, plus) - rollout_loss(base, minus)) / (2.0 * h);
    };
    struct Check {
        const char* name;
        double adjoint, fd;
    };
    std::vector<Check> checks;
    {
        double a = 0.0;
        for (std::size_t p = 0; p < n; ++p) a += g.particles.v[p].dot(dv[p]);
        checks.push_back({"particle v0", a,
                          along(
                              [&](CoupledState<dim>& s, double h) {
                                  for (std::size_t p = 0; p < n; ++p) s.particles.v[p] += h * dv[p];
                              },
                              1e-5)});
    }
    // With friction the gradient holds each step's lagged pairs, which move with the start's positions: exact
    // along the velocities and the moduli over one step, not along the positions.
    if (mu == 0.0) {
        double a = 0.0;
        for (std::size_t p = 0; p < n; ++p) a += g.particles.x[p].dot(dx[p]);
        checks.push_back({"particle x0", a,
                          along(
                              [&](CoupledState<dim>& s, double h) {
                                  // Small: the quadratic B-splines' second derivative jumps between cells, so the
                                  // central difference's error is first order in h here.
                                  for (std::size_t p = 0; p < n; ++p) s.particles.x[p] += h * dx[p];
                              },
                              1e-8)});
    }
    if (mu == 0.0) {
        double a = 0.0;
        for (std::size_t i = 0; i < nodes; ++i) a += g.node_x[i].dot(dxa[i]);
        checks.push_back({"node x0", a,
                          along(
                              [&](CoupledState<dim>& s, double h) {
                                  for (std::size_t i = 0; i < nodes; ++i) s.mesh.x[i] += h * dxa[i];
                              },
                              1e-6)});
    }
    {
        double a = 0.0;
        for (std::size_t i = 0; i < nodes; ++i) a += g.node_v[i].dot(dva[i]);
        checks.push_back({"node v0", a,
                          along(
                              [&](CoupledState<dim>& s, double h) {
                                  for (std::size_t i = 0; i < nodes; ++i) s.mesh.v[i] += h * dva[i];
                              },
                              1e-4)});
    }
    {
        const double h = 1e-4 * sand_E;
        const Coupled<dim> plus(pressed_scene<dim>(-0.5, plasticity, sand_E + h, disk_E), kappa);
        const Coupled<dim> minus(pressed_scene<dim>(-0.5, plasticity, sand_E - h, disk_E), kappa);
        checks.push_back({"sand E", g.particles.youngs_modulus,
                          (rollout_loss(plus, base.start) - rollout_loss(minus, base.start)) / (2.0 * h)});
    }
    if (std::string(plasticity) != "none") {
        const double h = 1e-3;  // degrees: at 1e-2 the differences straddle particles' yield onsets (5e-3 apart)
        Coupled<dim> plus(pressed_scene<dim>(-0.5, plasticity, sand_E, disk_E, 30.0 + h), kappa);
        Coupled<dim> minus(pressed_scene<dim>(-0.5, plasticity, sand_E, disk_E, 30.0 - h), kappa);
        checks.push_back({"friction angle", g.particles.friction_angle,
                          (rollout_loss(plus, base.start) - rollout_loss(minus, base.start)) / (2.0 * h)});
    }
    if (disk_E_check) {
        const double h = 1e-3 * disk_E;  // the disk barely deforms: a smaller h leaves the solves' noise
        const Coupled<dim> plus(pressed_scene<dim>(-0.5, plasticity, sand_E, disk_E + h), kappa);
        const Coupled<dim> minus(pressed_scene<dim>(-0.5, plasticity, sand_E, disk_E - h), kappa);
        checks.push_back({"disk E", g.mesh_youngs_modulus,
                          (rollout_loss(plus, base.start) - rollout_loss(minus, base.start)) / (2.0 * h)});
    }
    for (const Check& c : checks) {
        const double relative = std::abs(c.adjoint - c.fd) / std::max(std::abs(c.fd), 1e-300);
        std::printf(
            "coupled adjoint (%dD, %s, %s, mu %g, %d steps, %zu particles, %zu nodes, up to %zu pairs): dL/d%s %.10e, "
            "central differences %.10e, relative %.2e\n",
            dim, plasticity, to_string(method), mu, steps, n, nodes, pairs_seen, c.name, c.adjoint, c.fd, relative);
        EXPECT_LT(relative, tolerance) << c.name;
    }
    (void)last;
}

TEST(CoupledAdjoint2d, ElasticSandUnderTheDiskMatchesCentralDifferences) {
    check_coupled_gradient<2>("none", Method::Lagged, 20, 1e-4);
}

// Drucker-Prager sand: lagged (the elastic solve, the return mapping in G2P) and return_map (the return-mapped
// stress and its consistent tangent in the solve: J not symmetric).
TEST(CoupledAdjoint2d, SandUnderTheDiskMatchesCentralDifferencesUnderLaggedAndReturnMap) {
    check_coupled_gradient<2>("drucker_prager", Method::Lagged, 20, 1e-4, 5e-3);
    // Six steps: over longer ones the bed flows plastically under the disk and central differences along the
    // start's positions straddle the cone's branches (they moved by 1e-3 relative between h = 1e-7 and 1e-8 at
    // 12 steps, while dL/dE matched to 1e-6). Over six steps the disk has hardly deformed: dL/dE of the disk is
    // 1e-13 per Pa, below what central differences of the solves resolve, and is not compared.
    check_coupled_gradient<2>("drucker_prager", Method::ReturnMap, 6, 1e-4, 5e-3, false);
}

// Lagged friction between the disk and the bed (mu 0.3, smoothed below 1 m/s so that its Hessian along the slip is
// not 0 as it is for a saturated 2D slip), held: one step, whose lagged pairs depend on the start's
// positions alone, so that the gradient along the velocities and the sand's modulus is exact (the disk's, 1e-14 per
// Pa after one step, is below what the differences resolve).
TEST(CoupledAdjoint2d, WithLaggedFrictionOneStepsGradientMatchesCentralDifferences) {
    {  // the friction acts: the disk's nodes end the step elsewhere
        const Coupled<2> base(pressed_scene<2>(-0.5, "none"), 1e6);
        CoupledAdjoint<2> with = base.adjoint(Method::Lagged, 1.0), without = base.adjoint(Method::Lagged);
        const CoupledState<2> a = with.forward(base.start, 1e-3, 1), b = without.forward(base.start, 1e-3, 1);
        double change = 0.0;
        for (std::size_t i = 0; i < a.mesh.v.size(); ++i) change = std::max(change, (a.mesh.v[i] - b.mesh.v[i]).norm());
        std::printf("the friction changes the disk's node velocities by up to %.3e m/s in one step\n", change);
        EXPECT_GT(change, 1e-4);
    }
    check_coupled_gradient<2>("none", Method::Lagged, 1, 1e-4, 0.0, false, 1.0);
    check_coupled_gradient<2>("drucker_prager", Method::ReturnMap, 1, 1e-4, 5e-3, false, 1.0);
}

TEST(CoupledAdjoint3d, ElasticSandUnderTheSphereMatchesCentralDifferences) {
    check_coupled_gradient<3>("none", Method::Lagged, 20, 1e-4);
}

// Every state kept (a checkpoint per step) and the default sqrt(N) checkpoints with the segments recomputed give
// the same gradient to the last bit, at fewer states held.
TEST(CoupledAdjoint2d, CheckpointedAndStoredTapeGradientsAreIdentical) {
    const Coupled<2> base(pressed_scene<2>(-0.5, "none"));
    const int steps = 9;
    const std::size_t n = base.start.particles.size(), nodes = base.start.mesh.x.size();
    test::Random random(3);
    const LinearLoss<2> loss(n, nodes, random);
    std::vector<std::vector<Vec<2>>> px(steps + 1), pv(steps + 1), nx(steps + 1), nv(steps + 1);
    px.back() = loss.a;
    pv[4] = loss.b;  // a loss of an inner state too
    nx.back() = loss.c;
    nv[2] = loss.d;
    CoupledAdjoint<2> stored = base.adjoint(Method::Lagged), checkpointed = base.adjoint(Method::Lagged);
    stored.forward(base.start, 1e-3, steps, {}, 1);
    checkpointed.forward(base.start, 1e-3, steps);
    const CoupledRolloutGradient<2> a = stored.backward(px, pv, nx, nv), b = checkpointed.backward(px, pv, nx, nv);
    EXPECT_LT(checkpointed.peak_states(), stored.peak_states());
    for (std::size_t p = 0; p < n; ++p) {
        EXPECT_EQ(a.particles.x[p], b.particles.x[p]);
        EXPECT_EQ(a.particles.v[p], b.particles.v[p]);
        EXPECT_EQ(a.particles.F[p], b.particles.F[p]);
    }
    for (std::size_t i = 0; i < nodes; ++i) {
        EXPECT_EQ(a.node_x[i], b.node_x[i]);
        EXPECT_EQ(a.node_v[i], b.node_v[i]);
    }
    EXPECT_EQ(a.particles.youngs_modulus, b.particles.youngs_modulus);
    EXPECT_EQ(a.mesh_youngs_modulus, b.mesh_youngs_modulus);
}

/// The message of the std::invalid_argument that f throws ("" if none).
template <typename F>
std::string refusal(F&& f) {
    try {
        f();
    } catch (const std::invalid_argument& e) {
        return e.what();
    }
    return "";
}

TEST(CoupledAdjoint2d, RefusesWhatItDoesNotCover) {
    Coupled<2> base(pressed_scene<2>(-0.5, "none"));
    const CouplingOptions coupling;
    auto make = [&](const MpmSystem<2>& mpm, const FemSystem<2>& fem, Method method,
                    const ImplicitOptions& options = ImplicitOptions{}) {
        return [&, method, options] {
            CoupledAdjoint<2>(mpm, fem, nullptr, base.contact, options, MpmOptions{}, coupling, method);
        };
    };
    EXPECT_NE(refusal(make(base.mpm, base.fem.system, Method::PlasticityNet)).find("integrator 'plasticitynet'"),
              std::string::npos);
    MpmSystem<2> coulomb = base.mpm;
    coulomb.boundary.floor_friction = 0.5;
    EXPECT_NE(refusal(make(coulomb, base.fem.system, Method::ReturnMap)).find("boundary.floor_friction"),
              std::string::npos);
    FemSystem<2> plastic = base.fem.system;
    MaterialDescription metal = plastic.materials[0].description();
    metal.plasticity = PlasticityModel::VonMises;
    metal.elasticity = ElasticityModel::StvkHencky;
    plastic.materials[0] = Material<2>(metal);
    EXPECT_NE(refusal(make(base.mpm, plastic, Method::Lagged)).find("meshes[0].material.plasticity 'von_mises'"),
              std::string::npos);
    FemSystem<2> kinematic = base.fem.system;
    kinematic.fixed_node.assign(kinematic.mesh.nodes(), 0);
    kinematic.fixed_node[0] = 1;
    EXPECT_NE(refusal(make(base.mpm, kinematic, Method::Lagged)).find("kinematic"), std::string::npos);
    ImplicitOptions bdf2;
    bdf2.time_integrator = "bdf2";
    EXPECT_NE(refusal(make(base.mpm, base.fem.system, Method::Lagged, bdf2)).find("time_integrator 'bdf2'"),
              std::string::npos);
    // A loss with the wrong number of entries names what it needs.
    CoupledAdjoint<2> adjoint = base.adjoint(Method::Lagged);
    adjoint.forward(base.start, 1e-3, 2);
    std::vector<std::vector<Vec<2>>> empty(3), wrong(3);
    wrong[2].resize(5);
    EXPECT_NE(refusal([&] { adjoint.backward(empty, empty, wrong, empty); }).find("one entry per mesh node"),
              std::string::npos);
    EXPECT_NE(refusal([&] {
                  adjoint.backward(empty, empty, empty, std::vector<std::vector<Vec<2>>>(2));
              }).find("one entry per state (3)"),
              std::string::npos);
}

}  // namespace
}  // namespace pnet
