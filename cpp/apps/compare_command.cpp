#include "compare_command.hpp"

#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <regex>
#include <stdexcept>
#include <string>
#include <vector>

#include "pnet/io/atomic_file.hpp"
#include "pnet/io/ply.hpp"
#include "pnet/io/png.hpp"
#include "pnet/io/render.hpp"
#include "pnet/metrics/iou.hpp"

namespace pnet::apps {

namespace {

namespace fs = std::filesystem;

constexpr const char* kUsage = "usage: pnet compare DIR_A DIR_B [--out DIR] [--dx DX]\n";

// Two grids of this many nodes (8 bytes each) are held at once: 2^27 nodes is 2 GiB in all.
constexpr double kMaxGridNodes = double(1 << 27);

class UsageError : public std::invalid_argument {
public:
    using std::invalid_argument::invalid_argument;
};

// Bad input files or directories (exit code 2), as opposed to a failure to write the results (1).
class InputError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

struct Options {
    std::string dir_a, dir_b, out;
    double dx = 0.0;  // 0: DIR_A's run.json dx
};

Options parse(int argc, char** argv) {
    Options o;
    std::vector<std::string> dirs;
    for (int i = 1; i < argc; ++i) {
        const std::string arg = argv[i];
        auto value = [&]() -> std::string {
            if (i + 1 >= argc) throw UsageError(arg + " needs a value");
            return argv[++i];
        };
        if (arg == "--out") {
            o.out = value();
            if (o.out.empty()) throw UsageError("--out: empty path");
        } else if (arg == "--dx") {
            const std::string text = value();
            std::size_t used = 0;
            try {
                o.dx = std::stod(text, &used);
            } catch (const std::exception&) {
                used = 0;
            }
            if (used == 0 || used != text.size() || !std::isfinite(o.dx) || !(o.dx > 0.0))
                throw UsageError("--dx: expected a positive number, got \"" + text + "\"");
        } else if (arg.size() > 1 && arg[0] == '-') {
            throw UsageError("unknown option " + arg);
        } else {
            dirs.push_back(arg);
        }
    }
    if (dirs.size() != 2)
        throw UsageError(dirs.size() < 2 ? "two run directories are needed" : "unexpected argument " + dirs[2]);
    o.dir_a = dirs[0];
    o.dir_b = dirs[1];
    return o;
}

/// The last component of a directory path, ignoring a trailing separator ("runs/sand/" -> "sand").
std::string base_name(const std::string& dir) {
    fs::path p = fs::absolute(fs::path(dir)).lexically_normal();
    if (p.filename().empty()) p = p.parent_path();
    return p.filename().string();
}

/// What compare needs from one run directory.
struct Run {
    std::string dir, name, json_file;
    int dim = 0;
    std::array<double, 3> domain_min{}, domain_max{};
    double dx = 0.0, frame_dt = 0.0;
    std::map<int, std::string> frames;  // frame number -> PLY path
};

double positive_number(const nlohmann::json& j, const std::string& file, const char* key) {
    if (!j.contains(key)) throw InputError(file + ": missing \"" + key + "\"");
    const nlohmann::json& v = j.at(key);
    if (!v.is_number() || !std::isfinite(v.get<double>()) || !(v.get<double>() > 0.0))
        throw InputError(file + ": " + key + ": expected a positive number, got " + v.dump());
    return v.get<double>();
}

std::array<double, 3> point(const nlohmann::json& j, const std::string& file, const char* key, int dim) {
    if (!j.contains(key)) throw InputError(file + ": missing \"" + key + "\"");
    const nlohmann::json& v = j.at(key);
    bool ok = v.is_array() && v.size() == static_cast<std::size_t>(dim);
    std::array<double, 3> p{};
    for (int d = 0; ok && d < dim; ++d) {
        ok = v[d].is_number() && std::isfinite(v[d].get<double>());
        if (ok) p[d] = v[d].get<double>();
    }
    if (!ok)
        throw InputError(file + ": " + key + ": expected " + std::to_string(dim) + " finite numbers, got " + v.dump());
    return p;
}

Run read_run(const std::string& dir) {
    Run run;
    run.dir = dir;
    run.name = base_name(dir);
    std::error_code ec;
    if (!fs::is_directory(dir, ec))
        throw InputError(dir + (fs::exists(dir, ec) ? ": not a directory" : ": no such directory"));
    run.json_file = (fs::path(dir) / "run.json").string();
    std::ifstream in(run.json_file);
    if (!in) throw InputError(run.json_file + ": cannot read (is " + dir + " the output of pnet simulate?)");
    nlohmann::json j;
    try {
        j = nlohmann::json::parse(in);
    } catch (const nlohmann::json::exception& e) {
        throw InputError(run.json_file + ": not valid JSON: " + e.what());
    }
    if (!j.is_object()) throw InputError(run.json_file + ": expected a JSON object");
    if (!j.contains("dim")) throw InputError(run.json_file + ": missing \"dim\"");
    const nlohmann::json& dim = j.at("dim");
    if (!dim.is_number_integer() || (dim.get<int>() != 2 && dim.get<int>() != 3))
        throw InputError(run.json_file + ": dim: expected 2 or 3, got " + dim.dump());
    run.dim = dim.get<int>();
    run.domain_min = point(j, run.json_file, "domain_min", run.dim);
    run.domain_max = point(j, run.json_file, "domain_max", run.dim);
    for (int d = 0; d < run.dim; ++d)
        if (!(run.domain_max[d] > run.domain_min[d]))
            throw InputError(run.json_file + ": domain_max: must exceed domain_min on every axis, got " +
                             j.at("domain_max").dump() + " and " + j.at("domain_min").dump());
    run.dx = positive_number(j, run.json_file, "dx");
    run.frame_dt = positive_number(j, run.json_file, "frame_dt");

    // frame_NNNNN.ply: at least 5 digits (%05d); temporary files of an atomic write (".tmp.<pid>") do not match.
    static const std::regex frame_name(R"(frame_(\d{5,9})\.ply)");
    for (const fs::directory_entry& e : fs::directory_iterator(dir, ec)) {
        std::smatch m;
        const std::string name = e.path().filename().string();
        if (std::regex_match(name, m, frame_name)) run.frames[std::stoi(m[1].str())] = e.path().string();
    }
    if (ec) throw InputError(dir + ": cannot list the directory: " + ec.message());
    return run;
}

bool same(double a, double b, double scale) {
    return std::abs(a - b) <= 1e-9 * scale;
}

/// Errors, naming B's run.json and the field, if B cannot be compared frame by frame with A.
void check_consistent(const Run& a, const Run& b) {
    auto differs = [&](const std::string& field, const std::string& va, const std::string& vb) {
        return InputError(b.json_file + ": " + field + " is " + vb + " but " + a.json_file + " has " + va +
                          "; the runs cannot be compared");
    };
    auto list = [](const std::array<double, 3>& p, int dim) {
        return nlohmann::json(std::vector<double>(p.begin(), p.begin() + dim)).dump();
    };
    if (a.dim != b.dim) throw differs("dim", std::to_string(a.dim), std::to_string(b.dim));
    for (int d = 0; d < a.dim; ++d) {
        const double extent = a.domain_max[d] - a.domain_min[d];
        if (!same(a.domain_min[d], b.domain_min[d], extent))
            throw differs("domain_min", list(a.domain_min, a.dim), list(b.domain_min, b.dim));
        if (!same(a.domain_max[d], b.domain_max[d], extent))
            throw differs("domain_max", list(a.domain_max, a.dim), list(b.domain_max, b.dim));
    }
    // Frames are paired by number, so they must be the same times.
    if (!same(a.frame_dt, b.frame_dt, a.frame_dt))
        throw differs("frame_dt", nlohmann::json(a.frame_dt).dump(), nlohmann::json(b.frame_dt).dump());
}

/// "3, 7-9, 12" for the sorted frame numbers.
std::string ranges(const std::vector<int>& frames) {
    std::string s;
    for (std::size_t i = 0; i < frames.size();) {
        std::size_t j = i;
        while (j + 1 < frames.size() && frames[j + 1] == frames[j] + 1) ++j;
        if (!s.empty()) s += ", ";
        s += std::to_string(frames[i]);
        if (j > i) s += "-" + std::to_string(frames[j]);
        i = j + 1;
    }
    return s;
}

GridField rasterize(const std::string& path, const PlyParticles& p, const Run& run, double dx, std::size_t& clamped) {
    double total = 0.0;
    for (double m : p.mass) total += m;
    if (!(total > 0.0))
        throw InputError(path + ": no particle mass to compare (" + std::to_string(p.size()) + " particles)");
    std::size_t c = 0;
    GridField g;
    try {
        g = rasterize_mass(run.dim, p.position, p.mass, run.domain_min.data(), run.domain_max.data(), dx, &c);
    } catch (const std::invalid_argument& e) {
        throw InputError(path + ": " + e.what());
    }
    clamped += c;
    return g;
}

struct FrameIou {
    int frame;
    double time, soft, binary, plasticinelab;
};

struct Summary {
    double min = 0.0, mean = 0.0;
    std::size_t argmin = 0;
};

Summary summarize(const std::vector<FrameIou>& rows, double FrameIou::*field) {
    Summary s;
    s.min = rows[0].*field;
    for (std::size_t i = 0; i < rows.size(); ++i) {
        s.mean += rows[i].*field;
        if (rows[i].*field < s.min) {
            s.min = rows[i].*field;
            s.argmin = i;
        }
    }
    s.mean /= static_cast<double>(rows.size());
    return s;
}

int compare(const Options& o) {
    const Run a = read_run(o.dir_a);
    const Run b = read_run(o.dir_b);
    check_consistent(a, b);
    const double dx = o.dx > 0.0 ? o.dx : a.dx;
    double nodes = 1.0;
    for (int d = 0; d < a.dim; ++d) nodes *= std::ceil((a.domain_max[d] - a.domain_min[d]) / dx) + 1.0;
    if (nodes > kMaxGridNodes)
        throw InputError("dx = " + nlohmann::json(dx).dump() + " gives a grid of " + nlohmann::json(nodes).dump() +
                         " nodes; choose a coarser --dx");

    std::vector<int> common, only_a, only_b;
    for (const auto& [frame, path] : a.frames) (b.frames.count(frame) ? common : only_a).push_back(frame);
    for (const auto& [frame, path] : b.frames)
        if (!a.frames.count(frame)) only_b.push_back(frame);
    if (common.empty())
        throw InputError("no frame_NNNNN.ply present in both " + a.dir + " (" +
                         (a.frames.empty() ? "none" : ranges(only_a)) + ") and " + b.dir + " (" +
                         (b.frames.empty() ? "none" : ranges(only_b)) + ")");
    if (!only_a.empty())
        std::fprintf(stderr, "pnet compare: warning: frames only in %s, not compared: %s\n", a.dir.c_str(),
                     ranges(only_a).c_str());
    if (!only_b.empty())
        std::fprintf(stderr, "pnet compare: warning: frames only in %s, not compared: %s\n", b.dir.c_str(),
                     ranges(only_b).c_str());

    const fs::path out = o.out.empty() ? fs::path(b.dir) / ("compare_" + a.name) : fs::path(o.out);
    std::error_code ec;
    if (fs::exists(out, ec) && !fs::is_directory(out, ec))
        throw InputError(out.string() + ": exists and is not a directory");

    // All frames are compared before anything is written, so a bad frame leaves no partial result.
    const bool progress = isatty(fileno(stderr));
    std::vector<FrameIou> rows;
    std::size_t clamped_a = 0, clamped_b = 0;
    for (std::size_t k = 0; k < common.size(); ++k) {
        const int frame = common[k];
        const std::string& path_a = a.frames.at(frame);
        const std::string& path_b = b.frames.at(frame);
        // read_particles_ply's errors start with the path; requiring run.json's dim checks the file against it.
        const GridField ga = rasterize(path_a, read_particles_ply(path_a, a.dim), a, dx, clamped_a);
        const GridField gb = rasterize(path_b, read_particles_ply(path_b, b.dim), b, dx, clamped_b);
        IouResult r{};
        try {
            r = iou(ga, gb);
        } catch (const std::invalid_argument& e) {
            throw InputError(path_a + " vs " + path_b + ": " + e.what());
        }
        rows.push_back({frame, frame * a.frame_dt, r.soft, r.binary, r.plasticinelab});
        if (progress) std::fprintf(stderr, "\rframe %d  (%zu/%zu)   ", frame, k + 1, common.size());
    }
    if (progress) std::fprintf(stderr, "\n");
    if (clamped_a + clamped_b > 0)
        std::fprintf(stderr,
                     "pnet compare: warning: %zu particle positions in %s and %zu in %s lie outside the domain; "
                     "their mass was put at its edge\n",
                     clamped_a, a.dir.c_str(), clamped_b, b.dir.c_str());

    std::string csv = "frame,time_s,soft_iou,binary_iou,plasticinelab_iou\n";
    LinePlot plot;
    plot.title = "IoU: " + a.name + " vs " + b.name;
    plot.x_label = "time (s)";
    plot.y_label = "IoU";
    plot.y_min = 0.0;
    plot.y_max = 1.05;  // headroom, so that a curve at 1 does not run along the frame
    plot.series = {{"soft IoU", {}, {}}, {"binary IoU", {}, {}}};
    for (const FrameIou& r : rows) {
        char line[160];
        std::snprintf(line, sizeof line, "%d,%.9g,%.9g,%.9g,%.9g\n", r.frame, r.time, r.soft, r.binary,
                      r.plasticinelab);
        csv += line;
        plot.series[0].x.push_back(r.time);
        plot.series[0].y.push_back(r.soft);
        plot.series[1].x.push_back(r.time);
        plot.series[1].y.push_back(r.binary);
    }
    const Image image = render_line_plot(plot);

    try {
        fs::create_directories(out);
        write_text_atomically((out / "iou.csv").string(), csv);
        write_png((out / "iou.png").string(), image);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "pnet compare: %s\n", e.what());
        return 1;
    }

