#pragma once
// Helpers of the MPM-FEM coupling tests: a bit-for-bit comparison of two coupled runs' states
// (settings_for and same_bytes: support/identical_states.hpp), and the parts of one coupled
// implicit step set up by hand.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "pnet/coupling/coupled_potential.hpp"
#include "pnet/energy/particle_energy.hpp"
#include "pnet/mpm/transfer.hpp"
#include "pnet/scene/sampler.hpp"
#include "pnet/sim/coupled_simulation.hpp"
#include "support/identical_states.hpp"
#include "support/random.hpp"

namespace pnet::test {

/// The particles' positions, velocities and elastic F and the mesh's positions and velocities are identical.
template <int dim>
void expect_identical(const CoupledSimulation<dim>& a, const CoupledSimulation<dim>& b) {
    EXPECT_TRUE(same_bytes(a.particles().x, b.particles().x));
    EXPECT_TRUE(same_bytes(a.particles().v, b.particles().v));
    EXPECT_TRUE(same_bytes(a.particles().F_elastic, b.particles().F_elastic));
    EXPECT_TRUE(same_bytes(a.state().x, b.state().x));
    EXPECT_TRUE(same_bytes(a.state().v, b.state().v));
}

/// The parts of a coupled implicit step with the mesh within dhat of the bed, lagged (elastic)
/// energies, and lagged friction mu (smoothed below eps_v m/s).
template <int dim>
struct CoupledFixture {
    Scene scene;
    MpmSystem<dim> mpm = make_mpm_system<dim>(scene);
    Particles<dim> particles = sample_particles<dim>(scene);
    FemSceneSystem<dim> fem = make_fem_system<dim>(scene);
    FemState<dim> state = FemState<dim>::at_rest(fem.system);
    Grid<dim> grid{mpm.origin, mpm.dx, mpm.cells};
    ElasticParticleEnergy<dim> mpm_energy{mpm.materials};
    ElasticParticleEnergy<dim> fem_energy{fem.system.materials};
    IncrementalPotential<dim> mpm_potential{mpm_energy};
    FemPotential<dim> fem_potential{fem.system.mesh, fem.system.rest, fem_energy};
    Contact<dim> contact{fem.system.mesh.boundary,
                         {},
                         0.5 * scene.dx,
                         1e6,
                         ContactPoints{static_cast<int>(fem.system.mesh.nodes()), true}};
    CoupledPotential<dim> coupled{mpm_potential, fem_potential, contact};
    double dt = 1e-3;

    CoupledFixture(Scene s, double mu = 0.0, double eps_v = 1e-4) : scene(std::move(s)) {
        particles_to_grid<dim>(grid, particles, nullptr);
        BoundaryConditions bc = mpm.boundary;
        bc.slip_walls = false;
        grid.update_velocity(dt, mpm.gravity, bc);
        mpm_potential.begin_step(grid, particles, dt, bc);
        mpm_potential.set_reference(particles.F_elastic);
        const std::size_t n = fem.system.mesh.nodes();
        VecX v_star(dim * n);
        for (std::size_t i = 0; i < n; ++i) v_star.template segment<dim>(dim * i) = dt * mpm.gravity;
        fem_potential.begin_step(state.x, v_star, dt, state.plastic_inverse, {});
        fem_potential.set_material_state(fem.system.element_object, state.hardening);
        fem_potential.set_reference({});
        coupled.begin_step();
        std::vector<Vec<dim>> x;
        CoupledVertices<dim>::join(state.x, particles.x, x);
        coupled.set_friction(contact.lagged_pairs(x), mu, eps_v);
    }
};

/// v*, its free components (residual mass > 0) moved by up to 0.05 m/s at random.
template <int dim>
VecX perturbed_v_star(const CoupledPotential<dim>& coupled, Random& rng) {
    VecX v = coupled.v_star();
    for (Eigen::Index i = 0; i < v.size(); ++i)
        v[i] += 0.05 * rng.uniform(-1.0, 1.0) * (coupled.residual_mass()[i] > 0.0);
    return v;
}

/// At v with the block-preconditioned solve, the matrix-free product (three random directions)
/// and the diagonal apply the assembled Hessian H. Leaves that solve selected.
template <int dim>
void expect_matrix_free_hessian(CoupledPotential<dim>& coupled, const VecX& v, const Eigen::MatrixXd& H, Random& rng) {
    coupled.set_linear_solve(CoupledPotential<dim>::LinearSolve::BlockPreconditioned);
    VecX g;
    coupled.value_gradient_hessian(v, g);
    for (int trial = 0; trial < 3; ++trial) {
        const VecX d = rng.uniform_vector(v.size(), -1.0, 1.0);
        VecX Hd;
        coupled.hessian_multiply(d, Hd);
        EXPECT_LT((Hd - H * d).norm(), 1e-12 * (H * d).norm()) << "trial " << trial;
    }
    VecX diagonal;
    coupled.hessian_diagonal(diagonal);
    EXPECT_LT((diagonal - H.diagonal()).norm(), 1e-12 * H.diagonal().norm());
}

}  // namespace pnet::test
