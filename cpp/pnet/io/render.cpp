#include "pnet/io/render.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <numeric>
#include <stdexcept>

#include <Eigen/Core>
#include <Eigen/Geometry>  // cross()

#include "pnet/io/particle_spacing.hpp"
#include "pnet/io/raster.hpp"

namespace pnet {

using namespace raster;

namespace {

// ---------------------------------------------------------------------------------------------
// Particle renderers.

constexpr int kMaxImageSide = 16384;

int text_scale_for(int width_px) {
    return width_px >= 600 ? 2 : 1;
}

void check_particle_input(const std::vector<double>& position, const std::vector<double>& value, int dim,
                          const ParticleRenderOptions& options, const char* who) {
    const std::string prefix = std::string(who) + ": ";
    if (position.size() % std::size_t(dim) != 0) {
        throw std::invalid_argument(prefix + "position has " + std::to_string(position.size()) +
                                    " values, not a multiple of " + std::to_string(dim));
    }
    const std::size_t n = position.size() / std::size_t(dim);
    if (!value.empty() && value.size() != n) {
        throw std::invalid_argument(prefix + "value has " + std::to_string(value.size()) + " entries for " +
                                    std::to_string(n) + " particles");
    }
    for (int k = 0; k < dim; ++k) {
        if (!(options.domain_max[k] > options.domain_min[k]) ||
            !std::isfinite(options.domain_max[k] - options.domain_min[k])) {
            throw std::invalid_argument(prefix + "empty or non-finite domain along axis " + std::to_string(k));
        }
    }
    if (options.width_px < 16 || options.width_px > kMaxImageSide) {
        throw std::invalid_argument(prefix + "width_px " + std::to_string(options.width_px) + " outside [16, 16384]");
    }
}

int image_height(double extent_px, int margin, const char* who) {
    const double h = std::round(extent_px) + 2 * margin;
    if (!(h >= 1 && h <= kMaxImageSide)) {
        throw std::invalid_argument(std::string(who) + ": the domain's aspect ratio makes the image " +
                                    std::to_string(h) + " pixels high");
    }
    return int(h);
}

Rgb particle_colour(const std::vector<double>& value, std::size_t i, const ParticleRenderOptions& options) {
    if (value.empty()) return viridis(0.45);
    const double range = options.value_max - options.value_min;
    return viridis(range > 0 ? (value[i] - options.value_min) / range : 0.5);
}


// Sphere (disk) radius in pixels for world-to-pixel scale s: the option, or 0.75 x the particle
// spacing (more than half the diagonal of a square lattice cell, so that a body shows no gaps)
// and at least 0.6 x the grid spacing when it is known (rows of particles that shear apart by
// less than a cell stay joined, as the grid sees them), within [0.8, 1/16 of the image width].
double disk_radius(const std::vector<double>& position, int dim, const ParticleRenderOptions& options, double s) {
    if (options.radius_px > 0) return options.radius_px;
    double spacing = particle_spacing(position, dim);
    if (!(spacing > 0)) spacing = (options.domain_max[0] - options.domain_min[0]) / 100.0;
    const double radius = std::max(0.75 * spacing, 0.6 * options.grid_spacing_m);
    return std::clamp(radius * s, 0.8, options.width_px / 16.0);
}

// The automatic 2D splats at world-to-pixel scale s: {half-width H, particle spacing h}, both in
// pixels; h is options.particle_spacing_m or else the median nearest-neighbour distance, H the
// larger of h and the grid spacing (options.grid_spacing_m), within [1, 1/16 of the image width].
std::array<double, 2> splat_size(const std::vector<double>& position, const ParticleRenderOptions& options, double s) {
    double spacing = options.particle_spacing_m > 0 ? options.particle_spacing_m : particle_spacing(position, 2);
    if (!(spacing > 0)) spacing = (options.domain_max[0] - options.domain_min[0]) / 100.0;
    const double H = std::clamp(std::max(spacing, options.grid_spacing_m) * s, 1.0, options.width_px / 16.0);
    return {H, spacing * s};
}

// Partition-of-unity splats (2D, automatic size). Particle i adds the tent
//     w(u, v) = max(0, 1 - |u - u_i| / H) max(0, 1 - |v - v_i| / H)
// at each pixel centre (u, v), H the splat half-width in pixels. The tents are the bilinear
// interpolation basis of a lattice of spacing H, so on a lattice of spacing h = H / k they sum
// to k^2 = (H / h)^2 at every pixel inside a body, whatever the pixel pitch: with the coverage
// (h / H)^2 sum w, the body fills evenly, with none of the moire that disks at a non-integer
// pitch make. With h the particles' rest spacing (h^2 the area each stands for), the coverage is
// the local density over the rest density, 1 / J: a stretched body shows lighter and a gap wider
// than 2H stays open. With H the grid
// spacing, particles are spread over the cells their mass goes to, as MPM's grid sees the
// material, and rows of particles that shear apart by less than a cell do not show as stripes.
// A pixel shows the weighted mean value's colour at opacity min(1, coverage) over the white.
void splat_particles_2d(Image& img, const std::vector<double>& position, const std::vector<double>& value,
                        const ParticleRenderOptions& options, int margin, double s, double H, double h) {
    const std::size_t n = position.size() / 2;
    const std::size_t pixels = std::size_t(img.width) * std::size_t(img.height);
    std::vector<double> weight(pixels, 0.0), weighted_value(pixels, 0.0);
    for (std::size_t i = 0; i < n; ++i) {
        const double x = position[2 * i], y = position[2 * i + 1];
        if (!std::isfinite(x) || !std::isfinite(y)) continue;
        const double u = margin + (x - options.domain_min[0]) * s, v = margin + (options.domain_max[1] - y) * s;
        const int u0 = std::max(0, int(std::floor(u - H))), u1 = std::min(img.width - 1, int(std::ceil(u + H)));
        const int v0 = std::max(0, int(std::floor(v - H))), v1 = std::min(img.height - 1, int(std::ceil(v + H)));
        const double value_i = value.empty() ? 0.0 : value[i];
        for (int py = v0; py <= v1; ++py) {
            const double wy = 1.0 - std::abs(py + 0.5 - v) / H;
            if (wy <= 0) continue;
            for (int px = u0; px <= u1; ++px) {
                const double w = wy * (1.0 - std::abs(px + 0.5 - u) / H);
                if (w <= 0) continue;
                const std::size_t k = std::size_t(py) * std::size_t(img.width) + std::size_t(px);
                weight[k] += w;
                weighted_value[k] += w * value_i;
            }
        }
    }
    const double range = options.value_max - options.value_min;
    for (int py = 0; py < img.height; ++py)
        for (int px = 0; px < img.width; ++px) {
            const std::size_t k = std::size_t(py) * std::size_t(img.width) + std::size_t(px);
            if (weight[k] <= 0) continue;
            const double mean = weighted_value[k] / weight[k];
            const Rgb c = value.empty() ? viridis(0.45) : viridis(range > 0 ? (mean - options.value_min) / range : 0.5);
            const double alpha = std::min(1.0, weight[k] * (h / H) * (h / H));
            const Rgb under = img.get(px, py);
            auto mix = [&](std::uint8_t top, std::uint8_t bottom) {
                return std::uint8_t(std::lround(alpha * top + (1.0 - alpha) * bottom));
            };
            img.set(px, py, {mix(c.r, under.r), mix(c.g, under.g), mix(c.b, under.b)});
        }
}

void draw_caption(Image& img, const ParticleRenderOptions& options, int margin) {
    if (options.caption.empty()) return;
    draw_text(img, margin + 4, margin + 4, options.caption, {40, 40, 40}, text_scale_for(options.width_px));
}

/// A length in metres as text in the unit that keeps it readable ("0.2 m", "5 cm", "2 mm").
std::string length_text(double metres) {
    char text[32];
    if (metres >= 1.0)
        std::snprintf(text, sizeof text, "%g m", metres);
    else if (metres >= 0.01)
        std::snprintf(text, sizeof text, "%g cm", metres * 100.0);
    else
        std::snprintf(text, sizeof text, "%g mm", metres * 1000.0);
    return text;
}

/// img with the legend band of `options` appended below it: in 2D (pixels_per_metre > 0) a
/// scale bar at the left, and a colour bar at the right.
Image with_legend(const Image& img, const ParticleRenderOptions& options, double pixels_per_metre) {
    if (!options.legend) return img;
    Image out(img.width, img.height + kLegendHeight, {255, 255, 255});
    std::copy(img.rgb.begin(), img.rgb.end(), out.rgb.begin());
    const Rgb ink{40, 40, 40};
    const int top = img.height + 4, bar_y = top + 9;
    if (pixels_per_metre > 0.0) {
        // The longest 1, 2 or 5 x 10^k m not over a quarter of the box width.
        const double limit = 0.25 * (options.domain_max[0] - options.domain_min[0]);
        const double decade = std::pow(10.0, std::floor(std::log10(limit)));
        double length = decade;
        for (double m : {2.0, 5.0})
            if (m * decade <= limit) length = m * decade;
        const int x0 = 8, x1 = x0 + int(std::lround(length * pixels_per_metre));
        for (int x = x0; x <= x1; ++x)
            for (int dy = 0; dy < 2; ++dy) out.set(x, bar_y + dy, ink);
        for (int dy = -3; dy <= 4; ++dy) {
            out.set(x0, bar_y + dy, ink);
            out.set(x1, bar_y + dy, ink);
        }
        draw_text(out, x1 + 6, bar_y - 3, length_text(length), ink);
    }
    // Colour bar: "label  min [gradient] max" at the right.
    char lo[32], hi[32];
    std::snprintf(lo, sizeof lo, "%.3g", options.value_min);
    std::snprintf(hi, sizeof hi, "%.3g", options.value_max);
    const int bar_w = std::min(160, img.width / 4);
    const int right = img.width - 8 - text_width(hi);
    const int bar_x1 = right - 6, bar_x0 = bar_x1 - bar_w;
    for (int x = bar_x0; x <= bar_x1; ++x) {
        const Rgb c = viridis(double(x - bar_x0) / std::max(1, bar_w));
        for (int dy = -4; dy <= 4; ++dy) out.set(x, bar_y + dy, c);
    }
    draw_text(out, right, bar_y - 3, hi, ink);
    draw_text(out, bar_x0 - 6 - text_width(lo), bar_y - 3, lo, ink);
    if (!options.value_label.empty())
        draw_text(out, bar_x0 - 18 - text_width(lo) - text_width(options.value_label), bar_y - 3, options.value_label,
                  ink);
    return out;
}

}  // namespace

// ---------------------------------------------------------------------------------------------
Image render_particles_2d(const std::vector<double>& position, const std::vector<double>& value,
                          const ParticleRenderOptions& options) {
    constexpr const char* who = "render_particles_2d";
    check_particle_input(position, value, 2, options, who);
    const std::size_t n = position.size() / 2;
    const double ex = options.domain_max[0] - options.domain_min[0];
    const double ey = options.domain_max[1] - options.domain_min[1];

    // The radius (disk, or splat half-width) sets the margin that keeps particles at the boundary
    // whole, and the margin the scale; the automatic size uses the scale of a 4-pixel margin (a
    // sub-pixel difference).
    const bool splat = !(options.radius_px > 0);
    const double s4 = (options.width_px - 8) / ex;
    const std::array<double, 2> size = splat ? splat_size(position, options, s4) : std::array<double, 2>{};
    const double radius = splat ? size[0] : options.radius_px;
    // Splats fade out at their edge and need no room beyond 4 px: the frame of a mesh drawn in the
    // same picture (render_mesh_2d) then matches.
    const int margin = splat ? 4 : std::max(4, int(std::ceil(radius)) + 2);
    const double s = (options.width_px - 2 * margin) / ex;
    if (!(s > 0)) throw std::invalid_argument(std::string(who) + ": disks too large for the image width");
    Image img(options.width_px, image_height(ey * s, margin, who), {255, 255, 255});

    // Frame just outside the domain, so that it does not cover particles lying on the boundary.
    draw_rect(img, {margin - 1, margin - 1, margin + int(std::lround(ex * s)), margin + int(std::lround(ey * s))},
              {170, 170, 170});
    if (splat) {
        // The spacing measured at the scale s4, rescaled to the final scale s.
        splat_particles_2d(img, position, value, options, margin, s, radius * s / s4, size[1] * s / s4);
        draw_caption(img, options, margin);
        return with_legend(img, options, s);
    }
    for (std::size_t i = 0; i < n; ++i) {
        const double x = position[2 * i], y = position[2 * i + 1];
        if (!std::isfinite(x) || !std::isfinite(y)) continue;
        draw_disk(img, margin + (x - options.domain_min[0]) * s, margin + (options.domain_max[1] - y) * s, radius,
                  particle_colour(value, i, options));
    }
    draw_caption(img, options, margin);
    return with_legend(img, options, s);
}

Image render_mesh_2d(const std::vector<double>& position, const std::vector<int>& triangles,
                     const std::vector<double>& value, const ParticleRenderOptions& options) {
    constexpr const char* who = "render_mesh_2d";
    check_particle_input(position, {}, 2, options, who);
    const std::size_t n = position.size() / 2, m = triangles.size() / 3;
    if (triangles.size() % 3 != 0) throw std::invalid_argument(std::string(who) + ": triangles is not a multiple of 3");
    if (!value.empty() && value.size() != m)
        throw std::invalid_argument(std::string(who) + ": " + std::to_string(value.size()) + " values for " +
                                    std::to_string(m) + " triangles");
    for (int t : triangles)
        if (t < 0 || static_cast<std::size_t>(t) >= n)
            throw std::invalid_argument(std::string(who) + ": triangle node " + std::to_string(t) + " out of range");
    const double ex = options.domain_max[0] - options.domain_min[0];
    const double ey = options.domain_max[1] - options.domain_min[1];
    const int margin = 4;
    const double s = (options.width_px - 2 * margin) / ex;
    Image img(options.width_px, image_height(ey * s, margin, who), {255, 255, 255});
    draw_rect(img, {margin - 1, margin - 1, margin + int(std::lround(ex * s)), margin + int(std::lround(ey * s))},
              {170, 170, 170});
    auto px = [&](std::size_t i) {
        return std::array<double, 2>{margin + (position[2 * i] - options.domain_min[0]) * s,
                                     margin + (options.domain_max[1] - position[2 * i + 1]) * s};
    };
    const Rect clip{0, 0, img.width - 1, img.height - 1};
    // Fill: a pixel whose centre lies in the triangle (edge functions) takes its colour.
    for (std::size_t k = 0; k < m; ++k) {
        const auto a = px(triangles[3 * k]), b = px(triangles[3 * k + 1]), c = px(triangles[3 * k + 2]);
        if (!std::isfinite(a[0] + a[1] + b[0] + b[1] + c[0] + c[1])) continue;
        const Rgb colour = particle_colour(value, k, options);
        const int x0 = std::max(0, int(std::floor(std::min({a[0], b[0], c[0]}))));
        const int x1 = std::min(img.width - 1, int(std::ceil(std::max({a[0], b[0], c[0]}))));
        const int y0 = std::max(0, int(std::floor(std::min({a[1], b[1], c[1]}))));
        const int y1 = std::min(img.height - 1, int(std::ceil(std::max({a[1], b[1], c[1]}))));
        auto edge = [](const std::array<double, 2>& p, const std::array<double, 2>& q, double x, double y) {
            return (q[0] - p[0]) * (y - p[1]) - (q[1] - p[1]) * (x - p[0]);
        };
        for (int y = y0; y <= y1; ++y)
            for (int x = x0; x <= x1; ++x) {
                const double cx = x + 0.5, cy = y + 0.5;
                const double d1 = edge(a, b, cx, cy), d2 = edge(b, c, cx, cy), d3 = edge(c, a, cx, cy);
                if ((d1 >= 0 && d2 >= 0 && d3 >= 0) || (d1 <= 0 && d2 <= 0 && d3 <= 0)) img.set(x, y, colour);
            }
    }
    // Edges: thin, darker, translucent, so that the element size shows without hiding the colour.
    for (std::size_t k = 0; k < m; ++k)
        for (int e = 0; e < 3; ++e) {
            const auto a = px(triangles[3 * k + e]), b = px(triangles[3 * k + (e + 1) % 3]);
            if (!std::isfinite(a[0] + a[1] + b[0] + b[1])) continue;
            draw_segment(img, a[0], a[1], b[0], b[1], 0.6, {30, 30, 30}, clip, 0.45);
        }
    draw_caption(img, options, margin);
    return with_legend(img, options, s);
}

namespace {

/// The orthographic camera of the 3D renders: looking along `forward` from direction
/// (1, 0.8, 1.5) towards the domain's centre, y up on screen; the domain box's corners in view
/// coordinates (screen u, screen v, depth: larger is farther) and their bounds.
struct Camera3d {
    using V3 = Eigen::Vector3d;
    V3 centre, forward, right, up, lo, hi;
    std::array<V3, 8> corners;

