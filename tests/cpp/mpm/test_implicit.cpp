// The implicit MPM integrators (plasticitynet, lagged): the incremental
// potential's gradient and Hessian-vector product against finite differences,
// monotone Newton steps, plasticitynet = lagged without plasticity, thread-count
// independence, checkpoint/resume, and a few steps of every tiny scene.
//
// The learned energies here are random or all-zero MLPs built in memory, so
// that these tests need no model file (and no LibTorch); the shipped models run
// in tests/python/test_pnet_cli.py.
#include <gtest/gtest.h>
#include <omp.h>

#include <array>
#include <filesystem>
#include <iostream>
#include <memory>

#include "pnet/metrics/deposit_shape.hpp"
#include "pnet/mpm/floor_friction_passes.hpp"
#include "pnet/mpm/implicit_integrator.hpp"
#include "pnet/mpm/mpm_options.hpp"
#include "pnet/mpm/step_predictor.hpp"
#include "pnet/mpm/transfer.hpp"
#include "pnet/scene/sampler.hpp"
#include "pnet/sim/mpm_simulation.hpp"
#include "pnet/solver/fixed_point.hpp"
#include "pnet/solver/method_energy.hpp"
#include "pnet/solver/newton.hpp"
#include "support/dims.hpp"
#include "support/finite_difference.hpp"
#include "support/identical_states.hpp"
#include "support/random.hpp"
#include "support/temp_dir.hpp"

namespace pnet {
namespace {

namespace fs = std::filesystem;

Scene tiny_scene(const std::string& name) {
    return load_scene(std::string(PNET_SCENES_DIR) + "/tiny/" + name + ".json");
}

/// An energy model of `material` with random weights (scale: PyTorch's default
/// init times `scale`; 0: every weight zero, so that N = 0 and Psi is the
/// regularized linearization of Ptilde about F0).
template <int dim>
std::shared_ptr<const ModelFile> memory_model(MaterialDescription material, double scale, unsigned seed = 7) {
    auto model = std::make_shared<ModelFile>();
    model->path = "<in-memory test model>";
    ModelMetadata& meta = model->metadata;
    meta.kind = ModelKind::Energy;
    meta.dim = dim;
    meta.has_hardening = material.plasticity == PlasticityModel::CamClay;
    const int hidden = dim == 2 ? 32 : 64;
    meta.widths = {2 * dim * dim + (meta.has_hardening ? 1 : 0), hidden, hidden, hidden, 1};
    meta.training_E = 1.0;
    meta.hardening_min = material.plasticity == PlasticityModel::CamClay ? (dim == 2 ? -0.5 : -1.0) : 0.0;
    meta.hardening_max = material.plasticity == PlasticityModel::CamClay ? 0.0 : 1.0;
    material.elastic.E = 1.0;
    meta.material = material;
    model->weights = random_mlp(meta.widths, seed, scale == 0.0 ? 1.0 : scale);
    if (scale == 0.0) {
        for (auto& w : model->weights.weight) std::fill(w.begin(), w.end(), 0.0);
        for (auto& b : model->weights.bias) std::fill(b.begin(), b.end(), 0.0);
    }
    return model;
}

template <int dim>
std::string scene_name(const char* stem) {
    return std::string(stem) + (dim == 2 ? "_2d" : "_3d");
}

/// One implicit step's potential, set up on a perturbed tiny scene: F^E and v_p
/// randomized, P2G done, reference F0 = F(v* + noise).
template <int dim>
struct PotentialFixture {
    Scene scene;
    MpmSystem<dim> system;
    Particles<dim> particles;
    std::unique_ptr<ParticleEnergy<dim>> energy;
    std::unique_ptr<Grid<dim>> grid;
    std::unique_ptr<IncrementalPotential<dim>> potential;
    VecX v;

    PotentialFixture(const std::string& name, bool neural, double dt = 1e-3, bool bdf2 = false)
        : scene(tiny_scene(name)), system(make_mpm_system<dim>(scene)), particles(sample_particles<dim>(scene)) {
        test::Random random(11);
        for (std::size_t p = 0; p < particles.size(); ++p) {
            particles.F_elastic[p] =
                Mat<dim>::Identity() + 0.05 * Mat<dim>::NullaryExpr([&] { return random.uniform(-1, 1); });
            particles.v[p] = random.uniform_vec<dim>(-0.5, 0.5);
        }
        if (neural) {
            std::vector<std::shared_ptr<const ModelFile>> models = {memory_model<dim>(scene.objects[0].material, 0.3)};
            energy = std::make_unique<NeuralParticleEnergy<dim>>(models, system.materials,
                                                                 std::vector<std::string>{"test"}, 1.0);
        } else {
            energy = std::make_unique<ElasticParticleEnergy<dim>>(system.materials);
        }
        grid = std::make_unique<Grid<dim>>(system.origin, system.dx, system.cells);
        particles_to_grid<dim>(*grid, particles, nullptr);
        grid->update_velocity(dt, system.gravity, system.boundary);
        potential = std::make_unique<IncrementalPotential<dim>>(*energy);
        potential->begin_step(*grid, particles, dt, system.boundary);
        if (bdf2) {  // BDF2's potential about random history fields (IncrementalPotential::use_bdf2), after a
                     // longer step (the variable-step coefficients, step ratio 0.7)
            VecX u(potential->size()), v_previous(potential->size());
            for (Eigen::Index i = 0; i < u.size(); ++i) {
                u[i] = random.uniform(-0.1, 0.1);
                v_previous[i] = random.uniform(-0.5, 0.5);
            }
            potential->use_bdf2(u, v_previous, system.gravity, 0.7);
        }
        v = potential->v_star();
        for (Eigen::Index i = 0; i < v.size(); ++i)
            if (potential->residual_scale()[i] > 0.0) v[i] += random.uniform(-0.3, 0.3);
        std::vector<Mat<dim>> F0;
        VecX v0 = v;
        for (Eigen::Index i = 0; i < v.size(); ++i)
            if (potential->residual_scale()[i] > 0.0) v0[i] += random.uniform(-0.1, 0.1);
        potential->deformation(v0, F0);
        potential->set_reference(F0);
    }

