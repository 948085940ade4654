#include "compare_command.hpp"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

#include "pnet/io/png.hpp"
#include "pnet/metrics/comparison_report.hpp"
#include "pnet/metrics/run_comparison.hpp"
#include "command_line.hpp"

namespace pnet::apps {

namespace {

namespace fs = std::filesystem;

constexpr const char* kUsage =
    "usage: pnet compare DIR_A DIR_B [--out DIR] [--dx DX] [--image]\n"
    "  compares run B with run A (the reference) frame by frame, into DIR_B/compare_<A> or --out:\n"
    "  particles (MPM, coupling): iou.csv, iou.png; meshes (FEM, coupling): nodal.csv (docs/metrics.md)\n";

// A bad --out (exit code 2, like the library's RunInputError for the runs), as opposed to a failure to write the
// results (1).
class InputError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

struct Options {
    std::string dir_a, dir_b, out;
    double dx = 0.0;  // 0: DIR_A's run.json dx
    bool image = false;  // also compare.png: the last common frame side by side (and overlaid in 2D)
};

Options parse(int argc, char** argv) {
    Options o;
    std::vector<std::string> dirs;
    for (int i = 1; i < argc; ++i) {
        const std::string arg = argv[i];
        if (arg == "--out") {
            o.out = path_value(argc, argv, i);
        } else if (arg == "--dx") {
            o.dx = number_value(argc, argv, i, [](double x) { return std::isfinite(x) && x > 0.0; }, "a positive number");
        } else if (arg == "--image") {
            o.image = true;
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

int compare(const Options& o) {
    const RunPair pair = pair_runs(o.dir_a, o.dir_b, o.dx);
    const RunInfo& a = pair.a;
    const RunInfo& b = pair.b;
    if (!pair.only_a.empty())
        std::fprintf(stderr, "pnet compare: warning: frames only in %s, not compared: %s\n", a.dir.c_str(),
                     frame_ranges(pair.only_a).c_str());
    if (!pair.only_b.empty())
        std::fprintf(stderr, "pnet compare: warning: frames only in %s, not compared: %s\n", b.dir.c_str(),
                     frame_ranges(pair.only_b).c_str());

    const fs::path out = o.out.empty() ? fs::path(b.dir) / ("compare_" + a.name) : fs::path(o.out);
    std::error_code ec;
    if (fs::exists(out, ec) && !fs::is_directory(out, ec))
        throw InputError(out.string() + ": exists and is not a directory");

    // Every frame is compared before anything is written, so a bad frame leaves no partial result.
    std::function<void(std::size_t, std::size_t)> progress;
    if (isatty(fileno(stderr)))
        progress = [&](std::size_t k, std::size_t n) {
            std::fprintf(stderr, "\rframe %d  (%zu/%zu)   ", pair.common[k - 1], k, n);
        };
    RunComparison c;
    if (a.particles) {
        c = compare_runs(pair, progress);
        if (progress) std::fprintf(stderr, "\n");
        if (c.clamped_a + c.clamped_b > 0)
            std::fprintf(stderr,
                         "pnet compare: warning: %zu particle positions in %s and %zu in %s lie outside the domain; "
                         "their mass was put at its edge\n",
                         c.clamped_a, a.dir.c_str(), c.clamped_b, b.dir.c_str());
    }
    MeshComparison meshes;
    if (a.meshes) {
        meshes = compare_meshes(pair, progress);
        if (progress) std::fprintf(stderr, "\n");
    }

    try {
        if (a.particles) write_comparison(out, c, a.name, b.name);
        if (a.meshes) write_mesh_comparison(out, meshes);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "pnet compare: %s\n", e.what());
        return 1;
    }
    if (a.particles) {
        std::fputs(comparison_summary(pair, c).c_str(), stdout);
        std::printf("wrote %s and %s\n", (out / "iou.csv").string().c_str(), (out / "iou.png").string().c_str());
    } else {
        std::printf("compared %zu frames (%s) of %s and %s\n", pair.common.size(), frame_ranges(pair.common).c_str(),
                    a.dir.c_str(), b.dir.c_str());
    }
    if (a.meshes) {
        std::fputs(mesh_comparison_summary(meshes).c_str(), stdout);
        std::printf("wrote %s\n", (out / "nodal.csv").string().c_str());
    }
    if (o.image) {
        const int frame = pair.common.back();  // the last common frame
        try {
            const fs::path path = out / "compare.png";
            write_png(path.string(), comparison_picture(pair, frame));
            std::printf("wrote %s (frame %d)\n", path.string().c_str(), frame);
        } catch (const std::exception& e) {
            std::fprintf(stderr, "pnet compare: --image: %s\n", e.what());
            return 1;
        }
    }
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
        // RunInputError (run directories, run.json, frames), InputError (--out) and filesystem errors: all about
        // the inputs.
        std::fprintf(stderr, "pnet compare: %s\n", e.what());
        return 2;
    }
}

}  // namespace pnet::apps
