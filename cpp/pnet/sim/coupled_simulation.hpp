#pragma once
// An MPM-FEM coupled run of a scene (BFEMP; docs/methods.md, docs/scenes.md): particle
// objects (MPM) and meshes (FEM, elastic) in one 2D or 3D scene, meeting through the
// particle / mesh barrier and its friction (the scene's contact.friction). The particles use the grid, materials and
// boundary conditions of an MPM run of the same objects (make_mpm_system, sample_particles), the meshes those of a FEM
// run (make_fem_system, with its own contact: ground, between meshes). Integrators: explicit (the ground truth, both
// symplectic Euler at one step), plasticitynet and lagged (the particles' energy; the meshes are elastic in both).
// Every frame ends with a test that no particle is inside a mesh (SimulationError if one is).
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "pnet/contact/collisions/contact.hpp"
#include "pnet/coupling/coupled_integrator.hpp"
#include "pnet/sim/fem_simulation.hpp"
#include "pnet/sim/mpm_simulation.hpp"
#include "pnet/sim/simulation_base.hpp"

namespace pnet {

/// The particle / mesh barrier of a coupled scene (the mesh's boundary facets, the particles as stand-alone points
/// after its nodes): contact.particle_dhat (default half a cell) and contact.particle_kappa (default IPC's lower
/// bound for the particles' average mass at the implicit MPM step).
template <int dim>
std::unique_ptr<Contact<dim>> make_particle_contact(const Scene& scene, const FemSystem<dim>& fem,
                                                    const Particles<dim>& particles);

template <int dim>
class CoupledSimulation : public SimulationBase, public WithParticles<dim>, public WithMesh<dim> {
public:
    static constexpr int kDim = dim;

    /// Throws std::invalid_argument for an unknown integrator, a bad dt or missing models
    /// (as Simulation), SceneError for a start state with a particle inside or on a mesh.
    CoupledSimulation(const Scene& scene, const IntegratorSettings& settings);

    /// One step (explicit with dt = 0: the smaller of the MPM CFL step and the FEM elements'),
    /// shortened to land on the end of the frame.
    StepRecord step() override;
    /// Advances to the end of the next frame, then tests for particles inside a mesh.
    FrameStats advance_frame(const std::function<void()>& after_step = {}) override;

    const Particles<dim>& particles() const override { return particles_; }
    const MpmSystem<dim>& system() const { return mpm_; }
    const FemState<dim>& state() const override { return state_; }
    const FemSceneSystem<dim>& scene_system() const override { return fem_; }
    const Mesh<dim>& mesh() const override { return fem_.system.mesh; }
    /// The particles against the meshes: a Contact whose stand-alone points are the particles.
    const Contact<dim>& coupling() const { return *coupling_; }
    /// Its positions now: the meshes' nodes, then the particles.
    const std::vector<Vec<dim>>& contact_positions() const;
    double step_size() const { return dt_; }

    /// Particles inside a mesh or on its boundary now (must be 0).
    std::size_t penetrations() const { return count_inside<dim>(particles_.x, state_.x, mesh().boundary); }

    /// Atomic; load refuses another scene, integrator or size (std::invalid_argument) and a missing
    /// file (FileNotFoundError).
    void save_checkpoint(const std::string& path) const override;
    void load_checkpoint(const std::string& path) override;

    /// dx, particles, mesh sizes, the particle / mesh barrier's dhat and kappa, the step.
    nlohmann::json describe() const override;
    void write_frame(const FrameFiles& files) const override;
    double contact_dhat() const override { return coupling_->dhat(); }
    nlohmann::json contact_state() const override;
    std::string size_text() const override;

private:
    MpmSystem<dim> mpm_;
    Particles<dim> particles_;
    FemSceneSystem<dim> fem_;
    FemState<dim> state_;
    std::unique_ptr<ContactPotential<dim>> fem_contact_;
    std::unique_ptr<Contact<dim>> coupling_;
    mutable std::vector<Vec<dim>> contact_x_;
    std::unique_ptr<CoupledImplicitIntegrator<dim>> implicit_;
    std::unique_ptr<CoupledExplicitIntegrator<dim>> explicit_;
    double dt_ = 0.0;
};

using CoupledSimulation2d = CoupledSimulation<2>;
using CoupledSimulation3d = CoupledSimulation<3>;

}  // namespace pnet
