// bench_table1: the paper's Table 1, measured here: seconds per frame of
// `plasticitynet` (the learned energy on every Newton iteration; MPM at dt 1e-3 s, FEM metal at 1e-2 s)
// and of `return_map` (the classical solver, the strong baseline: docs/integrators.md) against
// `explicit` at 1e-5 s (the paper's ground-truth step) and at its CFL step, on the same
// scene, in one run; each implicit row gives its time as a multiple of return_map's and its network
// passes per step. Rows: sand_column_2d, snowball_2d (MPM), metal_frame_2d
// ("Von-Mises metal") and metal_nh_frame_2d ("Neo-hookean metal", with the
// learned return mapping), and with --3d the 3D MPM scenes, metal_frame_3d and
// sand_fem_coupling_3d (the coupling in 3D: a stiff sphere onto a sand bed).
// FEM rows also give the share of the step time spent in contact's broad phase
// and CCD (measured by the 3D contact). The "MPM-FEM coupling" row
// (sand_fem_coupling_2d) compares plasticitynet at 1e-3 with explicit coupling
// at 1e-6 s (the paper's step: the stiff disk's elements need it) and at its
// CFL step, over --coupling-frames frames (default 10: the disk falls, lands at
// frame 4 and settles). The stiff rows (scenes/stiff/: sand_column_2d and
// snowball_2d with E x100, issue 19; --stiff-frames, default --frames; --no-stiff
// leaves them out) compare with explicit at 1e-6 s, their CFL step being 10x
// smaller. Every row also gives its speed-up against explicit at its own CFL
// step, the integrator a user would otherwise pick.
//
//   bench_table1 [--frames N] [--fem-frames N] [--coupling-frames N] [--stiff-frames N] [--threads T]
//                [--scenes DIR] [--only NAME] [--dt-implicit S] [--with-lagged] [--with-one-solve]
//                [--with-fixed-point] [--with-last-velocity] [--with-uncapped] [--with-v-star] [--3d] [--no-fem]
//                [--no-stiff]
//
// The metal frames run --fem-frames frames (default: all 100 of the scene: the
// plate's whole travel, since the plastic phase that costs the most solves
// comes late); --with-lagged adds lagged and, on metal_frame_2d, analytic.
//
// --with-one-solve adds plasticitynet with one solve per step (F0 = F(v*), the
// fixed point not converged: the paper's cheapest mode) beside the default; --with-fixed-point adds
// plasticitynet with the paper's outer iteration (eq. 10), --with-newton-outer with the reference
// following every iterate; --with-last-velocity adds the metal frames' plasticitynet with
// every step started from the last velocities with the plate on its target
// (FemOptions::kinematic_start); --with-uncapped adds, on the MPM scenes, plasticitynet and
// return_map with the advection limit (on by default, 0.2 cells per step) off; --with-v-star adds, on the
// MPM and coupling scenes, plasticitynet and return_map with every Newton solve started from v* instead
// of the last step's velocity change (MpmOptions::newton_start). Implicit rows give the Newton solves, the updates of
// F0 to F(v) (outer iterations) per step and the largest true residual |R(v)| at a step's end (docs/solver.md).
//
// Every integrator runs the same simulated interval, frames [0, N) from the
// scene's initial state (default N = 10: 0.2 s, the sand column collapsing, the
// snowball falling and hitting the floor), so the implicit solver sees the
// same physics it would in a full run. Speed-ups are ratios of seconds per
// frame measured in this run. Implicit rows also show where the time went
// (energy: the per-particle networks/elasticity with their Hessians; CG: the
// Hessian-vector products) and the mean Newton, CG and fixed-point iterations.
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <memory>
#include <string>
#include <type_traits>
#include <vector>

#include "pnet/nn/model_file.hpp"
#include "pnet/nn/torchscript.hpp"
#include "pnet/sim/threads.hpp"
#include "pnet/scene/scene.hpp"
#include "pnet/sim/coupled_simulation.hpp"
#include "pnet/sim/fem_simulation.hpp"
#include "pnet/sim/mpm_simulation.hpp"
#include "pnet/sim/scene_models.hpp"