    std::printf("compared %zu frames (%s) of %s and %s on a grid with dx = %g m\n", rows.size(),
                ranges(common).c_str(), a.dir.c_str(), b.dir.c_str(), dx);
    const Summary soft = summarize(rows, &FrameIou::soft);
    const Summary binary = summarize(rows, &FrameIou::binary);
    std::printf("soft IoU:   min %.4f at frame %d (t = %.4g s), mean %.4f\n", soft.min, rows[soft.argmin].frame,
                rows[soft.argmin].time, soft.mean);
    std::printf("binary IoU: min %.4f at frame %d (t = %.4g s), mean %.4f\n", binary.min, rows[binary.argmin].frame,
                rows[binary.argmin].time, binary.mean);
    std::printf("wrote %s and %s\n", (out / "iou.csv").string().c_str(), (out / "iou.png").string().c_str());
    return 0;
}

}  // namespace

int compare_command(int argc, char** argv) {
    Options o;
    try {
        if (argc == 2 && (std::string(argv[1]) == "--help" || std::string(argv[1]) == "-h")) {
            std::fputs(kUsage, stdout);
            return 0;
        }
        o = parse(argc, argv);
    } catch (const UsageError& e) {
        std::fprintf(stderr, "pnet compare: %s\n%s", e.what(), kUsage);
        return 2;
    }
    try {
        return compare(o);
    } catch (const std::exception& e) {
        // InputError, read_particles_ply's "<path>: ..." and filesystem errors: all about the inputs.
        std::fprintf(stderr, "pnet compare: %s\n", e.what());
        return 2;
    }
}

}  // namespace pnet::apps