    explicit Camera3d(const ParticleRenderOptions& options) {
        const V3 dlo(options.domain_min[0], options.domain_min[1], options.domain_min[2]);
        const V3 dhi(options.domain_max[0], options.domain_max[1], options.domain_max[2]);
        centre = 0.5 * (dlo + dhi);
        forward = -V3(1.0, 0.8, 1.5).normalized();
        right = forward.cross(V3::UnitY()).normalized();
        up = right.cross(forward);
        for (int c = 0; c < 8; ++c)
            corners[std::size_t(c)] =
                view(V3(c & 1 ? dhi.x() : dlo.x(), c & 2 ? dhi.y() : dlo.y(), c & 4 ? dhi.z() : dlo.z()));
        lo = hi = corners[0];
        for (const V3& c : corners) {
            lo = lo.cwiseMin(c);
            hi = hi.cwiseMax(c);
        }
    }
    V3 view(const V3& p) const {
        const V3 d = p - centre;
        return V3(d.dot(right), d.dot(up), d.dot(forward));
    }
    /// The domain box's edges in grey at s pixels per metre inside margin: those meeting at the
    /// nearest corner (front, drawn faintly after the contents) or the others (before them).
    void draw_box(Image& img, int margin, double s, bool front) const {
        const int nearest =
            int(std::min_element(corners.begin(), corners.end(), [](const V3& a, const V3& b) { return a.z() < b.z(); }) -
                corners.begin());
        const Rect whole{0, 0, img.width - 1, img.height - 1};
        auto px = [&](const V3& q) { return Eigen::Vector2d(margin + (q.x() - lo.x()) * s, margin + (hi.y() - q.y()) * s); };
        for (int a = 0; a < 8; ++a)
            for (int bit = 1; bit < 8; bit <<= 1) {
                const int b = a | bit;
                if (b == a || (a == nearest || b == nearest) != front) continue;
                const Eigen::Vector2d pa = px(corners[std::size_t(a)]), pb = px(corners[std::size_t(b)]);
                draw_segment(img, pa.x(), pa.y(), pb.x(), pb.y(), 1.0, {150, 150, 150}, whole, front ? 0.5 : 1.0);
            }
    }
};

/// Throws std::invalid_argument (naming `who`) for a surface whose sizes do not match.
void check_surface(const std::vector<double>& position, const std::vector<int>& triangles,
                   const std::vector<double>& value, const char* who) {
    const std::size_t n = position.size() / 3, m = triangles.size() / 3;
    if (position.size() % 3 != 0) throw std::invalid_argument(std::string(who) + ": surface positions are not n x 3");
    if (triangles.size() % 3 != 0) throw std::invalid_argument(std::string(who) + ": triangles is not a multiple of 3");
    if (!value.empty() && value.size() != m)
        throw std::invalid_argument(std::string(who) + ": " + std::to_string(value.size()) + " values for " +
                                    std::to_string(m) + " triangles");
    for (int t : triangles)
        if (t < 0 || static_cast<std::size_t>(t) >= n)
            throw std::invalid_argument(std::string(who) + ": triangle node " + std::to_string(t) + " out of range");
}

/// Flat-shaded triangles (node positions in pixels, x right, y down, z the view depth) into img
/// and its depth buffer (depth interpolated in screen space: the view is orthographic), Lambert
/// with ambient light, darkened with depth (fog from depth_min over depth_range), both sides lit,
/// with thin dark edges; s: pixels per metre.
void rasterize_triangles(Image& img, std::vector<double>& depth, const std::vector<Eigen::Vector3d>& screen,
                         const std::vector<int>& triangles, const std::vector<double>& value,
                         const ParticleRenderOptions& options, double depth_min, double depth_range, double s) {
    using V3 = Eigen::Vector3d;
    const V3 light = V3(-0.4, 0.7, -0.6).normalized();  // towards the light, in screen axes (x right, y up, z away)
    const std::size_t m = triangles.size() / 3;
    for (std::size_t k = 0; k < m; ++k) {
        const V3 &a = screen[triangles[3 * k]], &b = screen[triangles[3 * k + 1]], &c = screen[triangles[3 * k + 2]];
        if (!(a.allFinite() && b.allFinite() && c.allFinite())) continue;
        const double area = (b.x() - a.x()) * (c.y() - a.y()) - (b.y() - a.y()) * (c.x() - a.x());
        if (area == 0.0) continue;  // seen edge-on
        // The face normal in screen axes (y flipped back to up).
        const V3 e1(b.x() - a.x(), -(b.y() - a.y()), (b.z() - a.z()) * s), e2(c.x() - a.x(), -(c.y() - a.y()), (c.z() - a.z()) * s);
        const V3 normal = e1.cross(e2).normalized();
        const double diffuse = std::abs(normal.dot(light));
        const double fog = std::clamp(((a.z() + b.z() + c.z()) / 3.0 - depth_min) / depth_range, 0.0, 1.0);
        const Rgb colour = scaled(particle_colour(value, k, options), (0.35 + 0.65 * diffuse) * (1.0 - 0.35 * fog));
        const int x0 = std::max(0, int(std::floor(std::min({a.x(), b.x(), c.x()}))));
        const int x1 = std::min(img.width - 1, int(std::ceil(std::max({a.x(), b.x(), c.x()}))));
        const int y0 = std::max(0, int(std::floor(std::min({a.y(), b.y(), c.y()}))));
        const int y1 = std::min(img.height - 1, int(std::ceil(std::max({a.y(), b.y(), c.y()}))));
        for (int y = y0; y <= y1; ++y)
            for (int x = x0; x <= x1; ++x) {
                const double px = x + 0.5, py = y + 0.5;
                const double wa = ((b.x() - px) * (c.y() - py) - (b.y() - py) * (c.x() - px)) / area;
                const double wb = ((c.x() - px) * (a.y() - py) - (c.y() - py) * (a.x() - px)) / area;
                const double wc = 1.0 - wa - wb;
                if (wa < 0.0 || wb < 0.0 || wc < 0.0) continue;
                const double z = wa * a.z() + wb * b.z() + wc * c.z();
                double& zbuf = depth[std::size_t(y) * std::size_t(img.width) + std::size_t(x)];
                if (z >= zbuf) continue;
                zbuf = z;
                // Thin dark edges: pixels within about one pixel of the triangle's border.
                const double edge = std::min({wa * std::abs(area) / (b - c).head<2>().norm(),
                                              wb * std::abs(area) / (c - a).head<2>().norm(),
                                              wc * std::abs(area) / (a - b).head<2>().norm()});
                img.set(x, y, edge < 0.6 ? scaled(colour, 0.55) : colour);
            }
    }
}

}  // namespace

Image render_particles_3d(const std::vector<double>& position, const std::vector<double>& value,
                          const ParticleRenderOptions& options, const SurfaceMesh* surface) {
    constexpr const char* who = "render_particles_3d";
    check_particle_input(position, value, 3, options, who);
    if (surface) check_surface(surface->position, surface->triangles, surface->value, who);
    const std::size_t n = position.size() / 3;
    using V3 = Eigen::Vector3d;
    const Camera3d camera(options);
    auto view = [&](const V3& p) { return camera.view(p); };
    const V3 &vlo = camera.lo, &vhi = camera.hi;

    const double radius = disk_radius(position, 3, options, (options.width_px - 8) / (vhi.x() - vlo.x()));
    const int margin = std::max(4, int(std::ceil(radius)) + 2);
    const double s = (options.width_px - 2 * margin) / (vhi.x() - vlo.x());
    if (!(s > 0)) throw std::invalid_argument(std::string(who) + ": disks too large for the image width");
    Image img(options.width_px, image_height((vhi.y() - vlo.y()) * s, margin, who), {255, 255, 255});
    auto to_px = [&](const V3& q) {
        return Eigen::Vector2d(margin + (q.x() - vlo.x()) * s, margin + (vhi.y() - q.y()) * s);
    };
    // Box edges: those meeting at the nearest corner pass in front of the particles and are drawn
    // after them, faintly; the others before them.
    auto draw_edges = [&](bool front) { camera.draw_box(img, margin, s, front); };
    draw_edges(false);

    // Each particle's projection and colour, gathered once so that the far-to-near pass streams
    // through one sorted array instead of missing the cache on every particle's fields.
    struct Splat {
        double depth;
        Eigen::Vector2d centre;  // pixels
        Rgb colour;
    };
    std::vector<Splat> splats;
    splats.reserve(n);
    for (std::size_t i = 0; i < n; ++i) {
        const V3 p(position[3 * i], position[3 * i + 1], position[3 * i + 2]);
        if (!p.allFinite()) continue;
        const V3 q = view(p);
        splats.push_back({q.z(), to_px(q), particle_colour(value, i, options)});
    }
    // Painter's order, far to near, so that anti-aliased edges blend over what lies behind; the
    // depth buffer of sphere-surface depths then resolves particles that interpenetrate.
    std::sort(splats.begin(), splats.end(), [](const Splat& a, const Splat& b) { return a.depth > b.depth; });

    std::vector<double> depth(std::size_t(img.width) * std::size_t(img.height),
                              std::numeric_limits<double>::infinity());
    const double radius_world = radius / s;
    const double depth_range = std::max(vhi.z() - vlo.z(), 1e-300);
    if (surface) {  // opaque: drawn first, into the depth buffer the particles are tested against
        std::vector<V3> screen(surface->position.size() / 3);
        for (std::size_t i = 0; i < screen.size(); ++i) {
            const V3 q = view(V3(surface->position[3 * i], surface->position[3 * i + 1], surface->position[3 * i + 2]));
            const Eigen::Vector2d px = to_px(q);
            screen[i] = V3(px.x(), px.y(), q.z());
        }
        rasterize_triangles(img, depth, screen, surface->triangles, surface->value, options, vlo.z(), depth_range, s);
    }
    const V3 light = V3(-0.4, 0.7, -0.6).normalized();  // towards the light: upper left, camera side
    for (const Splat& splat : splats) {
        const Eigen::Vector2d& c = splat.centre;
        const double fog = std::clamp((splat.depth - vlo.z()) / depth_range, 0.0, 1.0);
        const Rgb base = splat.colour;
        const int x0 = int(std::floor(c.x() - radius - 1)), x1 = int(std::ceil(c.x() + radius + 1));
        const int y0 = int(std::floor(c.y() - radius - 1)), y1 = int(std::ceil(c.y() + radius + 1));
        for (int y = std::max(0, y0); y <= std::min(img.height - 1, y1); ++y)
            for (int x = std::max(0, x0); x <= std::min(img.width - 1, x1); ++x) {
                const double dx = x + 0.5 - c.x(), dy = y + 0.5 - c.y();
                const double d = std::sqrt(dx * dx + dy * dy);
                const double coverage = std::min(1.0, radius + 0.5 - d);
                if (coverage <= 0) continue;
                // Unit normal of the sphere seen at this pixel (screen x right, y up, z away).
                const double scale = std::max(radius, d);
                const double nx = dx / scale, ny = -dy / scale;
                const double nz = -std::sqrt(std::max(0.0, 1.0 - nx * nx - ny * ny));
                const double z = splat.depth + nz * radius_world;
                double& zbuf = depth[std::size_t(y) * std::size_t(img.width) + std::size_t(x)];
                if (z >= zbuf) continue;
                const double diffuse = std::max(0.0, nx * light.x() + ny * light.y() + nz * light.z());
                img.blend(x, y, scaled(base, (0.45 + 0.55 * diffuse) * (1.0 - 0.4 * fog)), coverage);
                if (coverage >= 0.5) zbuf = z;
            }
    }
    draw_edges(true);
    draw_caption(img, options, margin);
    // Orthographic: s pixels per metre for every length parallel to the picture plane.
    return with_legend(img, options, s);
}

Image render_mesh_3d(const std::vector<double>& position, const std::vector<int>& triangles,
                     const std::vector<double>& value, const ParticleRenderOptions& options) {
    constexpr const char* who = "render_mesh_3d";
    check_particle_input(position, {}, 3, options, who);
    const std::size_t n = position.size() / 3;
    check_surface(position, triangles, value, who);
    using V3 = Eigen::Vector3d;
    const Camera3d camera(options);  // the camera of render_particles_3d
    auto view = [&](const V3& p) { return camera.view(p); };
    const V3 &vlo = camera.lo, &vhi = camera.hi;
    const int margin = 4;
    const double s = (options.width_px - 2 * margin) / (vhi.x() - vlo.x());
    Image img(options.width_px, image_height((vhi.y() - vlo.y()) * s, margin, who), {255, 255, 255});
    auto to_px = [&](const V3& q) { return V3(margin + (q.x() - vlo.x()) * s, margin + (vhi.y() - q.y()) * s, q.z()); };
    auto draw_box = [&](bool front) { camera.draw_box(img, margin, s, front); };
    draw_box(false);
    std::vector<V3> screen(n);
    for (std::size_t i = 0; i < n; ++i) screen[i] = to_px(view(V3(position[3 * i], position[3 * i + 1], position[3 * i + 2])));
    // Flat-shaded triangles into a depth buffer (depth interpolated in screen space: the view is
    // orthographic), Lambert with ambient light, darkened with depth; both sides lit.
    std::vector<double> depth(std::size_t(img.width) * std::size_t(img.height), std::numeric_limits<double>::infinity());
    const double depth_range = std::max(vhi.z() - vlo.z(), 1e-300);
    rasterize_triangles(img, depth, screen, triangles, value, options, vlo.z(), depth_range, s);
    draw_box(true);
    draw_caption(img, options, margin);
    return with_legend(img, options, s);  // orthographic: s pixels per metre in the picture plane
}

}  // namespace pnet
