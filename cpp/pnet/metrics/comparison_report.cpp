#include "pnet/metrics/comparison_report.hpp"

#include <algorithm>
#include <cstdio>

#include "pnet/io/atomic_file.hpp"
#include "pnet/io/ply.hpp"
#include "pnet/io/plot.hpp"
#include "pnet/io/render.hpp"

namespace pnet {

namespace {

namespace fs = std::filesystem;

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

}  // namespace

std::string comparison_csv(const RunComparison& c) {
    std::string csv =
        "frame,time_s,soft_iou,binary_iou,plasticinelab_iou,soft_iou_coarse,spread_a_m,spread_b_m,height_a_m,"
        "height_b_m\n";
    for (const FrameIou& r : c.frames) {
        char line[256];
        std::snprintf(line, sizeof line, "%d,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g,%.9g\n", r.frame, r.time, r.soft,
                      r.binary, r.plasticinelab, r.soft_coarse, r.spread_a, r.spread_b, r.height_a, r.height_b);
        csv += line;
    }
    return csv;
}

Image comparison_plot(const RunComparison& c, const std::string& name_a, const std::string& name_b) {
    LinePlot plot;
    plot.title = "IoU: " + name_a + " vs " + name_b;
    plot.x_label = "time (s)";
    plot.y_label = "IoU";
    plot.y_min = 0.0;
    plot.y_max = 1.05;  // headroom, so that a curve at 1 does not run along the frame
    plot.series = {{"soft IoU", {}, {}}, {"binary IoU", {}, {}}, {"soft IoU at 4 dx", {}, {}}};
    for (const FrameIou& r : c.frames) {
        plot.series[0].x.push_back(r.time);
        plot.series[0].y.push_back(r.soft);
        plot.series[1].x.push_back(r.time);
        plot.series[1].y.push_back(r.binary);
        plot.series[2].x.push_back(r.time);
        plot.series[2].y.push_back(r.soft_coarse);
    }
    return render_line_plot(plot);
}

void write_comparison(const fs::path& out, const RunComparison& c, const std::string& name_a,
                      const std::string& name_b) {
    const Image image = comparison_plot(c, name_a, name_b);
    fs::create_directories(out);
    write_text_atomically((out / "iou.csv").string(), comparison_csv(c));
    write_png((out / "iou.png").string(), image);
}

std::string comparison_summary(const RunPair& pair, const RunComparison& c) {
    const std::vector<FrameIou>& rows = c.frames;
    std::string text;
    char line[512];
    std::snprintf(line, sizeof line, "compared %zu frames (%s) of %s and %s on a grid with dx = %g m\n", rows.size(),
                  frame_ranges(pair.common).c_str(), pair.a.dir.c_str(), pair.b.dir.c_str(), c.dx);
    text += line;
    const Summary soft = summarize(rows, &FrameIou::soft);
    const Summary binary = summarize(rows, &FrameIou::binary);
    std::snprintf(line, sizeof line, "soft IoU:   min %.4f at frame %d (t = %.4g s), mean %.4f\n", soft.min,
                  rows[soft.argmin].frame, rows[soft.argmin].time, soft.mean);
    text += line;
    std::snprintf(line, sizeof line, "binary IoU: min %.4f at frame %d (t = %.4g s), mean %.4f\n", binary.min,
                  rows[binary.argmin].frame, rows[binary.argmin].time, binary.mean);
    text += line;
    const Summary coarse = summarize(rows, &FrameIou::soft_coarse);
    std::snprintf(line, sizeof line, "soft IoU at %d dx: min %.4f at frame %d (t = %.4g s), mean %.4f\n",
                  kCoarseFactor, coarse.min, rows[coarse.argmin].frame, rows[coarse.argmin].time, coarse.mean);
    text += line;
    const FrameIou& last = rows.back();
    std::snprintf(line, sizeof line,
                  "deposit at frame %d: spread %.4f m vs %.4f m (%+.1f%%), height %.4f m vs %.4f m (%+.1f%%)\n",
                  last.frame, last.spread_b, last.spread_a, 100.0 * (last.spread_b / last.spread_a - 1.0),
                  last.height_b, last.height_a, 100.0 * (last.height_b / last.height_a - 1.0));
    text += line;
    return text;
}

void write_mesh_comparison(const fs::path& out, const MeshComparison& c) {
    fs::create_directories(out);
    write_text_atomically((out / "nodal.csv").string(), mesh_comparison_csv(c));
}

std::string mesh_comparison_summary(const MeshComparison& c) {
    std::string text;
    char line[512];
    const FrameMeshError& last = c.frames.back();
    const auto worst = std::max_element(c.frames.begin(), c.frames.end(), [](const auto& x, const auto& y) {
        return x.mean < y.mean;
    });
    std::snprintf(line, sizeof line,
                  "body (%zu nodes, size %.4g m): nodal distance at frame %d mean %.4g m (%.3f%%), max %.4g m "
                  "(%.3f%%); worst mean %.3f%% at frame %d\n",
                  c.nodes, c.size, last.frame, last.mean, last.mean_pct, last.max, last.max_pct, worst->mean_pct,
                  worst->frame);
    text += line;
    if (last.penetrations >= 0) {
        long most = 0;
        for (const FrameMeshError& f : c.frames) most = std::max(most, f.penetrations);
        std::snprintf(line, sizeof line, "particles inside the body: at most %ld in a frame\n", most);
        text += line;
    }
    return text;
}

Image comparison_picture(const RunPair& pair, int frame) {
    const RunInfo& a = pair.a;
    const RunInfo& b = pair.b;
    char name[32];
    std::snprintf(name, sizeof name, "frame_%05d.png", frame);
    std::vector<Image> panels;
    for (const RunInfo* run : {&a, &b}) {
        const fs::path png = fs::path(run->dir) / name;
        if (fs::exists(png)) panels.push_back(titled(read_png_rgb(png.string()), run->name));
    }
    if (a.dim == 2 && a.particles) {
        const int width = panels.empty() ? 640 : panels.front().width;
        panels.push_back(titled(overlay_2d(a, b, frame, width),
                                "overlay: blue " + a.name + " only, orange " + b.name + " only, grey both"));
    }
    return side_by_side(panels);
}

}  // namespace pnet
