#include "pnet/sim/run.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "pnet/io/atomic_file.hpp"
#include "pnet/io/run_folder.hpp"
#include "pnet/sim/coupled_simulation.hpp"
#include "pnet/sim/fem_simulation.hpp"
#include "pnet/sim/frame_files.hpp"
#include "pnet/sim/mpm_simulation.hpp"
#include "pnet/sim/run_output.hpp"
#include "pnet/sim/threads.hpp"

namespace pnet {

namespace {

namespace fs = std::filesystem;

/// The options and the id of the run being written.
struct Output : RunOptions {
    std::string run_id;  // written into run.json and every frame file
};

/// The energy model files the run's objects and meshes use, in order (none: empty).
nlohmann::json scene_models(const Scene& scene) {
    nlohmann::json models = nlohmann::json::array();
    for (const SceneObject& object : scene.objects)
        if (!object.model.empty()) models.push_back(object.model);
    for (const SceneMesh& mesh : scene.meshes)
        if (!mesh.model.empty()) models.push_back(mesh.model);
    return models;
}

void run(SimulationBase& sim, const Scene& scene, Output o, const IntegratorSettings& settings) {
    const int dim = sim.dimension();
    const double dhat = sim.contact_dhat();
    const bool contact = dhat > 0.0;
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
        remove_stale_temporaries(out);  // the killed run's half-written files
    } else {
        remove_stale_temporaries(out);
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
    run_json.update(sim.describe());
    // The models the run read: none unless its integrator reads them (solver/integrators.hpp).
    run_json["models"] = integrator.reads_models ? scene_models(scene) : nlohmann::json::array();
    if (implicit) {
        run_json["solver"] = settings.options_json();
        if (settings.method() == Method::PlasticityNet)
            run_json["solver"]["outer_iteration_resolved"] = settings.implicit.resolved_outer_iteration();
    }
    write_text_atomically((out / "run.json").string(), run_json.dump(2) + "\n");

    // stats.csv: one row per frame; steps.csv: one row per step (implicit
    // solver figures included). On resume, rows after the checkpoint's frame are dropped.
    const RunColumns columns{dim, contact, settings.name};
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
    const FrameFiles files(scene, out, o.run_id, o.color, o.vtu);
    if (!o.resume) sim.write_frame(files);

    const auto start = std::chrono::steady_clock::now();
    const int first = sim.frame();
    long run_steps = 0, run_unconverged = 0;
    double run_worst_residual = 0.0;
    std::size_t run_hardening_clamped = 0;
    long run_fixed_point_capped = 0, run_floor_retried = 0, run_prediction_rejected = 0;
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
        sim.write_frame(files);
        run_steps += f.steps;
        run_unconverged += f.unconverged_steps;
        if (f.unconverged_steps > 0) run_worst_residual = std::max(run_worst_residual, f.max_residual);
        run_hardening_clamped = std::max(run_hardening_clamped, f.hardening_clamped);
        run_fixed_point_capped += f.fixed_point_capped_steps;
        run_floor_retried += f.floor_friction_retried_steps;
        run_prediction_rejected += f.prediction_rejected_steps;
        stats += stats_csv_row(f, columns);
        double t = f.time;  // the frame's start time, from its step sizes
        for (const StepRecord& s : sim.last_frame_steps()) t -= s.dt;
        long step = sim.total_steps() - static_cast<long>(sim.last_frame_steps().size());
        for (const StepRecord& s : sim.last_frame_steps()) {
            t += s.dt;
            steps_csv += steps_csv_row(f.frame, step++, t, s, columns);
        }
        write_text_atomically(stats_path.string(), stats);
        write_text_atomically(steps_path.string(), steps_csv);
        if (o.checkpoint_every > 0 && sim.frame() % o.checkpoint_every == 0) sim.save_checkpoint(checkpoint.string());
        const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        const double per_frame = elapsed / (sim.frame() - first);
        if (implicit) {
            // The advection limit applies to particles (implicit MPM and coupling), not to meshes alone.
            char capped[64] = "";
            if (scene.has_particles())
                std::snprintf(capped, sizeof capped, " (%ld cut by the advection limit)", f.advection_capped_steps);
            std::fprintf(stderr,
                         "\rframe %d/%d  steps %ld%s  Newton %.1f  CG %.0f per step  "
                         "%.2f s/frame  ETA %.0f s   ",
                         sim.frame(), frames, f.steps, capped, static_cast<double>(f.newton_iterations) / f.steps,
                         static_cast<double>(f.cg_iterations) / f.steps, per_frame, per_frame * (frames - sim.frame()));
        } else
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
        if (run_unconverged > 0) {
            std::printf(
                "warning: %ld of %ld steps ended with the Newton solve unconverged (largest residual %.3g m/s, "
                "tolerance %s); they are marked converged = 0 in steps.csv "
                "(--fail-on-unconverged stops at the first)\n",
                run_unconverged, run_steps, run_worst_residual, tolerance);
            if (settings.method() == Method::PlasticityNet)
                std::printf(
                    "note: the learned energy's Newton slows where its curvature along plastic flow exceeds the "
                    "material's (stiff materials, grids finer than its scenes': docs/integrators.md, \"The stiff "
                    "column\"); --integrator return_map solves the same step with the return mapping's tangent\n");
        } else {
            std::printf("all %ld steps converged (Newton residual <= %s)\n", run_steps, tolerance);
        }
        if (run_fixed_point_capped > 0)
            std::printf(
                "note: in %ld of %ld steps the fixed point on F0 stopped above its tolerance %.3g "
                "(max_fixed_point_iterations %d, or it stopped contracting; fixed_point_converged = 0 in "
                "steps.csv)\n",
                run_fixed_point_capped, run_steps, settings.implicit.fixed_point_tolerance,
                settings.implicit.max_fixed_point_iterations);
        if (run_floor_retried > 0)
            std::printf(
                "note: in %ld of %ld steps the Coulomb floor's one solve failed and its three passes solved the "
                "step again (floor_friction_retried in steps.csv)\n",
                run_floor_retried, run_steps);
        if (run_prediction_rejected > 0)
            std::printf(
                "note: in %ld of %ld steps the solve from the last step's velocity change ended far from converged "
                "and the step was solved again from v* (prediction_rejected in steps.csv; --newton-start v_star "
                "starts every step there)\n",
                run_prediction_rejected, run_steps);
        if (run_hardening_clamped > 0)
            std::printf(
                "note: up to %zu particles in a step had a hardening state outside the range the model was "
                "trained on (clamped; hardening_clamped in stats.csv)\n",
                run_hardening_clamped);
    }
    if (contact) {
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
            closest, dhat, most_pairs, ccd_limited);
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

void run_to_folder(SimulationBase& sim, const Scene& scene, const IntegratorSettings& settings,
                   const RunOptions& options) {
    if (options.color != "speed" && options.color != "hardening")
        throw std::invalid_argument("color: expected speed or hardening, got '" + options.color + "'");
    if (options.resume && options.overwrite)
        throw std::invalid_argument("resume continues the run in " + options.out +
                                    ", overwrite replaces it: give one");
    if (options.out.empty()) throw std::invalid_argument("no output folder given");
    Output o;
    static_cast<RunOptions&>(o) = options;
    run(sim, scene, o, settings);
}

}  // namespace pnet
