#include "pnet/sim/frame_files.hpp"

#include <algorithm>
#include <array>
#include <cstdio>
#include <map>
#include <string>
#include <vector>

#include "pnet/io/ply.hpp"
#include "pnet/io/png.hpp"
#include "pnet/io/render.hpp"
#include "pnet/io/run_folder.hpp"
#include "pnet/io/vtu.hpp"

namespace pnet {

namespace {

namespace fs = std::filesystem;

std::string frame_name(int frame, const char* extension) {
    char name[64];
    std::snprintf(name, sizeof name, "frame_%05d.%s", frame, extension);
    return name;
}

/// A frame's picture, tagged with the run that drew it.
void write_frame_png(const fs::path& path, Image image, const FrameFiles& o) {
    if (!o.run_id.empty()) image.text[kPngRunIdKey] = o.run_id;
    write_png(path.string(), image);
}

/// The particles as a PLY record, written to frame_N.ply, with each particle's colour value (speed or hardening).
template <int dim>
PlyParticles write_particles(const Particles<dim>& P, int frame, const FrameFiles& o, const fs::path& out,
                             std::vector<double>& colour) {
    PlyParticles ply;
    ply.dim = dim;
    ply.run_id = o.run_id;
    colour.resize(P.size());
    for (std::size_t p = 0; p < P.size(); ++p) {
        for (int a = 0; a < dim; ++a) {
            ply.position.push_back(P.x[p][a]);
            ply.velocity.push_back(P.v[p][a]);
        }
        ply.mass.push_back(P.mass[p]);
        ply.hardening.push_back(P.hardening[p]);
        colour[p] = o.color == "speed" ? P.v[p].norm() : P.hardening[p];
    }
    write_particles_ply((out / frame_name(frame, "ply")).string(), ply);
    return ply;
}

/// The particles of a frame as a VTK unstructured grid of vertices (ParaView's particle view).
void write_particles_vtu(const fs::path& path, const PlyParticles& ply) {
    VtuMesh m;
    m.dim = ply.dim;
    m.position = ply.position;
    m.point_data = {{"velocity", ply.dim, ply.velocity}, {"mass", 1, ply.mass}, {"hardening", 1, ply.hardening}};
    write_vtu(path.string(), m);
}

/// A 2D FEM frame as a VTK unstructured grid of triangles.
void write_mesh_vtu(const fs::path& path, const PlyMesh& ply) {
    VtuMesh m;
    m.dim = 2;
    m.position = ply.position;
    m.cells = ply.triangles;
    m.point_data = {{"velocity", 2, ply.velocity}};
    m.cell_data = {{"hardening", 1, ply.hardening}};
    write_vtu(path.string(), m);
}

/// How a frame's picture is drawn: the scene's view, a caption with the time, and the colour scale
/// (speed from 0 to speed_max m/s, or the range of the hardening values in `colour`).
ParticleRenderOptions frame_render_options(const Scene& scene, double time, int dim, const FrameFiles& o,
                                           const std::vector<double>& colour, double speed_max) {
    ParticleRenderOptions r;
    r.legend = true;
    r.value_label = o.color == "speed" ? "speed (m/s)" : o.color;
    r.value_min = o.color == "speed" ? 0.0 : *std::min_element(colour.begin(), colour.end());
    r.value_max = o.color == "speed"
                      ? speed_max
                      : std::max(r.value_min + 1e-6, *std::max_element(colour.begin(), colour.end()));
    for (int a = 0; a < dim; ++a) {
        r.domain_min[a] = scene.view_min[a];
        r.domain_max[a] = scene.view_max[a];
    }
    char caption[128];
    std::snprintf(caption, sizeof caption, "%s  t = %.3f s  (%s)", scene.name.c_str(), time, o.color.c_str());
    r.caption = caption;
    r.width_px = dim == 2 ? 640 : 720;
    return r;
}

/// Particle pictures: disks sized from the particles' lattice spacing, speeds up to 3 m/s.
ParticleRenderOptions particle_render_options(const Scene& scene, double time, int dim, const FrameFiles& o,
                                              const std::vector<double>& colour) {
    ParticleRenderOptions r = frame_render_options(scene, time, dim, o, colour, 3.0);
    r.grid_spacing_m = scene.dx;
    r.particle_spacing_m = scene.dx / scene.particles_per_cell;
    return r;
}

/// Mesh pictures: speeds up to twice the fastest prescribed or initial speed (the plate's 0.05 m/s:
/// 0.1 m/s).
ParticleRenderOptions mesh_render_options(const Scene& scene, double time, int dim, const FrameFiles& o,
                                          const std::vector<double>& colour) {
    double speed_scale = 0.0;
    for (const SceneMesh& m : scene.meshes) speed_scale = std::max(speed_scale, m.velocity.norm());
    return frame_render_options(scene, time, dim, o, colour, std::max(0.1, 2.0 * speed_scale));
}

/// A mesh frame's nodes: every node's position and velocity.
template <int dim>
PlyMesh mesh_nodes(const FemState<dim>& state, const FrameFiles& o) {
    PlyMesh ply;
    ply.run_id = o.run_id;
    ply.dim = dim;
    for (std::size_t i = 0; i < state.x.size(); ++i)
        for (int a = 0; a < dim; ++a) {
            ply.position.push_back(state.x[i][a]);
            ply.velocity.push_back(state.v[i][a]);
        }
    return ply;
}

/// A 2D mesh frame: every node and triangle, each triangle coloured by its mean speed or hardening.
PlyMesh mesh_frame(const FemState<2>& state, const Mesh<2>& mesh, const FrameFiles& o, std::vector<double>& colour) {
    PlyMesh ply = mesh_nodes(state, o);
    colour.resize(mesh.elements.size());
    for (std::size_t e = 0; e < mesh.elements.size(); ++e) {
        Vec<2> v = Vec<2>::Zero();
        for (int a = 0; a < 3; ++a) {
            ply.triangles.push_back(mesh.elements[e][a]);
            v += state.v[mesh.elements[e][a]] / 3.0;
        }
        ply.hardening.push_back(state.hardening[e]);
        colour[e] = o.color == "speed" ? v.norm() : state.hardening[e];
    }
    return ply;
}

}  // namespace

template <int dim>
void write_particle_frame(const FrameFiles& o, const Particles<dim>& particles, int frame, double time) {
    const fs::path& out = o.out;
    std::vector<double> colour;
    const PlyParticles ply = write_particles(particles, frame, o, out, colour);
    if (o.vtu) write_particles_vtu(out / frame_name(frame, "vtu"), ply);
    const ParticleRenderOptions r = particle_render_options(o.scene, time, dim, o, colour);
    const Image image =
        dim == 2 ? render_particles_2d(ply.position, colour, r) : render_particles_3d(ply.position, colour, r);
    write_frame_png(out / frame_name(frame, "png"), image, o);
}

namespace {

/// The element each boundary facet of a 3D mesh belongs to (the one element that has it).
std::vector<int> boundary_owner(const Mesh<3>& mesh) {
    std::map<std::array<int, 3>, int> owner;
    for (std::size_t e = 0; e < mesh.elements.size(); ++e)
        for (int skip = 0; skip < 4; ++skip) {
            std::array<int, 3> face;
            for (int k = 0, j = 0; k < 4; ++k)
                if (k != skip) face[j++] = mesh.elements[e][k];
            std::sort(face.begin(), face.end());
            owner[face] = static_cast<int>(e);
        }
    std::vector<int> out;
    for (std::array<int, 3> face : mesh.boundary) {
        std::sort(face.begin(), face.end());
        out.push_back(owner.at(face));
    }
    return out;
}

/// A 3D mesh's frame: every node with the boundary triangles (the PLY), each triangle coloured by
/// its element's speed or hardening.
PlyMesh mesh_frame(const FemState<3>& state, const Mesh<3>& mesh, const FrameFiles& o, std::vector<double>& colour) {
    const std::vector<int> owner = boundary_owner(mesh);
    PlyMesh ply = mesh_nodes(state, o);
    colour.resize(mesh.boundary.size());
    for (std::size_t f = 0; f < mesh.boundary.size(); ++f) {
        const int e = owner[f];
        for (int a = 0; a < 3; ++a) ply.triangles.push_back(mesh.boundary[f][a]);
        ply.hardening.push_back(state.hardening[e]);
        Vec<3> v = Vec<3>::Zero();
        for (int a = 0; a < 4; ++a) v += state.v[mesh.elements[e][a]] / 4.0;
        colour[f] = o.color == "speed" ? v.norm() : state.hardening[e];
    }
    return ply;
}

/// The whole tetrahedral mesh as VTU (ParaView): node velocities, element hardening.
void write_mesh_vtu(const fs::path& path, const FemState<3>& state, const Mesh<3>& mesh, const PlyMesh& ply) {
    VtuMesh vtu;
    vtu.dim = 3;
    vtu.position = ply.position;
    for (const auto& el : mesh.elements) vtu.cells.insert(vtu.cells.end(), el.begin(), el.end());
    vtu.point_data.push_back({"velocity", 3, ply.velocity});
    vtu.cell_data.push_back({"hardening", 1, state.hardening});
    write_vtu(path.string(), vtu);
}

}  // namespace

/// A 2D FEM frame: the mesh (PLY, optionally VTU) and its picture.
template <>
void write_mesh_frame<2>(const FrameFiles& o, const FemState<2>& state, const Mesh<2>& mesh, int frame, double time) {
    const fs::path& out = o.out;
    std::vector<double> colour;
    const PlyMesh ply = mesh_frame(state, mesh, o, colour);
    write_mesh_ply((out / frame_name(frame, "ply")).string(), ply);
    if (o.vtu) write_mesh_vtu(out / frame_name(frame, "vtu"), ply);
    const ParticleRenderOptions r = mesh_render_options(o.scene, time, 2, o, colour);
    write_frame_png(out / frame_name(frame, "png"), render_mesh_2d(ply.position, ply.triangles, colour, r), o);
}

/// A 3D FEM frame: every node with the boundary triangles (PLY), the whole tetrahedral
/// mesh (VTU, for ParaView), and a shaded render of the surface (PNG).
template <>
void write_mesh_frame<3>(const FrameFiles& o, const FemState<3>& state, const Mesh<3>& mesh, int frame, double time) {
    const fs::path& out = o.out;
    std::vector<double> colour;
    const PlyMesh ply = mesh_frame(state, mesh, o, colour);
    write_mesh_ply((out / frame_name(frame, "ply")).string(), ply);
    write_mesh_vtu(out / frame_name(frame, "vtu"), state, mesh, ply);
    const ParticleRenderOptions r = mesh_render_options(o.scene, time, 3, o, colour);
    write_frame_png(out / frame_name(frame, "png"), render_mesh_3d(ply.position, ply.triangles, colour, r), o);
}

template <int dim>
void write_coupled_frame(const FrameFiles& o, const Particles<dim>& particle_state, const FemState<dim>& state,
                         const Mesh<dim>& mesh, int frame, double time) {
    const fs::path& out = o.out;
    std::vector<double> colour;
    const PlyParticles particles = write_particles(particle_state, frame, o, out, colour);
    if (o.vtu) write_particles_vtu(out / frame_name(frame, "vtu"), particles);
    std::vector<double> mesh_colour;
    const PlyMesh ply = mesh_frame(state, mesh, o, mesh_colour);
    char mesh_name[64];
    std::snprintf(mesh_name, sizeof mesh_name, "frame_%05d_mesh.ply", frame);
    write_mesh_ply((out / mesh_name).string(), ply);
    if (o.vtu) {
        std::snprintf(mesh_name, sizeof mesh_name, "frame_%05d_mesh.vtu", frame);
        if constexpr (dim == 2)
            write_mesh_vtu(out / mesh_name, ply);
        else
            write_mesh_vtu(out / mesh_name, state, mesh, ply);
    }
    const ParticleRenderOptions r = particle_render_options(o.scene, time, dim, o, colour);
    if (o.color == "hardening") mesh_colour.clear();  // the mesh has no hardening: one colour
    if constexpr (dim == 3) {
        const SurfaceMesh surface{ply.position, ply.triangles, mesh_colour};
        write_frame_png(out / frame_name(frame, "png"), render_particles_3d(particles.position, colour, r, &surface),
                        o);
    } else {
        Image image = render_particles_2d(particles.position, colour, r);
        const Image drawn = render_mesh_2d(ply.position, ply.triangles, mesh_colour, r);
        // The same frame and scale when both renders have the same margin (the particle disks are
        // small): the mesh's pixels are copied over the particles.
        if (drawn.width == image.width && drawn.height == image.height)
            for (int y = 0; y < image.height; ++y)
                for (int x = 0; x < image.width; ++x) {
                    const Rgb c = drawn.get(x, y);
                    if (!(c.r == 255 && c.g == 255 && c.b == 255)) image.set(x, y, c);
                }
        write_frame_png(out / frame_name(frame, "png"), image, o);
    }
}

template void write_particle_frame<2>(const FrameFiles&, const Particles<2>&, int, double);
template void write_particle_frame<3>(const FrameFiles&, const Particles<3>&, int, double);
template void write_coupled_frame<2>(const FrameFiles&, const Particles<2>&, const FemState<2>&, const Mesh<2>&, int,
                                     double);
template void write_coupled_frame<3>(const FrameFiles&, const Particles<3>&, const FemState<3>&, const Mesh<3>&, int,
                                     double);

}  // namespace pnet