    std::vector<Eigen::Index> free_components() const {
        std::vector<Eigen::Index> free;
        for (Eigen::Index i = 0; i < v.size(); ++i)
            if (potential->residual_scale()[i] > 0.0) free.push_back(i);
        return free;
    }
};

PNET_TYPED_TEST_SUITE_2D_3D(ImplicitTest);

// Gradient of E on the free components against central differences of E, and
// H d against differences of the gradient along random directions and unit
// vectors, for the elastic (lagged) and the neural (plasticitynet) energy.
TYPED_TEST(ImplicitTest, GradientAndHessianMatchFiniteDifferences) {
    constexpr int dim = TypeParam::value;
    for (const bool neural : {false, true})
      for (const bool bdf2 : {false, true}) {
        for (const char* stem : {"sand_column", "snowball"}) {
            SCOPED_TRACE(std::string(stem) + (neural ? " (plasticitynet energy)" : " (lagged, elastic energy)") +
                         (bdf2 ? ", BDF2" : ""));
            PotentialFixture<dim> f(scene_name<dim>(stem), neural, 1e-3, bdf2);
            IncrementalPotential<dim>& E = *f.potential;
            E.set_project_psd(false);  // the exact Hessian (the random F^E has indefinite ones)
            const std::vector<Eigen::Index> free = f.free_components();
            ASSERT_GT(free.size(), 20u);
            VecX g(E.size());
            E.value_gradient(f.v, g);
            // The gradient is not trivially small: the energy terms dominate the test.
            ASSERT_GT(g.norm(), 1e-3);

            // Every free component of the gradient (a reduced function of the free
            // unknowns). E carries a large constant (the network's N scaled by the
            // scene's E), so the step is 1e-4 m/s: round-off stays below 1e-9.
            Eigen::VectorXd x(free.size()), g_free(free.size());
            for (std::size_t k = 0; k < free.size(); ++k) {
                x[k] = f.v[free[k]];
                g_free[k] = g[free[k]];
            }
            auto embed = [&](const Eigen::VectorXd& y) {
                VecX full = f.v;
                for (std::size_t k = 0; k < free.size(); ++k) full[free[k]] = y[k];
                return full;
            };
            test::FdStats stats;
            EXPECT_TRUE(test::check_gradient([&](const Eigen::VectorXd& y) { return E.value(embed(y)); }, g_free, x,
                                             stats, 1e-4, 1e-5, 1e-3 * g_free.cwiseAbs().maxCoeff()));
            EXPECT_EQ(stats.checks, static_cast<int>(free.size()));

            // H d against (g(v + h d) - g(v - h d)) / 2h on the free rows.
            E.prepare_hessian(f.v);
            test::Random random(5);
            int directions = 0;
            double worst = 0.0;
            for (int trial = 0; trial < 8; ++trial) {
                VecX d = VecX::Zero(E.size());
                if (trial < 4) {
                    for (Eigen::Index i : free) d[i] = random.uniform(-1, 1);
                } else {
                    d[free[(trial * 7919) % free.size()]] = 1.0;
                }
                VecX Hd(E.size()), gp(E.size()), gm(E.size());
                E.hessian_multiply(d, Hd);
                // m/s. The gradient sums large cancelling terms, so round-off, not
                // truncation, dominates: measured on every case here, the worst error
                // falls from ~1e-4 at h = 1e-6 to ~2e-7 at h = 1e-3, and h = 1e-5 left
                // the 3D snowball at 8e-6 here and 1.4e-5 on an AVX2 machine.
                const double h = 1e-3;
                E.value_gradient(f.v + h * d, gp);
                E.value_gradient(f.v - h * d, gm);
                E.prepare_hessian(f.v);  // value_gradient does not disturb the prepared Hessian, but be explicit
                const VecX numeric = (gp - gm) / (2 * h);
                double scale = 0.0;
                for (Eigen::Index i : free) scale = std::max(scale, std::abs(Hd[i]));
                ASSERT_GT(scale, 0.0);
                for (Eigen::Index i : free) {
                    const double err =
                        std::abs(Hd[i] - numeric[i]) / std::max({std::abs(Hd[i]), std::abs(numeric[i]), 1e-3 * scale});
                    worst = std::max(worst, err);
                }
                ++directions;
            }
            EXPECT_EQ(directions, 8);
            EXPECT_LT(worst, 1e-5) << "largest relative error of H d";

            // diag(H) equals e_i^T H e_i.
            VecX diagonal(E.size()), e = VecX::Zero(E.size()), He(E.size());
            E.hessian_diagonal(diagonal);
            for (int k = 0; k < 5; ++k) {
                const Eigen::Index i = free[(k * 104729) % free.size()];
                e.setZero();
                e[i] = 1.0;
                E.hessian_multiply(e, He);
                EXPECT_NEAR(diagonal[i], He[i], 1e-12 * std::abs(He[i]));
            }

            // The node blocks of the block-Jacobi preconditioner equal e_(k,a)^T H e_(k,b),
            // fixed components included (mass on the diagonal, no coupling).
            VecX blocks;
            ASSERT_EQ(E.hessian_block_size(), dim);
            E.hessian_block_diagonal(blocks);
            ASSERT_EQ(blocks.size(), E.size() * dim);
            for (int k = 0; k < 5; ++k) {
                const Eigen::Index node = ((k * 7919) % E.size()) / dim;
                for (int b = 0; b < dim; ++b) {
                    e.setZero();
                    e[dim * node + b] = 1.0;
                    E.hessian_multiply(e, He);
                    for (int a = 0; a < dim; ++a)
                        EXPECT_NEAR(blocks[dim * dim * node + dim * a + b], He[dim * node + a],
                                    1e-12 * std::abs(He[dim * node + b]))
                            << "node " << node << " (" << a << ", " << b << ")";
                }
            }
        }
      }
}

// The Coulomb floor's friction in the one solve (FloorFrictionForm::begin_newton): the residual of a
// contact node's slip is mu J f1(|u|) u / |u| with J the floor's reaction at v, and the Jacobian carries
// J's derivative. Along directions that leave the contacts' slips alone (where the Jacobian takes the
// majorizer's curvature instead of the friction's own), H d matches central differences of the residual
// on every free row, the contacts' slip rows included, where J's change along d is not small.
TYPED_TEST(ImplicitTest, TheCoulombFloorsFrictionInOneSolveCarriesTheImpulsesDerivative) {
    constexpr int dim = TypeParam::value;
    constexpr double dt = 1e-3, mu = 0.5;
    PotentialFixture<dim> f(scene_name<dim>("sand_column"), false, dt);
    BoundaryConditions bc = f.system.boundary;
    bc.floor_friction = mu;
    ASSERT_TRUE(bc.coulomb_floor());
    particles_to_grid<dim>(*f.grid, f.particles, nullptr);
    f.grid->update_velocity(dt, f.system.gravity, unprojected_floor(bc));
    IncrementalPotential<dim>& E = *f.potential;
    E.set_project_psd(false);  // the exact Hessian of the elastic energy
    E.set_floor_friction_newton(true);
    E.begin_step(*f.grid, f.particles, dt, bc);
    EXPECT_EQ(E.floor_friction_contacts(), E.floor_friction_form().newton_contacts().size()) << "no passes to set up";
    EXPECT_FALSE(E.hessian_symmetric());

    test::Random random(3);
    VecX v = E.v_star();
    for (Eigen::Index i = 0; i < v.size(); ++i)
        if (E.residual_scale()[i] > 0.0) v[i] += random.uniform(-0.3, 0.3);
    VecX g(E.size());
    E.value_gradient_hessian(v, g);
    const auto& contacts = E.floor_friction_form().newton_contacts();
    std::vector<bool> slip_row(E.size(), false);
    int pressing = 0;
    for (const auto& c : contacts) {
        if (c.impulse > 0.0) ++pressing;
        for (int a = 0; a < dim; ++a)
            if (a != 1) slip_row[dim * c.dof + a] = true;
    }
    ASSERT_GT(pressing, 2) << "the column presses on the floor";

    double worst = 0.0, coupling = 0.0;
    for (int trial = 0; trial < 4; ++trial) {
        VecX d = VecX::Zero(E.size());
        for (Eigen::Index i = 0; i < d.size(); ++i)
            if (E.residual_scale()[i] > 0.0 && !slip_row[i]) d[i] = random.uniform(-1, 1);
        VecX gp(E.size()), gm(E.size()), Hd(E.size());
        const double h = 1e-4;
        E.value_gradient(v + h * d, gp);
        std::vector<double> Jp;
        for (const auto& c : contacts) Jp.push_back(c.impulse);
        E.value_gradient(v - h * d, gm);
        E.value_gradient_hessian(v, g);
        E.hessian_multiply(d, Hd);
        const VecX numeric = (gp - gm) / (2 * h);
        double scale = 0.0;
        for (Eigen::Index i = 0; i < d.size(); ++i)
            if (E.residual_scale()[i] > 0.0) scale = std::max(scale, std::abs(numeric[i]));
        for (Eigen::Index i = 0; i < d.size(); ++i)
            if (E.residual_scale()[i] > 0.0)
                worst = std::max(worst, std::abs(Hd[i] - numeric[i]) / std::max(std::abs(numeric[i]), 1e-3 * scale));
        for (std::size_t k = 0; k < contacts.size(); ++k)  // the friction's change through J alone, on slip rows
            if (contacts[k].impulse > 0.0)
                coupling = std::max(coupling, mu * std::abs(Jp[k] - contacts[k].impulse) / h / std::max(scale, 1e-30));
    }
    // The value an energy line search compares holds J at the last Hessian's iterate: a trial point's
    // gradient (which moves the impulses) leaves the iterate's value as it was (with J taken from the
    // last gradient, the learned energy's line search failed near the tolerance in 29 of 738 steps of
    // the sand column).
    {
        VecX g0(E.size()), g1(E.size());
        const double at_iterate = E.value_gradient_hessian(v, g0);
        VecX trial = v;
        for (Eigen::Index i = 0; i < trial.size(); ++i)
            if (E.residual_scale()[i] > 0.0) trial[i] += 0.05;
        E.value_gradient(trial, g1);
        EXPECT_EQ(E.value(v), at_iterate);
        E.value_gradient_hessian(v, g0);
    }

    // The multigrid's operator (assemble_by_nodes: H^T) has the floor's friction on its diagonal too.
    SparseMatrix assembled;
    E.assemble_by_nodes(assembled);
    VecX diagonal;
    E.hessian_diagonal(diagonal);
    for (const auto& c : contacts) {
        if (c.impulse > 0.0) {
            EXPECT_NEAR(assembled.coeff(dim * c.dof, dim * c.dof), diagonal[dim * c.dof], 1e-9 * diagonal[dim * c.dof])
                << "contact node " << c.dof;
        }
    }
    std::cout << "floor friction in one solve: worst relative error of H d " << worst
              << ", largest friction change through J " << coupling << " of the largest entry\n";
    EXPECT_LT(worst, 1e-5);
    EXPECT_GT(coupling, 1e-3) << "J changes along d: without its derivative the slip rows would be off";
}

// Fixed components (sticky floor, slip walls) stay at v*: zero gradient, and a
// Hessian that does not couple them to the free ones.
TYPED_TEST(ImplicitTest, BoundaryComponentsAreFixed) {
    constexpr int dim = TypeParam::value;
    PotentialFixture<dim> f(scene_name<dim>("sand_column"), false);
    IncrementalPotential<dim>& E = *f.potential;
    VecX g(E.size()), Hd(E.size());
    E.value_gradient(f.v, g);
    E.prepare_hessian(f.v);
    VecX d = VecX::Ones(E.size());
    E.hessian_multiply(d, Hd);
    int fixed = 0;
    for (Eigen::Index i = 0; i < E.size(); ++i)
        if (E.residual_scale()[i] == 0.0) {
            ++fixed;
            EXPECT_EQ(g[i], 0.0);
            VecX e = VecX::Zero(E.size());
            e[i] = 1.0;
            VecX He(E.size());
            E.hessian_multiply(e, He);
            EXPECT_EQ((He - He[i] * e).cwiseAbs().maxCoeff(), 0.0) << "component " << i;
            if (fixed > 30) break;
        }
    EXPECT_GT(fixed, 0) << "the column stands on the sticky floor";
}

// The assembled grid Hessian (add_hessian_triplets, for CHOLMOD) is the matrix-free one: the same
// products and diagonal, symmetric, fixed components holding only their mass; a Newton solve with
// CHOLMOD, or PCG with an incomplete Cholesky preconditioner, reaches the minimum Jacobi PCG reaches.
TYPED_TEST(ImplicitTest, AssembledHessianEqualsTheMatrixFreeProductAndCholeskySolvesAlike) {
    constexpr int dim = TypeParam::value;
    for (const bool neural : {false, true}) {
        SCOPED_TRACE(neural ? "plasticitynet energy" : "elastic energy");
        PotentialFixture<dim> f(scene_name<dim>("sand_column"), neural);
        IncrementalPotential<dim>& E = *f.potential;
        EXPECT_EQ(E.hessian_matrix(), nullptr);
        E.set_assemble(true);
        VecX g(E.size());
        E.value_gradient_hessian(f.v, g);
        ASSERT_NE(E.hessian_matrix(), nullptr);
        const SparseMatrix& H = *E.hessian_matrix();
        EXPECT_LT((SparseMatrix(H.transpose()) - H).norm(), 1e-13 * H.norm());  // blocks (s, t), (t, s) summed apart
        test::Random random(5);
        for (int trial = 0; trial < 3; ++trial) {
            VecX d(E.size()), Hd;
            for (Eigen::Index i = 0; i < d.size(); ++i) d[i] = random.uniform(-1.0, 1.0);
            E.hessian_multiply(d, Hd);
            EXPECT_LT((H * d - Hd).norm(), 1e-12 * Hd.norm()) << "trial " << trial;
        }
        VecX diagonal;
        E.hessian_diagonal(diagonal);
        EXPECT_LT((VecX(H.diagonal()) - diagonal).norm(), 1e-12 * diagonal.norm());

        NewtonOptions options;
        options.tolerance = 1e-9;
        options.residual_mass = E.residual_mass();
        options.cg_tolerance = 1e-6;
        VecX v_pcg = E.v_star(), v_cholesky = E.v_star();
        E.set_assemble(false);
        const NewtonStats pcg = minimize(E, v_pcg, options);
        E.set_assemble(true);
        options.linear_solver = NewtonOptions::LinearSolver::Cholesky;
        const NewtonStats cholesky = minimize(E, v_cholesky, options);
        EXPECT_TRUE(pcg.converged && cholesky.converged);
        EXPECT_GT(cholesky.factorizations, 0);
        EXPECT_EQ(cholesky.cg_iterations, 0);
        EXPECT_LT((v_pcg - v_cholesky).lpNorm<Eigen::Infinity>(), 1e-6);

        // PCG preconditioned by the incomplete Cholesky of the assembled Hessian: the same minimum,
        // in fewer CG iterations than Jacobi.
        options.linear_solver = NewtonOptions::LinearSolver::Pcg;
        options.incomplete_cholesky = true;
        VecX v_ichol = E.v_star();
        const NewtonStats ichol = minimize(E, v_ichol, options);
        EXPECT_TRUE(ichol.converged);
        EXPECT_LT((v_pcg - v_ichol).lpNorm<Eigen::Infinity>(), 1e-6);
        EXPECT_GT(ichol.cg_iterations, 0);
        EXPECT_LT(static_cast<double>(ichol.cg_iterations) / std::max(ichol.iterations, 1),
                  static_cast<double>(pcg.cg_iterations) / std::max(pcg.iterations, 1));

        // The multigrid's assembly, node by node from the pair blocks, is the triplets' matrix
        // (transposed: H's rows as columns).
        E.value_gradient_hessian(f.v, g);
        SparseMatrix by_nodes;
        E.assemble_by_nodes(by_nodes);
        EXPECT_LT((SparseMatrix(by_nodes.transpose()) - *E.hessian_matrix()).norm(), 1e-13 * H.norm());

        // PCG preconditioned by the grid multigrid (built at the step's first Hessian, kept): the
        // same minimum, in fewer CG iterations than Jacobi.
        options.incomplete_cholesky = false;
        E.set_assemble(false);
        MultigridOptions coarse_early;
        coarse_early.coarsest_nodes = 24;  // a tiny scene's grid: coarsen it all the same
        E.set_multigrid(true, false, coarse_early);
        // A Hessian pass alone builds nothing (a step that converges without a linear solve, a body
        // in free fall, pays for no hierarchy); the first preconditioner application builds it.
        E.value_gradient_hessian(f.v, g);
        EXPECT_FALSE(E.multigrid().ready());
        VecX z;
        E.apply_preconditioner(g, z);
        EXPECT_TRUE(E.multigrid().ready());
        EXPECT_TRUE(z.allFinite());
        EXPECT_GT(g.dot(z), 0.0);  // M^-1 is positive definite
        VecX v_multigrid = E.v_star();
        const NewtonStats multigrid = minimize(E, v_multigrid, options);
        const int levels = E.multigrid().levels();
        E.set_multigrid(false);
        EXPECT_TRUE(multigrid.converged);
        EXPECT_GE(levels, 2);
        EXPECT_LT((v_pcg - v_multigrid).lpNorm<Eigen::Infinity>(), 1e-6);
        EXPECT_LT(static_cast<double>(multigrid.cg_iterations) / std::max(multigrid.iterations, 1),
                  static_cast<double>(pcg.cg_iterations) / std::max(pcg.iterations, 1));
        std::cout << "CG iterations per Newton iteration: Jacobi "
                  << static_cast<double>(pcg.cg_iterations) / std::max(pcg.iterations, 1) << ", incomplete Cholesky "
                  << static_cast<double>(ichol.cg_iterations) / std::max(ichol.iterations, 1) << ", multigrid "
                  << static_cast<double>(multigrid.cg_iterations) / std::max(multigrid.iterations, 1) << " ("
                  << levels << " levels)\n";
    }
}

/// Records E at every value_gradient() call: with the line search, the energies
/// of accepted iterates.
template <int dim>
class RecordingObjective final : public Objective {
public:
    explicit RecordingObjective(IncrementalPotential<dim>& inner) : inner_(inner) {}
    Eigen::Index size() const override { return inner_.size(); }
    double value(const VecX& x) override { return inner_.value(x); }
    double value_gradient(const VecX& x, VecX& g) override {
        energies.push_back(inner_.value_gradient(x, g));
        return energies.back();
    }
    void prepare_hessian(const VecX& x) override { inner_.prepare_hessian(x); }
    void hessian_multiply(const VecX& d, VecX& out) const override { inner_.hessian_multiply(d, out); }
    void hessian_diagonal(VecX& d) const override { inner_.hessian_diagonal(d); }
    std::vector<double> energies;

private:
    IncrementalPotential<dim>& inner_;
};

TYPED_TEST(ImplicitTest, EveryNewtonStepLowersTheEnergy) {
    constexpr int dim = TypeParam::value;
    for (const bool neural : {false, true}) {
        SCOPED_TRACE(neural ? "plasticitynet energy" : "elastic energy");
        PotentialFixture<dim> f(scene_name<dim>("snowball"), neural, 2e-3);
        RecordingObjective<dim> recorder(*f.potential);
        NewtonOptions options;
        options.tolerance = 1e-9;
        options.residual_scale = f.potential->residual_scale();
        VecX v = f.potential->v_star();
        const NewtonStats stats = minimize(recorder, v, options, "test");
        EXPECT_TRUE(stats.converged || stats.roundoff_floor);
        ASSERT_GE(recorder.energies.size(), 3u) << "a few Newton steps were taken";
        for (std::size_t k = 1; k < recorder.energies.size(); ++k)
            EXPECT_LE(recorder.energies[k], recorder.energies[k - 1] + 1e-12 * std::abs(recorder.energies[k - 1]))
                << "step " << k;
    }
}

// The fixed point on F0 (paper eq. 10) with each acceleration of issue 19 -- later solves from the kept
// Hessian, Anderson over 3 iterates, inexact inner solves while F0 moves -- reaches the plain
// iteration's self-consistent solution: F(v) = F0 to the tolerance, the last solve converged to the
// Newton tolerance itself, v within the tolerances of the plain iteration's.
TYPED_TEST(ImplicitTest, FixedPointAccelerationsReachThePlainIterationsSolution) {
    constexpr int dim = TypeParam::value;
    PotentialFixture<dim> f(scene_name<dim>("sand_column"), true, 2e-3);
    IncrementalPotential<dim>& E = *f.potential;
    NewtonOptions newton;
    newton.tolerance = 1e-6;
    newton.cg_tolerance = 1e-3;
    newton.lazy_hessian = 0.5;
    newton.residual_mass = E.residual_mass();
    struct Variant {
        const char* name;
        bool keep;
        int anderson;
        double inexact;  // forcing of the inner solves
    };
    const Variant variants[] = {{"plain", false, 0, 0.0},
                                {"kept Hessian", true, 0, 0.0},
                                {"Anderson 3", false, 3, 0.0},
                                {"inexact", false, 0, 0.1},
                                {"all three", true, 3, 0.1}};
    VecX v_plain;
    int plain_solves = 0;
    for (const Variant& variant : variants) {
        SCOPED_TRACE(variant.name);
        ReferenceSolveOptions options;
        options.fixed_point = true;
        options.outer = OuterIteration::FixedPoint;  // the paper's eq. 10 and its accelerations
        options.max_solves = 30;
        options.tolerance = 1e-7;
        options.keep_hessian = variant.keep;
        options.anderson_depth = variant.anderson;
        options.inexact_forcing = variant.inexact;
        ReferenceSolveWork<dim> work;
        VecX v = E.v_star();
        const ReferenceSolveStats stats = solve_with_reference<dim>(E, v, newton, options, "test", work);
        EXPECT_TRUE(stats.fixed_point_converged) << "change " << stats.change;
        EXPECT_TRUE(stats.converged);
        EXPECT_LE(stats.residual, newton.tolerance) << "the last solve met the Newton tolerance";
        EXPECT_LE(stats.change, options.tolerance);
        // F(v) is the reference the energy holds: the fixed point is self-consistent at the returned v.
        std::vector<Mat<dim>> F;
        E.deformation(v, F);
        double change = 0.0;
        for (std::size_t p = 0; p < F.size(); ++p) change = std::max(change, (F[p] - work.F0[p]).norm());
        if (variant.anderson == 0) {
            EXPECT_LE(change, options.tolerance);
        }
        if (v_plain.size() == 0) {
            v_plain = v;
            plain_solves = stats.solves;
            EXPECT_GE(plain_solves, 3) << "the fixed point needs several solves here, or the test shows nothing";
        } else {
            EXPECT_LT((v - v_plain).lpNorm<Eigen::Infinity>(), 1e-4 * std::max(1.0, v_plain.lpNorm<Eigen::Infinity>()));
        }
    }
}

template <int dim>
IntegratorSettings implicit_settings(const std::string& name, const Scene& scene, double model_scale) {
    IntegratorSettings s;
    s.name = name;
    s.dt = 1e-3;
    if (name == "plasticitynet") s.models = {memory_model<dim>(scene.objects[0].material, model_scale)};
    return s;
}

// Without plasticity and with N = 0, Psi(F; F0) = Ptilde(F0) : F + w mu/2 |F - F0|^2
// (+ const): at a converged fixed point F0 = F(v) its gradient is the elastic
// P(F(v)), so plasticitynet must solve the same equations as lagged.
TYPED_TEST(ImplicitTest, PlasticityNetEqualsLaggedWithoutPlasticity) {
    constexpr int dim = TypeParam::value;
    Scene scene = tiny_scene(scene_name<dim>("sand_column"));
    scene.objects[0].material.plasticity = PlasticityModel::None;
    scene.objects[0].material.elasticity = ElasticityModel::StvkHencky;
    IntegratorSettings lagged = implicit_settings<dim>("lagged", scene, 0.0);
    lagged.implicit.newton_tolerance = 1e-10;
    Simulation<dim> a(scene, lagged);
    a.advance_frame();
    // Both outer iterations: the paper's fixed point (several solves per step) and the reference
    // following every Newton iterate (one solve, several updates of F0).
    for (const char* outer : {"fixed_point", "newton"}) {
        SCOPED_TRACE(outer);
        IntegratorSettings net = implicit_settings<dim>("plasticitynet", scene, 0.0);
        net.implicit.newton_tolerance = 1e-10;
        net.implicit.fixed_point_tolerance = 1e-11;
        net.implicit.max_fixed_point_iterations = 200;
        net.implicit.outer_iteration = outer;
        Simulation<dim> b(scene, net);
        const FrameStats fb = b.advance_frame();
        if (std::string(outer) == "fixed_point") {
            EXPECT_GT(fb.fixed_point_iterations, fb.steps) << "the fixed point needs more than one solve per step";
        } else {
            EXPECT_EQ(fb.fixed_point_iterations, fb.steps) << "one solve per step";
            long updates = 0;
            for (const StepRecord& st : b.last_frame_steps()) updates += st.reference_updates;
            EXPECT_GT(updates, fb.steps) << "F0 followed the iterates";
        }
        double worst = 0.0, motion = 0.0;
        for (std::size_t p = 0; p < a.particles().size(); ++p) {
            worst = std::max(worst, (a.particles().x[p] - b.particles().x[p]).norm());
            motion = std::max(motion, a.particles().v[p].norm());
        }
        EXPECT_GT(motion, 0.01) << "the column sags";
        EXPECT_LT(worst, 1e-9) << "m, after a frame of 20 steps";
    }
    // With a real (random) network the two differ: the comparison is not vacuous.
    IntegratorSettings random_net = implicit_settings<dim>("plasticitynet", scene, 1.0);
    Simulation<dim> c(scene, random_net);
    c.advance_frame();
    double differ = 0.0;
    for (std::size_t p = 0; p < a.particles().size(); ++p)
        differ = std::max(differ, (a.particles().x[p] - c.particles().x[p]).norm());
    EXPECT_GT(differ, 1e-6);
}

using test::identical;

TYPED_TEST(ImplicitTest, OneAndTwoThreadsGiveIdenticalResults) {
    constexpr int dim = TypeParam::value;
    const int saved = omp_get_max_threads();
    for (const std::string variant : {"plasticitynet", "return_map", "lagged", "plasticitynet bdf2"}) {
        SCOPED_TRACE(variant);
        const Scene scene = tiny_scene(scene_name<dim>("sand_column"));
        IntegratorSettings settings = implicit_settings<dim>(variant.substr(0, variant.find(' ')), scene, 0.3);
        if (variant.find("bdf2") != std::string::npos) settings.implicit.time_integrator = "bdf2";
        omp_set_num_threads(1);
        Simulation<dim> one(scene, settings);
        const FrameStats stats = one.advance_frame();
        omp_set_num_threads(2);
        Simulation<dim> two(scene, settings);
        two.advance_frame();
        EXPECT_TRUE(identical(one.particles(), two.particles()));
        EXPECT_GT(stats.newton_iterations, 0);
    }
    omp_set_num_threads(saved);
}

// The Krylov method of a Hessian with a skew part (ImplicitOptions::nonsymmetric_solver: sand's tangent and
// its Coulomb floor under return_map): GMRES and BiCGSTAB solve the same steps, each to the Newton tolerance,
// and GMRES takes fewer Hessian products per Newton iteration (measured on the shipped scenes:
// docs/solver.md, "GMRES for the tangent's skew part").
TYPED_TEST(ImplicitTest, GmresAndBicgstabSolveTheSameStepsGmresInFewerProducts) {
    constexpr int dim = TypeParam::value;
    const Scene scene = tiny_scene(scene_name<dim>("sand_column"));
    IntegratorSettings settings = implicit_settings<dim>("return_map", scene, 0.3);
    settings.implicit.newton_tolerance = 1e-6;  // the two paths' stopping points within 1e-6 m/s of the step
    settings.implicit.newton_acceleration_tolerance = 0.0;
    settings.implicit.nonsymmetric_solver = "gmres";
    Simulation<dim> gmres(scene, settings);
    settings.implicit.nonsymmetric_solver = "bicgstab";
    Simulation<dim> bicgstab(scene, settings);
    long newton[2] = {0, 0}, products[2] = {0, 0};
    for (int f = 0; f < 2; ++f) {
        const FrameStats a = gmres.advance_frame(), b = bicgstab.advance_frame();
        EXPECT_EQ(a.unconverged_steps + b.unconverged_steps, 0);
        newton[0] += a.newton_iterations;
        products[0] += a.cg_iterations;
        newton[1] += b.newton_iterations;
        products[1] += b.cg_iterations;
    }
    double worst = 0.0;
    for (std::size_t p = 0; p < gmres.particles().size(); ++p)
        worst = std::max(worst, (gmres.particles().x[p] - bicgstab.particles().x[p]).norm());
    const double gmres_rate = static_cast<double>(products[0]) / newton[0];
    const double bicgstab_rate = static_cast<double>(products[1]) / newton[1];
    std::cout << "products per Newton iteration: GMRES " << gmres_rate << " (" << newton[0] << " iterations), BiCGSTAB "
              << bicgstab_rate << " (" << newton[1] << "); positions within " << worst << " m\n";
    EXPECT_GT(newton[0], 0);
    EXPECT_LT(worst, 1e-6) << "m after two frames";
    EXPECT_LT(gmres_rate, bicgstab_rate);
}

TYPED_TEST(ImplicitTest, CheckpointResumeEqualsAnUninterruptedRun) {
    constexpr int dim = TypeParam::value;
    test::TempDir dir;
    // bdf2: the history resumes; at 0.7 ms a frame ends on a clipped step of 0.4 ms, so the resumed run's
    // first step (a step ratio of 1.75) needs the last step's dt from the checkpoint.
    for (const std::string variant :
         {"plasticitynet", "return_map", "lagged", "lagged bdf2", "lagged bdf2 clipped"}) {
        SCOPED_TRACE(variant);
        const std::string integrator = variant.substr(0, variant.find(' '));
        const Scene scene = tiny_scene(scene_name<dim>("sand_column"));
        IntegratorSettings settings = implicit_settings<dim>(integrator, scene, 0.3);
        if (variant.find("bdf2") != std::string::npos) settings.implicit.time_integrator = "bdf2";
        if (variant == "lagged bdf2 clipped") settings.dt = 7e-4;
        Simulation<dim> full(scene, settings);
        full.advance_frame();
        full.advance_frame();
        Simulation<dim> first(scene, settings);
        first.advance_frame();
        const std::string path = dir.file(std::to_string(variant.size()) + integrator + ".bin");
        first.save_checkpoint(path);
        Simulation<dim> resumed(scene, settings);
        resumed.load_checkpoint(path);
        EXPECT_EQ(resumed.frame(), 1);
        resumed.advance_frame();
        EXPECT_TRUE(identical(full.particles(), resumed.particles()));
        // A checkpoint of another integrator is refused.
        IntegratorSettings other = settings;
        other.name = other.name == "lagged" ? "explicit" : "lagged";
        Simulation<dim> wrong(scene, other);
        try {
            wrong.load_checkpoint(path);
            ADD_FAILURE() << "a checkpoint of another integrator was accepted";
        } catch (const std::invalid_argument& e) {
            EXPECT_NE(std::string(e.what()).find("written by the " + std::string(integrator)), std::string::npos)
                << e.what();
        }
    }
}

TYPED_TEST(ImplicitTest, EveryTinySceneRunsWithEveryImplicitIntegrator) {
    constexpr int dim = TypeParam::value;
    for (const char* stem : {"sand_column", "snowball"})
        for (const char* integrator : {"plasticitynet", "return_map", "lagged"}) {
            SCOPED_TRACE(std::string(stem) + " " + integrator);
            const Scene scene = tiny_scene(scene_name<dim>(stem));
            Simulation<dim> sim(scene, implicit_settings<dim>(integrator, scene, 0.3));
            const FrameStats stats = sim.advance_frame();
            EXPECT_EQ(stats.steps, 20);
            EXPECT_TRUE(stats.converged);
            // The snowball falls freely in its first frame: v* is already the minimizer.
            if (std::string(stem) == "sand_column") {
                EXPECT_GT(stats.newton_iterations, 0);
            }
            EXPECT_EQ(sim.last_frame_steps().size(), 20u);
            for (const Vec<dim>& x : sim.particles().x) ASSERT_TRUE(x.allFinite());
        }
}

// The integrator block's keys of every layer (the solver's, MPM's, FEM's) are read by one reader
// (IntegratorSettings::read_options over integrator_option_fields()).
TEST(IntegratorSettings, ReadsAndValidatesTheIntegratorBlock) {
    const nlohmann::json ok = {{"name", "plasticitynet"},
                               {"dt", 1e-3},
                               {"newton_tolerance", 1e-4},
                               {"max_fixed_point_iterations", 3},
                               {"regularizer_weight", 0},
                               {"tangent_damping", 0.1},
                               {"preconditioner", "block_jacobi"},
                               {"lazy_hessian", 0},
                               {"max_kinematic_stages", 5},
                               {"fail_on_unconverged", true},
                               {"fixed_point_anderson", 2},
                               {"fixed_point_keep_hessian", false},
                               {"advection_cfl", 0.25}};
    IntegratorSettings settings;
    settings.read_options(ok, "s.json");
    const ImplicitOptions& o = settings.implicit;
    EXPECT_EQ(settings.mpm.advection_cfl, 0.25);
    EXPECT_EQ(MpmOptions{}.advection_cfl, 0.2) << "on by default";
    EXPECT_EQ(o.preconditioner, "block_jacobi");
    EXPECT_EQ(o.lazy_hessian, 0.0);
    EXPECT_EQ(settings.fem.max_kinematic_stages, 5);
    EXPECT_TRUE(o.fail_on_unconverged);
    EXPECT_EQ(o.fixed_point_anderson, 2);
    EXPECT_FALSE(o.fixed_point_keep_hessian);
    // The lazy Hessian's "auto" (the default) is the integrator's measured value; a number overrides it.
    EXPECT_EQ(ImplicitOptions{}.lazy_hessian, -1.0);
    EXPECT_EQ(ImplicitOptions{}.newton_options(1e-3, Method::PlasticityNet).lazy_hessian, 0.8);
    EXPECT_EQ(ImplicitOptions{}.newton_options(1e-3, Method::ReturnMap).lazy_hessian, 0.1);
    EXPECT_EQ(ImplicitOptions{}.newton_options(1e-3, Method::Lagged).lazy_hessian, 0.5);
    EXPECT_EQ(o.newton_options(1e-3, Method::PlasticityNet).lazy_hessian, 0.0);
    EXPECT_EQ(ImplicitOptions::from_json({{"lazy_hessian", "auto"}}, "s.json").lazy_hessian, -1.0);
    EXPECT_EQ(ImplicitOptions{}.to_json()["lazy_hessian"], "auto");
    EXPECT_TRUE(ImplicitOptions{}.fixed_point_keep_hessian);
    EXPECT_EQ(ImplicitOptions{}.fixed_point_anderson, 0);
    EXPECT_EQ(ImplicitOptions{}.fixed_point_inexact, 0.0);
    EXPECT_EQ(ImplicitOptions::from_json(o.to_json(), "s.json").to_json(), o.to_json());
    IntegratorSettings again;
    again.read_options(settings.options_json(), "s.json");
    EXPECT_EQ(again.options_json(), settings.options_json());
    // A layer's own reader knows its keys only: the solver's refuses MPM's.
    EXPECT_THROW(ImplicitOptions::from_json({{"advection_cfl", 0.25}}, "s.json"), std::invalid_argument);
    EXPECT_EQ(o.newton_tolerance, 1e-4);
    EXPECT_EQ(o.max_fixed_point_iterations, 3);
    EXPECT_EQ(o.regularizer_weight, 0.0);
    EXPECT_EQ(o.tangent_damping, 0.1);
    EXPECT_EQ(ImplicitOptions{}.tangent_damping, 0.3);
    auto message = [](const nlohmann::json& block) {
        try {
            IntegratorSettings{}.read_options(block, "s.json");
        } catch (const std::invalid_argument& e) {
            return std::string(e.what());
        }
        return std::string("accepted");
    };
    // A bad value is refused naming the file, the key and what the key expects.
    const std::vector<std::pair<nlohmann::json, std::string>> refused = {
        {{{"newton_tolerance", -1}}, "s.json: integrator.newton_tolerance: expected a positive number (m/s), got -1"},
        {{{"lazy_hessian", 1}}, "s.json: integrator.lazy_hessian: expected a number in [0, 1) or \"auto\", got 1"},
        {{{"fixed_point_inexact", 1.0}},
         "s.json: integrator.fixed_point_inexact: expected a number in [0, 1), got 1.0"},
        {{{"preconditioner", "ilu"}},
         "s.json: integrator.preconditioner: expected \"jacobi\", \"block_jacobi\", \"ichol\" or \"multigrid\", got \"ilu\""},
        {{{"max_fixed_point_iterations", 1.5}},
         "s.json: integrator.max_fixed_point_iterations: expected an integer >= 1, got 1.5"},
        {{{"cg_tolerance", 2}}, "s.json: integrator.cg_tolerance: expected a number in (0, 1), got 2"},
        {{{"fixed_point_keep_hessian", "yes"}},
         "s.json: integrator.fixed_point_keep_hessian: expected true or false, got \"yes\""},
        {{{"fail_on_unconverged", 1}}, "s.json: integrator.fail_on_unconverged: expected true or false, got 1"},
        {{{"advection_cfl", 1.5}}, "s.json: integrator.advection_cfl: expected a number in [0, 1], got 1.5"},
        {{{"advection_cfl", -0.1}}, "s.json: integrator.advection_cfl: expected a number in [0, 1], got -0.1"},
        {{{"regularizer_weight", "one"}},
         "s.json: integrator.regularizer_weight: expected a number >= 0 or \"auto\", got \"one\""},
        {{{"tangent_damping", -0.5}}, "s.json: integrator.tangent_damping: expected a number >= 0, got -0.5"},
    };
    for (const auto& [block, expected] : refused) EXPECT_EQ(message(block), expected) << block.dump();
    // A key that is no option is refused, naming the known ones (it was silently ignored).
    const std::string unknown = message({{"newton_tol", 1e-4}});
    EXPECT_EQ(unknown.rfind("s.json: integrator.newton_tol: unknown key (known: name, dt, cfl, newton_tolerance, ", 0), 0u)
        << unknown;
    EXPECT_EQ(message({{"name", "lagged"}, {"dt", 1e-3}, {"cfl", 0.5}}), "accepted");
}

// Every option is declared once, in its layer's table (integrator_option_fields() joins them):
// options_json holds exactly their keys, each field reads back what it writes, keys and flags are
// unique across the layers, and each flag's words parse to values the scene reader accepts.
TEST(IntegratorSettings, EveryOptionIsDeclaredOnceAndItsFlagParsesToAnAcceptedValue) {
    const IntegratorSettings defaults;
    const nlohmann::json j = defaults.options_json();
    std::set<std::string> keys, flags;
    for (const OptionField<IntegratorSettings>& f : integrator_option_fields()) {
        EXPECT_TRUE(keys.insert(f.key).second) << f.key;
        if (f.flag) {
            EXPECT_TRUE(flags.insert(f.flag).second) << f.flag;
        }
        ASSERT_TRUE(j.contains(f.key)) << f.key;
        EXPECT_TRUE(f.accepts(j[f.key])) << f.key << " default " << j[f.key].dump();
        EXPECT_EQ(find_option_field(f.key), &f);
        if (f.flag) {
            EXPECT_EQ(find_option_field(f.flag), &f);
        }
        IntegratorSettings o;
        f.set(o, j[f.key]);
        EXPECT_EQ(f.get(o), j[f.key]) << f.key;
    }
    EXPECT_EQ(keys.size(), j.size());
    EXPECT_EQ(keys.size(), implicit_option_fields().size() + mpm_option_fields().size() + fem_option_fields().size() +
                               coupling_option_fields().size());
    const OptionSpec& tol = *find_option_field("--newton-tol");
    EXPECT_EQ(tol.parse_flag("1e-4"), nlohmann::json(1e-4));
    EXPECT_FALSE(tol.parse_flag("-1"));
    EXPECT_FALSE(tol.parse_flag("nan"));
    EXPECT_FALSE(tol.parse_flag("1e-4x"));
    EXPECT_EQ(find_option_field("--fixed-point-iterations")->parse_flag("3"), nlohmann::json(3));
    EXPECT_FALSE(find_option_field("--fixed-point-iterations")->parse_flag("2.5"));
    EXPECT_EQ(find_option_field("--return-map")->parse_flag("exact"), nlohmann::json(false));
    EXPECT_EQ(find_option_field("--regularizer")->parse_flag("auto"), nlohmann::json("auto"));
    EXPECT_FALSE(find_option_field("--preconditioner")->parse_flag("ilu"));
    EXPECT_EQ(find_option_field("--preconditioner")->flag_expected(), "jacobi, block_jacobi, ichol or multigrid");
}

TEST(NeuralParticleEnergy, RefusesMissingAndMismatchedModels) {
    const Scene scene = tiny_scene("sand_column_2d");
    const MpmSystem<2> system = make_mpm_system<2>(scene);
    auto message = [&](std::shared_ptr<const ModelFile> model) {
        try {
            NeuralParticleEnergy<2>({model}, system.materials, {"s.json: objects[0].model"}, 1.0);
        } catch (const std::invalid_argument& e) {
            return std::string(e.what());
        }
        return std::string("accepted");
    };
    EXPECT_EQ(message(memory_model<2>(scene.objects[0].material, 1.0)), "accepted");
    EXPECT_NE(message(nullptr).find("s.json: objects[0].model: the plasticitynet integrator needs an energy model"),
              std::string::npos);
    EXPECT_NE(message(memory_model<2>(material_preset("snow"), 1.0))
                  .find("<in-memory test model> was trained for material.elasticity.model = \"neo_hookean_snow\", "
                        "the object's material has \"stvk_hencky\""),
              std::string::npos);
    EXPECT_NE(message(memory_model<3>(scene.objects[0].material, 1.0)).find("s.json: objects[0].model:"),
              std::string::npos);
}

// The Auto Hessian resolves to the consistent tangent, undamped for von Mises (its tangent is the
// Jacobian) and damped by tangent_damping for non-associative sand and snow, whatever the scene's
// regularizer weight; an explicit choice keeps that weight. Only Auto's tangent of non-associative
// flow keeps its skew part (a non-symmetric Hessian).
TEST(NeuralParticleEnergy, TheAutoHessianDampsOnlyNonAssociativeFlowByTheTangentDamping) {
    using Hessian = NeuralElastoplasticEnergy<2>::Options::Hessian;
    auto resolved = [](const char* preset, Hessian hessian, double tangent_damping) {
        const MaterialDescription material = material_preset(preset);
        const std::vector<Material<2>> materials = {Material<2>(material)};
        NeuralParticleEnergy<2> energy({memory_model<2>(material, 1.0)}, materials, {"s.json: objects[0].model"},
                                       /*regularizer_weight=*/1.0, hessian, tangent_damping);
        const NeuralElastoplasticEnergy<2>& object = energy.object_energy(0);
        EXPECT_EQ(object.hessian_kind(), hessian == Hessian::Network ? Hessian::Network : Hessian::Tangent);
        const bool skew = hessian == Hessian::Auto && material.plasticity != PlasticityModel::VonMises;
        EXPECT_EQ(energy.symmetric_hessian(), !skew) << preset;
        EXPECT_EQ(object.symmetric_hessian(), !skew) << preset;
        return object.regularizer_weight();
    };
    EXPECT_EQ(resolved("sand", Hessian::Auto, 0.3), 0.3);
    EXPECT_EQ(resolved("snow", Hessian::Auto, 0.1), 0.1);
    EXPECT_EQ(resolved("metal", Hessian::Auto, 0.3), 0.0);
    EXPECT_EQ(resolved("sand", Hessian::Tangent, 0.3), 1.0);
    EXPECT_EQ(resolved("sand", Hessian::Network, 0.3), 1.0);
    EXPECT_EQ(kDefaultTangentDamping, 0.3);
}

// A model is used only for the material it was trained for: every plasticity
// parameter is compared, not only the models and nu (a 35 deg sand scene with a
// 30 deg model would mix both angles, one in c and one in G2P).
TEST(NeuralParticleEnergy, RefusesModelsTrainedForOtherPlasticityParameters) {
    auto message = [](const MaterialDescription& trained, const MaterialDescription& scene) {
        const std::vector<Material<2>> materials = {Material<2>(scene)};
        try {
            NeuralParticleEnergy<2>({memory_model<2>(trained, 1.0)}, materials, {"s.json: objects[0].model"}, 1.0);
        } catch (const std::invalid_argument& e) {
            return std::string(e.what());
        }
        return std::string("accepted");
    };
    const MaterialDescription sand = material_preset("sand"), snow = material_preset("snow");
    MaterialDescription other = sand;
    other.elastic.E *= 7.0;  // E is scaled, density and the initial state are not the model's
    other.density *= 2.0;
    EXPECT_EQ(message(sand, other), "accepted");
    other = sand;
    other.drucker_prager.friction_angle_deg = 35.0;
    EXPECT_EQ(message(sand, other),
              "s.json: objects[0].model: <in-memory test model> was trained for material.plasticity.friction_angle_deg "
              "= 30.0, the object's material has 35.0 (a model is used only for the material it was trained for)");
    struct Case {
        const char* field;
        void (*change)(MaterialDescription&);
    };
    const Case cases[] = {
        {"plasticity.friction_angle_deg", [](MaterialDescription& m) { m.cam_clay.friction_angle_deg = 40.0; }},
        {"plasticity.xi", [](MaterialDescription& m) { m.cam_clay.xi = 0.7; }},
        {"plasticity.beta", [](MaterialDescription& m) { m.cam_clay.beta = 0.2; }},
        {"plasticity.variant", [](MaterialDescription& m) { m.cam_clay.variant = CamClayVariant::Paper; }},
        {"elasticity.nu", [](MaterialDescription& m) { m.elastic.nu = 0.25; }},
    };
    for (const Case& c : cases) {
        MaterialDescription scene = snow;
        c.change(scene);
        const std::string what = message(snow, scene);
        EXPECT_NE(what.find(std::string("was trained for material.") + c.field + " = "), std::string::npos) << what;
    }
    const MaterialDescription metal = material_preset("metal");
    MaterialDescription harder = metal;
    harder.von_mises.hardening_coefficient = 0.2;
    EXPECT_EQ(constitutive_differences(metal, harder).size(), 1u);
    EXPECT_EQ(constitutive_differences(metal, harder)[0].field, "plasticity.hardening_coefficient");
}

// A parametric model (issue 36) takes the object's parameters, each within the range it was trained
// for, and refuses a value outside naming the field and the range; every other constitutive field must
// still be the model's. Its energy is exact at F0 for the object's material, not the reference's.
TEST(NeuralParticleEnergy, ParametricModelsTakeTheObjectsParametersWithinTheirRanges) {
    const MaterialDescription sand = material_preset("sand");
    auto model = std::make_shared<ModelFile>(*memory_model<2>(sand, 1.0));
    model->metadata.representation = EnergyRepresentation::Principal;
    model->metadata.parameters = {{"plasticity.friction_angle_deg", 20.0, 45.0}, {"elasticity.nu", 0.2, 0.45}};
    model->metadata.widths = {8, 32, 32, 32, 1};
    model->weights = random_mlp(model->metadata.widths, 7, 1.0);
    auto message = [&](const MaterialDescription& scene) {
        const std::vector<Material<2>> materials = {Material<2>(scene)};
        try {
            NeuralParticleEnergy<2>({model}, materials, {"s.json: objects[0].model"}, 1.0);
        } catch (const std::invalid_argument& e) {
            return std::string(e.what());
        }
        return std::string("accepted");
    };
    MaterialDescription other = sand;
    other.drucker_prager.friction_angle_deg = 45.0;  // the ends of the ranges are inside
    other.elastic.nu = 0.2;
    EXPECT_EQ(message(other), "accepted");
    other.drucker_prager.friction_angle_deg = 50.0;
    EXPECT_EQ(message(other), "s.json: objects[0].model: <in-memory test model>: material.plasticity.friction_angle_deg "
                              "= 50.0 is outside the range [20.0, 45.0] this parametric model was trained for");
    other = sand;
    other.elastic.nu = 0.1;
    EXPECT_EQ(message(other), "s.json: objects[0].model: <in-memory test model>: material.elasticity.nu = 0.1 is "
                              "outside the range [0.2, 0.45] this parametric model was trained for");
    EXPECT_NE(message(material_preset("snow")).find("was trained for material.elasticity.model = \"stvk_hencky\""),
              std::string::npos);

    // grad Psi(F0) = E Ptilde(F0) of the object's material at 25 deg and nu 0.4, and the network sees
    // those parameters: the gradient away from F0 differs from the 40 deg object's.
    auto gradients = [&](double angle, double nu, const Mat<2>& F0, const Mat<2>& F) {
        MaterialDescription object = sand;
        object.drucker_prager.friction_angle_deg = angle;
        object.elastic.nu = nu;
        typename NeuralElastoplasticEnergy<2>::Options options;
        options.youngs_modulus = object.elastic.E;
        options.material = object;
        NeuralElastoplasticEnergy<2> energy(*model, options);
        energy.set_reference(&F0, nullptr, 1);
        double psi = 0.0;
        std::array<Mat<2>, 2> g;
        energy.value_gradient(&F0, &psi, &g[0]);
        energy.value_gradient(&F, &psi, &g[1]);
        return std::pair{g, Material<2>(object).elastoplastic_stress(F0, 0.0)};
    };
    Mat<2> F0, F;
    F0 << 0.8, 0.05, 0.0, 1.1;  // sheared: on the 25 deg cone, inside the 40 deg one
    F << 0.82, 0.03, 0.02, 1.09;
    const auto [g25, P25] = gradients(25.0, 0.4, F0, F);
    const auto [g40, P40] = gradients(40.0, 0.4, F0, F);
    EXPECT_LT((g25[0] - P25).norm(), 1e-9 * P25.norm());
    EXPECT_LT((g40[0] - P40).norm(), 1e-9 * P40.norm());
    EXPECT_GT((P25 - P40).norm(), 1e-3 * P25.norm());  // the two materials differ at F0
    EXPECT_GT(((g25[1] - P25) - (g40[1] - P40)).norm(), 1e-6 * P25.norm());  // and so does the network's part
}

// --- Implicit against explicit ---------------------------------------------------

/// An elastic box (StVK-Hencky, no plasticity, E = 1e4 Pa, rho = 1000 kg/m^3: CFL step ~4e-3 s at
/// dx = 1/32 m) moving at `velocity`, with `gravity` and a sticky floor of `floor_cells` cells.
template <int dim>
Scene elastic_box(const std::vector<double>& lo, const std::vector<double>& hi, const std::vector<double>& velocity,
                  double gravity, int floor_cells, double floor_friction = -1.0, double E = 1e4) {
    std::vector<double> g(dim, 0.0);
    g[1] = gravity;
    const nlohmann::json j = {
        {"name", "elastic_box"},
        {"dim", dim},
        {"domain", {{"min", std::vector<double>(dim, 0.0)}, {"max", std::vector<double>(dim, 1.0)}}},
        {"dx", 1.0 / 32},
        {"gravity", g},
        {"frame_dt", 0.02},
        {"frames", 4},
        {"particles_per_cell", 2},
        {"boundary", floor_friction < 0.0 ? nlohmann::json{{"walls", "slip"}, {"sticky_floor_cells", floor_cells}}
                                          : nlohmann::json{{"walls", "slip"}, {"sticky_floor_cells", floor_cells},
                                                           {"floor_friction", floor_friction}}},
        {"objects",
         {{{"shape", "box"},
           {"min", lo},
           {"max", hi},
           {"velocity", velocity},
           {"material",
            {{"name", "jelly"},
             {"density", 1000},
             {"elasticity", {{"model", "stvk_hencky"}, {"E", E}, {"nu", 0.3}}},
             {"plasticity", {{"model", "none"}}}}}}}}};
    return scene_from_json(j, "elastic_box.json", ".");
}

/// Largest particle distance (m) between an explicit and a lagged run of `frames` frames at dt.
template <int dim>
double explicit_lagged_distance(const Scene& scene, double dt, int frames, double* motion) {
    IntegratorSettings ex, im;
    ex.name = "explicit";
    im.name = "lagged";
    ex.dt = im.dt = dt;
    im.implicit.newton_tolerance = 1e-7;
    Simulation<dim> a(scene, ex), b(scene, im);
    const std::vector<Vec<dim>> start = a.particles().x;
    for (int f = 0; f < frames; ++f) {
        a.advance_frame();
        b.advance_frame();
    }
    double worst = 0.0;
    *motion = 0.0;
    for (std::size_t p = 0; p < a.particles().size(); ++p) {
        worst = std::max(worst, (a.particles().x[p] - b.particles().x[p]).norm());
        *motion = std::max(*motion, (a.particles().x[p] - start[p]).norm());
    }
    return worst;
}

// Implicit (lagged, purely elastic: the same model in both) and explicit MPM
// share transfers and boundary conditions, so at a dt far below the CFL step
// they must agree: an elastic box dropped on the sticky floor, bouncing.
TYPED_TEST(ImplicitTest, LaggedAgreesWithExplicitOnAnElasticBlockAtSmallDt) {
    constexpr int dim = TypeParam::value;
    const double s = dim == 2 ? 0.2 : 0.12;  // box size, m
    std::vector<double> lo(dim, 0.5 - s / 2), hi(dim, 0.5 + s / 2), v(dim, 0.0);
    lo[1] = 0.15;
    hi[1] = 0.15 + s;
    v[1] = -1.0;
    double motion = 0.0;
    const double worst = explicit_lagged_distance<dim>(elastic_box<dim>(lo, hi, v, -9.8, 3), 2e-4, 4, &motion);
    EXPECT_GT(motion, 0.05) << "the box falls and hits the floor";
    // Measured: 3.0e-4 m (2D) and 2.5e-4 m (3D): the O(dt) difference of the two time integrations.
    EXPECT_LT(worst, 4.5e-4) << "m: within 1.5% of a cell after 0.08 s";
}

// Slip walls act the same in both integrators (docs/methods.md): only the
// wall-ward normal velocity is removed. Holding the whole normal component
// fixed in the implicit solve (as before) ignores the elastic forces of every
// node within 3 cells of the wall.
TYPED_TEST(ImplicitTest, SlipWallsActTheSameInBothIntegrators) {
    constexpr int dim = TypeParam::value;
    const double s = dim == 2 ? 0.2 : 0.12;
    std::vector<double> lo(dim, 0.5 - s / 2), hi(dim, 0.5 + s / 2), v(dim, 0.0);
    lo[0] = 0.12;  // 1 cell from the wall band (x < 3 dx = 0.094 m)
    hi[0] = 0.12 + s;
    v[0] = -1.5;  // into the left wall, without gravity or floor
    double motion = 0.0;
    const double worst = explicit_lagged_distance<dim>(elastic_box<dim>(lo, hi, v, 0.0, 0), 2e-4, 4, &motion);
    EXPECT_GT(motion, 0.03) << "the box reaches the wall";
    // Measured: 2.5e-4 m (2D) and 2.2e-4 m (3D); with the whole normal component held fixed (the old
    // implicit walls) 1.9e-3 m and 7.3e-4 m.
    EXPECT_LT(worst, 4.5e-4) << "m: within 1.5% of a cell after 0.08 s";
}

// How far a column has spread: the deposit's mass-weighted rms horizontal distance from its centre of
// mass (metrics/deposit_shape.hpp), m.
template <int dim>
double spread_of(const Particles<dim>& particles) {
    std::vector<double> position;
    position.reserve(dim * particles.size());
    for (const Vec<dim>& x : particles.x) position.insert(position.end(), x.data(), x.data() + dim);
    return deposit_shape(dim, position, particles.mass).spread;
}

// How far a scene's column spreads (spread_of) over `frames` frames under `settings`, m.
template <int dim>
double spread_growth(const Scene& scene, const IntegratorSettings& settings, int frames) {
    Simulation<dim> sim(scene, settings);
    const double before = spread_of(sim.particles());
    for (int f = 0; f < frames; ++f) sim.advance_frame();
    return spread_of(sim.particles()) - before;
}

/// The Coulomb floor's sliding box: an elastic box (E 1e5 Pa) on the 3-cell floor layer of a dx = 1/32
/// grid, sliding along x at kSlideSpeed on a floor of friction kSlideFriction under gravity kSlideGravity.
constexpr double kSlideFriction = 0.25, kSlideSpeed = 0.7, kSlideGravity = 9.8;

template <int dim>
Scene sliding_box() {
    const double s = dim == 2 ? 0.2 : 0.12, dx = 1.0 / 32;
    std::vector<double> lo(dim, 0.5 - s / 2), hi(dim, 0.5 + s / 2), v(dim, 0.0);
    lo[0] = 0.2;
    hi[0] = 0.2 + s;
    lo[1] = 3 * dx;  // on the floor layer (3 cells)
    hi[1] = 3 * dx + s;
    v[0] = kSlideSpeed;
    return elastic_box<dim>(lo, hi, v, -kSlideGravity, 3, kSlideFriction, 1e5);
}

/// The particles' mean x.
template <int dim>
double mean_position_x(const Particles<dim>& particles) {
    double x = 0.0;
    for (const Vec<dim>& p : particles.x) x += p[0];
    return x / static_cast<double>(particles.size());
}

// The Coulomb floor (boundary.floor_friction): a box sliding at v0 on it stops after v0^2 / (2 mu g), the
// same distance for explicit MPM at two steps and for the implicit solve (the floor's friction a form of
// the potential, IncrementalPotential::floor_friction_contacts) at steps 10 and 40 times larger.
TYPED_TEST(ImplicitTest, ACoulombFloorStopsASlidingBoxAfterTheSameDistanceAtEveryStep) {
    constexpr int dim = TypeParam::value;
    constexpr double mu = kSlideFriction, v0 = kSlideSpeed, g = kSlideGravity;
    const Scene scene = sliding_box<dim>();
    auto slide = [&](const std::string& integrator, double dt) {
        IntegratorSettings settings;
        settings.name = integrator;
        settings.dt = dt;
        settings.implicit.newton_tolerance = 1e-7;
        Simulation<dim> sim(scene, settings);
        auto mean_x = [&] { return mean_position_x<dim>(sim.particles()); };
        const double start = mean_x();
        for (int f = 0; f < 20; ++f) sim.advance_frame();  // 0.4 s; it stops at v0 / (mu g) = 0.29 s
        return mean_x() - start;
    };
    const double expected = v0 * v0 / (2.0 * mu * g);  // 0.1 m
    const double fine = slide("explicit", 1e-4), coarse = slide("explicit", 4e-4);
    const double implicit = slide("lagged", 1e-3), large = slide("lagged", 4e-3);
    EXPECT_NEAR(fine, expected, 0.1 * expected);
    EXPECT_NEAR(coarse, fine, 0.03 * expected);
    EXPECT_NEAR(implicit, fine, 0.05 * expected);
    EXPECT_NEAR(large, fine, 0.1 * expected);
    std::cout << "slide (m): expected " << expected << ", explicit 1e-4 " << fine << ", 4e-4 " << coarse
              << ", lagged 1e-3 " << implicit << ", 4e-3 " << large << "\n";
}

// The Coulomb floor's friction within one solve (MpmOptions::floor_friction_solve "newton", the default):
// a step is one solve, not three passes, and the sliding box still stops after v0^2 / (2 mu g), as with
// the passes (solved to 1e-7 m/s) and as explicit MPM does. The one solve is asked for the default
// tolerance: its residual is Coulomb's law itself, which converges linearly on nodes that slide slowly
// (the majorizer's curvature in the slip), and as the box stops, 1e-5 m/s took more than 100 iterations
// at 4e-3 s (docs/solver.md, "The Coulomb floor in one solve").
TYPED_TEST(ImplicitTest, TheCoulombFloorsFrictionWithinOneSolveStopsASlidingBoxAsThePassesDo) {
    constexpr int dim = TypeParam::value;
    constexpr double mu = kSlideFriction, v0 = kSlideSpeed, g = kSlideGravity;
    const Scene scene = sliding_box<dim>();
    struct Slide {
        double distance;
        long solves, steps;
    };
    auto slide = [&](bool in_solve, double dt) {
        IntegratorSettings settings;
        settings.name = "return_map";
        settings.dt = dt;
        if (!in_solve) settings.implicit.newton_tolerance = 1e-7;
        settings.mpm.floor_friction_solve = in_solve ? "newton" : "passes";
        Simulation<dim> sim(scene, settings);
        auto mean_x = [&] { return mean_position_x<dim>(sim.particles()); };
        const double start = mean_x();
        Slide out{0.0, 0, 0};
        for (int f = 0; f < 20; ++f) {
            const FrameStats frame = sim.advance_frame();
            out.solves += frame.fixed_point_iterations;
            out.steps += frame.steps;
            EXPECT_TRUE(frame.converged) << "frame " << f << (in_solve ? ", in one solve" : ", in passes") << " at "
                                         << dt << ": residual " << frame.max_residual;
        }
        out.distance = mean_x() - start;
        return out;
    };
    const double expected = v0 * v0 / (2.0 * mu * g);  // 0.1 m
    const Slide one = slide(true, 1e-3), passes = slide(false, 1e-3), large = slide(true, 4e-3);
    std::cout << "slide (m): expected " << expected << ", return_map in one solve " << one.distance << " ("
              << static_cast<double>(one.solves) / one.steps << " solves per step), in passes " << passes.distance
              << " (" << static_cast<double>(passes.solves) / passes.steps << "), one solve at 4e-3 " << large.distance
              << "\n";
    EXPECT_EQ(one.solves, one.steps) << "one solve per step";
    EXPECT_EQ(passes.solves, 3 * passes.steps) << "MpmOptions{}.floor_friction_passes passes";
    EXPECT_NEAR(one.distance, expected, 0.1 * expected);
    EXPECT_NEAR(one.distance, passes.distance, 0.03 * expected);
    EXPECT_NEAR(large.distance, one.distance, 0.1 * expected);
}

// The floor's default (floor_friction_solve "auto"): one solve per step in 2D under return_map's work
// line search, the three passes in 3D (where one solve stopped at the default tolerance ended below
// the scene's floor) and under an energy line search (lagged's here; mpm_options.hpp).
TYPED_TEST(ImplicitTest, TheCoulombFloorsDefaultIsOneSolveIn2DUnderTheWorkLineSearch) {
    constexpr int dim = TypeParam::value;
    for (const std::string integrator : {"return_map", "lagged"}) {
        IntegratorSettings settings;
        settings.name = integrator;
        settings.dt = 1e-3;
        EXPECT_EQ(settings.mpm.floor_friction_solve, "auto");
        const bool one_solve = dim == 2 && integrator == "return_map";
        EXPECT_EQ(floor_friction_in_one_solve(settings.mpm, dim, integrator == "return_map"), one_solve);
        Simulation<dim> sim(sliding_box<dim>(), settings);
        const FrameStats frame = sim.advance_frame();
        EXPECT_EQ(frame.floor_friction_retried_steps, 0) << integrator;
        EXPECT_EQ(frame.fixed_point_iterations, (one_solve ? 1 : MpmOptions{}.floor_friction_passes) * frame.steps) << integrator;
    }
}

// Under "auto" a step whose one solve fails is solved again by the passes, from v*: here every one
// solve stops at a cap of one Newton iteration, so every step takes 1 + 3 solves and says so in its
// record; "newton" keeps the unconverged one solve. (2D under return_map: elsewhere "auto" takes the
// passes from the start.)
TEST(ImplicitFloorTest, AFailedOneSolveOnTheCoulombFloorIsSolvedAgainByThePasses) {
    constexpr int dim = 2;
    for (const std::string mode : {"auto", "newton"}) {
        IntegratorSettings settings;
        settings.name = "return_map";
        settings.dt = 1e-3;
        settings.mpm.floor_friction_solve = mode;
        settings.implicit.max_newton_iterations = 1;
        settings.implicit.newton_tolerance = 1e-9;
        Simulation<dim> sim(sliding_box<dim>(), settings);
        const FrameStats frame = sim.advance_frame();
        ASSERT_GT(frame.steps, 0);
        const bool retries = mode == "auto";
        EXPECT_EQ(frame.floor_friction_retried_steps, retries ? frame.steps : 0) << mode;
        EXPECT_EQ(frame.fixed_point_iterations, (retries ? 1 + MpmOptions{}.floor_friction_passes : 1) * frame.steps) << mode;
        for (const StepRecord& s : sim.last_frame_steps()) EXPECT_EQ(s.floor_friction_retried, retries) << mode;
    }
}

// floor_friction_passes sets how many passes a step on the Coulomb floor takes ("passes", and after a
// failed one solve under "auto"); the scene key refuses fewer than one, naming itself.
TEST(ImplicitFloorTest, FloorFrictionPassesSetsThePassesPerStep) {
    constexpr int dim = 2;
    for (const int passes : {1, 2, 5}) {
        IntegratorSettings settings;
        settings.name = "return_map";
        settings.dt = 1e-3;
        settings.mpm.floor_friction_solve = "passes";
        settings.mpm.floor_friction_passes = passes;
        Simulation<dim> sim(sliding_box<dim>(), settings);
        const FrameStats frame = sim.advance_frame();
        ASSERT_GT(frame.steps, 0);
        EXPECT_EQ(frame.fixed_point_iterations, passes * frame.steps) << passes << " passes";
        EXPECT_TRUE(frame.converged) << passes << " passes";
    }
    IntegratorSettings settings;
    settings.name = "return_map";
    settings.dt = 1e-3;
    settings.mpm.floor_friction_passes = 2;
    settings.implicit.max_newton_iterations = 1;  // every one solve fails: 1 + 2 solves per step
    settings.implicit.newton_tolerance = 1e-9;
    Simulation<dim> sim(sliding_box<dim>(), settings);
    const FrameStats frame = sim.advance_frame();
    EXPECT_EQ(frame.fixed_point_iterations, 3 * frame.steps);
    MpmOptions options;
    try {
        read_options(mpm_option_fields(), options, nlohmann::json{{"floor_friction_passes", 0}},
                     "scene.json: integrator");
        ADD_FAILURE() << "0 passes accepted";
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("integrator.floor_friction_passes"), std::string::npos) << e.what();
    }
}

// The sand column collapsing on a floor of its own friction (tan 30 deg), 0.2 s at 1e-3 s under return_map:
// the friction within one solve (the 2D default) at the default Newton tolerance spreads the column as far
// as the three passes with a tight solve (1e-7 m/s). Each step from v*: started from the last step's
// velocity change (the default) the one solve stopped at the tolerance ends 0.05% (2D) and 1.6% (3D, where
// the passes are the default) from the tight passes, against 0.02% and 0.8% from v* (docs/solver.md) with
// BiCGSTAB; with GMRES (the default since 2026-11-30) 0.94% in 3D from v*, and 1.4% when GMRES judged its
// residual in the Euclidean norm instead of Newton's (NewtonOptions::nonsymmetric_solver).
TYPED_TEST(ImplicitTest, TheCoulombFloorsFrictionWithinOneSolveEndsWhereTightPassesDo) {
    constexpr int dim = TypeParam::value;
    Scene scene = tiny_scene(scene_name<dim>("sand_column"));
    scene.boundary.floor_friction = std::tan(30.0 * M_PI / 180.0);
    scene.flip_relaxation_time = 0.01;
    auto spread = [&](bool in_solve, double tolerance) {
        IntegratorSettings settings;
        settings.name = "return_map";
        settings.dt = 1e-3;
        settings.mpm.floor_friction_solve = in_solve ? "newton" : "passes";
        settings.mpm.newton_start = "v_star";
        if (tolerance > 0.0) settings.implicit.newton_tolerance = tolerance;
        return spread_growth<dim>(scene, settings, 10);
    };
    const double one = spread(true, 0.0), tight = spread(false, 1e-7);
    std::cout << "spread (m): friction within one solve " << one << ", tight passes " << tight << "\n";
    EXPECT_GT(tight, 0.005) << "m: the column collapses";
    EXPECT_NEAR(one, tight, 0.01 * tight);
}

// The Coulomb floor's friction passes (floor_friction_passes.hpp) end where a tightly converged solve
// does: the sand column collapsing on a floor of its own friction (tan 30 deg), 0.2 s at 1e-3 s, spreads
// as far at the default Newton tolerance as at 1e-9 m/s. Each pass after the first changes the friction
// only on the floor's nodes, a residual the mass-weighted one (over every node) hid below the tolerance,
// so those passes took no Newton step and the friction stayed that of the first pass's slips (measured:
// 3.8% (2D) and 1.9% (3D) farther on this column by the particles' mean distance from the axis; the
// granular collapse at dx = 1/128 ran out 1.12 L0 against explicit's 1.29). Now the default ends 0.03%
// (2D) and 0.12% (3D) from the tight solve by the deposit's rms spread.
TYPED_TEST(ImplicitTest, TheCoulombFloorsFrictionPassesEndWhereATightSolveDoes) {
    constexpr int dim = TypeParam::value;
    Scene scene = tiny_scene(scene_name<dim>("sand_column"));
    scene.boundary.floor_friction = std::tan(30.0 * M_PI / 180.0);
    scene.flip_relaxation_time = 0.01;
    auto spread = [&](double tolerance) {
        IntegratorSettings settings;
        settings.name = "lagged";
        settings.mpm.floor_friction_solve = "passes";
        settings.dt = 1e-3;
        if (tolerance > 0.0) settings.implicit.newton_tolerance = tolerance;
        return spread_growth<dim>(scene, settings, 10);
    };
    const double by_default = spread(0.0), tight = spread(1e-9);
    std::cout << "spread (m): default tolerance " << by_default << ", 1e-9 m/s " << tight << "\n";
    EXPECT_GT(tight, 0.005) << "m: the column collapses";
    EXPECT_NEAR(by_default, tight, 0.01 * tight);
}

// The 2D sand column of the tiny scene as a granular collapse at dx = 1/128: the column [x0, x1] from
// the 3-cell floor layer to `top`, on a Coulomb floor of tan 30 deg, AFLIP transfers, the domain
// [0, domain_x] x [0, 0.40625].
Scene coulomb_column_128(double x0, double x1, double top, double domain_x) {
    Scene scene = tiny_scene(scene_name<2>("sand_column"));
    scene.dx = 1.0 / 128.0;
    scene.domain_max = Eigen::Vector2d(domain_x, 0.40625);
    scene.view_max = scene.domain_max;
    scene.boundary.sticky_floor_cells = 3;
    scene.boundary.floor_friction = std::tan(30.0 * M_PI / 180.0);
    scene.flip_relaxation_time = 0.01;
    scene.objects[0].min = Eigen::Vector2d(x0, 3.0 / 128.0);
    scene.objects[0].max = Eigen::Vector2d(x1, top);
    return scene;
}

// return_map's solve (until 2026-11-28 plasticitynet's default) stopped by the default tolerance ends
// where a tight one does on a flowing sand column: the granular collapse of scripts/granular_collapse.py
// at 30 deg and aspect 4 (a column 0.1 m wide and 0.2 m tall on a Coulomb floor of its own friction,
// dx = 1/128, AFLIP), 0.5 s at 1e-3 s (the step is the exact elastoplastic one). With the tangent
// non-associative tangent damped by the paper's w = 1, Newton converged at ~0.7 per iteration and the
// solves its tolerance stopped were biased toward v*, a bias the momentum carries over the flow
// (ImplicitOptions::tangent_damping, docs/solver.md). Measured (growth of the rms spread): 0.114221 m
// at 1e-5 m/s, 0.114392 m (+0.15%) by default, 0.112284 m (-1.7%) with w = 1; with the tangent's skew
// part (the default since), 0.114228 m and 0.113940 m (-0.25%); with the floor's friction in the one
// solve (the default since), 0.114167 m and 0.114473 m (+0.27%); with GMRES judging its residual in
// Newton's norm (the default since 2026-11-30), 0.114168 m and 0.114288 m (+0.11%), where GMRES in the
// Euclidean norm ended at 0.114908 m (+0.65%).
TEST(ImplicitTangentDamping, AFlowingColumnStoppedByTheToleranceEndsWhereATightSolveDoes) {
    constexpr int dim = 2;
    const Scene scene = coulomb_column_128(0.5515625, 0.6515625, 3.0 / 128.0 + 0.2, 1.203125);
    auto spread = [&](double tolerance) {  // the default tangent_damping (measured with 1.0 too: above)
        IntegratorSettings settings = implicit_settings<dim>("return_map", scene, 0.0);
        if (tolerance > 0.0) settings.implicit.newton_tolerance = tolerance;
        settings.implicit.max_newton_iterations = 400;
        return spread_growth<dim>(scene, settings, 25);
    };
    // One thread: ctest runs two tests at once, and the 30 s of simulations here slowed tenfold when
    // their OpenMP threads shared the cores with another test's (results do not depend on it:
    // OneAndTwoThreadsGiveIdenticalResults).
    const int saved = omp_get_max_threads();
    omp_set_num_threads(1);
    const double tight = spread(1e-5), by_default = spread(0.0);
    omp_set_num_threads(saved);
    std::cout << "spread growth (m): tight " << tight << ", default tolerance " << by_default << "\n";
    EXPECT_GT(tight, 0.05) << "m: the column flows out";
    EXPECT_NEAR(by_default, tight, 0.005 * tight);
}

// return_map's Newton converges on the collapse of a stiff sand column (E x 100, dx = 1/128, a Coulomb
// floor of its own friction, AFLIP; the step is the exact elastoplastic one). Drucker-Prager
// flows non-associatively: with its tangent symmetrized, the solves of the flow fell to about 3e-3 m/s
// and then chattered between 1e-3 and 4e-3 m/s at the deposit's fronts until an iterate happened to
// fall below the tolerance (docs/solver.md): measured 118-140 Newton iterations per step over frames
// 8-14 and 10 of 280 steps unconverged, against 11-25 and none with the tangent's skew part kept.
TEST(ImplicitTangentSkew, AStiffSandColumnsCollapseConvergesWithoutChatter) {
    constexpr int dim = 2;
    Scene scene = coulomb_column_128(0.45, 0.55, 0.3, 1.0);
    scene.objects[0].material.elastic.E *= 100.0;
    const IntegratorSettings settings = implicit_settings<dim>("return_map", scene, 0.0);
    const int saved = omp_get_max_threads();
    omp_set_num_threads(1);  // as above: ctest runs two tests at once
    Simulation<dim> sim(scene, settings);
    for (int f = 0; f < 7; ++f) sim.advance_frame();
    long newton = 0, steps = 0, unconverged = 0;
    for (int f = 7; f < 10; ++f) {  // the collapse
        const FrameStats frame = sim.advance_frame();
        newton += frame.newton_iterations;
        steps += frame.steps;
        unconverged += frame.unconverged_steps;
    }
    omp_set_num_threads(saved);
    const double per_step = static_cast<double>(newton) / static_cast<double>(steps);
    std::cout << "frames 8-10: " << per_step << " Newton iterations per step, " << unconverged
              << " steps unconverged\n";
    EXPECT_EQ(unconverged, 0);
    EXPECT_LT(per_step, 30.0);
}

// A step far below the default one is solved as accurately (ImplicitOptions::newton_tolerance_at): the
// 2D sand column on its sticky floor, 0.04 s in steps of 1e-5 s, settles outward as explicit MPM at the
// same step does. With the tolerance a fixed 1e-3 m/s, the residual the step's forces leave (about
// g dt = 1e-4 m/s) was below it from the start: 3808 of the 4000 steps took no Newton step, the stresses
// lagged behind, and the column spread 0.32 mm against explicit's 0.83 mm (the particles' mean distance
// from the axis; now 0.947 against 0.950 mm by the deposit's rms spread). (2D only: the 3D column takes
// about 20 s per 0.02 s at this step.)
TEST(ImplicitSmallStep, AStepFarBelowTheDefaultIsSolvedAsAccurately) {
    constexpr int dim = 2;
    Scene scene = tiny_scene(scene_name<dim>("sand_column"));
    scene.flip_relaxation_time = 0.01;
    auto spread = [&](const std::string& integrator) {
        IntegratorSettings settings;
        settings.name = integrator;
        settings.dt = 1e-5;
        return spread_growth<dim>(scene, settings, 2);
    };
    const double explicit_spread = spread("explicit"), implicit_spread = spread("lagged");
    std::cout << "spread (m) after 0.04 s at 1e-5 s: explicit " << explicit_spread << ", lagged " << implicit_spread
              << "\n";
    EXPECT_GT(explicit_spread, 5e-4) << "m: the column settles outward";
    EXPECT_NEAR(implicit_spread, explicit_spread, 0.05 * explicit_spread);
}

// BDF2 (ImplicitOptions::time_integrator): the first step, without history, is backward Euler's bit for
// bit; it leaves the history (3 n + 1 matrices of checkpoint state); the second step uses it.
TYPED_TEST(ImplicitTest, Bdf2StartsWithABackwardEulerStepThenUsesItsHistory) {
    constexpr int dim = TypeParam::value;
    const Scene scene = tiny_scene(scene_name<dim>("sand_column"));  // on the floor: stresses, not free fall
    const MpmSystem<dim> system = make_mpm_system<dim>(scene);
    ImplicitOptions be, bdf2;
    bdf2.time_integrator = "bdf2";
    ImplicitIntegrator<dim> a(system, ImplicitMethod::Lagged, be, MpmOptions{}, std::make_unique<ElasticParticleEnergy<dim>>(system.materials));
    ImplicitIntegrator<dim> b(system, ImplicitMethod::Lagged, bdf2, MpmOptions{},
                              std::make_unique<ElasticParticleEnergy<dim>>(system.materials));
    Particles<dim> pa = sample_particles<dim>(scene), pb = pa;
    a.step(pa, 1e-3, 0);
    b.step(pb, 1e-3, 0);
    EXPECT_TRUE(identical(pa, pb));
    EXPECT_TRUE(a.checkpoint_state().empty());
    EXPECT_EQ(b.checkpoint_state().size(), 3 * pb.size() + 1);
    EXPECT_EQ(b.checkpoint_state().back()(0, 0), 1e-3) << "the last step's dt";
    a.step(pa, 1e-3, 1);
    b.step(pb, 1e-3, 1);
    double differ = 0.0;
    for (std::size_t p = 0; p < pa.size(); ++p) differ = std::max(differ, (pa.v[p] - pb.v[p]).norm());
    EXPECT_GT(differ, 1e-6) << "m/s";
}

// Variable steps (the advection limit, a frame's clipped last step): BDF2 with the variable-step
// coefficients is exact for a velocity linear in time, so a block falling freely under gravity keeps
// v = v0 + g t over steps of 1, 0.5, 2, 1 and 0.25 ms (the first is backward Euler's, also exact for
// it). The constant-step formulas were off by (dt_prev - dt) g / 3 at each change of step: 1.6e-3 m/s
// after the first one here, 3.2e-3 m/s at the end. A history restored without its step (a checkpoint written before the step was kept) is read
// as the next step's.
TYPED_TEST(ImplicitTest, Bdf2WithChangingStepsKeepsAFreeFallExact) {
    constexpr int dim = TypeParam::value;
    const Scene scene = tiny_scene(scene_name<dim>("sand_column"));
    const MpmSystem<dim> system = make_mpm_system<dim>(scene);
    ImplicitOptions bdf2;
    bdf2.time_integrator = "bdf2";
    ImplicitIntegrator<dim> integrator(system, ImplicitMethod::Lagged, bdf2, MpmOptions{},
                                       std::make_unique<ElasticParticleEnergy<dim>>(system.materials));
    Particles<dim> particles = sample_particles<dim>(scene);
    Vec<dim> v0 = Vec<dim>::Zero();
    v0[0] = 0.3;
    v0[1] = 1.0;
    for (std::size_t p = 0; p < particles.size(); ++p) {
        particles.x[p][1] += 0.2;  // in the air: no floor, no walls within the stencils
        particles.v[p] = v0;
    }
    double t = 0.0;
    long step = 0;
    auto worst_error = [&] {
        double worst = 0.0;
        for (std::size_t p = 0; p < particles.size(); ++p)
            worst = std::max(worst, (particles.v[p] - (v0 + t * system.gravity)).norm());
        return worst;
    };
    for (const double dt : {1e-3, 5e-4, 2e-3, 1e-3, 2.5e-4}) {
        integrator.step(particles, dt, step++);
        t += dt;
        EXPECT_LT(worst_error(), 1e-9) << "m/s after the step of " << dt << " s";
    }
    // Resumed from a 3 n state (no step recorded), the next step is taken as the last one's size.
    std::vector<Mat<dim>> state = integrator.checkpoint_state();
    ASSERT_EQ(state.size(), 3 * particles.size() + 1);
    EXPECT_EQ(state.back()(0, 0), 2.5e-4);
    state.pop_back();
    ImplicitIntegrator<dim> resumed(system, ImplicitMethod::Lagged, bdf2, MpmOptions{},
                                    std::make_unique<ElasticParticleEnergy<dim>>(system.materials));
    resumed.restore_checkpoint_state(state);
    resumed.step(particles, 2.5e-4, step++);
    t += 2.5e-4;
    EXPECT_LT(worst_error(), 1e-9) << "m/s after resuming";
}

// MpmOptions::newton_start "last_step" (the default; mpm/step_predictor.hpp): after the first step, a
// step's Newton solve starts from v* plus the last step's implicit velocity change. On the tiny sand
// column resting on its floor most of that change is the stress holding the sand against gravity, so
// the start's residual is far below v*'s, the solve takes fewer iterations, and it converges to the same
// step within the Newton tolerance.
TYPED_TEST(ImplicitTest, NewtonStartsFromTheLastStepsVelocityChange) {
    constexpr int dim = TypeParam::value;
    const Scene scene = tiny_scene(scene_name<dim>("sand_column"));
    const MpmSystem<dim> system = make_mpm_system<dim>(scene);
    const Particles<dim> start = sample_particles<dim>(scene);
    struct Run {
        double start_residual = 0.0;  // summed over the steps after the first
        int newton = 0;
        Particles<dim> particles;
    };
    auto run = [&](const std::string& newton_start) {
        MpmOptions options;
        options.newton_start = newton_start;
        ImplicitIntegrator<dim> integrator(
            system, ImplicitMethod::ReturnMap, ImplicitOptions{}, options,
            model_free_energy<dim>(ImplicitMethod::ReturnMap, ImplicitOptions{}, system.materials));
        Run r{0.0, 0, start};
        for (long k = 0; k < 10; ++k) {
            const MpmStepStats stats = integrator.step(r.particles, 1e-3, k);
            EXPECT_TRUE(stats.converged) << newton_start << " step " << k;
            if (k > 0) r.start_residual += stats.initial_residual;
            if (k > 0) r.newton += stats.newton_iterations;
        }
        return r;
    };
    const Run v_star = run("v_star"), last = run("last_step");
    std::cout << "steps 1-9: start residual " << v_star.start_residual << " (v*) against " << last.start_residual
              << " m/s, Newton iterations " << v_star.newton << " against " << last.newton << "\n";
    EXPECT_LT(last.start_residual, 0.6 * v_star.start_residual);
    EXPECT_LT(last.newton, v_star.newton);
    double squared = 0.0;
    for (std::size_t p = 0; p < start.size(); ++p)
        squared += (last.particles.x[p] - v_star.particles.x[p]).squaredNorm();
    EXPECT_LT(std::sqrt(squared / static_cast<double>(start.size())), 1e-5)
        << "m rms: the same steps, to the Newton tolerance (1e-3 m/s rms over 10 ms)";
}

// The prediction (StepPredictor::predict): dt times the last step's rate on each free node, faded by
// m / (m + kFade m_max) with m the lighter of the node's masses then and now, and nothing on a node with
// a held component (the floor's), whatever it held.
TYPED_TEST(ImplicitTest, TheNewtonStartsPredictionFadesLightNodesAndSkipsHeldOnes) {
    constexpr int dim = TypeParam::value;
    const Scene scene = tiny_scene(scene_name<dim>("sand_column"));
    const MpmSystem<dim> system = make_mpm_system<dim>(scene);
    ImplicitIntegrator<dim> integrator(
        system, ImplicitMethod::ReturnMap, ImplicitOptions{}, MpmOptions{},
        model_free_energy<dim>(ImplicitMethod::ReturnMap, ImplicitOptions{}, system.materials));
    Particles<dim> particles = sample_particles<dim>(scene);
    integrator.step(particles, 1e-3, 0);
    // A prediction of a known rate at every node of the last step's potential, predicted onto it.
    const IncrementalPotential<dim>& potential = integrator.potential();
    std::vector<Mat<dim>> state;
    double heaviest = 0.0;
    for (std::size_t k = 0; k < potential.nodes(); ++k) {
        Mat<dim> m = Mat<dim>::Zero();
        for (int a = 0; a < dim; ++a) m(a, 0) = 1.0 + a + 0.01 * static_cast<double>(k);
        m(0, 1) = static_cast<double>(potential.dof_node(k));
        // The node's mass when recorded: a third of today's on every other node (the lighter one fades).
        const double now = potential.grid().node(potential.dof_node(k)).mass;
        m(1, 1) = k % 2 ? now / 3.0 : 2.0 * now;
        state.push_back(m);
        heaviest = std::max(heaviest, potential.grid().node(potential.dof_node(k)).mass);
    }
    StepPredictor<dim> predictor;
    predictor.restore(state, potential.grid().storage_size(), "test");
    VecX v = VecX::Zero(dim * static_cast<Eigen::Index>(potential.nodes()));
    const double dt = 5e-4;
    predictor.predict(potential, dt, v);
    int held = 0, faded = 0;
    for (std::size_t k = 0; k < potential.nodes(); ++k) {
        bool node_held = false;
        for (int a = 0; a < dim; ++a) node_held = node_held || potential.residual_scale()[dim * k + a] == 0.0;
        const double m = std::min(state[k](1, 1), potential.grid().node(potential.dof_node(k)).mass);
        const double weight = node_held ? 0.0 : dt * m / (m + StepPredictor<dim>::kFade * heaviest);
        held += node_held;
        faded += !node_held && m < 0.5 * heaviest;
        for (int a = 0; a < dim; ++a) ASSERT_NEAR(v[dim * k + a], weight * state[k](a, 0), 1e-15) << "node " << k;
    }
    EXPECT_GT(held, 0) << "the floor holds some nodes";
    EXPECT_GT(faded, 0) << "some free nodes weigh less than half the heaviest (their fade is over 2%)";
    // A refused state leaves the prediction as it was.
    std::vector<Mat<dim>> bad = state;
    bad.back()(0, 1) = -1.0;
    EXPECT_THROW(predictor.restore(bad, potential.grid().storage_size(), "test"), std::invalid_argument);
    bad = state;
    bad.front()(0, 0) = std::numeric_limits<double>::infinity();
    EXPECT_THROW(predictor.restore(bad, potential.grid().storage_size(), "test"), std::invalid_argument);
    EXPECT_EQ(predictor.state().size(), state.size());
}

// A solve from a prediction that ends far from converged (here a prediction of 50 m/s at every node, and
// Newton capped at 2 iterations, where it needs 4 from there and none from v*) is solved again from v*: the step equals
// the one started there, bit for bit, is marked prediction_rejected and counts both solves' iterations. "auto" predicts
// under return_map and lagged, not under plasticitynet (IntegratorInfo::predicts_newton_start).
TYPED_TEST(ImplicitTest, AStepWhosePredictionFailsIsSolvedAgainFromVStar) {
    constexpr int dim = TypeParam::value;
    EXPECT_TRUE(predicts_newton_start("auto", Method::ReturnMap));
    EXPECT_TRUE(predicts_newton_start("auto", Method::Lagged));
    EXPECT_FALSE(predicts_newton_start("auto", Method::PlasticityNet));
    EXPECT_TRUE(predicts_newton_start("last_step", Method::PlasticityNet));
    EXPECT_FALSE(predicts_newton_start("v_star", Method::ReturnMap));
    const Scene scene = tiny_scene(scene_name<dim>("sand_column"));
    const MpmSystem<dim> system = make_mpm_system<dim>(scene);
    ImplicitOptions options;
    options.max_newton_iterations = 2;
    auto integrator = [&](const char* start) {
        MpmOptions mpm;
        mpm.newton_start = start;
        return std::make_unique<ImplicitIntegrator<dim>>(
            system, ImplicitMethod::ReturnMap, options, mpm,
            model_free_energy<dim>(ImplicitMethod::ReturnMap, options, system.materials));
    };
    const auto predicting = integrator("last_step"), from_v_star = integrator("v_star");
    Particles<dim> a = sample_particles<dim>(scene), b = a;
    const MpmStepStats first = predicting->step(a, 1e-3, 0);
    from_v_star->step(b, 1e-3, 0);
    ASSERT_TRUE(first.converged);
    ASSERT_FALSE(first.prediction_rejected);
    ASSERT_TRUE(identical(a, b)) << "the first step has no prediction";
    std::vector<Mat<dim>> wild = predicting->checkpoint_prediction();
    ASSERT_FALSE(wild.empty());
    for (Mat<dim>& m : wild) m.col(0).setConstant(5e4);  // 50 m/s over a step of 1 ms
    predicting->restore_checkpoint_prediction(wild);
    const MpmStepStats second = predicting->step(a, 1e-3, 1);
    const MpmStepStats reference = from_v_star->step(b, 1e-3, 1);
    std::cout << "from the wild prediction: " << second.newton_iterations << " Newton iterations, start residual "
              << second.initial_residual << ", end " << second.residual
              << " m/s; from v*: " << reference.newton_iterations << "\n";
    EXPECT_TRUE(second.prediction_rejected);
    EXPECT_TRUE(second.converged);
    EXPECT_FALSE(reference.prediction_rejected);
    EXPECT_GT(second.newton_iterations, reference.newton_iterations) << "both solves counted";
    EXPECT_TRUE(identical(a, b)) << "solved again from v*";
}

}  // namespace
}  // namespace pnet
