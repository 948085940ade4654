#pragma once
// Time integrators of MPM-FEM coupling (BFEMP; docs/methods.md), 2D and 3D: MPM
// particles (sand, snow: any MPM material) and elastic FEM bodies meeting
// through the particle / mesh barrier (a Contact whose stand-alone points are
// the particles, contact/collisions/contact.hpp) and its lagged
// friction (Coulomb coefficient mu: the scene's contact.friction, which also
// holds between the meshes and the ground).
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
// with w_ip after the grid update) and -dB/dx_a on the FEM nodes; friction as
// Coulomb impulses on the same lagged pairs after the grid update (pair by pair,
// each at most mu lambda h and at most what stops the pair's slip: the particle's
// grid velocity against the facet's point, through the effective mass
// 1 / (sum_i w_ip^2 / m_i + sum_j c_j^2 / m_j)), as the FEM contact's; the step's
// motion (particles by their grid velocities, nodes by theirs) is checked by
// CCD, and a step that would let a particle cross the mesh is an error
// (SimulationError: the step is too large for the barrier).
#include <memory>
#include <vector>

#include "pnet/contact/friction.hpp"
#include "pnet/coupling/coupled_potential.hpp"
#include "pnet/coupling/coupling_options.hpp"
#include "pnet/fem/fem_integrator.hpp"
#include "pnet/mpm/explicit_integrator.hpp"
#include "pnet/mpm/implicit_integrator.hpp"
#include "pnet/mpm/mpm_step_stats.hpp"
#include "pnet/mpm/mpm_system.hpp"

namespace pnet {

/// What a coupled step returns: the particles' fields and the meshes'.
using CoupledStepStats = StepStatsWith<MpmStepFields, FemStepFields, ContactStepFields>;

/// Coulomb friction of every contact pair of a coupled scene: coefficient mu >= 0 (0: none) and
/// the slip velocity eps_v > 0 (m/s) below which the implicit integrators smooth it.
struct CouplingFriction {
    double mu = 0.0;
    double eps_v = 1e-4;
};

template <int dim>
class CoupledImplicitIntegrator {
public:
    /// mpm_energy: the particles' energy (NeuralParticleEnergy for plasticitynet,
    /// ElasticParticleEnergy for lagged); return_maps as ImplicitIntegrator's; fem_contact: the
    /// meshes' own contact (ground, between meshes), may be null.
    CoupledImplicitIntegrator(const MpmSystem<dim>& mpm, const FemSystem<dim>& fem, ImplicitMethod method,
                              const ImplicitOptions& options, const MpmOptions& mpm_options,
                              const CouplingOptions& coupling_options, std::unique_ptr<ParticleEnergy<dim>> mpm_energy,
                              std::vector<const LearnedReturnMap<dim>*> return_maps,
                              const ContactPotential<dim>* fem_contact, const ContactPotential<dim>& contact,
                              CouplingFriction friction = {});

    /// Throws SimulationError naming the step on a failed solve or a blow-up.
    CoupledStepStats step(Particles<dim>& particles, FemState<dim>& state, double dt, long step_index);

    CoupledPotential<dim>& potential() { return coupled_; }
    /// The last step's solution [grid velocities; node velocities] (before the slip walls' projection).
    const VecX& solution() const { return v_; }
    /// The grid's Newton start predicted from the last step (MpmOptions::newton_start; the mesh's nodes
    /// start at v*): empty before the first step or after one that did not converge. Checkpoints keep it.
    const StepPredictor<dim>& predictor() const { return predictor_; }
    StepPredictor<dim>& predictor() { return predictor_; }
    const Grid<dim>& grid() const { return grid_; }

private:
    /// The step's solve, from v* or (`predicted`) v* plus the grid's Newton start prediction (as far as
    /// CCD allows), into v_ and `stats`: both potentials set up on grid_'s P2G and the state, then the
    /// Newton solves (floor_friction_passes.hpp).
    void solve_step(const Particles<dim>& particles, const FemState<dim>& state, double dt, const std::string& context,
                    const BoundaryConditions& solve_boundary, bool predicted, CoupledStepStats& stats);

    const MpmSystem<dim>& mpm_system_;
    const FemSystem<dim>& fem_system_;
    ImplicitMethod method_;
    ImplicitOptions options_;
    MpmOptions mpm_options_;
    CouplingOptions coupling_options_;
    std::unique_ptr<ParticleEnergy<dim>> mpm_energy_;
    std::vector<const LearnedReturnMap<dim>*> return_maps_;
    const ContactPotential<dim>* fem_contact_;
    const ContactPotential<dim>& contact_;  // the particles against the meshes
    CouplingFriction friction_;
    Friction<dim> mesh_friction_;      // the meshes' own pairs (ground, between meshes)
    std::vector<Vec<dim>> contact_x_;  // the contact's positions: the mesh's nodes, then the particles
    Grid<dim> grid_;
    IncrementalPotential<dim> mpm_;
    ElasticParticleEnergy<dim> fem_energy_;
    FemPotential<dim> fem_;
    CoupledPotential<dim> coupled_;
    ReferenceSolveWork<dim> work_;
    VecX v_;
    StepPredictor<dim> predictor_;    // MpmOptions::newton_start "last_step", on the grid's unknowns
    std::vector<Vec<dim>> residual_;  // AFLIP's r_p (MpmSystem::flip_relaxation_time)
};

template <int dim>
class CoupledExplicitIntegrator {
public:
    CoupledExplicitIntegrator(const MpmSystem<dim>& mpm, const FemSystem<dim>& fem,
                              const ContactPotential<dim>* fem_contact, const ContactPotential<dim>& contact,
                              CouplingFriction friction = {});

    /// One symplectic Euler step of both (the FEM part in as many substeps as its elements need).
    CoupledStepStats step(Particles<dim>& particles, FemState<dim>& state, double dt, long step_index);

    /// The MPM part's cached stresses (checkpoints: bit-identical resume).
    ExplicitIntegrator<dim>& mpm() { return mpm_; }
    /// The largest stable step: the MPM CFL step and the FEM elements' (cfl 0.5 each).
    double cfl_time_step(const Particles<dim>& particles, double cfl) const;

private:
    /// Coulomb impulses of the lagged particle-mesh pairs on the grid velocities and the FEM
    /// nodes' velocities over a step h.
    void apply_friction(Grid<dim>& grid, const Particles<dim>& particles, FemState<dim>& state, double h) const;

    const MpmSystem<dim>& mpm_system_;
    const FemSystem<dim>& fem_system_;
    ExplicitIntegrator<dim> mpm_;
    FemExplicitIntegrator<dim> fem_;
    const ContactPotential<dim>& contact_;
    CouplingFriction friction_;
    Friction<dim> mesh_friction_;
    std::vector<ContactPairTerms<dim>> pairs_;  // the barrier's at the step's start
    std::vector<FrictionPair<dim>> friction_pairs_;
    std::vector<Vec<dim>> node_force_, x_start_, dx_, contact_x_, contact_dx_;
};

using CoupledImplicitIntegrator2d = CoupledImplicitIntegrator<2>;
using CoupledExplicitIntegrator2d = CoupledExplicitIntegrator<2>;

}  // namespace pnet
