// MPM-FEM coupling (docs/methods.md): the particle / mesh barrier's CCD (its derivatives:
// test_coupling_3d_friction.cpp), the coupled incremental potential's gradient and Hessian with
// respect to grid and FEM velocities (finite differences), Newton on it, and
// the coupled simulation on the tiny scene: every integrator that needs no
// network (plasticitynet: tests/python/test_pnet_fem_cli.py), no particle ever
// inside the disk, a block resting on the bed stays at rest, thread counts and
// checkpoints do not change the result.
#include <gtest/gtest.h>
#include <omp.h>

#include <nlohmann/json.hpp>

#include "pnet/coupling/coupled_potential.hpp"
#include "pnet/energy/particle_energy.hpp"
#include "pnet/mpm/transfer.hpp"
#include "pnet/scene/sampler.hpp"
#include "pnet/sim/coupled_simulation.hpp"
#include "pnet/solver/newton.hpp"
#include "support/coupled_runs.hpp"
#include "support/finite_difference.hpp"
#include "support/random.hpp"
#include "support/temp_dir.hpp"

namespace pnet {
namespace {

const char* const kTiny = PNET_SCENES_DIR "/tiny/sand_fem_coupling_2d.json";

using test::expect_identical;
using test::settings_for;

/// The tiny scene with the disk's centre moved to y (m) and its velocity set.
Scene tiny_with_disk_at(double y, double vy) {
    nlohmann::json j = scene_to_json(load_scene(kTiny));
    j["meshes"][0]["center"][1] = y;
    j["meshes"][0]["velocity"] = {0.0, vy};
    return scene_from_json(j, "tiny_edited.json", "");
}

// The top particle row of the tiny bed (lattice spacing dx / 2 = 1/128 m, bed to 0.1 m).
constexpr double kBedTop = 0.09765625;

TEST(ContactPoints2d, CcdStopsAParticleBeforeTheEdgeAndPenetrationIsDetected) {
    const std::vector<std::array<int, 2>> edges = {{0, 1}, {1, 2}, {2, 0}};  // a triangle, counter-clockwise
    const std::vector<Vec<2>> x = {Vec<2>(0, 0), Vec<2>(1, 0), Vec<2>(0, 1)};
    const Contact2d contact(edges, {}, 0.01, 1.0, ContactPoints{3, true});
    const std::vector<Vec<2>> outside = {Vec<2>(0.3, -0.2)}, inside = {Vec<2>(0.2, 0.2)};
    // Moving up by 0.4 crosses the bottom edge at t = 0.5: CCD stops short of it.
    const double t = contact.max_step({x[0], x[1], x[2], outside[0]},
                                      {Vec<2>::Zero(), Vec<2>::Zero(), Vec<2>::Zero(), Vec<2>(0, 0.4)});
    EXPECT_GT(t, 0.0);
    EXPECT_LT(t, 0.5);
    EXPECT_EQ(first_inside<2>(outside, x, edges), "");
    EXPECT_EQ(count_inside<2>(inside, x, edges), 1u);
    EXPECT_EQ(first_inside<2>(inside, x, edges, "particle"), "particle 0 inside the mesh");
}

/// The parts of a coupled implicit step on the tiny scene with the disk just above the bed
/// (within dhat of the top row), lagged (elastic) energies, no friction.
struct CoupledFixture : test::CoupledFixture<2> {
    CoupledFixture() : test::CoupledFixture<2>(tiny_with_disk_at(kBedTop + 0.05 + 0.003, 0.0)) {}
};

TEST(CoupledPotential, GradientAndHessianWithRespectToGridAndFemVelocitiesMatchFiniteDifferences) {
    CoupledFixture f;
    f.mpm_potential.set_project_psd(false);
    f.fem_potential.set_project_psd(false);
    f.coupled.set_project_psd(false);
    test::Random rng(7);
    const VecX v = test::perturbed_v_star(f.coupled, rng);
    VecX g;
    f.coupled.set_linear_solve(CoupledPotential2d::LinearSolve::Assembled);
    f.coupled.value_gradient_hessian(v, g);
    ASSERT_GT(f.coupled.pairs(), 0u) << "the disk should be within dhat of the bed";
    const Eigen::MatrixXd H = Eigen::MatrixXd(*f.coupled.hessian_matrix());
    // The matrix-free product of the block-preconditioned solve applies the same H.
    {
        test::expect_matrix_free_hessian(f.coupled, v, H, rng);
        EXPECT_EQ(f.coupled.hessian_matrix(), nullptr);
        VecX g2;
        f.coupled.set_linear_solve(CoupledPotential2d::LinearSolve::Assembled);
        f.coupled.value_gradient_hessian(v, g2);
    }
    test::FdStats stats;
    // The components the barrier couples (a particle's stencil, an edge's nodes) and a sample of the others.
    std::vector<Eigen::Index> columns;
    for (Eigen::Index i = 0; i < v.size(); ++i)
        if (f.coupled.residual_mass()[i] > 0.0 && (i % 7 == 0 || std::abs(g[i]) > 0.0)) columns.push_back(i);
    auto value = [&](const VecX& y) { return f.coupled.value(y); };
    auto gradient = [&](const VecX& y) {
        VecX gy;
        f.coupled.value_gradient(y, gy);
        return gy;
    };
    int coupled_entries = 0;
    for (Eigen::Index k : columns) {
        // Each column: d(gradient)/dv_k against the Hessian's column k, and dE/dv_k.
        auto along = [&](const Eigen::VectorXd& t) {
            VecX y = v;
            y[k] = t[0];
            return gradient(y);
        };
        Eigen::VectorXd t0(1);
        t0[0] = v[k];
        ASSERT_TRUE(test::check_jacobian(along, H.col(k), t0, stats, 1e-6, 2e-4, 1e-4 * H.col(k).cwiseAbs().maxCoeff()))
            << "column " << k;
        auto along_value = [&](const Eigen::VectorXd& t) {
            VecX y = v;
            y[k] = t[0];
            return value(y);
        };
        ASSERT_TRUE(test::check_gradient(along_value, Eigen::VectorXd::Constant(1, g[k]), t0, stats, 1e-6, 1e-4, 1e-8))
            << "component " << k;
        const Eigen::Index ng = f.coupled.grid_size();
        for (Eigen::Index i = 0; i < H.rows(); ++i)
            if (H(i, k) != 0.0 && ((i < ng) != (k < ng))) ++coupled_entries;
    }
    EXPECT_GT(coupled_entries, 0) << "no grid-FEM entry of the Hessian was checked";
    EXPECT_GT(stats.checks, 1000);
    RecordProperty("fd_checks", stats.checks);
    std::printf("coupled potential: %d finite-difference comparisons over %zu columns (largest relative error %.2e)\n",
                stats.checks, columns.size(), stats.max_error);
}

TEST(CoupledPotential, NewtonLowersTheEnergyAndKeepsEveryParticleOutsideTheDisk) {
    for (const auto solve :
         {CoupledPotential2d::LinearSolve::BlockPreconditioned, CoupledPotential2d::LinearSolve::Assembled}) {
        SCOPED_TRACE(solve == CoupledPotential2d::LinearSolve::Assembled ? "assembled" : "block preconditioned");
        CoupledFixture f;
        f.coupled.set_linear_solve(solve);
        VecX v = f.coupled.v_star();
        const double alpha = f.coupled.max_step(VecX::Zero(v.size()), v);
        v *= std::min(1.0, alpha);
        NewtonOptions options;
        options.tolerance = 1e-6;
        options.residual_mass = f.coupled.residual_mass();
        options.linear_solver = NewtonOptions::LinearSolver::Cholesky;
        options.throw_on_line_search_failure = true;
        // Each Newton iteration separately, so that every step's energy is seen.
        double energy = f.coupled.value(v);
        int iterations = 0;
        for (; iterations < 30; ++iterations) {
            NewtonOptions one = options;
            one.max_iterations = 1;
            const NewtonStats s = minimize(f.coupled, v, one);
            EXPECT_LE(s.energy, energy) << "iteration " << iterations;
            energy = s.energy;
            if (s.converged) break;
        }
        EXPECT_LT(iterations, 30);
        std::vector<Vec<2>> x;
        f.coupled.positions(v, x);
        const std::size_t nodes = f.fem.system.mesh.nodes();
        const std::vector<Vec<2>> mesh(x.begin(), x.begin() + nodes), particles(x.begin() + nodes, x.end());
        EXPECT_EQ(count_inside<2>(particles, mesh, f.fem.system.mesh.boundary), 0u);
        EXPECT_GT(f.contact.min_distance(x), 0.0);
    }
}

TEST(CoupledSimulation, TinySceneRunsWithExplicitReturnMapAndLaggedWithoutPenetration) {
    const Scene scene = load_scene(kTiny);
    for (const auto& [integrator, dt] :
         std::vector<std::pair<std::string, double>>{{"lagged", 1e-3}, {"return_map", 1e-3}, {"explicit", 1e-5}}) {
        SCOPED_TRACE(integrator);
        CoupledSimulation2d sim(scene, settings_for(scene, integrator, dt));
        std::size_t most_pairs = 0;
        for (int frame = 0; frame < 2; ++frame) {
            const FrameStats f = sim.advance_frame();  // throws if a particle is inside the disk
            most_pairs = std::max(most_pairs, f.contact_pairs);
            EXPECT_EQ(sim.penetrations(), 0u);
            EXPECT_TRUE(f.converged);
        }
        EXPECT_GT(most_pairs, 0u) << "the disk should have reached the bed";
        // The disk was stopped by the bed: its centre is above the floor's sticky layer.
        double lowest = 1e300;
        for (const Vec<2>& x : sim.state().x) lowest = std::min(lowest, x[1]);
        EXPECT_GT(lowest, 3 * scene.dx);
    }
}

TEST(CoupledSimulation, ABlockRestingOnTheBedStaysAtRest) {
    nlohmann::json j = scene_to_json(load_scene(kTiny));
    const double dhat = 0.5 * j["dx"].get<double>();
    // Where the barrier carries the block's weight with the default stiffness (0.97 dhat, measured):
    // started deeper, inside the barrier's reach, the barrier launches it.
    j["meshes"][0] = {
        {"shape", "box"},       {"min", {0.45, kBedTop + 0.96 * dhat}},   {"max", {0.55, kBedTop + 0.96 * dhat + 0.02}},
        {"element_size", 0.01}, {"material", j["meshes"][0]["material"]}, {"velocity", {0.0, 0.0}}};
    const Scene scene = scene_from_json(j, "block.json", "");
    CoupledSimulation2d sim(scene, settings_for(scene, "lagged", 1e-3));
    const std::vector<Vec<2>> start = sim.state().x;
    for (int frame = 0; frame < 4; ++frame) sim.advance_frame();
    double sink = 0.0, speed = 0.0;
    for (std::size_t i = 0; i < start.size(); ++i) {
        sink = std::max(sink, start[i][1] - sim.state().x[i][1]);
        speed = std::max(speed, sim.state().v[i].norm());
    }
    EXPECT_LT(sink, 0.1 * scene.dx) << "the block sank";
    EXPECT_LT(speed, 0.02) << "the block is not at rest";
    EXPECT_EQ(sim.penetrations(), 0u);
    EXPECT_GT(sim.coupling().active_pairs(sim.contact_positions()), 0u) << "the block does not rest on the bed";
}

TEST(CoupledSimulation, OneAndTwoThreadsGiveIdenticalFrames) {
    const Scene scene = load_scene(kTiny);
    const int threads = omp_get_max_threads();
    for (const auto& [integrator, dt] :
         std::vector<std::pair<std::string, double>>{{"lagged", 1e-3}, {"explicit", 1e-5}}) {
        SCOPED_TRACE(integrator);
        std::vector<std::unique_ptr<CoupledSimulation2d>> runs;
        for (int t : {1, 2}) {
            omp_set_num_threads(t);
            runs.push_back(std::make_unique<CoupledSimulation2d>(scene, settings_for(scene, integrator, dt)));
            for (int frame = 0; frame < 2; ++frame) runs.back()->advance_frame();  // the disk lands in frame 1
        }
        omp_set_num_threads(threads);
        expect_identical(*runs[0], *runs[1]);
    }
}

TEST(CoupledSimulation, CheckpointThenResumeEqualsAnUninterruptedRun) {
    for (const auto& [integrator, dt] :
         std::vector<std::pair<std::string, double>>{{"lagged", 1e-3}, {"explicit", 1e-5}}) {
        SCOPED_TRACE(integrator);
        const Scene scene = load_scene(kTiny);
        const IntegratorSettings settings = settings_for(scene, integrator, dt);
        test::TempDir dir;
        CoupledSimulation2d uninterrupted(scene, settings), first(scene, settings), resumed(scene, settings);
        for (int f = 0; f < 2; ++f) uninterrupted.advance_frame();
        first.advance_frame();
        first.save_checkpoint(dir.file("state.bin"));
        resumed.load_checkpoint(dir.file("state.bin"));
        EXPECT_EQ(resumed.frame(), 1);
        resumed.advance_frame();
        EXPECT_EQ(resumed.total_steps(), uninterrupted.total_steps());
        expect_identical(resumed, uninterrupted);
        const std::string bytes = test::read_file(dir.file("state.bin"));
        test::write_file(dir.file("short.bin"), bytes.substr(0, bytes.size() - 10));
        test::expect_error<std::invalid_argument>([&] { resumed.load_checkpoint(dir.file("short.bin")); },
                                                  dir.file("short.bin"), "truncated");
    }
}

TEST(CoupledSimulation, AParticleInsideTheDiskAtTheStartIsRefused) {
    const Scene scene = tiny_with_disk_at(0.08, 0.0);  // the disk overlaps the bed
    test::expect_error<SceneError>([&] { CoupledSimulation2d sim(scene, settings_for(scene, "lagged", 1e-3)); },
                                   "tiny_edited.json", "objects and meshes overlap at the start: particle");
}

}  // namespace
}  // namespace pnet
