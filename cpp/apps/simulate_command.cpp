#include "simulate_command.hpp"

#include <cstdio>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "command_line.hpp"
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
    "  MPM scenes, overriding the scene: [--flip-relaxation-time S] (AFLIP transfers, transfer.flip_relaxation_time;\n"
    "                     0: APIC) [--floor-friction MU] (a Coulomb floor, boundary.floor_friction; docs/methods.md)\n"
    "  FEM scenes (meshes): analytic is the closed-form StVK-Hencky + von Mises energy.\n";

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

/// `lead` then `entry` wrapped, its lines indented to kIndent (a lead too long for the indent on a line
/// of its own).
void add_entry(std::string& text, const std::string& lead, const std::string& entry) {
    constexpr std::size_t kIndent = 20, kWidth = 110;
    const bool own_line = lead.size() + 1 > kIndent;
    if (own_line) text += lead + "\n";
    const std::vector<std::string> lines = wrapped(entry, kWidth - kIndent);
    for (std::size_t k = 0; k < lines.size(); ++k) {
        const std::string first = k == 0 && !own_line ? lead : "";
        text += first + std::string(kIndent - first.size(), ' ') + lines[k] + "\n";
    }
}

/// The usage, the implicit solvers' options (solver/implicit_options.hpp, each with its scene key
/// and default), then each integrator of solver/integrators.hpp with what a step solves.
std::string usage() {
    std::string text = kUsage;
    text += "  implicit solvers (every integrator but explicit; the scene's integrator block holds the same keys):\n";
    const IntegratorSettings defaults;
    for (const OptionField<IntegratorSettings>& f : integrator_option_fields()) {
        if (!f.flag) continue;
        const bool is_switch = f.is_switch();
        const std::string lead = std::string("    ") + f.flag + (is_switch ? "" : " X");
        const nlohmann::json value = f.get(defaults);
        std::string shown = value.dump();
        if (f.kind == OptionSpec::Kind::Boolean) shown = is_switch ? "off" : f.choices[value.get<bool>() ? 0 : 1];
        if (value.is_string()) shown = value.get<std::string>();
        if (value.is_number_float() && value.get<double>() == std::floor(value.get<double>()))
            shown = std::to_string(static_cast<long>(value.get<double>()));
        add_entry(text, lead,
                  std::string(f.help) + (is_switch ? "" : "; X: " + f.flag_expected()) + " (scene key " + f.key +
                      ", default " + shown + ")");
    }
    text += "  integrators (--integrator; the scene's by default; docs/integrators.md):\n";
    for (const IntegratorInfo& info : integrators()) {
        std::string entry = std::string(info.solves) + " [" +
                            (info.particles && info.meshes ? "particles, meshes"
                             : info.particles            ? "particles"
                                                         : "meshes") +
                            (info.reads_models ? "; reads the objects' models" : "; reads no model") + "]";
        add_entry(text, std::string("    ") + info.name, entry);
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
    bool trust_model = false;
    // The implicit solvers' options given on the command line, by key (solver/implicit_options.hpp).
    nlohmann::json solver = nlohmann::json::object();
    std::optional<double> flip_relaxation_time, floor_friction;  // scene overrides (MPM)
};

Options parse(int argc, char** argv) {
    Options o;
    for (int i = 1; i < argc; ++i) {
        const std::string arg = argv[i];
        auto value = [&] { return option_value(argc, argv, i); };
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
        else if (arg == "--flip-relaxation-time")
            o.flip_relaxation_time = number(value());
        else if (arg == "--floor-friction")
            o.floor_friction = number(value());
        else if (const OptionField<IntegratorSettings>* f = find_option_field(arg); f && f->flag && arg == f->flag) {
            const bool is_switch = f->is_switch();
            const std::string word = is_switch ? std::string() : value();
            const std::optional<nlohmann::json> v = f->parse_flag(word);
            if (!v) throw UsageError(arg + ": expected " + f->flag_expected() + ", got \"" + word + "\"");
            o.solver[f->key] = *v;
        }
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
    if (o.flip_relaxation_time && !(std::isfinite(*o.flip_relaxation_time) && *o.flip_relaxation_time >= 0.0))
        throw UsageError("--flip-relaxation-time must be a finite number >= 0 (seconds; 0: APIC)");
    if (o.floor_friction && !(std::isfinite(*o.floor_friction) && *o.floor_friction >= 0.0))
        throw UsageError("--floor-friction must be a finite number >= 0 (a Coulomb friction coefficient)");
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
        for (const auto& [key, value] : o.solver.items()) find_option_field(key)->set(settings, value);
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
