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

#include "pnet/io/atomic_file.hpp"
#include "pnet/io/ply.hpp"
#include "pnet/io/png.hpp"
#include "pnet/io/plot.hpp"
#include "pnet/io/render.hpp"
#include "pnet/metrics/run_comparison.hpp"
#include "parse_number.hpp"

namespace pnet::apps {

namespace {

namespace fs = std::filesystem;

constexpr const char* kUsage = "usage: pnet compare DIR_A DIR_B [--out DIR] [--dx DX] [--image]\n";

class UsageError : public std::invalid_argument {
public:
    using std::invalid_argument::invalid_argument;
};

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
        auto value = [&]() -> std::string {
            if (i + 1 >= argc) throw UsageError(arg + " needs a value");
            return argv[++i];
        };
        if (arg == "--out") {
            o.out = value();
            if (o.out.empty()) throw UsageError("--out: empty path");
        } else if (arg == "--dx") {
            const std::string text = value();
            o.dx = parse_number(text).value_or(0.0);
            if (!std::isfinite(o.dx) || !(o.dx > 0.0))
                throw UsageError("--dx: expected a positive number, got \"" + text + "\"");
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

/// img with a title band of `title` above it.
Image titled(const Image& img, const std::string& title) {
    constexpr int band = 20;
    Image out(img.width, img.height + band, {255, 255, 255});
    std::copy(img.rgb.begin(), img.rgb.end(), out.rgb.begin() + 3 * std::size_t(band) * std::size_t(img.width));
    draw_text(out, 6, 6, title, {40, 40, 40});
    return out;
}

/// Images side by side, tops aligned, 8 white pixels apart.
Image side_by_side(const std::vector<Image>& images) {
    int width = 0, height = 0;
    for (const Image& img : images) {
        width += img.width + 8;
        height = std::max(height, img.height);
    }
    Image out(width - 8, height, {255, 255, 255});
    int x0 = 0;
    for (const Image& img : images) {
        for (int y = 0; y < img.height; ++y)
            for (int x = 0; x < img.width; ++x) out.set(x0 + x, y, img.get(x, y));
        x0 += img.width + 8;
    }
    return out;
}

/// 2D: both runs' particles of one frame in one picture: A only blue, B only orange, both grey.
Image overlay_2d(const RunInfo& a, const RunInfo& b, int frame, int width_px) {
    ParticleRenderOptions r;
    for (int k = 0; k < 2; ++k) {
        r.domain_min[k] = a.view_min[k];
        r.domain_max[k] = a.view_max[k];
    }
    r.width_px = width_px;
    r.grid_spacing_m = a.dx;
    const PlyParticles pa = read_particles_ply(a.frames.at(frame), 2), pb = read_particles_ply(b.frames.at(frame), 2);
    // Each run's disks sized from its own particle spacing (radius_px 0), as in its frames.
    const Image ia = render_particles_2d(pa.position, {}, r);
    const Image ib = render_particles_2d(pb.position, {}, r);
    Image out(ia.width, std::min(ia.height, ib.height), {255, 255, 255});
    const Rgb white{255, 255, 255};
    for (int y = 0; y < out.height; ++y)
        for (int x = 0; x < out.width; ++x) {
            const bool in_a = ia.get(x, y) != white, in_b = ib.get(x, y) != white;
            if (in_a && in_b)
                out.set(x, y, {150, 150, 150});
            else if (in_a)
                out.set(x, y, {31, 119, 180});
            else if (in_b)
                out.set(x, y, {255, 127, 14});
        }
    return out;
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

    // compare_runs compares all frames before anything is written, so a bad frame leaves no partial result.
    std::function<void(std::size_t, std::size_t)> progress;
    if (isatty(fileno(stderr)))
        progress = [&](std::size_t k, std::size_t n) {
            std::fprintf(stderr, "\rframe %d  (%zu/%zu)   ", pair.common[k - 1], k, n);
        };
    const RunComparison c = compare_runs(pair, progress);
    const std::vector<FrameIou>& rows = c.frames;
    if (progress) std::fprintf(stderr, "\n");
    if (c.clamped_a + c.clamped_b > 0)
        std::fprintf(stderr,
                     "pnet compare: warning: %zu particle positions in %s and %zu in %s lie outside the domain; "
                     "their mass was put at its edge\n",
                     c.clamped_a, a.dir.c_str(), c.clamped_b, b.dir.c_str());

    std::string csv =
        "frame,time_s,soft_iou,binary_iou,plasticinelab_iou,soft_iou_coarse,spread_a_m,spread_b_m,height_a_m,"
        "height_b_m\n";
    LinePlot plot;
    plot.title = "IoU: " + a.name + " vs " + b.name;
    plot.x_label = "time (s)";
    plot.y_label = "IoU";
    plot.y_min = 0.0;
    plot.y_max = 1.05;  // headroom, so that a curve at 1 does not run along the frame
    plot.series = {{"soft IoU", {}, {}}, {"binary IoU", {}, {}}, {"soft IoU at 4 dx", {}, {}}};
    for (const FrameIou& r : rows) {
        char line[256];
        std::snprintf(line, sizeof line, "%d,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g\n", r.frame, r.time, r.soft,
                      r.binary, r.plasticinelab, r.soft_coarse, r.spread_a, r.spread_b, r.height_a, r.height_b);
        csv += line;
        plot.series[0].x.push_back(r.time);
        plot.series[0].y.push_back(r.soft);
        plot.series[1].x.push_back(r.time);
        plot.series[1].y.push_back(r.binary);
        plot.series[2].x.push_back(r.time);
        plot.series[2].y.push_back(r.soft_coarse);
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
                frame_ranges(pair.common).c_str(), a.dir.c_str(), b.dir.c_str(), c.dx);
    const Summary soft = summarize(rows, &FrameIou::soft);
    const Summary binary = summarize(rows, &FrameIou::binary);
    std::printf("soft IoU:   min %.4f at frame %d (t = %.4g s), mean %.4f\n", soft.min, rows[soft.argmin].frame,
                rows[soft.argmin].time, soft.mean);
    std::printf("binary IoU: min %.4f at frame %d (t = %.4g s), mean %.4f\n", binary.min, rows[binary.argmin].frame,
                rows[binary.argmin].time, binary.mean);
    const Summary coarse = summarize(rows, &FrameIou::soft_coarse);
    std::printf("soft IoU at %d dx: min %.4f at frame %d (t = %.4g s), mean %.4f\n", kCoarseFactor, coarse.min,
                rows[coarse.argmin].frame, rows[coarse.argmin].time, coarse.mean);
    const FrameIou& last = rows.back();
    std::printf("deposit at frame %d: spread %.4f m vs %.4f m (%+.1f%%), height %.4f m vs %.4f m (%+.1f%%)\n",
                last.frame, last.spread_b, last.spread_a, 100.0 * (last.spread_b / last.spread_a - 1.0), last.height_b,
                last.height_a, 100.0 * (last.height_b / last.height_a - 1.0));
    std::printf("wrote %s and %s\n", (out / "iou.csv").string().c_str(), (out / "iou.png").string().c_str());
    if (o.image) {
        // The last common frame: each run's own picture (its frame PNG) and, in 2D, both overlaid.
        const int frame = pair.common.back();
        char name[32];
        std::snprintf(name, sizeof name, "frame_%05d.png", frame);
        std::vector<Image> panels;
        try {
            for (const RunInfo* run : {&a, &b}) {
                const fs::path png = fs::path(run->dir) / name;
                if (fs::exists(png)) panels.push_back(titled(read_png_rgb(png.string()), run->name));
            }
            if (a.dim == 2) {
                const int width = panels.empty() ? 640 : panels.front().width;
                panels.push_back(titled(overlay_2d(a, b, frame, width),
                                        "overlay: blue " + a.name + " only, orange " + b.name + " only, grey both"));
            }
            const fs::path path = out / "compare.png";
            write_png(path.string(), side_by_side(panels));
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