namespace {

struct Row {
    std::string integrator;
    double dt = 0.0;  // 0: CFL
    double seconds_per_frame = 0.0, mean_dt = 0.0;
    double newton = 0.0, cg = 0.0, fixed_point = 0.0;  // per step (fixed_point: Newton solves)
    double reference_updates = 0.0;  // per step: F0 set to F(v) (plasticitynet's outer iterations)
    double network = 0.0;            // per step: passes of the energy network (plasticitynet)
    double max_true_residual = 0.0;  // the largest |R(v)| of a step's end, m/s (plasticitynet)
    double energy_share = 0.0, cg_share = 0.0;
    double contact_share = -1.0;  // broad phase + CCD (3D FEM); < 0: not measured
    int frames = 0;               // frames completed
    std::string failure;          // why the run stopped early ("" if it did not)
};

template <class Sim>
Row measure(const pnet::Scene& scene, pnet::IntegratorSettings settings, int frames) {
    Row row;
    row.integrator = settings.name;
    row.dt = settings.dt;
    Sim sim(scene, settings);
    double wall = 0.0, energy = 0.0, cg = 0.0, contact = 0.0;
    long steps = 0, newton = 0, cg_iterations = 0, fixed_point = 0;
    for (int f = 0; f < frames; ++f) {
        const auto start = std::chrono::steady_clock::now();
        pnet::FrameStats s;
        try {
            s = sim.advance_frame();
        } catch (const pnet::SimulationError& e) {
            row.failure = e.what();
            std::fprintf(stderr, "\n  %s: %s\n", settings.name.c_str(), e.what());
            break;
        }
        ++row.frames;
        wall += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        steps += s.steps;
        newton += s.newton_iterations;
        cg_iterations += s.cg_iterations;
        fixed_point += s.fixed_point_iterations;
        for (const pnet::StepRecord& step : sim.last_frame_steps()) {
            row.reference_updates += step.reference_updates;
            row.network += static_cast<double>(step.network_evaluations);
            row.max_true_residual = std::max(row.max_true_residual, step.true_residual);
            energy += step.energy_seconds;
            cg += step.cg_seconds;
            contact += step.broad_phase_seconds + step.ccd_seconds;
        }
        std::fprintf(stderr, "\r  %s dt %s: frame %d/%d (%.2f s/frame)   ", settings.name.c_str(),
                     settings.dt > 0 ? std::to_string(settings.dt).c_str() : "CFL", f + 1, frames, wall / (f + 1));
    }
    std::fprintf(stderr, "\n");
    const int done = std::max(row.frames, 1);
    steps = std::max(steps, 1L);
    row.seconds_per_frame = wall / done;
    row.mean_dt = done * scene.frame_dt / steps;
    row.newton = static_cast<double>(newton) / steps;
    row.cg = static_cast<double>(cg_iterations) / steps;
    row.fixed_point = static_cast<double>(fixed_point) / steps;
    row.reference_updates /= steps;
    row.network /= steps;
    row.energy_share = energy / wall;
    row.cg_share = cg / wall;
    if (contact > 0.0) row.contact_share = contact / wall;
    return row;
}

/// plasticitynet with an explicit outer iteration (docs/solver.md): "fixed_point", the paper's eq. 10
/// (a full solve per F0), or "newton", the reference following every iterate; both with the
/// network's Hessian, beside the default's choice.
template <class Sim>
Row outer_row(const pnet::Scene& scene, pnet::IntegratorSettings settings, int frames, const char* outer) {
    settings.name = "plasticitynet";
    settings.implicit.outer_iteration = outer;
    Row row = measure<Sim>(scene, settings, frames);
    row.integrator = std::string("plasticitynet, outer ") + outer;
    return row;
}

/// What --with-* adds beside plasticitynet and return_map.
struct Extras {
    bool lagged = false, one_solve = false, fixed_point = false, newton = false, last_velocity = false,
         uncapped = false, v_star = false;
};

/// --with-v-star's rows: plasticitynet and return_map with each Newton solve started from v*.
template <class Sim>
void add_v_star_rows(std::vector<Row>& rows, const pnet::Scene& scene, const pnet::IntegratorSettings& base, int frames,
                     const Extras& extras) {
    if (!extras.v_star) return;
    for (const char* name : {"plasticitynet", "return_map"}) {
        pnet::IntegratorSettings s = base;
        s.name = name;
        s.mpm.newton_start = "v_star";
        rows.push_back(measure<Sim>(scene, s, frames));
        rows.back().integrator = std::string(name) + ", from v*";
    }
}

/// plasticitynet's outer-iteration rows asked for.
template <class Sim>
void add_outer_rows(std::vector<Row>& rows, const pnet::Scene& scene, const pnet::IntegratorSettings& base, int frames,
                    const Extras& extras) {
    if (extras.fixed_point) rows.push_back(outer_row<Sim>(scene, base, frames, "fixed_point"));
    if (extras.newton) rows.push_back(outer_row<Sim>(scene, base, frames, "newton"));
}

/// The explicit step the rows of a scene are compared with: the paper's 1e-5 s; 1e-6 s where the CFL
/// step is near or below 1e-5 s (the 2D coupling's stiff disk of 2.5 mm elements, the stiff
/// variants; the 3D coupling's sphere has 2 cm elements and keeps 1e-5 s).
double reference_step(const std::string& name) {
    return name == "sand_fem_coupling_2d" || name.rfind("stiff/", 0) == 0 ? 1e-6 : 1e-5;
}

/// `base` with another integrator and step.
pnet::IntegratorSettings with_integrator(const pnet::IntegratorSettings& base, const char* name, double dt) {
    pnet::IntegratorSettings s = base;
    s.name = name;
    s.dt = dt;
    return s;
}

template <int dim>
std::vector<Row> bench_scene(const pnet::Scene& scene, int frames, double dt_implicit, double reference_dt,
                             const Extras& extras) {
    pnet::IntegratorSettings base = pnet::IntegratorSettings::from_scene(scene);
    for (const pnet::SceneObject& object : scene.objects) {
        pnet::LoadOptions load;
        load.expected_dim = dim;
        load.expected_kind = pnet::ModelKind::Energy;
        base.models.push_back(object.model.empty()
                                  ? nullptr
                                  : std::make_shared<const pnet::ModelFile>(pnet::load_model_file(object.model, load)));
    }
    std::vector<Row> rows;
    using Sim = pnet::Simulation<dim>;
    rows.push_back(measure<Sim>(scene, with_integrator(base, "plasticitynet", dt_implicit), frames));
    rows.push_back(measure<Sim>(scene, with_integrator(base, "return_map", dt_implicit), frames));
    if (extras.uncapped) {  // the scene's dt alone, the advection limit (on by default) off
        for (const char* name : {"plasticitynet", "return_map"}) {
            pnet::IntegratorSettings s = with_integrator(base, name, dt_implicit);
            s.mpm.advection_cfl = 0.0;
            rows.push_back(measure<Sim>(scene, s, frames));
            rows.back().integrator = std::string(name) + ", uncapped";
        }
    }
    add_v_star_rows<Sim>(rows, scene, with_integrator(base, "plasticitynet", dt_implicit), frames, extras);
    if (extras.one_solve) {  // the paper's cheapest mode: one solve per step about F0 = F(v*), not converged
        pnet::IntegratorSettings one = with_integrator(base, "plasticitynet", dt_implicit);
        one.implicit.outer_iteration = "fixed_point";
        one.implicit.max_fixed_point_iterations = 1;
        rows.push_back(measure<Sim>(scene, one, frames));
        rows.back().integrator = "plasticitynet, 1 solve";
    }
    add_outer_rows<Sim>(rows, scene, with_integrator(base, "plasticitynet", dt_implicit), frames, extras);
    if (extras.lagged) rows.push_back(measure<Sim>(scene, with_integrator(base, "lagged", dt_implicit), frames));
    rows.push_back(measure<Sim>(scene, with_integrator(base, "explicit", reference_dt), frames));
    rows.push_back(measure<Sim>(scene, with_integrator(base, "explicit", 0.0), frames));
    return rows;
}

/// The rows of a scene with meshes, FEM (the metal frames) or MPM-FEM coupling: plasticitynet at the
/// scene's own implicit settings (dt 1e-2 FEM, 1e-3 coupling) and the other integrators at that step,
/// against explicit at the reference step (1e-5 s; 1e-6 s for the 2D coupling) and at its CFL step.
template <class Sim>
std::vector<Row> bench_mesh_scene(const pnet::Scene& scene, int frames, const Extras& extras) {
    constexpr bool fem = std::is_same_v<Sim, pnet::FemSimulation<Sim::kDim>>;
    pnet::IntegratorSettings base = pnet::integrator_settings(scene, "plasticitynet");
    pnet::load_scene_models(scene, false, base);
    std::vector<Row> rows;
    rows.push_back(measure<Sim>(scene, base, frames));
    rows.push_back(measure<Sim>(scene, with_integrator(base, "return_map", base.dt), frames));
    add_outer_rows<Sim>(rows, scene, base, frames, extras);
    if (!fem) add_v_star_rows<Sim>(rows, scene, base, frames, extras);
    if (fem && extras.last_velocity) {  // each step from the last velocities with the plate on its target
        pnet::IntegratorSettings last = base;
        last.fem.kinematic_start = "last_velocity";
        rows.push_back(measure<Sim>(scene, last, frames));
        rows.back().integrator = "plasticitynet, last-velocity start";
    }
    if (fem && extras.lagged && scene.meshes[0].material.name == "metal")
        rows.push_back(measure<Sim>(scene, with_integrator(base, "analytic", base.dt), frames));
    if (extras.lagged) rows.push_back(measure<Sim>(scene, with_integrator(base, "lagged", base.dt), frames));
    rows.push_back(measure<Sim>(scene, with_integrator(base, "explicit", reference_step(scene.name)), frames));
    rows.push_back(measure<Sim>(scene, with_integrator(base, "explicit", 0.0), frames));
    return rows;
}

}  // namespace

