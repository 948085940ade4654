// FEM on a metal bar crushed past yield: the classical return_map integrator lands on the analytic ECI
// step, and plasticitynet (the learned metal energy, models/metal_2d.pt, on every Newton iteration)
// converges to the same step, at the paper's FEM step (1e-2 s) and a smaller one, closer to it than
// the lagged baseline.
#include <gtest/gtest.h>

#include <memory>
#include <cstdio>
#include <string>

#include <omp.h>

#include "pnet/energy/analytic_elastoplastic.hpp"
#include "pnet/energy/return_mapping_energy.hpp"
#include "pnet/fem/fem_integrator.hpp"
#include "pnet/fem/gmsh_mesher.hpp"
#include "support/fem_systems.hpp"
#include "pnet/nn/learned_return_map.hpp"
#include "pnet/nn/model_file.hpp"

namespace pnet {
namespace {

using test::crushed_bar;

struct RunCounts {
    int unconverged = 0;           // steps whose solve ended above its tolerance
    int fixed_point_capped = 0;    // steps whose outer iteration did not reach its tolerance
    double max_true_residual = 0;  // plasticitynet: the largest |R(v)| at a step's end, m/s
};

FemState<2> run(const FemSystem<2>& system, FemMethod method, double dt, double T, int* unconverged,
                const std::string& outer = "newton", RunCounts* counts = nullptr, double newton_tolerance = 1e-6,
                int max_newton_iterations = 200) {
    ImplicitOptions options;
    options.newton_tolerance = newton_tolerance;
    options.max_newton_iterations = max_newton_iterations;
    // FEM metal moves far less per step than MPM sand (here 0.05% strain per step at dt 1e-3): the
    // paper's fixed point on F0 must be converged much tighter than MPM's 1e-3 (measured: mean distance
    // to analytic 0.34% of the diagonal at 1e-3, 0.0095% at 1e-6).
    options.fixed_point_tolerance = 1e-6;
    options.max_fixed_point_iterations = 50;
    options.outer_iteration = outer;
    std::unique_ptr<ParticleEnergy<2>> energy;
    const std::vector<std::string> context = {"bar"};
    if (method == FemMethod::Analytic) {
        energy = std::make_unique<AnalyticElastoplasticEnergy<2>>(system.materials, context);
    } else if (method == FemMethod::Lagged) {
        energy = std::make_unique<ElasticParticleEnergy<2>>(system.materials);
    } else if (method == FemMethod::ReturnMap) {
        energy = std::make_unique<ReturnMappingEnergy<2>>(system.materials, options.tangent_damping);
    } else {
        // As a scene builds it (the registry's energy, solver/integrators.cpp): the network's Hessian with the family's w
        // (plasticitynet_defaults: 0.05 for von Mises) unless the test sets one.
        auto model = std::make_shared<const ModelFile>(load_model_file(std::string(PNET_MODELS_DIR) + "/metal_2d.pt"));
        energy = std::make_unique<NeuralParticleEnergy<2>>(std::vector<std::shared_ptr<const ModelFile>>{model},
                                                           system.materials, context,
                                                           options.resolved_regularizer_weight(PlasticityModel::VonMises),
                                                           options.neural_hessian<2>());
    }
    FemImplicitIntegrator<2> integrator(system, method, options, std::move(energy), nullptr);
    FemState<2> state = FemState<2>::at_rest(system);
    const int steps = static_cast<int>(std::lround(T / dt));
    for (int s = 0; s < steps; ++s) {
        const FemStepStats st = integrator.step(state, dt, s);
        *unconverged += !st.converged;
        if (counts) {
            counts->unconverged += !st.converged;
            counts->fixed_point_capped += !st.fixed_point_converged;
            counts->max_true_residual = std::max(counts->max_true_residual, st.true_residual);
        }
    }
    return state;
}

std::string scientific(double x) {
    char text[32];
    std::snprintf(text, sizeof text, "%.3e", x);
    return text;
}

double mean_distance(const FemState<2>& a, const FemState<2>& b) {
    double sum = 0.0;
    for (std::size_t i = 0; i < a.x.size(); ++i) sum += (a.x[i] - b.x[i]).norm();
    return sum / a.x.size();
}

// The top moves like the metal frame scene's plate (0.05 m/s: 0.5 mm per step of 1e-2 s, a sixth of
// an element). Faster kinematic nodes (a whole element per step) make v* itself invert the elements
// next to them: that needs the augmented-Lagrangian kinematic constraint of IPC (not yet built).
TEST(FemLearned, PlasticityNetReproducesTheAnalyticEnergyAndBeatsLagged) {
    const FemSystem<2> system = crushed_bar(0.05);
    const double T = 0.4;  // 2 cm of crushing: 20% strain, well past the 5% yield
    const double diagonal = std::sqrt(0.02 * 0.02 + 0.1 * 0.1);
    for (double dt : {1e-2, 1e-3}) {
        SCOPED_TRACE("dt " + std::to_string(dt));
        int unconverged = 0, learned_unconverged = 0;
        // A tight tolerance (m/s): the bar's perfectly plastic flow is a mode of near-zero stiffness, in
        // which the mass-weighted residual at 1e-6 m/s still allows 2.5e-5 m between two converged
        // steps (measured at dt 1e-2).
        const double tolerance = 1e-9;
        const FemState<2> analytic = run(system, FemMethod::Analytic, dt, T, &unconverged, "newton", nullptr, tolerance);
        const FemState<2> classical =
            run(system, FemMethod::ReturnMap, dt, T, &unconverged, "newton", nullptr, tolerance);
        const FemState<2> lagged = run(system, FemMethod::Lagged, dt, T, &unconverged);
        EXPECT_EQ(unconverged, 0) << "every Newton solve converged";
        // plasticitynet steps with the network's Hessian, not R's Jacobian: on perfectly plastic flow
        // Newton converges linearly, so it gets the scenes' tolerance (1e-6 m/s) and more iterations.
        const FemState<2> learned = run(system, FemMethod::PlasticityNet, dt, T, &learned_unconverged, "newton",
                                        nullptr, 1e-6, 1000);
        EXPECT_EQ(learned_unconverged, 0) << "every plasticitynet solve converged";
        const double d_classical = mean_distance(classical, analytic), d_learned = mean_distance(learned, analytic),
                     d_lagged = mean_distance(lagged, analytic);
        RecordProperty("dt_" + std::to_string(dt), scientific(d_classical / diagonal) + " / " +
                                                       scientific(d_learned / diagonal) + " / " +
                                                       scientific(d_lagged / diagonal));
        std::printf("dt %g: mean distance to analytic / diagonal: return_map %.3e, plasticitynet %.3e, lagged %.3e\n",
                    dt, d_classical / diagonal, d_learned / diagonal, d_lagged / diagonal);
        // return_map (F0 = F(v) at every iterate, the return mapping's consistent tangent) converges each
        // step on the true residual, whose root is the analytic step's: what is left is the Newton
        // tolerance. (The paper's fixed point, before issue 31: 0.061% at 1e-3 and 1.97% at 1e-2, where
        // it stalled near a change of 1e-4; FemLearned.PlainFixedPointStallsWhereNewtonConverges.)
        EXPECT_LT(d_classical, 1e-6 * diagonal) << "mean nodal distance to analytic (measured 2.5e-8 m at 1e-2, "
                                                    "1.2e-8 m at 1e-3)";
        // plasticitynet solves the same step to its looser tolerance.
        EXPECT_LT(d_learned, 1e-3 * diagonal) << "mean nodal distance to analytic";
        EXPECT_LT(d_learned, 0.5 * d_lagged) << "closer than lagged";
        double yielded = 0.0;
        for (double h : analytic.hardening) yielded = std::max(yielded, h - 0.05);
        EXPECT_GT(yielded, 0.005);
    }
}

// The mechanism of issue 31 on the crushed bar at the paper's step: with h held at h^n within a step
// the yielded bar is perfectly plastic, its plastic-flow modes have a near-zero true stiffness while
// each solve of the paper's fixed point (eq. 10) adds the network's Hessian and w mu: the plain
// iteration (no Anderson) contracts slowly there and hits its cap, and its steps end above the
// Newton tolerance on the true residual. return_map (the outer iteration merged into Newton, with the
// consistent tangent) ends every step converged on the true residual (m/s).
TEST(FemLearned, PlainFixedPointStallsWhereNewtonConverges) {
    const FemSystem<2> system = crushed_bar(0.05);
    const double dt = 1e-2, T = 0.3;
    int unconverged = 0;
    RunCounts plain, newton;
    const double tolerance = 1e-9;  // m/s: tight, so that the steps are the analytic ones to round-off
    RunCounts exact;
    const FemState<2> analytic = run(system, FemMethod::Analytic, dt, T, &unconverged, "newton", &exact, tolerance);
    const FemState<2> a = run(system, FemMethod::PlasticityNet, dt, T, &unconverged, "fixed_point", &plain, tolerance);
    const FemState<2> b = run(system, FemMethod::ReturnMap, dt, T, &unconverged, "newton", &newton, tolerance);
    RecordProperty("plain_capped_steps", plain.fixed_point_capped);
    RecordProperty("plain_max_true_residual", scientific(plain.max_true_residual));
    RecordProperty("newton_max_true_residual", scientific(newton.max_true_residual));
    RecordProperty("plain_distance", scientific(mean_distance(a, analytic)));
    RecordProperty("newton_distance", scientific(mean_distance(b, analytic)));
    EXPECT_GT(plain.fixed_point_capped, 0) << "the plain fixed point stalls on the yielded bar";
    EXPECT_EQ(newton.fixed_point_capped, 0);
    EXPECT_EQ(newton.unconverged, 0);
    EXPECT_GT(newton.max_true_residual, 0.0) << "the true residual was measured";
    EXPECT_LE(newton.max_true_residual, tolerance) << "every step converged on the true residual (m/s)";
    EXPECT_LT(mean_distance(b, analytic), 1e-8) << "the analytic step (m)";
    EXPECT_GT(mean_distance(a, analytic), 10.0 * mean_distance(b, analytic));
}

// Results do not depend on the thread count: the outer iteration with 1 and 2 threads, bitwise.
TEST(FemLearned, OuterIterationIsIndependentOfTheThreadCount) {
    const FemSystem<2> system = crushed_bar(0.05);
    const int threads = omp_get_max_threads();
    int unconverged = 0;
    omp_set_num_threads(1);
    const FemState<2> one = run(system, FemMethod::PlasticityNet, 1e-2, 0.1, &unconverged, "newton", nullptr, 1e-6, 1000);
    omp_set_num_threads(2);
    const FemState<2> two = run(system, FemMethod::PlasticityNet, 1e-2, 0.1, &unconverged, "newton", nullptr, 1e-6, 1000);
    omp_set_num_threads(threads);
    EXPECT_EQ(unconverged, 0);
    for (std::size_t i = 0; i < one.x.size(); ++i) ASSERT_EQ(one.x[i], two.x[i]) << "node " << i;
    for (std::size_t e = 0; e < one.hardening.size(); ++e) ASSERT_EQ(one.hardening[e], two.hardening[e]);
}

}  // namespace
}  // namespace pnet

