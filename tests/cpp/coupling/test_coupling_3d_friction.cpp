// MPM-FEM coupling in 3D and particle-mesh friction (docs/methods.md): the particles as the
// Contact's stand-alone points, the point-edge and point-triangle barriers' derivatives and lagged friction pairs, CCD
// and the winding-number inside test; the coupled incremental potential with lagged friction against finite differences
// in 2D and 3D (the matrix-free product against the assembled Hessian); friction that drags the sand under a sliding
// block, implicit and explicit; the 3D tiny scene without penetration, with 1 and 2 threads identical and a checkpoint
// that resumes bit-identically.
#include <gtest/gtest.h>
#include <omp.h>

#include <nlohmann/json.hpp>

#include "pnet/sim/coupled_simulation.hpp"
#include "support/coupled_runs.hpp"
#include "support/finite_difference.hpp"
#include "support/random.hpp"
#include "support/temp_dir.hpp"

namespace pnet {
namespace {

const char* const kTiny2d = PNET_SCENES_DIR "/tiny/sand_fem_coupling_2d.json";
const char* const kTiny3d = PNET_SCENES_DIR "/tiny/sand_fem_coupling_3d.json";

using test::expect_identical;
using test::settings_for;

/// A tiny scene with its mesh's centre at height y (m), velocity v and friction mu.
Scene edited(const char* file, double y, const std::vector<double>& velocity, double mu) {
    nlohmann::json j = scene_to_json(load_scene(file));
    j["meshes"][0]["center"][1] = y;
    j["meshes"][0]["velocity"] = velocity;
    j["contact"]["friction"] = mu;
    return scene_from_json(j, "edited.json", "");
}

/// The barrier of particle p (a stand-alone point of the Contact, after the facet's nodes) against
/// one facet (corners: its nodes' positions) against finite differences, and its lagged friction
/// pair: the closest point's weights, a tangent basis orthogonal to the normal, a positive normal
/// force.
template <int dim>
void check_barrier(const Contact<dim>& contact, const Vec<dim>& p, const std::vector<Vec<dim>>& corners,
                   test::FdStats& stats) {
    SCOPED_TRACE(p.transpose());
    constexpr int n = dim * (dim + 1);
    // q: the pair's stacked positions (the point, then the facet's nodes).
    Eigen::VectorXd q(n);
    q.template head<dim>() = p;
    for (int j = 0; j < dim; ++j) q.template segment<dim>(dim * (j + 1)) = corners[j];
    auto unpack = [](const Eigen::VectorXd& y) {
        std::vector<Vec<dim>> x;
        for (int j = 0; j < dim; ++j) x.push_back(y.template segment<dim>(dim * (j + 1)));
        x.push_back(y.template head<dim>());
        return x;
    };
    const std::vector<Vec<dim>> x = unpack(q);
    std::vector<ContactPairTerms<dim>> terms;
    contact.pair_terms(x, 1, false, terms);
    ASSERT_EQ(terms.size(), 1u);
    EXPECT_EQ(terms[0].node[0], dim);  // the point first
    const Eigen::VectorXd g = contact.kappa() * terms[0].gradient;
    auto energy = [&](const Eigen::VectorXd& y) { return contact.value(unpack(y)); };
    EXPECT_TRUE(test::check_gradient(energy, g, q, stats, 1e-7, 1e-5, 1e-4 * g.cwiseAbs().maxCoeff()));
    contact.pair_terms(x, 2, false, terms);
    const Eigen::MatrixXd H = contact.kappa() * terms[0].hessian;
    auto gradient = [&](const Eigen::VectorXd& y) {
        std::vector<ContactPairTerms<dim>> ty;
        contact.pair_terms(unpack(y), 1, false, ty);
        return Eigen::VectorXd(contact.kappa() * ty.at(0).gradient);
    };
    EXPECT_TRUE(test::check_jacobian(gradient, H, q, stats, 1e-7, 1e-4, 1e-4 * H.cwiseAbs().maxCoeff()));
    const auto lagged = contact.lagged_pairs(x);
    ASSERT_EQ(lagged.size(), 1u);
    EXPECT_EQ(lagged[0].weight[0], 1.0);
    Vec<dim> closest = Vec<dim>::Zero();
    for (int j = 0; j < dim; ++j) closest -= lagged[0].weight[j + 1] * x[lagged[0].node[j + 1]];
    EXPECT_NEAR((p - closest).norm(), std::sqrt(PointFacet<dim>::distance_sq(p, x, contact.facets()[0])), 1e-14);
    EXPECT_LT((lagged[0].tangent.transpose() * (p - closest)).norm(), 1e-14);
    EXPECT_LT((lagged[0].tangent.transpose() * lagged[0].tangent - Eigen::Matrix<double, dim - 1, dim - 1>::Identity())
                  .norm(),
              1e-14);
    EXPECT_GT(lagged[0].normal_force, 0.0);
}

TEST(ContactPoints2d, BarrierGradientAndHessianMatchFiniteDifferencesInEveryCase) {
    // One edge from (0, 0) to (1, 0); particles above its interior and beyond either end.
    const Contact2d contact({{0, 1}}, {}, 0.1, 1e3, ContactPoints{2, true});
    test::FdStats stats;
    for (const Vec<2>& p : {Vec<2>(0.4, 0.05), Vec<2>(-0.03, 0.04), Vec<2>(1.05, 0.02), Vec<2>(0.7, -0.06)})
        check_barrier<2>(contact, p, {Vec<2>(0, 0), Vec<2>(1, 0)}, stats);
    EXPECT_EQ(stats.checks, 4 * (6 + 36));
}

TEST(ContactPoints3d, BarrierGradientAndHessianMatchFiniteDifferencesInEveryCase) {
    // One triangle in the plane y = 0; particles above its interior, an edge and a corner.
    const Contact3d contact({{0, 1, 2}}, {}, 0.1, 1e3, ContactPoints{3, true});
    test::FdStats stats;
    for (const Vec<3>& p : {Vec<3>(0.2, 0.05, 0.2), Vec<3>(0.5, 0.04, -0.03), Vec<3>(-0.02, 0.06, -0.03),
                            Vec<3>(0.55, 0.03, 0.55), Vec<3>(0.3, -0.07, 0.1)})
        check_barrier<3>(contact, p, {Vec<3>(0, 0, 0), Vec<3>(1, 0, 0), Vec<3>(0, 0, 1)}, stats);
    EXPECT_EQ(stats.checks, 5 * (12 + 144));
}

TEST(ContactPoints3d, CcdStopsAParticleBeforeATriangleAndTheWindingNumberFindsInsidePoints) {
    // A closed tetrahedron, outward oriented; the particle is the stand-alone point after its nodes.
    const std::vector<Vec<3>> x = {Vec<3>(0, 0, 0), Vec<3>(1, 0, 0), Vec<3>(0, 1, 0), Vec<3>(0, 0, 1)};
    const std::vector<std::array<int, 3>> triangles = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
    const Contact3d contact(triangles, {}, 0.01, 1.0, ContactPoints{4, true});
    const std::vector<Vec<3>> outside = {Vec<3>(0.2, -0.2, 0.2)}, inside = {Vec<3>(0.1, 0.1, 0.1)};
    std::vector<Vec<3>> positions = x, motion(4, Vec<3>::Zero());
    positions.push_back(outside[0]);
    // Moving up by 0.4 crosses the face y = 0 at t = 0.5: CCD stops short of it.
    motion.push_back(Vec<3>(0, 0.4, 0));
    const double t = contact.max_step(positions, motion);
    EXPECT_GT(t, 0.0);
    EXPECT_LT(t, 0.5);
    motion.back() = Vec<3>(0, 0.1, 0);
    EXPECT_EQ(contact.max_step(positions, motion), 1.0);
    EXPECT_EQ(first_inside<3>(outside, x, triangles), "");
    EXPECT_EQ(count_inside<3>(inside, x, triangles), 1u);
    EXPECT_EQ(first_inside<3>(inside, x, triangles, "particle"), "particle 0 inside the mesh");
    // Reversed orientation: still inside; a point on a face is reported on it.
    std::vector<std::array<int, 3>> reversed = triangles;
    for (auto& f : reversed) std::swap(f[1], f[2]);
    EXPECT_EQ(count_inside<3>(inside, x, reversed), 1u);
    EXPECT_EQ(first_inside<3>({Vec<3>(0.2, 0.0, 0.2)}, x, triangles, "particle"), "particle 0 on triangle 0-1-3");
}

TEST(ContactPoints2d, PointsMeetOnlyFacetsAndAreNamedAsPoints) {
    // A square's boundary on the ground y = 0, and two stand-alone points: one touching the top
    // edge, one below the ground (points meet no half-space) and far from the square.
    const std::vector<std::array<int, 2>> edges = {{0, 1}, {1, 2}, {2, 3}, {3, 0}};
    std::vector<Vec<2>> x = {Vec<2>(0, 0.001), Vec<2>(1, 0.001), Vec<2>(1, 1),
                             Vec<2>(0, 1),     Vec<2>(0.5, 1.0), Vec<2>(3, -1)};
    Contact2d all(edges, {}, 0.01, 1.0, ContactPoints{4, false});
    all.add_half_space(HalfSpace2d{});
    // The square's bottom nodes against the ground (2 pairs) and the first point against the top
    // edge it touches; the second point meets nothing, though below the ground.
    EXPECT_EQ(all.active_pairs(x), 3u);
    EXPECT_EQ(all.first_intersection(x), "point 0 and edge 2-3");
    Contact2d only(edges, {}, 0.01, 1.0, ContactPoints{4, true});
    only.add_half_space(HalfSpace2d{});
    EXPECT_EQ(only.active_pairs(x), 1u);
    x[4] = Vec<2>(0.5, 1.005);
    EXPECT_EQ(only.first_intersection(x), "");
    EXPECT_THROW(Contact2d(edges, {}, 0.01, 1.0, ContactPoints{3, true}), std::invalid_argument);
}

using test::CoupledFixture;

/// tolerance: of the Hessian's columns, relative to each column's largest entry (the stiff
/// mesh's elements make the differences' truncation error larger in 3D).
template <int dim>
void check_coupled_derivatives(CoupledFixture<dim>& f, double tolerance) {
    f.mpm_potential.set_project_psd(false);
    f.fem_potential.set_project_psd(false);
    f.coupled.set_project_psd(false);
    ASSERT_GT(f.coupled.friction_pairs(), 0u) << "the mesh should be within dhat of the bed";
    test::Random rng(11);
    const VecX v = test::perturbed_v_star(f.coupled, rng);
    ASSERT_GT(f.coupled.friction_value(v), 0.0);
    VecX g;
    using Solve = typename CoupledPotential<dim>::LinearSolve;
    f.coupled.set_linear_solve(Solve::Assembled);
    f.coupled.value_gradient_hessian(v, g);
    const Eigen::MatrixXd H = Eigen::MatrixXd(*f.coupled.hessian_matrix());
    {  // the matrix-free product applies the same H, friction included
        test::expect_matrix_free_hessian(f.coupled, v, H, rng);
        VecX g2;
        f.coupled.set_linear_solve(Solve::Assembled);
        f.coupled.value_gradient_hessian(v, g2);
    }
    const double energy = f.coupled.value(v);
    test::FdStats stats;
    std::vector<Eigen::Index> columns;  // the coupled components and a sample of the others
    for (Eigen::Index i = 0; i < v.size(); ++i)
        if (f.coupled.residual_mass()[i] > 0.0 && (i % 11 == 0 || std::abs(g[i]) > 0.0)) columns.push_back(i);
    for (Eigen::Index k : columns) {
        Eigen::VectorXd t0(1);
        t0[0] = v[k];
        auto along = [&](const Eigen::VectorXd& t) {
            VecX y = v, gy;
            y[k] = t[0];
            f.coupled.value_gradient(y, gy);
            return gy;
        };
        // The round-off of a central difference of the gradient is ~ eps |g| / step = 1e-10 |g|: an
        // error that size is noise, so the denominator is at least that over the tolerance.
        const double scale = std::max(1e-4 * H.col(k).cwiseAbs().maxCoeff(), 5e-7 * g.cwiseAbs().maxCoeff());
        ASSERT_TRUE(test::check_jacobian(along, H.col(k), t0, stats, 1e-6, tolerance, scale))
            << "column " << k << " (largest entry " << H.col(k).cwiseAbs().maxCoeff() << ", |g|_inf "
            << g.cwiseAbs().maxCoeff() << ")";
        auto along_value = [&](const Eigen::VectorXd& t) {
            VecX y = v;
            y[k] = t[0];
            return f.coupled.value(y);
        };
        // Likewise for the energy: round-off ~ eps |E| / step.
        ASSERT_TRUE(test::check_gradient(along_value, Eigen::VectorXd::Constant(1, g[k]), t0, stats, 1e-6, 1e-4,
                                         std::max(1e-8, 1e-6 * std::abs(energy))))
            << "component " << k;
    }
    EXPECT_GT(stats.checks, 1000);
    std::printf(
        "coupled potential with friction, %dD: %zu friction pairs, %d finite-difference comparisons "
        "(largest relative error %.2e)\n",
        dim, f.coupled.friction_pairs(), stats.checks, stats.max_error);
}

TEST(CoupledPotential, WithFrictionMatchesFiniteDifferencesIn2d) {
    // The disk 3 mm above the bed's top row (0.0977 m), within dhat; eps_v larger than the
    // perturbation so that the smoothed (curved) part of friction is exercised.
    CoupledFixture<2> f(edited(kTiny2d, 0.09765625 + 0.05 + 0.003, {0.0, 0.0}, 0.5), 0.5, 0.2);
    check_coupled_derivatives(f, 2e-4);
}

TEST(CoupledPotential, WithFrictionMatchesFiniteDifferencesIn3d) {
    // The sphere ~1.5 cm above the bed's top row (0.297 m), within dhat = 3.1 cm.
    CoupledFixture<3> f(edited(kTiny3d, 0.296875 + 0.1 + 0.015, {0.0, 0.0, 0.0}, 0.5), 0.5, 0.2);
    check_coupled_derivatives(f, 1e-3);
}

/// A block resting on the tiny 2D bed, sliding along +x at 1 m/s, after one frame: its mean
/// horizontal velocity and the sand's horizontal momentum.
std::pair<double, double> slide(const std::string& integrator, double dt, double mu) {
    nlohmann::json j = scene_to_json(load_scene(kTiny2d));
    const double dhat = 0.5 * j["dx"].get<double>(), top = 0.09765625 + 0.96 * dhat;
    j["meshes"][0] = {{"shape", "box"},
                      {"min", {0.4, top}},
                      {"max", {0.5, top + 0.02}},
                      {"element_size", 0.01},
                      {"material", j["meshes"][0]["material"]},
                      {"velocity", {1.0, 0.0}}};
    j["contact"]["friction"] = mu;
    const Scene scene = scene_from_json(j, "slide.json", "");
    CoupledSimulation<2> sim(scene, settings_for(scene, integrator, dt));
    sim.advance_frame();
    EXPECT_EQ(sim.penetrations(), 0u);
    double vx = 0.0, momentum = 0.0;
    for (const Vec<2>& v : sim.state().v) vx += v[0] / sim.state().v.size();
    for (std::size_t p = 0; p < sim.particles().size(); ++p)
        momentum += sim.particles().mass[p] * sim.particles().v[p][0];
    return {vx, momentum};
}

TEST(CoupledSimulation, FrictionDragsTheSandUnderASlidingBlockAndSlowsIt) {
    for (const auto& [integrator, dt] :
         std::vector<std::pair<std::string, double>>{{"lagged", 1e-3}, {"explicit", 1e-5}}) {
        SCOPED_TRACE(integrator);
        const auto [vx_free, momentum_free] = slide(integrator, dt, 0.0);
        const auto [vx_rough, momentum_rough] = slide(integrator, dt, 0.5);
        std::printf("%s: block vx %.4f m/s frictionless, %.4f with mu 0.5; sand x-momentum %.3g, %.3g kg m/s\n",
                    integrator.c_str(), vx_free, vx_rough, momentum_free, momentum_rough);
        EXPECT_LT(vx_rough, vx_free - 0.02);
        EXPECT_GT(momentum_rough, momentum_free + 1e-3);
    }
}

TEST(CoupledSimulation3d, TinySceneRunsWithoutPenetrationAndIsThreadAndResumeIndependent) {
    const Scene scene = load_scene(kTiny3d);
    for (const auto& [integrator, dt] :
         std::vector<std::pair<std::string, double>>{{"lagged", 1e-3}, {"explicit", 1e-4}}) {
        SCOPED_TRACE(integrator);
        const IntegratorSettings settings = settings_for(scene, integrator, dt);
        const int threads = omp_get_max_threads();
        std::vector<std::unique_ptr<CoupledSimulation<3>>> runs;
        std::size_t most_pairs = 0;
        for (int t : {1, 2}) {
            omp_set_num_threads(t);
            runs.push_back(std::make_unique<CoupledSimulation<3>>(scene, settings));
            for (int frame = 0; frame < 2; ++frame) {
                const FrameStats f = runs.back()->advance_frame();  // throws if a particle is inside
                most_pairs = std::max(most_pairs, f.contact_pairs);
                EXPECT_EQ(runs.back()->penetrations(), 0u);
                EXPECT_TRUE(f.converged);
            }
        }
        omp_set_num_threads(threads);
        EXPECT_GT(most_pairs, 0u) << "the sphere should have reached the bed";
        expect_identical(*runs[0], *runs[1]);
        double lowest = 1e300;
        for (const Vec<3>& x : runs[0]->state().x) lowest = std::min(lowest, x[1]);
        EXPECT_GT(lowest, 3 * scene.dx) << "the bed should have stopped the sphere";

        test::TempDir dir;
        CoupledSimulation<3> first(scene, settings), resumed(scene, settings);
        first.advance_frame();
        first.save_checkpoint(dir.file("state.bin"));
        resumed.load_checkpoint(dir.file("state.bin"));
        resumed.advance_frame();
        expect_identical(resumed, *runs[1]);
    }
}

}  // namespace
}  // namespace pnet