int main(int argc, char** argv) {
    int frames = 10, fem_frames = 0, coupling_frames = 10, stiff_frames = 0, threads = 0;
    double dt_implicit = 1e-3;
    Extras extras;
    bool three_d = false, fem = true, stiff = true;
    std::string scenes_dir = PNET_SCENES_DIR, only;
    for (int i = 1; i < argc; ++i) {
        const std::string arg = argv[i];
        auto value = [&]() -> const char* {
            if (i + 1 >= argc) {
                std::fprintf(stderr, "bench_table1: %s needs a value\n", arg.c_str());
                std::exit(2);
            }
            return argv[++i];
        };
        if (arg == "--frames")
            frames = std::atoi(value());
        else if (arg == "--fem-frames")
            fem_frames = std::atoi(value());
        else if (arg == "--coupling-frames")
            coupling_frames = std::atoi(value());
        else if (arg == "--no-fem")
            fem = false;
        else if (arg == "--stiff-frames")
            stiff_frames = std::atoi(value());
        else if (arg == "--no-stiff")
            stiff = false;
        else if (arg == "--threads")
            threads = std::atoi(value());
        else if (arg == "--dt-implicit")
            dt_implicit = std::atof(value());
        else if (arg == "--scenes")
            scenes_dir = value();
        else if (arg == "--only")
            only = value();
        else if (arg == "--with-lagged")
            extras.lagged = true;
        else if (arg == "--with-one-solve")
            extras.one_solve = true;
        else if (arg == "--with-fixed-point")
            extras.fixed_point = true;
        else if (arg == "--with-newton-outer")
            extras.newton = true;
        else if (arg == "--with-last-velocity")
            extras.last_velocity = true;
        else if (arg == "--with-uncapped")
            extras.uncapped = true;
        else if (arg == "--with-v-star")
            extras.v_star = true;
        else if (arg == "--3d")
            three_d = true;
        else {
            std::fprintf(stderr,
                         "usage: bench_table1 [--frames N] [--fem-frames N] [--coupling-frames N] [--stiff-frames N] "
                         "[--threads T] [--dt-implicit S] [--scenes DIR] [--only NAME] [--with-lagged] "
                         "[--with-one-solve] [--with-fixed-point] [--with-newton-outer] [--with-last-velocity] "
                         "[--with-uncapped] [--with-v-star] [--3d] "
                         "[--no-fem] "
                         "[--no-stiff]\n");
            return 2;
        }
    }
    if (frames < 1 || fem_frames < 0 || coupling_frames < 1 || stiff_frames < 0 || !(dt_implicit > 0.0)) {
        std::fprintf(stderr,
                     "bench_table1: --frames and --coupling-frames must be >= 1, --fem-frames and "
                     "--stiff-frames >= 0 and --dt-implicit > 0\n");
        return 2;
    }
    if (stiff_frames == 0) stiff_frames = frames;
    pnet::use_threads(threads);  // --threads or every core; LibTorch's count too (sim/threads.hpp)
    // The paper's Table 1 (2D, s/frame; their machine): ours (MPM 1e-3, FEM 1e-2) vs explicit at 1e-5.
    const std::map<std::string, std::pair<double, double>> paper = {{"sand_column_2d", {12.58, 6.20}},
                                                                    {"snowball_2d", {35.56, 6.78}},
                                                                    {"metal_frame_2d", {1.08, 5.39}},
                                                                    {"metal_nh_frame_2d", {1.03, 7.88}},
                                                                    {"sand_fem_coupling_2d", {38.90, 184.58}}};
    std::vector<std::string> names = {"sand_column_2d", "snowball_2d"};
    if (stiff) names.insert(names.end(), {"stiff/sand_column_2d", "stiff/snowball_2d"});
    if (fem) names.insert(names.end(), {"metal_frame_2d", "metal_nh_frame_2d", "sand_fem_coupling_2d"});
    if (three_d) names.insert(names.end(), {"sand_column_3d", "snowball_3d"});
    if (three_d && fem) names.insert(names.end(), {"metal_frame_3d", "sand_fem_coupling_3d"});

    std::printf(
        "Table 1: seconds per frame (0.02 s) over frames 0-%d from the initial state (the metal frames: "
        "%s), %d threads\n\n",
        frames, fem_frames > 0 ? ("0-" + std::to_string(fem_frames)).c_str() : "all the scene's frames",
        omp_get_max_threads());
    std::printf(
        "| scene | integrator | dt (s) | s/frame | x return_map | Newton/step | CG/step | network passes/step |"
        " solves/step | F0 updates/step | max |R| (m/s) | energy %% | CG %% |"
        " contact %% | speed-up vs explicit 1e-5 (2D coupling, stiff: 1e-6) | speed-up vs explicit at CFL |"
        " paper s/frame | paper speed-up |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    for (const std::string& name : names) {
        if (!only.empty() && only != name) continue;
        std::vector<Row> rows;
        int scene_frames = frames;
        try {
            const pnet::Scene scene = pnet::load_scene(scenes_dir + "/" + name + ".json");
            std::fprintf(stderr, "%s:\n", name.c_str());
            if (scene.has_meshes() && scene.has_particles()) {
                scene_frames = coupling_frames;
                rows = scene.dim == 2 ? bench_mesh_scene<pnet::CoupledSimulation<2>>(scene, scene_frames, extras)
                                      : bench_mesh_scene<pnet::CoupledSimulation<3>>(scene, scene_frames, extras);
            } else if (scene.has_meshes()) {
                scene_frames = fem_frames > 0 ? fem_frames : scene.frames;
                rows = scene.dim == 2 ? bench_mesh_scene<pnet::FemSimulation<2>>(scene, scene_frames, extras)
                                      : bench_mesh_scene<pnet::FemSimulation<3>>(scene, scene_frames, extras);
            } else {
                if (name.rfind("stiff/", 0) == 0) scene_frames = stiff_frames;
                const double reference_dt = reference_step(name);
                rows = scene.dim == 2 ? bench_scene<2>(scene, scene_frames, dt_implicit, reference_dt, extras)
                                      : bench_scene<3>(scene, scene_frames, dt_implicit, reference_dt, extras);
            }
        } catch (const std::exception& e) {
            std::fprintf(stderr, "bench_table1: %s: %s\n", name.c_str(), e.what());
            return 1;
        }
        // The references: explicit at the paper's ground-truth step (1e-5 s; the coupling and the stiff
        // variants: 1e-6 s), and explicit at its CFL step (if it ran through the interval).
        const double reference_dt = reference_step(name);
        double explicit_1e5 = 0.0, explicit_cfl = 0.0, return_map = 0.0;
        for (const Row& r : rows) {
            if (r.integrator == "return_map" && r.failure.empty()) return_map = r.seconds_per_frame;
            if (r.integrator == "explicit" && r.dt == reference_dt) explicit_1e5 = r.seconds_per_frame;
            if (r.integrator == "explicit" && r.dt == 0.0 && r.failure.empty()) explicit_cfl = r.seconds_per_frame;
        }
        const auto p = paper.find(name);
        for (const Row& r : rows) {
            char dt[32], paper_cells[64] = "- | -";
            if (r.dt > 0)
                std::snprintf(dt, sizeof dt, "%g", r.dt);
            else
                std::snprintf(dt, sizeof dt, "CFL (mean %.2e)", r.mean_dt);
            if (p != paper.end()) {
                if (r.integrator == "plasticitynet" && (r.dt == 1e-3 || r.dt == 1e-2))
                    std::snprintf(paper_cells, sizeof paper_cells, "%.2f | %.2fx", p->second.first,
                                  p->second.second / p->second.first);
                else if (r.integrator == "explicit" && r.dt == reference_dt)
                    std::snprintf(paper_cells, sizeof paper_cells, "%.2f | 1x", p->second.second);
            }
            const bool implicit = r.integrator != "explicit";
            std::string seconds = std::to_string(r.seconds_per_frame).substr(0, 6);
            if (!r.failure.empty())
                seconds +=
                    " (failed after " + std::to_string(r.frames) + " of " + std::to_string(scene_frames) + " frames)";
            // No speed-up of a run that did not cover the interval.
            char speedup[32] = "-", speedup_cfl[64] = "-";
            if (r.failure.empty()) std::snprintf(speedup, sizeof speedup, "%.2fx", explicit_1e5 / r.seconds_per_frame);
            if (r.failure.empty() && explicit_cfl > 0.0)
                std::snprintf(speedup_cfl, sizeof speedup_cfl, "%.2fx", explicit_cfl / r.seconds_per_frame);
            else if (r.failure.empty())
                std::snprintf(speedup_cfl, sizeof speedup_cfl, "(explicit at CFL failed)");
            const std::string contact =
                r.contact_share >= 0.0 ? std::to_string(static_cast<int>(100 * r.contact_share + 0.5)) : "-";
            char residual[32] = "-", versus_classical[32] = "-", network[32] = "-";
            if (implicit && r.failure.empty() && return_map > 0.0)
                std::snprintf(versus_classical, sizeof versus_classical, "%.2f", r.seconds_per_frame / return_map);
            if (implicit) std::snprintf(network, sizeof network, "%.2f", r.network);
            if (implicit && r.reference_updates > 0.0)
                std::snprintf(residual, sizeof residual, "%.2e", r.max_true_residual);
            std::printf("| %s | %s | %s | %s | %s | %s | %s | %s | %s | %.2f | %s | %s | %s | %s | %s | %s | %s |\n",
                        name.c_str(),
                        r.integrator.c_str(), dt, seconds.c_str(), versus_classical,
                        implicit ? std::to_string(r.newton).substr(0, 4).c_str() : "-",
                        implicit ? std::to_string(static_cast<int>(r.cg + 0.5)).c_str() : "-", network,
                        implicit ? std::to_string(r.fixed_point).substr(0, 4).c_str() : "-", r.reference_updates,
                        residual,
                        implicit ? std::to_string(static_cast<int>(100 * r.energy_share + 0.5)).c_str() : "-",
                        implicit ? std::to_string(static_cast<int>(100 * r.cg_share + 0.5)).c_str() : "-",
                        contact.c_str(), speedup, speedup_cfl, paper_cells);
            std::fflush(stdout);
        }
    }
    std::printf(
        "\nTargets: MPM plasticitynet at 1e-3 >= 2x faster per frame than explicit at 1e-5 (paper: 0.49x "
        "sand, 0.19x snow); metal at 1e-2 >= 10x (paper: 5.0x, 7.65x) and faster than explicit at its CFL "
        "step; coupling at 1e-3 >= 20x faster than explicit coupling at 1e-6 (paper: 4.75x); MPM "
        "plasticitynet faster than explicit at its CFL step, and on the stiff variants >= 10x faster.\n");
    return 0;
}
