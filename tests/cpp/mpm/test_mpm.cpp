// MPM core: transfer conservation, free fall, rest on the floor, determinism
// across thread counts, in 2D and 3D.
#include <gtest/gtest.h>
#include <omp.h>

#include <Eigen/Geometry>  // cross()
#include <iostream>

#include "pnet/mpm/explicit_integrator.hpp"
#include "pnet/mpm/transfer.hpp"
#include "support/random.hpp"

namespace pnet {
namespace {

/// A box of particles, 2 per cell per axis, in a [0, 1]^d domain of `cells` cells.
template <int dim>
Particles<dim> make_box(const Vec<dim>& lo, const Vec<dim>& hi, double dx, double density) {
    const double h = 0.5 * dx;
    std::vector<Vec<dim>> xs;
    Eigen::Matrix<int, dim, 1> count;
    for (int a = 0; a < dim; ++a) count[a] = static_cast<int>(std::round((hi[a] - lo[a]) / h));
    const int total = count.prod();
    for (int flat = 0; flat < total; ++flat) {
        Vec<dim> x;
        int rest = flat;
        for (int a = 0; a < dim; ++a) {
            x[a] = lo[a] + (rest % count[a] + 0.5) * h;
            rest /= count[a];
        }
        xs.push_back(x);
    }
    Particles<dim> P;
    P.resize(xs.size());
    for (std::size_t p = 0; p < xs.size(); ++p) {
        P.x[p] = xs[p];
        P.v[p].setZero();
        P.rest_volume[p] = std::pow(h, dim);
        P.mass[p] = density * P.rest_volume[p];
        P.object[p] = 0;
        P.hardening[p] = 0.0;
    }
    return P;
}

template <int dim>
MpmSystem<dim> make_system(int cells, const MaterialDescription& material, double gravity) {
    MpmSystem<dim> s;
    s.dx = 1.0 / cells;
    s.cells.fill(cells);
    s.gravity.setZero();
    s.gravity[1] = -gravity;
    s.materials.emplace_back(material);
    s.density.push_back(material.density);
    return s;
}

/// APIC angular momentum about the origin (2D: the scalar; 3D: the vector):
/// sum x_p x m_p v_p + m_p eps : (C_p D_p)^T with D_p = dx^2/4 I.
template <int dim>
Eigen::Vector3d angular_momentum(const Particles<dim>& P, double dx) {
    Eigen::Vector3d L = Eigen::Vector3d::Zero();
    for (std::size_t p = 0; p < P.size(); ++p) {
        Eigen::Vector3d x = Eigen::Vector3d::Zero(), v = Eigen::Vector3d::Zero();
        Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
        x.head<dim>() = P.x[p];
        v.head<dim>() = P.v[p];
        C.topLeftCorner<dim, dim>() = P.C[p];
        const Eigen::Matrix3d B = C * (0.25 * dx * dx);  // B = C D
        const Eigen::Vector3d affine(B(2, 1) - B(1, 2), B(0, 2) - B(2, 0), B(1, 0) - B(0, 1));
        L += P.mass[p] * (x.cross(v) + affine);
    }
    return L;
}

template <typename Dim>
class MpmTest : public ::testing::Test {};
using Dimensions = ::testing::Types<std::integral_constant<int, 2>, std::integral_constant<int, 3>>;
struct DimName {
    template <typename T>
    static std::string GetName(int) { return std::to_string(T::value) + "d"; }
};
TYPED_TEST_SUITE(MpmTest, Dimensions, DimName);

TYPED_TEST(MpmTest, TransfersConserveMassMomentumAndAngularMomentum) {
    constexpr int dim = TypeParam::value;
    const double dx = 1.0 / 32;
    Particles<dim> P = make_box<dim>(Vec<dim>::Constant(0.3), Vec<dim>::Constant(0.55), dx, 1000.0);
    test::Random random(3);
    for (std::size_t p = 0; p < P.size(); ++p) {
        P.x[p] += random.uniform_vec<dim>(-0.2 * dx, 0.2 * dx);
        P.v[p] = random.uniform_vec<dim>(-1.0, 1.0);
        for (int i = 0; i < dim; ++i)
            for (int j = 0; j < dim; ++j) P.C[p](i, j) = random.uniform(-5.0, 5.0);
    }
    Grid<dim> grid(Vec<dim>::Zero(), dx, [] { std::array<int, dim> c; c.fill(32); return c; }());
    particles_to_grid<dim>(grid, P, nullptr);

    double mass_p = 0.0, mass_g = 0.0;
    Vec<dim> momentum_p = Vec<dim>::Zero(), momentum_g = Vec<dim>::Zero();
    Eigen::Vector3d L_g = Eigen::Vector3d::Zero();
    for (std::size_t p = 0; p < P.size(); ++p) {
        mass_p += P.mass[p];
        momentum_p += P.mass[p] * P.v[p];
    }
    const Eigen::Vector3d L_p = angular_momentum(P, dx);
    for (int block : grid.active_blocks())
        for (int k = 0; k < Grid<dim>::kBlockNodes; ++k) {
            const std::int64_t index = static_cast<std::int64_t>(block) * Grid<dim>::kBlockNodes + k;
            auto& n = grid.node(index);
            mass_g += n.mass;
            momentum_g += n.momentum;
            if (n.mass > 0) {
                int coord[dim];
                grid.coordinates(index, coord);
                Eigen::Vector3d x = Eigen::Vector3d::Zero(), mv = Eigen::Vector3d::Zero();
                for (int a = 0; a < dim; ++a) x[a] = coord[a] * dx;
                mv.head<dim>() = n.momentum;
                L_g += x.cross(mv);
            }
            n.momentum = n.mass > 0 ? Vec<dim>(n.momentum / n.mass) : Vec<dim>::Zero();  // velocity for G2P
        }
    EXPECT_NEAR(mass_g, mass_p, 1e-12 * mass_p);
    EXPECT_LE((momentum_g - momentum_p).norm(), 1e-12 * momentum_p.norm() + 1e-15);
    EXPECT_LE((L_g - L_p).norm(), 1e-12 * L_p.norm());

    // G2P gives the grid's momenta back.
    Particles<dim> Q = P;
    for (std::size_t p = 0; p < Q.size(); ++p) {
        Mat<dim> grad_v;
        gather_velocity(grid, Q.x[p], Q.v[p], Q.C[p], grad_v);
    }
    Vec<dim> momentum_q = Vec<dim>::Zero();
    for (std::size_t p = 0; p < Q.size(); ++p) momentum_q += Q.mass[p] * Q.v[p];
    EXPECT_LE((momentum_q - momentum_g).norm(), 1e-12 * momentum_g.norm());
    EXPECT_LE((angular_momentum(Q, dx) - L_g).norm(), 1e-12 * L_g.norm());
}

// AFLIP (MpmSystem::flip_relaxation_time): the residual r_p = v_p - sum w_ip v_i vanishes on an affine
// velocity field (APIC carries it exactly), and what the transfers take from a rough velocity field is
// a rate in time: two explicit runs of a free cloud (no gravity, E 1 Pa: no forces to speak of) at steps
// 4x apart keep the same kinetic energy, where APIC keeps less with more steps.
TYPED_TEST(MpmTest, AflipResidualVanishesOnAffineFieldsAndTransfersLoseEnergyPerTimeNotPerStep) {
    constexpr int dim = TypeParam::value;
    const double dx = 1.0 / 32;
    test::Random random(5);
    Particles<dim> P = make_box<dim>(Vec<dim>::Constant(0.3), Vec<dim>::Constant(0.55), dx, 1000.0);
    Mat<dim> B;
    for (int i = 0; i < dim; ++i)
        for (int j = 0; j < dim; ++j) B(i, j) = random.uniform(-2.0, 2.0);
    const Vec<dim> a = random.uniform_vec<dim>(-1.0, 1.0);
    for (std::size_t p = 0; p < P.size(); ++p) {
        P.x[p] += random.uniform_vec<dim>(-0.2 * dx, 0.2 * dx);
        P.v[p] = a + B * P.x[p];
        P.C[p] = B;
    }
    Grid<dim> grid(Vec<dim>::Zero(), dx, [] { std::array<int, dim> c; c.fill(32); return c; }());
    particles_to_grid<dim>(grid, P, nullptr);
    std::vector<Vec<dim>> r;
    velocity_residual(grid, P, r);
    double worst = 0.0;
    for (const Vec<dim>& rp : r) worst = std::max(worst, rp.norm());
    EXPECT_LT(worst, 1e-12);

    MaterialDescription soft;
    soft.name = "elastic";
    soft.density = 1000.0;
    soft.elastic = {1.0, 0.3};
    soft.elasticity = ElasticityModel::StvkHencky;
    MpmSystem<dim> system = make_system<dim>(32, soft, 0.0);
    for (std::size_t p = 0; p < P.size(); ++p) {
        P.v[p] = random.uniform_vec<dim>(-0.1, 0.1);
        P.C[p].setZero();
    }
    auto kinetic_after = [&](double tau, double dt) {
        system.flip_relaxation_time = tau;
        Particles<dim> Q = P;
        ExplicitIntegrator<dim> integrator(system);
        const int steps = static_cast<int>(std::lround(0.02 / dt));
        for (int s = 0; s < steps; ++s) integrator.step(Q, dt, s);
        double e = 0.0;
        for (std::size_t p = 0; p < Q.size(); ++p) e += 0.5 * Q.mass[p] * Q.v[p].squaredNorm();
        return e;
    };
    const double apic_coarse = kinetic_after(0.0, 1e-3), apic_fine = kinetic_after(0.0, 2.5e-4);
    const double aflip_coarse = kinetic_after(0.01, 1e-3), aflip_fine = kinetic_after(0.01, 2.5e-4);
    std::cout << "kinetic energy after 0.02 s (J): APIC " << apic_coarse << " / " << apic_fine << ", AFLIP "
              << aflip_coarse << " / " << aflip_fine << " (steps 1e-3 / 2.5e-4 s)\n";
    EXPECT_LT(apic_fine, 0.8 * apic_coarse) << "APIC: a loss per step";
    EXPECT_NEAR(aflip_fine, aflip_coarse, 0.05 * aflip_coarse) << "AFLIP: a loss per unit time";
    EXPECT_GT(aflip_fine, apic_fine);
}

// The floor layer's boundary conditions on one node's velocity: sticky zeroes it; Coulomb (mu 0.5) removes
// a velocity into the floor with mu times as much tangential speed (all of it when that is less: static
// friction) and leaves a velocity away from it; above the layer nothing changes.
TEST(Boundary, StickyAndCoulombFloors) {
    const Grid<3> grid(Vec<3>::Zero(), 0.1, {16, 16, 16});
    BoundaryConditions sticky, coulomb;
    sticky.slip_walls = coulomb.slip_walls = false;
    coulomb.floor_friction = 0.5;
    const int on_floor[3] = {8, 2, 8}, above[3] = {8, 4, 8};
    auto applied = [&](const BoundaryConditions& bc, const int* node, Vec<3> v) {
        grid.apply_boundary(node, v, bc);
        return v;
    };
    EXPECT_EQ(applied(sticky, on_floor, Vec<3>(1.0, 1.0, 0.0)), Vec<3>::Zero());
    EXPECT_EQ(applied(sticky, above, Vec<3>(1.0, -1.0, 0.0)), Vec<3>(1.0, -1.0, 0.0));
    // Kinetic: |v_t| = 5 shrinks by 0.5 * 2 = 1, along its direction (3, 4) / 5.
    EXPECT_TRUE(applied(coulomb, on_floor, Vec<3>(3.0, -2.0, 4.0)).isApprox(Vec<3>(2.4, 0.0, 3.2), 1e-15));
    EXPECT_EQ(applied(coulomb, on_floor, Vec<3>(0.4, -1.0, 0.3)), Vec<3>::Zero());  // static: 0.5 <= 0.5
    EXPECT_EQ(applied(coulomb, on_floor, Vec<3>(3.0, 2.0, 4.0)), Vec<3>(3.0, 2.0, 4.0));  // lifting off
    EXPECT_EQ(applied(coulomb, above, Vec<3>(3.0, -2.0, 4.0)), Vec<3>(3.0, -2.0, 4.0));
    bool fixed[3];
    grid.constrained_components(on_floor, fixed, coulomb);
    EXPECT_FALSE(fixed[0]);
    EXPECT_TRUE(fixed[1]) << "the normal component is held during an implicit solve";
    EXPECT_FALSE(fixed[2]);
    grid.constrained_components(on_floor, fixed, sticky);
    EXPECT_TRUE(fixed[0] && fixed[1] && fixed[2]);
}

TYPED_TEST(MpmTest, FreeFallMatchesTheAnalyticTrajectory) {
    constexpr int dim = TypeParam::value;
    MaterialDescription sand = material_preset("sand");
    MpmSystem<dim> system = make_system<dim>(32, sand, 9.8);
    Vec<dim> lo = Vec<dim>::Constant(0.4), hi = Vec<dim>::Constant(0.5);
    lo[1] = 0.6;
    hi[1] = 0.7;
    Particles<dim> P = make_box<dim>(lo, hi, system.dx, sand.density);
    const Particles<dim> start = P;
    ExplicitIntegrator<dim> integrator(system);
    const double dt = 1e-3;
    const int steps = 150;  // 0.15 s: falls 0.11 m, lands at y = 3 dx + ... later
    for (int s = 0; s < steps; ++s) integrator.step(P, dt, s);
    // Symplectic Euler: v_n = -g n dt, y_n = y_0 - g dt^2 n (n + 1) / 2.
    const double v_expected = -9.8 * steps * dt, drop = 9.8 * dt * dt * steps * (steps + 1) / 2.0;
    for (std::size_t p = 0; p < P.size(); ++p) {
        EXPECT_NEAR(P.v[p][1], v_expected, 1e-9) << p;
        EXPECT_NEAR(P.x[p][1], start.x[p][1] - drop, 1e-9) << p;
        EXPECT_NEAR(P.x[p][0], start.x[p][0], 1e-12) << p;
    }
}

TYPED_TEST(MpmTest, ElasticBlockRestsOnTheFloor) {
    constexpr int dim = TypeParam::value;
    MaterialDescription jelly;
    jelly.name = "elastic";
    jelly.density = 1000.0;
    jelly.elastic = {1e7, 0.3};  // Pa: the static sag rho g H^2 / E is ~1e-5 m
    jelly.elasticity = ElasticityModel::StvkHencky;
    MpmSystem<dim> system = make_system<dim>(32, jelly, 9.8);
    Vec<dim> lo = Vec<dim>::Constant(0.4), hi = Vec<dim>::Constant(0.6);
    lo[1] = 4 * system.dx;  // on the sticky floor layer
    hi[1] = lo[1] + 0.1;
    Particles<dim> P = make_box<dim>(lo, hi, system.dx, jelly.density);
    const Particles<dim> start = P;
    ExplicitIntegrator<dim> integrator(system);
    const double dt = cfl_time_step(system, P, 0.4);
    const int steps = static_cast<int>(0.05 / dt);  // ~40 crossings of the block by a pressure wave
    for (int s = 0; s < steps; ++s) integrator.step(P, dt, s);
    double max_shift = 0.0, max_speed = 0.0;
    for (std::size_t p = 0; p < P.size(); ++p) {
        max_shift = std::max(max_shift, (P.x[p] - start.x[p]).norm());
        max_speed = std::max(max_speed, P.v[p].norm());
    }
    // It only sags elastically (measured: shifts scale as 1/E), far under a cell.
    EXPECT_LT(max_shift, 0.02 * system.dx) << "after " << steps << " steps of " << dt << " s";
    EXPECT_LT(max_speed, 0.05);
}

TYPED_TEST(MpmTest, ThreadCountDoesNotChangeResults) {
    constexpr int dim = TypeParam::value;
    MaterialDescription snow = material_preset("snow");
    MpmSystem<dim> system = make_system<dim>(32, snow, 9.8);
    Vec<dim> lo = Vec<dim>::Constant(0.35), hi = Vec<dim>::Constant(0.6);
    lo[1] = 0.15;  // hits the floor at once: compaction hardens the snow
    hi[1] = 0.35;
    Particles<dim> initial = make_box<dim>(lo, hi, system.dx, snow.density);
    for (std::size_t p = 0; p < initial.size(); ++p) {
        initial.v[p][1] = -3.0;
        initial.hardening[p] = -0.1;
    }
    Particles<dim> results[2];
    const int saved = omp_get_max_threads();
    for (int threads : {1, 2}) {
        omp_set_num_threads(threads);
        Particles<dim> P = initial;
        ExplicitIntegrator<dim> integrator(system);
        for (int s = 0; s < 60; ++s) integrator.step(P, 2e-4, s);
        results[threads - 1] = P;
    }
    omp_set_num_threads(saved);
    EXPECT_EQ(results[0].x, results[1].x);
    EXPECT_EQ(results[0].v, results[1].v);
    EXPECT_EQ(results[0].F_elastic, results[1].F_elastic);
    EXPECT_EQ(results[0].hardening, results[1].hardening);
    // Something happened: the block moved and deformed plastically.
    EXPECT_NE(results[0].x, initial.x);
    EXPECT_NE(results[0].hardening, initial.hardening);
}

TYPED_TEST(MpmTest, BlowUpIsReportedWithStepAndParticle) {
    constexpr int dim = TypeParam::value;
    MaterialDescription sand = material_preset("sand");
    MpmSystem<dim> system = make_system<dim>(32, sand, 9.8);
    Particles<dim> P = make_box<dim>(Vec<dim>::Constant(0.4), Vec<dim>::Constant(0.5), system.dx, sand.density);
    P.v[7][0] = std::nan("");
    ExplicitIntegrator<dim> integrator(system);
    try {
        integrator.step(P, 1e-4, 42);
        FAIL() << "expected SimulationError";
    } catch (const SimulationError& e) {
        EXPECT_NE(std::string(e.what()).find("step 42"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("particle"), std::string::npos) << e.what();
    }
}

}  // namespace
}  // namespace pnet
