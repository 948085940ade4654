#include "simulate_command.hpp"

#include <cstdio>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "parse_number.hpp"
#include "pnet/io/run_folder.hpp"
#include "pnet/nn/model_file.hpp"
#include "pnet/nn/torchscript.hpp"
#include "pnet/scene/scene.hpp"
#include "pnet/sim/run.hpp"
#include "pnet/sim/scene_models.hpp"
#include "pnet/sim/threads.hpp"
#include "pnet/solver/integrators.hpp"

namespace pnet::apps {

namespace {

namespace fs = std::filesystem;

constexpr const char* kUsage =
    "usage: pnet simulate SCENE.json --out DIR [--integrator NAME] [--dt SECONDS]\n"
    "                     [--cfl C] [--frames N] [--threads T] [--checkpoint-every N] [--resume | --overwrite]\n"
    "                     [--color speed|hardening] [--model FILE.pt] [--trust-model] [--vtu]\n"
    "  implicit solver (every integrator but explicit; defaults from the scene's integrator block):\n"
    "                     [--newton-tol M_PER_S] [--cg-tol R] [--outer-iteration auto|newton|fixed_point]\n"
    "                     [--time-integrator backward_euler|bdf2]\n"
    "                     [--hessian auto|network|tangent] [--hessian-precision single|double]\n"
    "                     [--fixed-point-iterations N]\n"
    "                     [--fixed-point-tol T] [--regularizer W] [--tangent-damping W]\n"
    "                     [--preconditioner jacobi|block_jacobi|ichol|multigrid]\n"
    "                     [--lazy-hessian R] [--fixed-point-anderson M] [--fixed-point-keep-hessian yes|no]\n"
    "                     [--advection-cfl C] (MPM: cap a step so no particle moves more than C cells;\n"
    "                     default 0.2, 0: off)\n"
    "  MPM scenes, overriding the scene: [--flip-relaxation-time S] (AFLIP transfers, transfer.flip_relaxation_time;\n"
    "                     0: APIC) [--floor-friction MU] (a Coulomb floor, boundary.floor_friction; docs/methods.md)\n"
    "                     [--floor-friction-in-solve yes|no] (plasticitynet, return_map: the floor's friction\n"
    "                     follows the Newton iterates in one solve; no, the default: three passes of solves)\n"
    "                     [--fixed-point-inexact FORCING]\n"
    "                     [--fail-on-unconverged]\n"
    "  FEM scenes (meshes): analytic is the closed-form StVK-Hencky + von Mises energy;\n"
    "                     [--analytic-regularizer W] (analytic + W mu/2 |F - F0|^2 under plasticitynet's outer\n"
    "                     iteration: the learned solve without learning error, a diagnostic)\n"
    "                     [--return-map learned|exact] (plasticitynet: a model's learned return mapping or the\n"
    "                     material's exact one) [--kinematic-start scaled|last_velocity]\n";

/// `text` (words separated by single spaces) in lines of at most `width` columns.
std::vector<std::string> wrapped(const std::string& text, std::size_t width) {
    std::vector<std::string> lines(1);
    std::size_t start = 0;
    while (start < text.size()) {
        std::size_t end = text.find(' ', start);
        if (end == std::string::npos) end = text.size();
        const std::string word = text.substr(start, end - start);
        if (!lines.back().empty() && lines.back().size() + 1 + word.size() > width) lines.emplace_back();
        lines.back() += (lines.back().empty() ? "" : " ") + word;
        start = end + 1;
    }
    return lines;
}

/// The usage, then each integrator of solver/integrators.hpp with what a step solves.
std::string usage() {
    constexpr std::size_t kIndent = 20, kWidth = 110;
    std::string text = kUsage;
    text += "  integrators (--integrator; the scene's by default; docs/integrators.md):\n";
    for (const IntegratorInfo& info : integrators()) {
        std::string entry = std::string(info.solves) + " [" +
                            (info.particles && info.meshes ? "particles, meshes"
                             : info.particles            ? "particles"
                                                         : "meshes") +
                            (info.reads_models ? "; reads the objects' models" : "; reads no model") + "]";
        const std::string name = std::string("    ") + info.name;
        const std::vector<std::string> lines = wrapped(entry, kWidth - kIndent);
        for (std::size_t k = 0; k < lines.size(); ++k) {
            const std::string lead = k == 0 ? name : "";
            text += lead + std::string(kIndent > lead.size() ? kIndent - lead.size() : 1, ' ') + lines[k] + "\n";
        }
    }
    return text;
}

/// --help, -h: the usage on stdout, exit 0.
struct HelpRequested {};

struct Options {
    std::string scene, integrator;
    RunOptions run;  // --out, --frames, --checkpoint-every, --resume, --overwrite, --vtu, --color
    std::optional<std::string> model;  // --model: the energy model of every object and mesh that names one
    std::optional<double> dt, cfl;
    int threads = 0;
    bool trust_model = false, fail_on_unconverged = false;
    // Implicit solver overrides (unset: the scene's value).
    std::optional<double> newton_tol, cg_tol, fixed_point_tol, regularizer, tangent_damping, lazy_hessian,
        fixed_point_inexact;
    std::optional<double> advection_cfl;
    std::optional<double> flip_relaxation_time, floor_friction;  // scene overrides (MPM)
    std::optional<double> analytic_regularizer;
    std::optional<std::string> preconditioner, return_map, outer_iteration, hessian, hessian_precision, kinematic_start,
        time_integrator;
    std::optional<int> fixed_point_iterations, fixed_point_anderson;
    std::optional<bool> fixed_point_keep_hessian, floor_friction_in_solve;
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
        if (arg == "--help" || arg == "-h")
            throw HelpRequested{};
        else if (arg == "--out")
            o.run.out = value();
        else if (arg == "--integrator")
            o.integrator = value();
        else if (arg == "--dt")
            o.dt = number(value());
        else if (arg == "--cfl")
            o.cfl = number(value());
        else if (arg == "--frames")
            o.run.frames = integer(value(), 1, 10000000, " (frames to simulate)");
        else if (arg == "--threads")
            o.threads = integer(value(), 0, 1024, " (0: all cores)");
        else if (arg == "--checkpoint-every")
            o.run.checkpoint_every = integer(value(), 0, 10000000, " (frames between checkpoints; 0: none)");
        else if (arg == "--newton-tol")
            o.newton_tol = number(value());
        else if (arg == "--cg-tol")
            o.cg_tol = number(value());
        else if (arg == "--fixed-point-tol")
            o.fixed_point_tol = number(value());
        else if (arg == "--regularizer")
            o.regularizer = number(value());
        else if (arg == "--tangent-damping")
            o.tangent_damping = number(value());
        else if (arg == "--analytic-regularizer")
            o.analytic_regularizer = number(value());
        else if (arg == "--lazy-hessian")
            o.lazy_hessian = number(value());
        else if (arg == "--advection-cfl")
            o.advection_cfl = number(value());
        else if (arg == "--flip-relaxation-time")
            o.flip_relaxation_time = number(value());
        else if (arg == "--floor-friction")
            o.floor_friction = number(value());
        else if (arg == "--preconditioner")
            o.preconditioner = value();
        else if (arg == "--time-integrator") {
            const std::string text = value();
            if (text != "backward_euler" && text != "bdf2")
                throw UsageError("--time-integrator: expected backward_euler or bdf2, got \"" + text + "\"");
            o.time_integrator = text;
        } else if (arg == "--outer-iteration") {
            const std::string text = value();
            if (text != "auto" && text != "newton" && text != "fixed_point")
                throw UsageError("--outer-iteration: expected auto, newton or fixed_point, got \"" + text + "\"");
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
        } else if (arg == "--hessian-precision") {
            const std::string text = value();
            if (text != "single" && text != "double")
                throw UsageError("--hessian-precision: expected single or double, got \"" + text + "\"");
            o.hessian_precision = text;
        } else if (arg == "--floor-friction-in-solve") {
            const std::string text = value();
            if (text != "yes" && text != "no")
                throw UsageError("--floor-friction-in-solve: expected yes or no, got \"" + text + "\"");
            o.floor_friction_in_solve = text == "yes";
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
            o.run.color = value();
        else if (arg == "--resume")
            o.run.resume = true;
        else if (arg == "--overwrite")
            o.run.overwrite = true;
        else if (arg == "--vtu")
            o.run.vtu = true;
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
    if (o.run.out.empty()) throw UsageError("--out DIR is required");
    if (o.run.resume && o.run.overwrite)
        throw UsageError("--resume continues the run in --out, --overwrite replaces it: give one");
    if (o.run.color != "speed" && o.run.color != "hardening") throw UsageError("--color: speed or hardening");
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
    if (o.tangent_damping && !(std::isfinite(*o.tangent_damping) && *o.tangent_damping >= 0.0))
        throw UsageError("--tangent-damping must be a finite number >= 0");
    if (o.analytic_regularizer && !(std::isfinite(*o.analytic_regularizer) && *o.analytic_regularizer >= 0.0))
        throw UsageError("--analytic-regularizer must be a finite number >= 0");
    if (o.lazy_hessian && !(*o.lazy_hessian >= 0.0 && *o.lazy_hessian < 1.0))
        throw UsageError("--lazy-hessian must be in [0, 1)");
    if (o.advection_cfl && !(*o.advection_cfl >= 0.0 && *o.advection_cfl <= 1.0))
        throw UsageError("--advection-cfl must be in [0, 1]");
    if (o.flip_relaxation_time && !(std::isfinite(*o.flip_relaxation_time) && *o.flip_relaxation_time >= 0.0))
        throw UsageError("--flip-relaxation-time must be a finite number >= 0 (seconds; 0: APIC)");
    if (o.floor_friction && !(std::isfinite(*o.floor_friction) && *o.floor_friction >= 0.0))
        throw UsageError("--floor-friction must be a finite number >= 0 (a Coulomb friction coefficient)");
    if (o.preconditioner && *o.preconditioner != "jacobi" && *o.preconditioner != "block_jacobi" &&
        *o.preconditioner != "ichol" && *o.preconditioner != "multigrid")
        throw UsageError("--preconditioner: expected jacobi, block_jacobi, ichol or multigrid, got \"" +
                         *o.preconditioner + "\"");
    if (o.return_map && *o.return_map != "learned" && *o.return_map != "exact")
        throw UsageError("--return-map: expected learned or exact, got \"" + *o.return_map + "\"");
    if (o.fixed_point_inexact && !(*o.fixed_point_inexact >= 0.0 && *o.fixed_point_inexact < 1.0))
        throw UsageError("--fixed-point-inexact must be in [0, 1) (0: exact inner solves)");
    return o;
}

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

}  // namespace

int simulate_command(int argc, char** argv) {
    Options o;
    try {
        o = parse(argc, argv);
    } catch (const HelpRequested&) {
        std::fputs(usage().c_str(), stdout);
        return 0;
    } catch (const UsageError& e) {
        std::fprintf(stderr, "pnet simulate: %s\n%s", e.what(), usage().c_str());
        return 2;
    }
    // --threads, or every core the process may use; set in LibTorch too, whose first operation
    // (loading a model) would otherwise impose its own count on OpenMP (sim/threads.hpp).
    use_threads(o.threads);
    try {
        Scene scene = load_scene(o.scene);
        if (o.model) use_model(scene, *o.model);
        if ((o.flip_relaxation_time || o.floor_friction) && !scene.has_particles())
            throw UsageError(std::string(o.flip_relaxation_time ? "--flip-relaxation-time" : "--floor-friction") +
                             ": " + scene.file + " has no particles (an MPM option)");
        if (o.flip_relaxation_time) scene.flip_relaxation_time = *o.flip_relaxation_time;
        if (o.floor_friction) {
            if (scene.boundary.sticky_floor_cells == 0)
                throw UsageError("--floor-friction: " + scene.file + " has no floor layer (boundary.sticky_floor_cells 0)");
            scene.boundary.floor_friction = *o.floor_friction;
        }
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
        if (o.tangent_damping) settings.implicit.tangent_damping = *o.tangent_damping;
        if (o.analytic_regularizer) settings.implicit.analytic_regularizer = *o.analytic_regularizer;
        if (o.preconditioner) settings.implicit.preconditioner = *o.preconditioner;
        if (o.lazy_hessian) settings.implicit.lazy_hessian = *o.lazy_hessian;
        if (o.advection_cfl) settings.implicit.advection_cfl = *o.advection_cfl;
        if (o.fixed_point_iterations) settings.implicit.max_fixed_point_iterations = *o.fixed_point_iterations;
        if (o.fixed_point_anderson) settings.implicit.fixed_point_anderson = *o.fixed_point_anderson;
        if (o.outer_iteration) settings.implicit.outer_iteration = *o.outer_iteration;
        if (o.time_integrator) settings.implicit.time_integrator = *o.time_integrator;
        if (o.hessian) settings.implicit.hessian = *o.hessian;
        if (o.hessian_precision) settings.implicit.hessian_precision = *o.hessian_precision;
        if (o.kinematic_start) settings.implicit.kinematic_start = *o.kinematic_start;
        if (o.fixed_point_inexact) settings.implicit.fixed_point_inexact = *o.fixed_point_inexact;
        if (o.fixed_point_keep_hessian) settings.implicit.fixed_point_keep_hessian = *o.fixed_point_keep_hessian;
        if (o.floor_friction_in_solve) settings.implicit.floor_friction_in_solve = *o.floor_friction_in_solve;
        if (o.return_map) settings.implicit.learned_return_map = *o.return_map == "learned";
        load_scene_models(scene, o.trust_model, settings);
        // A folder holding another run is refused before the simulation is set up (meshing, models).
        if (!o.run.resume) check_run_folder(o.run.out, o.run.overwrite);
        AnySimulation sim = make_simulation(scene, settings);
        run_to_folder(*sim, scene, settings, o.run);
        return 0;
    } catch (const UsageError& e) {
        std::fprintf(stderr, "pnet simulate: %s\n%s", e.what(), usage().c_str());
        return 2;
    } catch (const SimulationError& e) {  // a blow-up or a failed solve: the frames before it are valid
        std::fprintf(stderr, "error: %s\n", e.what());
        return 1;
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
