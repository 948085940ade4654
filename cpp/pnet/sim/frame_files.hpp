#pragma once
// A run's frame files (docs/simulating.md): per frame a PLY of the particles (and frame_N_mesh.ply
// of a coupled scene's mesh) or of the mesh, a picture (PNG, tagged with the run's id), and with
// `vtu` (always for 3D meshes) the VTK files ParaView reads. Each method's write_frame()
// (SimulationBase) calls the writer of what it holds.
#include <filesystem>
#include <string>

#include "pnet/fem/fem_integrator.hpp"
#include "pnet/fem/mesh.hpp"
#include "pnet/mpm/particles.hpp"
#include "pnet/scene/scene.hpp"

namespace pnet {

/// Where and how a run writes its frames.
class FrameFiles {
public:
    FrameFiles(const Scene& scene, std::filesystem::path out, std::string run_id, std::string color, bool vtu)
        : scene(scene), out(std::move(out)), run_id(std::move(run_id)), color(std::move(color)), vtu(vtu) {}

    const Scene& scene;         // its view (the pictures' frame), name and grid spacing
    std::filesystem::path out;  // the run's folder
    std::string run_id;         // written into every frame file
    std::string color;          // what the pictures colour: "speed" or "hardening"
    bool vtu;                   // also frame_N.vtu for particles and 2D meshes
};

/// Particles: frame_N.ply (position, velocity, mass, hardening), frame_N.png, frame_N.vtu.
template <int dim>
void write_particle_frame(const FrameFiles& files, const Particles<dim>& particles, int frame, double time);

/// A mesh: frame_N.ply (2D: the triangles; 3D: the boundary triangles), frame_N.png, and the VTU
/// (3D always: the whole tetrahedral mesh).
template <int dim>
void write_mesh_frame(const FrameFiles& files, const FemState<dim>& state, const Mesh<dim>& mesh, int frame,
                      double time);

/// Particles and a mesh (MPM-FEM coupling): the particles as frame_N.ply, the mesh as
/// frame_N_mesh.ply (3D: its surface), and one PNG with the mesh drawn over the particles (3D: the
/// surface and the particles in one depth buffer).
template <int dim>
void write_coupled_frame(const FrameFiles& files, const Particles<dim>& particles, const FemState<dim>& state,
                         const Mesh<dim>& mesh, int frame, double time);

}  // namespace pnet
