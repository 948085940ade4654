#pragma once
// An MPM-FEM coupled run of a scene (BFEMP; docs/methods.md, docs/scenes.md): particle
// objects (MPM) and meshes (FEM, elastic) in one 2D scene, meeting through the
// particle / mesh barrier. The particles use the grid, materials and boundary
// conditions of an MPM run of the same objects (make_mpm_system,
// sample_particles), the meshes those of a FEM run (make_fem_system, with its
// own contact: ground, between meshes). Integrators: explicit (the ground
// truth, both symplectic Euler at one step), plasticitynet and lagged (the
// particles' energy; the meshes are elastic in both). Every frame ends with a
// test that no particle is inside a mesh (SimulationError if one is).
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "pnet/coupling/coupled_integrator.hpp"
#include "pnet/coupling/particle_contact.hpp"
#include "pnet/sim/fem_simulation.hpp"
#include "pnet/sim/mpm_simulation.hpp"
#include "pnet/sim/simulation_base.hpp"

namespace pnet {

class CoupledSimulation2d : public SimulationBase {
public:
    static constexpr int kDim = 2;

    /// Throws std::invalid_argument for an unknown integrator, a bad dt or missing models
    /// (as Simulation), SceneError for a start state with a particle inside or on a mesh.
    CoupledSimulation2d(const Scene& scene, const IntegratorSettings& settings);

    /// One step (explicit with dt = 0: the smaller of the MPM CFL step and the FEM elements'),
    /// shortened to land on the end of the frame.
    StepStats step();
    /// Advances to the end of the next frame, then tests for particles inside a mesh.
    FrameStats advance_frame(const std::function<void()>& after_step = {});

    const Particles<2>& particles() const { return particles_; }
    const MpmSystem<2>& system() const { return mpm_; }
    const FemState<2>& state() const { return state_; }
    const FemSceneSystem<2>& scene_system() const { return fem_; }
    const Mesh<2>& mesh() const { return fem_.system.mesh; }
    const ParticleContact2d& coupling() const { return *coupling_; }
    double step_size() const { return dt_; }

    /// Particles inside a mesh or on its boundary now (must be 0).
    std::size_t penetrations() const { return coupling_->penetrations(particles_.x, state_.x); }

    /// Atomic; load refuses another scene, integrator or size (std::invalid_argument) and a missing
    /// file (FileNotFoundError).
    void save_checkpoint(const std::string& path) const;
    void load_checkpoint(const std::string& path);

private:
    MpmSystem<2> mpm_;
    Particles<2> particles_;
    FemSceneSystem<2> fem_;
    FemState<2> state_;
    std::unique_ptr<ContactPotential<2>> fem_contact_;
    std::unique_ptr<ParticleContact2d> coupling_;
    std::unique_ptr<CoupledImplicitIntegrator2d> implicit_;
    std::unique_ptr<CoupledExplicitIntegrator2d> explicit_;
    double dt_ = 0.0;
};

}  // namespace pnet