namespace pnet {
namespace {

// The FEM return mapping uses an object's learned return mapping when one is
// given (metal_nh: models/metal_nh_rm_2d.pt), and it stays close to the exact
// root-find: a neo-Hookean metal bar crushed 20%, lagged at dt 1e-3, with each.
TEST(FemLearned, LearnedReturnMapFollowsTheExactOneOnANeoHookeanBar) {
    FemSystem<2> exact = crushed_bar(0.05);
    exact.materials = {Material<2>(material_preset("metal_nh"))};
    exact.make_rest();
    FemSystem<2> learned = exact;
    const LearnedReturnMap<2> rm(load_model_file(std::string(PNET_MODELS_DIR) + "/metal_nh_rm_2d.pt"));
    learned.return_maps = {&rm};
    int unconverged = 0;
    const FemState<2> a = run(exact, FemMethod::Lagged, 1e-3, 0.4, &unconverged);
    const FemState<2> b = run(learned, FemMethod::Lagged, 1e-3, 0.4, &unconverged);
    EXPECT_EQ(unconverged, 0);
    const double diagonal = std::sqrt(0.02 * 0.02 + 0.1 * 0.1);
    double plastic = 0.0, hardening_difference = 0.0;
    for (std::size_t e = 0; e < a.hardening.size(); ++e) {
        plastic = std::max(plastic, a.hardening[e] - 0.05);
        hardening_difference = std::max(hardening_difference, std::abs(a.hardening[e] - b.hardening[e]));
    }
    EXPECT_GT(plastic, 0.005) << "the bar yields";
    EXPECT_GT(hardening_difference, 0.0) << "the learned mapping was used";
    const double d = mean_distance(a, b);
    RecordProperty("learned_vs_exact_return_map", std::to_string(d / diagonal));
    // Measured: 0.82% of the diagonal. The shipped return-map network's mean |dgamma| error is 1.5e-3
    // per projection (models/MANIFEST), as large as a step's plastic increment here, and it
    // accumulates over the 400 steps. A guard at 2%, not a target (issue 16 retrains the models).
    EXPECT_LT(d, 0.02 * diagonal) << "mean nodal distance";
}

}  // namespace
}  // namespace pnet
