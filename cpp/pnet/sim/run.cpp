#include "pnet/sim/run.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include <nlohmann/json.hpp>

#include "pnet/io/atomic_file.hpp"
#include "pnet/io/ply.hpp"
#include "pnet/io/png.hpp"
#include "pnet/io/render.hpp"
#include "pnet/io/run_folder.hpp"
#include "pnet/io/vtu.hpp"
#include "pnet/sim/run_output.hpp"
#include "pnet/sim/threads.hpp"

namespace pnet {

namespace {

namespace fs = std::filesystem;

/// The options and the id of the run being written.
struct Output : RunOptions {
    std::string run_id;  // written into run.json and every frame file
};

std::string frame_name(int frame, const char* extension) {
    char name[64];
    std::snprintf(name, sizeof name, "frame_%05d.%s", frame, extension);
    return name;
}

/// A frame's picture, tagged with the run that drew it.
void write_frame_png(const fs::path& path, Image image, const Output& o) {
    if (!o.run_id.empty()) image.text[kPngRunIdKey] = o.run_id;
    write_png(path.string(), image);
}

/// The particles as a PLY record, written to frame_N.ply, with each particle's colour value (speed or hardening).
template <int dim>
PlyParticles write_particles(const Particles<dim>& P, int frame, const Output& o, const fs::path& out,
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
ParticleRenderOptions frame_render_options(const Scene& scene, double time, int dim, const Output& o,
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
ParticleRenderOptions particle_render_options(const Scene& scene, double time, int dim, const Output& o,
                                              const std::vector<double>& colour) {
    ParticleRenderOptions r = frame_render_options(scene, time, dim, o, colour, 3.0);
    r.grid_spacing_m = scene.dx;
    r.particle_spacing_m = scene.dx / scene.particles_per_cell;
    return r;
}

/// Mesh pictures: speeds up to twice the fastest prescribed or initial speed (the plate's 0.05 m/s:
/// 0.1 m/s).
ParticleRenderOptions mesh_render_options(const Scene& scene, double time, int dim, const Output& o,
                                          const std::vector<double>& colour) {
    double speed_scale = 0.0;
    for (const SceneMesh& m : scene.meshes) speed_scale = std::max(speed_scale, m.velocity.norm());
    return frame_render_options(scene, time, dim, o, colour, std::max(0.1, 2.0 * speed_scale));
}

/// A 2D mesh frame: every node and triangle, each triangle coloured by its mean speed or hardening.
PlyMesh mesh_frame_2d(const FemState<2>& state, const Mesh<2>& mesh, const Output& o, std::vector<double>& colour) {
    PlyMesh ply;
    ply.run_id = o.run_id;
    for (std::size_t i = 0; i < state.x.size(); ++i)
        for (int a = 0; a < 2; ++a) {
            ply.position.push_back(state.x[i][a]);
            ply.velocity.push_back(state.v[i][a]);
        }
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

template <int dim>
void write_frame(const Simulation<dim>& sim, const Scene& scene, const Output& o, const fs::path& out) {
    std::vector<double> colour;
    const PlyParticles ply = write_particles(sim.particles(), sim.frame(), o, out, colour);
    if (o.vtu) write_particles_vtu(out / frame_name(sim.frame(), "vtu"), ply);
    const ParticleRenderOptions r = particle_render_options(scene, sim.time(), dim, o, colour);
    const Image image =
        dim == 2 ? render_particles_2d(ply.position, colour, r) : render_particles_3d(ply.position, colour, r);
    write_frame_png(out / frame_name(sim.frame(), "png"), image, o);
}

void write_frame(const FemSimulation<2>& sim, const Scene& scene, const Output& o, const fs::path& out) {
    std::vector<double> colour;
    const PlyMesh ply = mesh_frame_2d(sim.state(), sim.mesh(), o, colour);
    write_mesh_ply((out / frame_name(sim.frame(), "ply")).string(), ply);
    if (o.vtu) write_mesh_vtu(out / frame_name(sim.frame(), "vtu"), ply);
    const ParticleRenderOptions r = mesh_render_options(scene, sim.time(), 2, o, colour);
    write_frame_png(out / frame_name(sim.frame(), "png"), render_mesh_2d(ply.position, ply.triangles, colour, r), o);
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

/// A 3D mesh's frame: every node with the boundary triangles (the PLY), each triangle coloured by
/// its element's speed or hardening.
PlyMesh mesh_frame_3d(const FemState<3>& state, const Mesh<3>& mesh, const Output& o, std::vector<double>& colour) {
    const std::vector<int> owner = boundary_owner(mesh);
    PlyMesh ply;
    ply.run_id = o.run_id;
    ply.dim = 3;
    for (std::size_t i = 0; i < state.x.size(); ++i)
        for (int a = 0; a < 3; ++a) {
            ply.position.push_back(state.x[i][a]);
            ply.velocity.push_back(state.v[i][a]);
        }
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

PlyMesh mesh_frame(const FemState<2>& state, const Mesh<2>& mesh, const Output& o, std::vector<double>& colour) {
    return mesh_frame_2d(state, mesh, o, colour);
}
PlyMesh mesh_frame(const FemState<3>& state, const Mesh<3>& mesh, const Output& o, std::vector<double>& colour) {
    return mesh_frame_3d(state, mesh, o, colour);
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

/// A 3D FEM frame: every node with the boundary triangles (PLY), the whole tetrahedral
/// mesh (VTU, for ParaView), and a shaded render of the surface (PNG).
void write_frame(const FemSimulation<3>& sim, const Scene& scene, const Output& o, const fs::path& out) {
    std::vector<double> colour;
    const PlyMesh ply = mesh_frame_3d(sim.state(), sim.mesh(), o, colour);
    write_mesh_ply((out / frame_name(sim.frame(), "ply")).string(), ply);
    write_mesh_vtu(out / frame_name(sim.frame(), "vtu"), sim.state(), sim.mesh(), ply);
    const ParticleRenderOptions r = mesh_render_options(scene, sim.time(), 3, o, colour);
    write_frame_png(out / frame_name(sim.frame(), "png"), render_mesh_3d(ply.position, ply.triangles, colour, r), o);
}

/// Particles and a mesh (MPM-FEM coupling): the particles as frame_N.ply, the mesh as
/// frame_N_mesh.ply (3D: its surface), and one PNG with the mesh drawn over the particles (3D:
/// the surface and the particles in one depth buffer).
template <int dim>
void write_frame(const CoupledSimulation<dim>& sim, const Scene& scene, const Output& o, const fs::path& out) {
    std::vector<double> colour;
    const PlyParticles particles = write_particles(sim.particles(), sim.frame(), o, out, colour);
    if (o.vtu) write_particles_vtu(out / frame_name(sim.frame(), "vtu"), particles);
    std::vector<double> mesh_colour;
    const PlyMesh ply = mesh_frame(sim.state(), sim.mesh(), o, mesh_colour);
    char mesh_name[64];
    std::snprintf(mesh_name, sizeof mesh_name, "frame_%05d_mesh.ply", sim.frame());
    write_mesh_ply((out / mesh_name).string(), ply);
    if (o.vtu) {
        std::snprintf(mesh_name, sizeof mesh_name, "frame_%05d_mesh.vtu", sim.frame());
        if constexpr (dim == 2)
            write_mesh_vtu(out / mesh_name, ply);
        else
            write_mesh_vtu(out / mesh_name, sim.state(), sim.mesh(), ply);
    }
    const ParticleRenderOptions r = particle_render_options(scene, sim.time(), dim, o, colour);
    if (o.color == "hardening") mesh_colour.clear();  // the mesh has no hardening: one colour
    if constexpr (dim == 3) {
        const SurfaceMesh surface{ply.position, ply.triangles, mesh_colour};
        write_frame_png(out / frame_name(sim.frame(), "png"), render_particles_3d(particles.position, colour, r, &surface),
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
        write_frame_png(out / frame_name(sim.frame(), "png"), image, o);
    }
}

template <class Sim>
constexpr bool is_coupled = std::is_same_v<Sim, CoupledSimulation<2>> || std::is_same_v<Sim, CoupledSimulation<3>>;
/// Runs with contact statistics (FEM meshes, alone or beside particles).
template <class Sim>
constexpr bool is_fem =
    std::is_same_v<Sim, FemSimulation<2>> || std::is_same_v<Sim, FemSimulation<3>> || is_coupled<Sim>;

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
void run(Sim& sim, const Scene& scene, Output o, const IntegratorSettings& settings) {
    constexpr int dim = Sim::kDim;
    constexpr bool fem = is_fem<Sim>;
    const fs::path out(o.out);
    // A folder holding another run is refused before any work, and cleared only once the run is set up.
    if (!o.resume) check_run_folder(out, o.overwrite);
    const int frames = o.frames > 0 ? o.frames : scene.frames;
    const IntegratorInfo& integrator = integrator_info(settings.method());
    const bool implicit = integrator.implicit;
    const fs::path checkpoint = out / "checkpoint.bin";
    const fs::path stats_path = out / "stats.csv";
    if (o.resume) {
        if (!fs::exists(checkpoint))
            throw std::invalid_argument(checkpoint.string() + ": no checkpoint to resume from");
        sim.load_checkpoint(checkpoint.string());
        std::fprintf(stderr, "resumed at frame %d (t = %.4f s, %ld steps)\n", sim.frame(), sim.time(),
                     sim.total_steps());
        // The run goes on under its own id; the frames after the checkpoint are rewritten.
        o.run_id = recorded_run_id(out);
        remove_frames_after(out, sim.frame());
    } else {
        if (const std::size_t removed = clear_run_folder(out))
            std::fprintf(stderr, "--overwrite: removed %zu files of the previous run in %s\n", removed,
                         out.string().c_str());
        o.run_id = new_run_id();
    }
    fs::create_directories(out);
    nlohmann::json run_json = {
        {"scene", fs::absolute(scene.file).string()},
        {"name", scene.name},
        {"run_id", o.run_id},
        {"dim", dim},
        {"integrator", settings.name},
        {"integrator_solves", integrator.solves},
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
    // The models the run read: none unless its integrator reads them (solver/integrators.hpp).
    run_json["models"] = integrator.reads_models ? scene_models(scene) : nlohmann::json::array();
    if (implicit) {
        run_json["solver"] = settings.implicit.to_json();
        if (settings.method() == Method::PlasticityNet)
            run_json["solver"]["outer_iteration_resolved"] = settings.implicit.resolved_outer_iteration();
    }
    write_text_atomically((out / "run.json").string(), run_json.dump(2) + "\n");

    // stats.csv: one row per frame; steps.csv: one row per step (implicit
    // solver figures included). On resume, rows after the checkpoint's frame are dropped.
    const RunColumns columns{dim, fem, settings.name};
    std::string stats = stats_csv_header(columns);
    std::string steps_csv = steps_csv_header(columns);
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
            f = sim.advance_frame(o.after_step);
        } catch (const SimulationError& e) {
            write_text_atomically(stats_path.string(), stats);
            write_text_atomically(steps_path.string(), steps_csv);
            std::fprintf(stderr, "\n");
            throw SimulationError(std::string(e.what()) + "\nframes up to " + std::to_string(sim.frame()) + " in " +
                                  out.string() + " are complete");
        }
        write_frame(sim, scene, o, out);
        run_steps += f.steps;
        run_unconverged += f.unconverged_steps;
        if (f.unconverged_steps > 0) run_worst_residual = std::max(run_worst_residual, f.max_residual);
        run_hardening_clamped = std::max(run_hardening_clamped, f.hardening_clamped);
        run_fixed_point_capped += f.fixed_point_capped_steps;
        stats += stats_csv_row(f, columns);
        double t = f.time;  // the frame's start time, from its step sizes
        for (const StepStats& s : sim.last_frame_steps()) t -= s.dt;
        long step = sim.total_steps() - static_cast<long>(sim.last_frame_steps().size());
        for (const StepStats& s : sim.last_frame_steps()) {
            t += s.dt;
            steps_csv += steps_csv_row(f.frame, step++, t, s, columns);
        }
        write_text_atomically(stats_path.string(), stats);
        write_text_atomically(steps_path.string(), steps_csv);
        if (o.checkpoint_every > 0 && sim.frame() % o.checkpoint_every == 0) sim.save_checkpoint(checkpoint.string());
        const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        const double per_frame = elapsed / (sim.frame() - first);
        if (implicit)
            std::fprintf(stderr,
                         "\rframe %d/%d  steps %ld (%ld cut by the advection limit)  Newton %.1f  CG %.0f per step  "
                         "%.2f s/frame  ETA %.0f s   ",
                         sim.frame(), frames, f.steps, f.advection_capped_steps,
                         static_cast<double>(f.newton_iterations) / f.steps,
                         static_cast<double>(f.cg_iterations) / f.steps, per_frame, per_frame * (frames - sim.frame()));
        else
            std::fprintf(stderr, "\rframe %d/%d  steps %ld  %.2f s/frame  ETA %.0f s   ", sim.frame(), frames, f.steps,
                         per_frame, per_frame * (frames - sim.frame()));
    }
    std::fprintf(stderr, "\n");
    if (implicit) {
        const ImplicitOptions& o = settings.implicit;
        char tolerance[96];
        if (o.newton_acceleration_tolerance > 0.0)
            std::snprintf(tolerance, sizeof tolerance, "min(%.3g m/s, %.3g m/s^2 x dt)", o.newton_tolerance,
                          o.newton_acceleration_tolerance);
        else
            std::snprintf(tolerance, sizeof tolerance, "%.3g m/s", o.newton_tolerance);
        if (run_unconverged > 0)
            std::printf(
                "warning: %ld of %ld steps ended with the Newton solve unconverged (largest residual %.3g m/s, "
                "tolerance %s); they are marked converged = 0 in steps.csv "
                "(--fail-on-unconverged stops at the first)\n",
                run_unconverged, run_steps, run_worst_residual, tolerance);
        else
            std::printf("all %ld steps converged (Newton residual <= %s)\n", run_steps, tolerance);
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
        for (const std::string& v : csv_column(stats, "contact_pairs")) most_pairs = std::max(most_pairs, std::stoul(v));
        for (const std::string& v : csv_column(stats, "min_distance_m")) closest = std::min(closest, std::stod(v));
        for (const std::string& v : csv_column(stats, "ccd_limited")) ccd_limited += std::stol(v);
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
}

}  // namespace

AnySimulation make_simulation(const Scene& scene, const IntegratorSettings& settings) {
    if (scene.has_meshes() && scene.has_particles()) {
        if (scene.dim == 2) return std::make_unique<CoupledSimulation<2>>(scene, settings);
        return std::make_unique<CoupledSimulation<3>>(scene, settings);
    }
    if (scene.has_meshes()) {
        if (scene.dim == 2) return std::make_unique<FemSimulation<2>>(scene, settings);
        return std::make_unique<FemSimulation<3>>(scene, settings);
    }
    if (scene.dim == 2) return std::make_unique<Simulation<2>>(scene, settings);
    return std::make_unique<Simulation<3>>(scene, settings);
}

void run_to_folder(AnySimulation& sim, const Scene& scene, const IntegratorSettings& settings,
                   const RunOptions& options) {
    if (options.color != "speed" && options.color != "hardening")
        throw std::invalid_argument("color: expected speed or hardening, got '" + options.color + "'");
    if (options.resume && options.overwrite)
        throw std::invalid_argument("resume continues the run in " + options.out +
                                    ", overwrite replaces it: give one");
    if (options.out.empty()) throw std::invalid_argument("no output folder given");
    Output o;
    static_cast<RunOptions&>(o) = options;
    visit_simulation(sim, [&](auto& s) { run(s, scene, o, settings); });
}

}  // namespace pnet
