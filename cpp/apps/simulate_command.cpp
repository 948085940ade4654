#include "simulate_command.hpp"

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <type_traits>

#include "pnet/io/atomic_file.hpp"
#include "pnet/io/ply.hpp"
#include "pnet/io/png.hpp"
#include "pnet/io/render.hpp"
#include "pnet/io/vtu.hpp"
#include "pnet/nn/model_file.hpp"
#include "pnet/nn/torchscript.hpp"
#include "pnet/sim/threads.hpp"
#include "pnet/scene/scene.hpp"
#include "pnet/sim/coupled_simulation.hpp"
#include "parse_number.hpp"
#include "pnet/sim/fem_simulation.hpp"
#include "pnet/sim/mpm_simulation.hpp"
#include "pnet/sim/scene_models.hpp"

namespace pnet::apps {

namespace {

namespace fs = std::filesystem;

constexpr const char* kUsage =
    "usage: pnet simulate SCENE.json --out DIR [--integrator explicit|plasticitynet|lagged|analytic] [--dt SECONDS]\n"
    "                     [--cfl C] [--frames N] [--threads T] [--checkpoint-every N] [--resume]\n"
    "                     [--color speed|hardening] [--model FILE.pt] [--trust-model] [--vtu]\n"
    "  implicit solver (plasticitynet, lagged; defaults from the scene's integrator block):\n"
    "                     [--newton-tol M_PER_S] [--cg-tol R] [--outer-iteration newton|fixed_point]\n"
    "                     [--time-integrator backward_euler|bdf2]\n"
    "                     [--hessian auto|network|tangent] [--fixed-point-iterations N]\n"
    "                     [--fixed-point-tol T] [--regularizer W] [--preconditioner jacobi|block_jacobi|ichol]\n"
    "                     [--lazy-hessian R] [--fixed-point-anderson M] [--fixed-point-keep-hessian yes|no]\n"
    "                     [--fixed-point-inexact FORCING]\n"
    "                     [--fail-on-unconverged]\n"
    "  FEM scenes (meshes): analytic is the closed-form StVK-Hencky + von Mises energy;\n"
    "                     [--analytic-regularizer W] (analytic + W mu/2 |F - F0|^2 under plasticitynet's outer\n"
    "                     iteration: the learned solve without learning error, a diagnostic)\n"
    "                     [--return-map learned|exact] (plasticitynet: a model's learned return mapping or the\n"
    "                     material's exact one) [--kinematic-start scaled|last_velocity]\n";

struct Options {
    std::string scene, out, integrator, color = "speed";
    std::optional<std::string> model;  // --model: the energy model of every object and mesh that names one
    std::optional<double> dt, cfl;
    int frames = -1, threads = 0, checkpoint_every = 10;
    bool resume = false, trust_model = false, fail_on_unconverged = false;
    bool vtu = false;  // also frame_NNNNN.vtu (ParaView) for particles and 2D meshes
    // Implicit solver overrides (unset: the scene's value).
    std::optional<double> newton_tol, cg_tol, fixed_point_tol, regularizer, lazy_hessian, fixed_point_inexact;
    std::optional<double> analytic_regularizer;
    std::optional<std::string> preconditioner, return_map, outer_iteration, hessian, kinematic_start, time_integrator;
    std::optional<int> fixed_point_iterations, fixed_point_anderson;
    std::optional<bool> fixed_point_keep_hessian;
};

class UsageError : public std::invalid_argument {
public:
    using std::invalid_argument::invalid_argument;
};

Options parse(int argc, char** argv) {
    Options o;
    for (int i = 1; i < argc; ++i) {
        const std::string arg = argv[i];
        auto value = [&]() -> std::string {
            if (i + 1 >= argc) throw UsageError(arg + " needs a value");
            return argv[++i];
        };
        auto number = [&](const std::string& text) {
            const std::optional<double> v = parse_number(text);
            if (!v) throw UsageError(arg + ": expected a number, got \"" + text + "\"");
            return *v;
        };
        // A whole number in [lo, hi], else a message naming the option and the range.
        auto integer = [&](const std::string& text, long lo, long hi, const char* meaning) {
            const double v = number(text);
            if (!(v >= double(lo) && v <= double(hi)) || v != std::floor(v))
                throw UsageError(arg + " must be a whole number in [" + std::to_string(lo) + ", " + std::to_string(hi) +
                                 "]" + meaning + ", got \"" + text + "\"");
            return static_cast<int>(v);
        };
        if (arg == "--out")
            o.out = value();
        else if (arg == "--integrator")
            o.integrator = value();
        else if (arg == "--dt")
            o.dt = number(value());
        else if (arg == "--cfl")
            o.cfl = number(value());
        else if (arg == "--frames")
            o.frames = integer(value(), 1, 10000000, " (frames to simulate)");
        else if (arg == "--threads")
            o.threads = integer(value(), 0, 1024, " (0: all cores)");
        else if (arg == "--checkpoint-every")
            o.checkpoint_every = integer(value(), 0, 10000000, " (frames between checkpoints; 0: none)");
        else if (arg == "--newton-tol")
            o.newton_tol = number(value());
        else if (arg == "--cg-tol")
            o.cg_tol = number(value());
        else if (arg == "--fixed-point-tol")
            o.fixed_point_tol = number(value());
        else if (arg == "--regularizer")
            o.regularizer = number(value());
        else if (arg == "--analytic-regularizer")
            o.analytic_regularizer = number(value());
        else if (arg == "--lazy-hessian")
            o.lazy_hessian = number(value());
        else if (arg == "--preconditioner")
            o.preconditioner = value();
        else if (arg == "--time-integrator") {
            const std::string text = value();
            if (text != "backward_euler" && text != "bdf2")
                throw UsageError("--time-integrator: expected backward_euler or bdf2, got \"" + text + "\"");
            o.time_integrator = text;
        } else if (arg == "--outer-iteration") {
            const std::string text = value();
            if (text != "newton" && text != "fixed_point")
                throw UsageError("--outer-iteration: expected newton or fixed_point, got \"" + text + "\"");
            o.outer_iteration = text;
        } else if (arg == "--kinematic-start") {
            const std::string text = value();
            if (text != "scaled" && text != "last_velocity")
                throw UsageError("--kinematic-start: expected scaled or last_velocity, got \"" + text + "\"");
            o.kinematic_start = text;
        } else if (arg == "--hessian") {
            const std::string text = value();
            if (text != "auto" && text != "network" && text != "tangent")
                throw UsageError("--hessian: expected auto, network or tangent, got \"" + text + "\"");
            o.hessian = text;
        } else if (arg == "--fixed-point-iterations")
            o.fixed_point_iterations = integer(value(), 1, 100000, "");
        else if (arg == "--fixed-point-inexact")
            o.fixed_point_inexact = number(value());
        else if (arg == "--fixed-point-anderson")
            o.fixed_point_anderson = integer(value(), 0, 100, " (0: the plain iteration)");
        else if (arg == "--fixed-point-keep-hessian") {
            const std::string text = value();
            if (text != "yes" && text != "no")
                throw UsageError("--fixed-point-keep-hessian: expected yes or no, got \"" + text + "\"");
            o.fixed_point_keep_hessian = text == "yes";
        } else if (arg == "--return-map")
            o.return_map = value();
        else if (arg == "--color")
            o.color = value();
        else if (arg == "--resume")
            o.resume = true;
        else if (arg == "--vtu")
            o.vtu = true;
        else if (arg == "--model")
            o.model = value();
        else if (arg == "--trust-model")
            o.trust_model = true;
        else if (arg == "--fail-on-unconverged")
            o.fail_on_unconverged = true;
        else if (!arg.empty() && arg[0] == '-')
            throw UsageError("unknown option " + arg);
        else if (o.scene.empty())
            o.scene = arg;
        else
            throw UsageError("unexpected argument " + arg);
    }
    if (o.scene.empty()) throw UsageError("no scene file given");
    if (o.out.empty()) throw UsageError("--out DIR is required");
    if (o.color != "speed" && o.color != "hardening") throw UsageError("--color: speed or hardening");
    if (o.dt && !(std::isfinite(*o.dt) && *o.dt >= 0.0))
        throw UsageError("--dt must be a number >= 0 (seconds; 0: the CFL step)");
    if (o.cfl && !(std::isfinite(*o.cfl) && *o.cfl > 0.0 && *o.cfl <= 1.0))
        throw UsageError("--cfl must be a number > 0 and <= 1 (a fraction of the cell size per step)");
    if (o.newton_tol && !(std::isfinite(*o.newton_tol) && *o.newton_tol > 0.0))
        throw UsageError("--newton-tol must be a finite number > 0 (m/s)");
    if (o.cg_tol && !(*o.cg_tol > 0.0 && *o.cg_tol < 1.0)) throw UsageError("--cg-tol must be in (0, 1)");
    if (o.fixed_point_tol && !(std::isfinite(*o.fixed_point_tol) && *o.fixed_point_tol >= 0.0))
        throw UsageError("--fixed-point-tol must be a finite number >= 0");
    if (o.regularizer && !(std::isfinite(*o.regularizer) && *o.regularizer >= 0.0))
        throw UsageError("--regularizer must be a finite number >= 0");
    if (o.analytic_regularizer && !(std::isfinite(*o.analytic_regularizer) && *o.analytic_regularizer >= 0.0))
        throw UsageError("--analytic-regularizer must be a finite number >= 0");
    if (o.lazy_hessian && !(*o.lazy_hessian >= 0.0 && *o.lazy_hessian < 1.0))
        throw UsageError("--lazy-hessian must be in [0, 1)");
    if (o.preconditioner && *o.preconditioner != "jacobi" && *o.preconditioner != "block_jacobi" &&
        *o.preconditioner != "ichol")
        throw UsageError("--preconditioner: expected jacobi, block_jacobi or ichol, got \"" + *o.preconditioner + "\"");
    if (o.return_map && *o.return_map != "learned" && *o.return_map != "exact")
        throw UsageError("--return-map: expected learned or exact, got \"" + *o.return_map + "\"");
    if (o.fixed_point_inexact && !(*o.fixed_point_inexact >= 0.0 && *o.fixed_point_inexact < 1.0))
        throw UsageError("--fixed-point-inexact must be in [0, 1) (0: exact inner solves)");
    return o;
}

std::string frame_name(int frame, const char* extension) {
    char name[64];
    std::snprintf(name, sizeof name, "frame_%05d.%s", frame, extension);
    return name;
}

/// The particles as a PLY record, written to frame_N.ply, with each particle's colour value (speed or hardening).
template <int dim>
PlyParticles write_particles(const Particles<dim>& P, int frame, const Options& o, const fs::path& out,
                             std::vector<double>& colour) {
    PlyParticles ply;
    ply.dim = dim;
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

template <int dim>
void write_frame(const Simulation<dim>& sim, const Scene& scene, const Options& o, const fs::path& out) {
    std::vector<double> colour;
    const PlyParticles ply = write_particles(sim.particles(), sim.frame(), o, out, colour);
    if (o.vtu) write_particles_vtu(out / frame_name(sim.frame(), "vtu"), ply);
    ParticleRenderOptions r;
    r.legend = true;
    r.value_label = o.color == "speed" ? "speed (m/s)" : o.color;
    r.value_min = o.color == "speed" ? 0.0 : *std::min_element(colour.begin(), colour.end());
    r.value_max =
        o.color == "speed" ? 3.0 : std::max(r.value_min + 1e-6, *std::max_element(colour.begin(), colour.end()));
    for (int a = 0; a < dim; ++a) {
        r.domain_min[a] = scene.view_min[a];
        r.domain_max[a] = scene.view_max[a];
    }
    char caption[128];
    std::snprintf(caption, sizeof caption, "%s  t = %.3f s  (%s)", scene.name.c_str(), sim.time(), o.color.c_str());
    r.caption = caption;
    r.width_px = dim == 2 ? 640 : 720;
    r.grid_spacing_m = scene.dx;
    r.particle_spacing_m = scene.dx / scene.particles_per_cell;
    const Image image =
        dim == 2 ? render_particles_2d(ply.position, colour, r) : render_particles_3d(ply.position, colour, r);
    write_png((out / frame_name(sim.frame(), "png")).string(), image);
}

void write_frame(const FemSimulation<2>& sim, const Scene& scene, const Options& o, const fs::path& out) {
    const FemState<2>& state = sim.state();
    const Mesh<2>& mesh = sim.mesh();
    PlyMesh ply;
    for (std::size_t i = 0; i < state.x.size(); ++i)
        for (int a = 0; a < 2; ++a) {
            ply.position.push_back(state.x[i][a]);
            ply.velocity.push_back(state.v[i][a]);
        }
    std::vector<double> colour(mesh.elements.size());
    for (std::size_t e = 0; e < mesh.elements.size(); ++e) {
        for (int a = 0; a < 3; ++a) ply.triangles.push_back(mesh.elements[e][a]);
        ply.hardening.push_back(state.hardening[e]);
        Vec<2> v = Vec<2>::Zero();
        for (int a = 0; a < 3; ++a) v += state.v[mesh.elements[e][a]] / 3.0;
        colour[e] = o.color == "speed" ? v.norm() : state.hardening[e];
    }
    write_mesh_ply((out / frame_name(sim.frame(), "ply")).string(), ply);
    if (o.vtu) write_mesh_vtu(out / frame_name(sim.frame(), "vtu"), ply);
    ParticleRenderOptions r;
    r.legend = true;
    r.value_label = o.color == "speed" ? "speed (m/s)" : o.color;
    // Speed: 0 to twice the fastest prescribed or initial speed (the plate's 0.05 m/s: 0.1 m/s).
    double speed_scale = 0.0;
    for (const SceneMesh& m : scene.meshes) speed_scale = std::max(speed_scale, m.velocity.norm());
    r.value_min = o.color == "speed" ? 0.0 : *std::min_element(colour.begin(), colour.end());
    r.value_max = o.color == "speed" ? std::max(0.1, 2.0 * speed_scale)
                                     : std::max(r.value_min + 1e-6, *std::max_element(colour.begin(), colour.end()));
    for (int a = 0; a < 2; ++a) {
        r.domain_min[a] = scene.view_min[a];
        r.domain_max[a] = scene.view_max[a];
    }
    char caption[128];
    std::snprintf(caption, sizeof caption, "%s  t = %.3f s  (%s)", scene.name.c_str(), sim.time(), o.color.c_str());
    r.caption = caption;
    r.width_px = 640;
    write_png((out / frame_name(sim.frame(), "png")).string(), render_mesh_2d(ply.position, ply.triangles, colour, r));
}

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

/// A 3D FEM frame: every node with the boundary triangles (PLY), the whole tetrahedral
/// mesh (VTU, for ParaView), and a shaded render of the surface (PNG).
void write_frame(const FemSimulation<3>& sim, const Scene& scene, const Options& o, const fs::path& out) {
    const FemState<3>& state = sim.state();
    const Mesh<3>& mesh = sim.mesh();
    const std::vector<int> owner = boundary_owner(mesh);
    PlyMesh ply;
    ply.dim = 3;
    for (std::size_t i = 0; i < state.x.size(); ++i)
        for (int a = 0; a < 3; ++a) {
            ply.position.push_back(state.x[i][a]);
            ply.velocity.push_back(state.v[i][a]);
        }
    std::vector<double> colour(mesh.boundary.size());
    for (std::size_t f = 0; f < mesh.boundary.size(); ++f) {
        const int e = owner[f];
        for (int a = 0; a < 3; ++a) ply.triangles.push_back(mesh.boundary[f][a]);
        ply.hardening.push_back(state.hardening[e]);
        Vec<3> v = Vec<3>::Zero();
        for (int a = 0; a < 4; ++a) v += state.v[mesh.elements[e][a]] / 4.0;
        colour[f] = o.color == "speed" ? v.norm() : state.hardening[e];
    }
    write_mesh_ply((out / frame_name(sim.frame(), "ply")).string(), ply);
    VtuMesh vtu;
    vtu.dim = 3;
    vtu.position = ply.position;
    for (const auto& el : mesh.elements) vtu.cells.insert(vtu.cells.end(), el.begin(), el.end());
    vtu.point_data.push_back({"velocity", 3, ply.velocity});
    vtu.cell_data.push_back({"hardening", 1, state.hardening});
    write_vtu((out / frame_name(sim.frame(), "vtu")).string(), vtu);
    ParticleRenderOptions r;
    r.legend = true;
    r.value_label = o.color == "speed" ? "speed (m/s)" : o.color;
    double speed_scale = 0.0;
    for (const SceneMesh& m : scene.meshes) speed_scale = std::max(speed_scale, m.velocity.norm());
    r.value_min = o.color == "speed" ? 0.0 : *std::min_element(colour.begin(), colour.end());
    r.value_max = o.color == "speed" ? std::max(0.1, 2.0 * speed_scale)
                                     : std::max(r.value_min + 1e-6, *std::max_element(colour.begin(), colour.end()));
    for (int a = 0; a < 3; ++a) {
        r.domain_min[a] = scene.view_min[a];
        r.domain_max[a] = scene.view_max[a];
    }
    char caption[128];
    std::snprintf(caption, sizeof caption, "%s  t = %.3f s  (%s)", scene.name.c_str(), sim.time(), o.color.c_str());
    r.caption = caption;
    r.width_px = 720;
    write_png((out / frame_name(sim.frame(), "png")).string(), render_mesh_3d(ply.position, ply.triangles, colour, r));
}

/// Particles and a mesh (MPM-FEM coupling): the particles as frame_N.ply, the mesh as
/// frame_N_mesh.ply, and one PNG with the mesh drawn over the particles.
void write_frame(const CoupledSimulation2d& sim, const Scene& scene, const Options& o, const fs::path& out) {
    std::vector<double> colour;
    const PlyParticles particles = write_particles(sim.particles(), sim.frame(), o, out, colour);
    if (o.vtu) write_particles_vtu(out / frame_name(sim.frame(), "vtu"), particles);
    const FemState<2>& state = sim.state();
    const Mesh<2>& mesh = sim.mesh();
    PlyMesh ply;
    for (std::size_t i = 0; i < state.x.size(); ++i)
        for (int a = 0; a < 2; ++a) {
            ply.position.push_back(state.x[i][a]);
            ply.velocity.push_back(state.v[i][a]);
        }
    std::vector<double> mesh_colour(mesh.elements.size());
    for (std::size_t e = 0; e < mesh.elements.size(); ++e) {
        Vec<2> v = Vec<2>::Zero();
        for (int a = 0; a < 3; ++a) {
            ply.triangles.push_back(mesh.elements[e][a]);
            v += state.v[mesh.elements[e][a]] / 3.0;
        }
        ply.hardening.push_back(state.hardening[e]);
        mesh_colour[e] = o.color == "speed" ? v.norm() : state.hardening[e];
    }
    char mesh_name[64];
    std::snprintf(mesh_name, sizeof mesh_name, "frame_%05d_mesh.ply", sim.frame());
    write_mesh_ply((out / mesh_name).string(), ply);
    if (o.vtu) {
        std::snprintf(mesh_name, sizeof mesh_name, "frame_%05d_mesh.vtu", sim.frame());
        write_mesh_vtu(out / mesh_name, ply);
    }
    ParticleRenderOptions r;
    r.legend = true;
    r.value_label = o.color == "speed" ? "speed (m/s)" : o.color;
    r.value_min = o.color == "speed" ? 0.0 : *std::min_element(colour.begin(), colour.end());
    r.value_max =
        o.color == "speed" ? 3.0 : std::max(r.value_min + 1e-6, *std::max_element(colour.begin(), colour.end()));
    for (int a = 0; a < 2; ++a) {
        r.domain_min[a] = scene.view_min[a];
        r.domain_max[a] = scene.view_max[a];
    }
    char caption[128];
    std::snprintf(caption, sizeof caption, "%s  t = %.3f s  (%s)", scene.name.c_str(), sim.time(), o.color.c_str());
    r.caption = caption;
    r.width_px = 640;
    r.grid_spacing_m = scene.dx;
    r.particle_spacing_m = scene.dx / scene.particles_per_cell;
    Image image = render_particles_2d(particles.position, colour, r);
    if (o.color == "hardening") mesh_colour.clear();  // the mesh has no hardening: one colour
    const Image drawn = render_mesh_2d(ply.position, ply.triangles, mesh_colour, r);
    // The same frame and scale when both renders have the same margin (the particle disks are
    // small): the mesh's pixels are copied over the particles.
    if (drawn.width == image.width && drawn.height == image.height)
        for (int y = 0; y < image.height; ++y)
            for (int x = 0; x < image.width; ++x) {
                const Rgb c = drawn.get(x, y);
                if (!(c.r == 255 && c.g == 255 && c.b == 255)) image.set(x, y, c);
            }
    write_png((out / frame_name(sim.frame(), "png")).string(), image);
}

template <class Sim>
constexpr bool is_coupled = std::is_same_v<Sim, CoupledSimulation2d>;
/// Runs with contact statistics (FEM meshes, alone or beside particles).
template <class Sim>
constexpr bool is_fem =
    std::is_same_v<Sim, FemSimulation<2>> || std::is_same_v<Sim, FemSimulation<3>> || is_coupled<Sim>;

/// --model FILE: FILE (relative to the working folder) replaces the model of every object and mesh
/// that names one, e.g. a model trained with other options; load_scene_models checks it as it would
/// the scene's (trusted, an energy of the scene's dimension, for the object's material).
void use_model(Scene& scene, const std::string& file) {
    if (file.empty()) throw UsageError("--model: expected a model file");
    const std::string path = fs::absolute(file).lexically_normal().string();
    int replaced = 0;
    for (SceneObject& object : scene.objects)
        if (!object.model.empty()) object.model = path, ++replaced;
    for (SceneMesh& mesh : scene.meshes)
        if (!mesh.model.empty()) mesh.model = path, ++replaced;
    if (replaced == 0) throw UsageError("--model " + file + ": " + scene.file + " names no model to replace");
}

/// The energy model files the run's objects and meshes use, in order (none: empty).
nlohmann::json scene_models(const Scene& scene) {
    nlohmann::json models = nlohmann::json::array();
    for (const SceneObject& object : scene.objects)
        if (!object.model.empty()) models.push_back(object.model);
    for (const SceneMesh& mesh : scene.meshes)
        if (!mesh.model.empty()) models.push_back(mesh.model);
    return models;
}

template <class Sim>
nlohmann::json describe_run(const Sim& sim) {
    if constexpr (is_coupled<Sim>) {
        return {{"dx", sim.system().dx},
                {"particles", sim.particles().size()},
                {"nodes", sim.mesh().nodes()},
                {"elements", sim.mesh().elements.size()},
                {"particle_dhat", sim.coupling().dhat()},
                {"particle_kappa", sim.coupling().kappa()},
                {"step", sim.step_size()}};
    } else if constexpr (is_fem<Sim>) {
        const auto& s = sim.scene_system();
        return {{"nodes", sim.mesh().nodes()},
                {"elements", sim.mesh().elements.size()},
                {"mesh_first_node", s.first_node},
                {"mesh_first_element", s.first_element},
                {"bbox_diagonal", s.diagonal},
                {"dhat", s.dhat},
                {"kappa", s.kappa},
                {"step", sim.step_size()}};
    } else {
        return {{"dx", sim.system().dx}, {"particles", sim.particles().size()}};
    }
}

template <class Sim>
int run(const Scene& scene, const Options& o, const IntegratorSettings& settings) {
    constexpr int dim = Sim::kDim;
    constexpr bool fem = is_fem<Sim>;
    const fs::path out(o.out);
    fs::create_directories(out);
    const int frames = o.frames > 0 ? o.frames : scene.frames;
    Sim sim(scene, settings);
    const bool implicit = settings.name != "explicit";
    const fs::path checkpoint = out / "checkpoint.bin";
    const fs::path stats_path = out / "stats.csv";
    if (o.resume) {
        if (!fs::exists(checkpoint))
            throw std::invalid_argument(checkpoint.string() + ": no checkpoint to resume from");
        sim.load_checkpoint(checkpoint.string());
        std::fprintf(stderr, "resumed at frame %d (t = %.4f s, %ld steps)\n", sim.frame(), sim.time(),
                     sim.total_steps());
    }
    nlohmann::json run_json = {
        {"scene", fs::absolute(scene.file).string()},
        {"name", scene.name},
        {"dim", dim},
        {"integrator", settings.name},
        {"dt", settings.dt},
        {"cfl", settings.cfl},
        {"frame_dt", scene.frame_dt},
        {"frames", frames},
        {"threads", thread_count()},
        {"domain_min", std::vector<double>(scene.domain_min.data(), scene.domain_min.data() + dim)},
        {"domain_max", std::vector<double>(scene.domain_max.data(), scene.domain_max.data() + dim)},
        {"view_min", std::vector<double>(scene.view_min.data(), scene.view_min.data() + dim)},
        {"view_max", std::vector<double>(scene.view_max.data(), scene.view_max.data() + dim)}};
    run_json.update(describe_run(sim));
    run_json["models"] = scene_models(scene);
    if (implicit) run_json["solver"] = settings.implicit.to_json();
    write_text_atomically((out / "run.json").string(), run_json.dump(2) + "\n");

    // stats.csv: one row per frame; steps.csv: one row per step (implicit
    // solver figures included). On resume, rows after the checkpoint's frame are dropped.
    std::string stats =
        "frame,time_s,steps,dt_min_s,dt_max_s,wall_s,clamped,kinetic_J,potential_J,momentum_x,momentum_y" +
        std::string(dim == 3 ? ",momentum_z" : "") +
        ",newton_iterations,cg_iterations,line_search_steps,fixed_point_iterations,max_residual_m_per_s,"
        "converged,unconverged_steps,hardening_clamped" +
        std::string(fem ? ",contact_pairs,min_distance_m,ccd_queries,ccd_limited" : "") + "\n";
    std::string steps_csv =
        "frame,step,time_s,dt_s,wall_s,p2g_s,solve_s,g2p_s,energy_s,cg_s,newton_iterations,cg_iterations,"
        "line_search_steps,fixed_point_iterations,fixed_point_change,initial_residual_m_per_s,residual_m_per_s,"
        "energy_J,converged,clamped,line_search_failed,hardening_clamped,fixed_point_converged,reference_updates,"
        "true_residual_m_per_s" +
        std::string(
            fem ? ",kinematic_stages,kinematic_reached,ccd_queries,ccd_limited,contact_pairs,min_distance_m,substeps,"
                  "broad_phase_s,ccd_s"
                : "") +
        "\n";
    const fs::path steps_path = out / "steps.csv";
    auto keep_rows = [&](const fs::path& path, std::string& text) {
        if (!o.resume || !fs::exists(path)) return;
        std::ifstream in(path);
        std::string line;
        std::getline(in, line);
        while (std::getline(in, line))
            if (!line.empty() && std::stoi(line.substr(0, line.find(','))) <= sim.frame()) text += line + "\n";
    };
    keep_rows(stats_path, stats);
    keep_rows(steps_path, steps_csv);
    if (!o.resume) write_frame(sim, scene, o, out);

    const auto start = std::chrono::steady_clock::now();
    const int first = sim.frame();
    long run_steps = 0, run_unconverged = 0;
    double run_worst_residual = 0.0;
    std::size_t run_hardening_clamped = 0;
    long run_fixed_point_capped = 0;
    while (sim.frame() < frames) {
        FrameStats f;
        try {
            f = sim.advance_frame();
        } catch (const SimulationError& e) {
            write_text_atomically(stats_path.string(), stats);
            write_text_atomically(steps_path.string(), steps_csv);
            std::fprintf(stderr, "\nerror: %s\nframes up to %d in %s are complete\n", e.what(), sim.frame(),
                         out.string().c_str());
            return 1;
        }
        write_frame(sim, scene, o, out);
        char row[512];
        int len = std::snprintf(row, sizeof row, "%d,%.6f,%ld,%.6g,%.6g,%.4f,%zu,%.9g,%.9g,%.9g,%.9g", f.frame, f.time,
                                f.steps, f.dt_min, f.dt_max, f.wall_seconds, f.clamped, f.kinetic, f.potential,
                                f.momentum[0], f.momentum[1]);
        if (dim == 3) len += std::snprintf(row + len, sizeof row - len, ",%.9g", f.momentum[2]);
        len += std::snprintf(row + len, sizeof row - len, ",%ld,%ld,%ld,%ld,%.6g,%d,%ld,%zu", f.newton_iterations,
                             f.cg_iterations, f.line_search_steps, f.fixed_point_iterations, f.max_residual,
                             f.converged ? 1 : 0, f.unconverged_steps, f.hardening_clamped);
        if (fem)
            std::snprintf(row + len, sizeof row - len, ",%zu,%.6g,%ld,%ld", f.contact_pairs, f.min_distance,
                          f.ccd_queries, f.ccd_limited);
        run_steps += f.steps;
        run_unconverged += f.unconverged_steps;
        if (f.unconverged_steps > 0) run_worst_residual = std::max(run_worst_residual, f.max_residual);
        run_hardening_clamped = std::max(run_hardening_clamped, f.hardening_clamped);
        run_fixed_point_capped += f.fixed_point_capped_steps;
        stats += std::string(row) + "\n";
        double t = f.time;  // the frame's start time, from its step sizes
        for (const StepStats& s : sim.last_frame_steps()) t -= s.dt;
        long step = sim.total_steps() - static_cast<long>(sim.last_frame_steps().size());
        for (const StepStats& s : sim.last_frame_steps()) {
            t += s.dt;
            int n = std::snprintf(
                row, sizeof row,
                "%d,%ld,%.9g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%.6g,%d,%d,%d,%d,%.6g,%.6g,%.6g,%.12g,%d,%zu,%d,%zu,%d,%d,%.6g",
                f.frame, step++, t, s.dt, s.wall_seconds, s.p2g_seconds, s.grid_seconds, s.g2p_seconds,
                s.energy_seconds, s.cg_seconds, s.newton_iterations, s.cg_iterations, s.line_search_steps,
                s.fixed_point_iterations, s.fixed_point_change, s.initial_residual, s.residual, s.energy,
                s.converged ? 1 : 0, s.clamped, s.line_search_failed ? 1 : 0, s.hardening_clamped,
                s.fixed_point_converged ? 1 : 0, s.reference_updates, s.true_residual);
            if (fem)
                n += std::snprintf(row + n, sizeof row - n, ",%d,%d,%d,%d,%zu,%.6g,%d,%.6g,%.6g", s.kinematic_stages,
                                   s.kinematic_reached ? 1 : 0, s.ccd_queries, s.ccd_limited, s.contact_pairs,
                                   s.min_distance, s.substeps, s.broad_phase_seconds, s.ccd_seconds);
            std::snprintf(row + n, sizeof row - n, "\n");
            steps_csv += row;
        }
        write_text_atomically(stats_path.string(), stats);
        write_text_atomically(steps_path.string(), steps_csv);
        if (o.checkpoint_every > 0 && sim.frame() % o.checkpoint_every == 0) sim.save_checkpoint(checkpoint.string());
        const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        const double per_frame = elapsed / (sim.frame() - first);
        if (implicit)
            std::fprintf(stderr, "\rframe %d/%d  steps %ld  Newton %.1f  CG %.0f per step  %.2f s/frame  ETA %.0f s   ",
                         sim.frame(), frames, f.steps, static_cast<double>(f.newton_iterations) / f.steps,
                         static_cast<double>(f.cg_iterations) / f.steps, per_frame, per_frame * (frames - sim.frame()));
        else
            std::fprintf(stderr, "\rframe %d/%d  steps %ld  %.2f s/frame  ETA %.0f s   ", sim.frame(), frames, f.steps,
                         per_frame, per_frame * (frames - sim.frame()));
    }
    std::fprintf(stderr, "\n");
    if (implicit) {
        if (run_unconverged > 0)
            std::printf(
                "warning: %ld of %ld steps ended with the Newton solve unconverged (largest residual %.3g m/s, "
                "tolerance %.3g m/s); they are marked converged = 0 in steps.csv "
                "(--fail-on-unconverged stops at the first)\n",
                run_unconverged, run_steps, run_worst_residual, settings.implicit.newton_tolerance);
        else
            std::printf("all %ld steps converged (Newton residual <= %.3g m/s)\n", run_steps,
                        settings.implicit.newton_tolerance);
        if (run_fixed_point_capped > 0)
            std::printf(
                "note: in %ld of %ld steps the fixed point on F0 stopped above its tolerance %.3g "
                "(max_fixed_point_iterations %d, or it stopped contracting; fixed_point_converged = 0 in "
                "steps.csv)\n",
                run_fixed_point_capped, run_steps, settings.implicit.fixed_point_tolerance,
                settings.implicit.max_fixed_point_iterations);
        if (run_hardening_clamped > 0)
            std::printf(
                "note: up to %zu particles in a step had a hardening state outside the range the model was "
                "trained on (clamped; hardening_clamped in stats.csv)\n",
                run_hardening_clamped);
    }
    if constexpr (fem) {
        double closest = 1e300;
        std::size_t most_pairs = 0;
        long ccd_limited = 0;
        // From the rows kept and written (a resumed run included).
        std::istringstream rows(stats);
        std::string line;
        std::getline(rows, line);
        while (std::getline(rows, line)) {
            std::vector<std::string> cells;
            std::stringstream fields(line);
            for (std::string c; std::getline(fields, c, ',');) cells.push_back(c);
            const std::size_t m = cells.size();
            most_pairs = std::max<std::size_t>(most_pairs, std::stoul(cells[m - 4]));
            closest = std::min(closest, std::stod(cells[m - 3]));
            ccd_limited += std::stol(cells[m - 1]);
        }
        std::printf(
            "contact: no intersection at any frame (exact test); smallest distance %.3g m (dhat %.3g m), "
            "up to %zu pairs within dhat, %ld CCD-shortened steps\n",
            closest,
            [&] {
                if constexpr (is_coupled<Sim>)
                    return sim.coupling().dhat();
                else
                    return sim.scene_system().dhat;
            }(),
            most_pairs, ccd_limited);
    }
    std::printf("wrote %d frames (PLY + PNG), stats.csv, steps.csv and run.json to %s\n", frames, out.string().c_str());
    return 0;
}

}  // namespace

int simulate_command(int argc, char** argv) {
    Options o;
    try {
        o = parse(argc, argv);
    } catch (const UsageError& e) {
        std::fprintf(stderr, "pnet simulate: %s\n%s", e.what(), kUsage);
        return 2;
    }
    // --threads, or every core the process may use; set in LibTorch too, whose first operation
    // (loading a model) would otherwise impose its own count on OpenMP (sim/threads.hpp).
    use_threads(o.threads);
    try {
        Scene scene = load_scene(o.scene);
        if (o.model) use_model(scene, *o.model);
        IntegratorSettings settings;
        try {
            settings = integrator_settings(scene, o.integrator);
        } catch (const std::invalid_argument& e) {
            if (o.integrator.empty()) throw;  // the scene's own name was checked when it was loaded
            throw UsageError(std::string("--") + e.what());
        }
        if (o.dt) settings.dt = *o.dt;
        if (o.cfl) settings.cfl = *o.cfl;
        if (o.fail_on_unconverged) settings.implicit.fail_on_unconverged = true;
        if (o.newton_tol) settings.implicit.newton_tolerance = *o.newton_tol;
        if (o.cg_tol) settings.implicit.cg_tolerance = *o.cg_tol;
        if (o.fixed_point_tol) settings.implicit.fixed_point_tolerance = *o.fixed_point_tol;
        if (o.regularizer) settings.implicit.regularizer_weight = *o.regularizer;
        if (o.analytic_regularizer) settings.implicit.analytic_regularizer = *o.analytic_regularizer;
        if (o.preconditioner) settings.implicit.preconditioner = *o.preconditioner;
        if (o.lazy_hessian) settings.implicit.lazy_hessian = *o.lazy_hessian;
        if (o.fixed_point_iterations) settings.implicit.max_fixed_point_iterations = *o.fixed_point_iterations;
        if (o.fixed_point_anderson) settings.implicit.fixed_point_anderson = *o.fixed_point_anderson;
        if (o.outer_iteration) settings.implicit.outer_iteration = *o.outer_iteration;
        if (o.time_integrator) settings.implicit.time_integrator = *o.time_integrator;
        if (o.hessian) settings.implicit.hessian = *o.hessian;
        if (o.kinematic_start) settings.implicit.kinematic_start = *o.kinematic_start;
        if (o.fixed_point_inexact) settings.implicit.fixed_point_inexact = *o.fixed_point_inexact;
        if (o.fixed_point_keep_hessian) settings.implicit.fixed_point_keep_hessian = *o.fixed_point_keep_hessian;
        if (o.return_map) settings.implicit.learned_return_map = *o.return_map == "learned";
        load_scene_models(scene, o.trust_model, settings);
        if (scene.has_meshes() && scene.has_particles()) return run<CoupledSimulation2d>(scene, o, settings);
        if (scene.has_meshes())
            return scene.dim == 2 ? run<FemSimulation<2>>(scene, o, settings)
                                  : run<FemSimulation<3>>(scene, o, settings);
        return scene.dim == 2 ? run<Simulation<2>>(scene, o, settings) : run<Simulation<3>>(scene, o, settings);
    } catch (const UsageError& e) {
        std::fprintf(stderr, "pnet simulate: %s\n%s", e.what(), kUsage);
        return 2;
    } catch (const SceneFileNotFound& e) {
        std::fprintf(stderr, "pnet simulate: %s\n", e.what());
        return 2;
    } catch (const FileNotFoundError& e) {  // a model the scene names
        std::fprintf(stderr, "pnet simulate: %s\n", e.what());
        return 2;
    } catch (const UntrustedModelError& e) {
        std::fprintf(stderr, "pnet simulate: %s\n", e.what());
        return 2;
    } catch (const std::invalid_argument& e) {
        std::fprintf(stderr, "pnet simulate: %s\n", e.what());
        return 2;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "pnet simulate: %s\n", e.what());
        return 1;
    }
}

}  // namespace pnet::apps
