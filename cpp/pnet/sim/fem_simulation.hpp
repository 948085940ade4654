#pragma once
// A FEM run of a scene (docs/methods.md, docs/scenes.md; 2D and 3D): the meshes of the scene's
// "meshes" (gmsh shapes or .msh files) joined into one mesh, one material per
// mesh, kinematic meshes (the plate) as prescribed-velocity nodes; IPC contact
// over the joined boundary (bodies, self-contact, the ground) with lagged
// friction; the integrator of the settings (explicit, plasticitynet, lagged,
// analytic); frame-by-frame advance with contact statistics and an exact
// intersection test at every frame end; checkpoints that resume bit-identically.
//
// The barrier stiffness is a property of the scene, not of the run: the same
// kappa for every integrator and step (Scene::Contact: by default 100 x IPC's
// lower bound for a 1e-2 s step), so that runs at different dt solve the same
// physics and can be compared.
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "pnet/contact/friction.hpp"
#include "pnet/contact/collisions/contact.hpp"
#include "pnet/fem/fem_integrator.hpp"
#include "pnet/scene/scene.hpp"
#include "pnet/sim/run_stats.hpp"
#include "pnet/sim/simulation_base.hpp"

namespace pnet {

/// The FEM system a scene describes, and where each mesh lies in it.
template <int dim>
struct FemSceneSystem {
    FemSystem<dim> system;
    std::vector<int> first_node;     // per mesh, and the node count at the end
    std::vector<int> first_element;  // per mesh, and the element count at the end
    double diagonal = 0.0;           // bounding-box diagonal of the rest positions, m
    double dhat = 0.0;               // m
    double kappa = 0.0;              // J/m^4

    /// Index of the mesh that holds `node`.
    int mesh_of_node(int node) const;
};

/// Meshes the scene (gmsh), builds the system and the contact parameters and
/// checks the start state: a mesh that intersects another, itself or the
/// ground is refused (SceneError naming the file, the meshes and the pair), as
/// is an empty mesh file (MeshError naming it).
template <int dim>
FemSceneSystem<dim> make_fem_system(const Scene& scene);

/// The meshes' IPC contact (Contact<dim>: between meshes, self-contact, and the ground
/// half-space when the scene has contact.ground_height) with the system's dhat and kappa.
template <int dim>
std::unique_ptr<ContactPotential<dim>> make_fem_contact(const Scene& scene, const FemSceneSystem<dim>& s);

/// A method with meshes (FEM, coupling): their state, the meshes and how the scene's meshes were
/// built into one system (what the Python bindings read).
template <int dim>
class WithMesh {
public:
    static constexpr int kDim = dim;
    virtual ~WithMesh() = default;
    virtual const FemState<dim>& state() const = 0;
    virtual const Mesh<dim>& mesh() const = 0;
    virtual const FemSceneSystem<dim>& scene_system() const = 0;
};

template <int dim>
class FemSimulation : public SimulationBase, public WithMesh<dim> {
public:
    static constexpr int kDim = dim;

    /// Throws std::invalid_argument for an unknown integrator, a bad dt, or a
    /// model that is missing or unfit ("<scene file>: meshes[k].model: ...");
    /// SceneError for an intersecting start.
    FemSimulation(const Scene& scene, const IntegratorSettings& settings);

    /// One step of the integrator's dt (explicit with dt = 0: the CFL step of
    /// the elements), shortened to land on the end of the frame. Throws
    /// SimulationError on a failed solve or a blow-up.
    StepRecord step() override;
    /// Advances to the end of the next frame (see Simulation::advance_frame),
    /// then tests the meshes for intersection exactly (SimulationError if any).
    FrameStats advance_frame(const std::function<void()>& after_step = {}) override;

    const FemState<dim>& state() const override { return state_; }
    const FemSceneSystem<dim>& scene_system() const override { return built_; }
    const FemSystem<dim>& system() const { return built_.system; }
    const Mesh<dim>& mesh() const override { return built_.system.mesh; }
    const ContactPotential<dim>& contact() const { return *contact_; }
    /// The step the integrator takes (explicit with dt = 0: the CFL step), s.
    double step_size() const { return dt_; }

    /// As Simulation: atomic, refuses another scene, integrator or mesh size.
    void save_checkpoint(const std::string& path) const override;
    void load_checkpoint(const std::string& path) override;

    /// Mesh sizes, the scene meshes' first nodes and elements, the contact's dhat and kappa, the step.
    nlohmann::json describe() const override;
    void write_frame(const FrameFiles& files) const override;
    double contact_dhat() const override { return built_.dhat; }
    nlohmann::json contact_state() const override;
    std::string size_text() const override;

private:
    FemSceneSystem<dim> built_;
    FemState<dim> state_;
    std::unique_ptr<ContactPotential<dim>> contact_;
    std::unique_ptr<Friction<dim>> friction_;
    std::unique_ptr<FemImplicitIntegrator<dim>> implicit_;
    std::unique_ptr<FemExplicitIntegrator<dim>> explicit_;
    double dt_ = 0.0;
};

}  // namespace pnet
