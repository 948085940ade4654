#pragma once
// Time integrators of MPM-FEM coupling (BFEMP; docs/methods.md), 2D: MPM
// particles (sand, snow: any MPM material) and elastic FEM bodies meeting
// through the particle / mesh barrier (particle_contact.hpp).
//
// Implicit (`plasticitynet`, `lagged` for the particles): one step is
//   P2G, v*_grid (sticky floor fixed; slip walls after the solve, as MPM);
//   v*_fem = v^n + dt g;
//   minimize the coupled incremental potential (coupled_potential.hpp) over
//   [v_grid; v_fem] with the one Newton loop (CHOLMOD on the assembled
//   Hessian) from [v*_grid; v*_fem] scaled by what CCD allows (so the start is
//   intersection-free), with the fixed point on F0 for plasticitynet;
//   G2P (return mapping, advection x_p += dt sum_i w_ip v_i: exactly the X_p(v)
//   the barrier saw), x_fem += dt v_fem, the FEM return mapping.
// Explicit (the ground truth): symplectic Euler of both with the same
// barrier as a force, -dB/dX_p on each particle (spread to its stencil nodes
// with w_ip after the grid update) and -dB/dx_a on the FEM nodes; the step's
// motion (particles by their grid velocities, nodes by theirs) is checked by
// CCD, and a step that would let a particle cross the mesh is an error
// (SimulationError: the step is too large for the barrier).
#include <memory>
#include <vector>

#include "pnet/coupling/coupled_potential.hpp"
#include "pnet/coupling/particle_contact.hpp"
#include "pnet/fem/fem_integrator.hpp"
#include "pnet/mpm/explicit_integrator.hpp"
#include "pnet/mpm/implicit_integrator.hpp"
#include "pnet/mpm/mpm_system.hpp"

namespace pnet {

class CoupledImplicitIntegrator2d {
public:
    /// mpm_energy: the particles' energy (NeuralParticleEnergy for plasticitynet,
    /// ElasticParticleEnergy for lagged); return_maps as ImplicitIntegrator's; fem_contact: the
    /// meshes' own contact (ground, between meshes), may be null.
    CoupledImplicitIntegrator2d(const MpmSystem<2>& mpm, const FemSystem<2>& fem, ImplicitMethod method,
                                const ImplicitOptions& options, std::unique_ptr<ParticleEnergy<2>> mpm_energy,
                                std::vector<const LearnedReturnMap<2>*> return_maps,
                                const ContactPotential<2>* fem_contact, const ParticleContact2d& contact);

    /// Throws SimulationError naming the step on a failed solve or a blow-up.
    StepStats step(Particles<2>& particles, FemState<2>& state, double dt, long step_index);

    CoupledPotential2d& potential() { return coupled_; }
    const Grid<2>& grid() const { return grid_; }

private:
    const MpmSystem<2>& mpm_system_;
    const FemSystem<2>& fem_system_;
    ImplicitMethod method_;
    ImplicitOptions options_;
    std::unique_ptr<ParticleEnergy<2>> mpm_energy_;
    std::vector<const LearnedReturnMap<2>*> return_maps_;
    Grid<2> grid_;
    IncrementalPotential<2> mpm_;
    ElasticParticleEnergy<2> fem_energy_;
    FemPotential<2> fem_;
    CoupledPotential2d coupled_;
    ReferenceSolveWork<2> work_;
    VecX v_;
};

class CoupledExplicitIntegrator2d {
public:
    CoupledExplicitIntegrator2d(const MpmSystem<2>& mpm, const FemSystem<2>& fem,
                                const ContactPotential<2>* fem_contact, const ParticleContact2d& contact);

    /// One symplectic Euler step of both (the FEM part in as many substeps as its elements need).
    StepStats step(Particles<2>& particles, FemState<2>& state, double dt, long step_index);

    /// The MPM part's cached stresses (checkpoints: bit-identical resume).
    ExplicitIntegrator<2>& mpm() { return mpm_; }
    /// The largest stable step: the MPM CFL step and the FEM elements' (cfl 0.5 each).
    double cfl_time_step(const Particles<2>& particles, double cfl) const;

private:
    const MpmSystem<2>& mpm_system_;
    ExplicitIntegrator<2> mpm_;
    FemExplicitIntegrator<2> fem_;
    const ParticleContact2d& contact_;
    std::vector<ParticleContact2d::Pair> pairs_;
    std::vector<Vec6> gradients_;
    std::vector<Vec<2>> node_force_, x_start_, dx_, near_X_, near_dX_;
};

}  // namespace pnet
