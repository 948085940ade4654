#include "pnet/io/plot.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>

#include "pnet/io/raster.hpp"

namespace pnet {

using namespace raster;

namespace {

// ---------------------------------------------------------------------------------------------
// Line plot helpers.

// Ticks at multiples of a "nice" step (1, 2 or 5 x 10^k) giving at most about max_ticks ticks.
std::vector<double> nice_ticks(double lo, double hi, int max_ticks, double& step) {
    const double raw = (hi - lo) / std::max(1, max_ticks);
    const double magnitude = std::pow(10.0, std::floor(std::log10(raw)));
    const double normalized = raw / magnitude;
    step = (normalized <= 1 ? 1 : normalized <= 2 ? 2 : normalized <= 5 ? 5 : 10) * magnitude;
    std::vector<double> ticks;
    const double first = std::ceil(lo / step - 1e-9), last = std::floor(hi / step + 1e-9);
    for (double k = first; k <= last; ++k) ticks.push_back(k * step);
    return ticks;
}

// Enough decimals to tell ticks `step` apart; exponent notation for very large or small values.
std::string format_tick(double v, double step) {
    if (std::abs(v) < 1e-9 * step) v = 0.0;  // no "-0" or "1e-17" at the origin
    char buffer[32];
    if (step >= 1e6 || step < 1e-4) {
        std::snprintf(buffer, sizeof(buffer), "%.3g", v);
    } else {
        const int decimals = step >= 1 ? 0 : int(std::ceil(-std::log10(step) - 1e-9));
        std::snprintf(buffer, sizeof(buffer), "%.*f", decimals, v);
    }
    return buffer;
}

// Axis range from the finite data, or the fixed ends when given; pad widens a free range by
// that fraction each side.
void axis_range(const std::vector<PlotSeries>& series, bool use_x, double fixed_min, double fixed_max, double pad,
                double& lo, double& hi) {
    lo = std::numeric_limits<double>::infinity();
    hi = -lo;
    for (const PlotSeries& s : series)
        for (double v : use_x ? s.x : s.y)
            if (std::isfinite(v)) {
                lo = std::min(lo, v);
                hi = std::max(hi, v);
            }
    if (!(lo <= hi)) {  // no finite data
        lo = 0.0;
        hi = 1.0;
    } else if (lo == hi) {
        const double half = 0.5 * std::max(1.0, std::abs(lo) * 0.1);
        lo -= half;
        hi += half;
    } else {
        const double margin = pad * (hi - lo);
        lo -= margin;
        hi += margin;
    }
    if (std::isfinite(fixed_min)) lo = fixed_min;
    if (std::isfinite(fixed_max)) hi = fixed_max;
    if (!(hi > lo)) hi = lo + 1.0;
}

// matplotlib's tab10 cycle: distinct hues that stay apart on white.
constexpr Rgb kPalette[10] = {{31, 119, 180}, {255, 127, 14},  {44, 160, 44},   {214, 39, 40},  {148, 103, 189},
                              {140, 86, 75},  {227, 119, 194}, {127, 127, 127}, {188, 189, 34}, {23, 190, 207}};
}  // namespace

Image render_line_plot(const LinePlot& plot) {
    const int W = plot.width_px, H = plot.height_px;
    if (W < 64 || H < 64 || W > 8192 || H > 8192) {
        throw std::invalid_argument("render_line_plot: size " + std::to_string(W) + " x " + std::to_string(H) +
                                    " outside [64, 8192]");
    }
    for (std::size_t k = 0; k < plot.series.size(); ++k) {
        const PlotSeries& s = plot.series[k];
        if (s.x.size() != s.y.size()) {
            throw std::invalid_argument("render_line_plot: series " + std::to_string(k) + " '" + s.label + "' has " +
                                        std::to_string(s.x.size()) + " x values and " + std::to_string(s.y.size()) +
                                        " y values");
        }
    }
    const int t = (W >= 600 && H >= 360) ? 2 : 1;  // font scale
    const int gap = 4 * t, tick = 3 * t, glyph_h = 7 * t;
    const Rgb ink{40, 40, 40}, grid{228, 228, 228}, frame{120, 120, 120};
    Image img(W, H, {255, 255, 255});

    double xlo, xhi, ylo, yhi, xstep, ystep;
    axis_range(plot.series, true, plot.x_min, plot.x_max, 0.0, xlo, xhi);
    axis_range(plot.series, false, plot.y_min, plot.y_max, 0.05, ylo, yhi);

    // Vertical layout first: the y ticks depend on the plot height only, and their label widths
    // then set the left margin.
    const int top = plot.title.empty() ? 3 * gap : glyph_h + 3 * gap;
    const int bottom = tick + gap + glyph_h + (plot.x_label.empty() ? gap : 3 * gap + glyph_h);
    const int plot_h = H - top - bottom;
    const std::vector<double> yticks = nice_ticks(ylo, yhi, std::max(2, plot_h / (28 * t)), ystep);
    int label_w = 0;
    for (double v : yticks) label_w = std::max(label_w, text_width(format_tick(v, ystep), t));
    const int left = tick + gap + label_w + (plot.y_label.empty() ? gap : 3 * gap + glyph_h);
    const int right = 6 * gap;
    const int plot_w = W - left - right;
    if (plot_w < 16 || plot_h < 16) throw std::invalid_argument("render_line_plot: image too small for the labels");
    const std::vector<double> xticks = nice_ticks(xlo, xhi, std::max(2, plot_w / (45 * t)), xstep);

    const Rect area{left, top, left + plot_w, top + plot_h};
    auto px = [&](double x) { return left + (x - xlo) / (xhi - xlo) * plot_w; };
    auto py = [&](double y) { return top + (yhi - y) / (yhi - ylo) * plot_h; };

    // Grid, ticks and tick labels.
    for (double v : xticks) {
        const int x = int(std::lround(px(v)));
        if (x < area.x0 || x > area.x1) continue;
        for (int y = area.y0; y <= area.y1; ++y) img.set(x, y, grid);
        for (int y = area.y1; y <= area.y1 + tick; ++y) img.set(x, y, frame);
        const std::string label = format_tick(v, xstep);
        draw_text(img, x - text_width(label, t) / 2, area.y1 + tick + gap, label, ink, t);
    }
    for (double v : yticks) {
        const int y = int(std::lround(py(v)));
        if (y < area.y0 || y > area.y1) continue;
        for (int x = area.x0; x <= area.x1; ++x) img.set(x, y, grid);
        for (int x = area.x0 - tick; x <= area.x0; ++x) img.set(x, y, frame);
        const std::string label = format_tick(v, ystep);
        draw_text(img, area.x0 - tick - gap - text_width(label, t), y - glyph_h / 2, label, ink, t);
    }
    draw_rect(img, area, frame);

    // Title, axis labels.
    if (!plot.title.empty()) draw_text(img, (W - text_width(plot.title, t)) / 2, 2 * gap, plot.title, ink, t);
    if (!plot.x_label.empty()) {
        draw_text(img, left + (plot_w - text_width(plot.x_label, t)) / 2, H - gap - glyph_h, plot.x_label, ink, t);
    }
    if (!plot.y_label.empty()) {
        draw_text_up(img, gap, top + (plot_h + text_width(plot.y_label, t)) / 2, plot.y_label, ink, t);
    }

    // Series, clipped to the plot area widened by the line width (so a line on the frame shows).
    const double line_width = 1.6 * t;
    const Rect clip{area.x0 - 2 * t, area.y0 - 2 * t, area.x1 + 2 * t, area.y1 + 2 * t};
    for (std::size_t k = 0; k < plot.series.size(); ++k) {
        const PlotSeries& s = plot.series[k];
        const Rgb colour = kPalette[k % 10];
        auto finite = [&](std::size_t i) { return i < s.x.size() && std::isfinite(s.x[i]) && std::isfinite(s.y[i]); };
        for (std::size_t i = 0; i < s.x.size(); ++i) {
            if (!finite(i)) continue;
            if (finite(i + 1)) {
                draw_segment(img, px(s.x[i]), py(s.y[i]), px(s.x[i + 1]), py(s.y[i + 1]), line_width, colour, clip);
            } else if (i == 0 || !finite(i - 1)) {
                // An isolated point would otherwise not show at all.
                draw_segment(img, px(s.x[i]), py(s.y[i]), px(s.x[i]), py(s.y[i]), 3 * line_width, colour, clip);
            }
        }
    }

    // Legend in the inside corner that hides the fewest data points (top right on a tie).
    std::vector<std::size_t> entries;
    int legend_text_w = 0;
    for (std::size_t k = 0; k < plot.series.size(); ++k) {
        if (plot.series[k].label.empty()) continue;
        entries.push_back(k);
        legend_text_w = std::max(legend_text_w, text_width(plot.series[k].label, t));
    }
    bool any_label = !entries.empty();
    if (any_label) {
        const int swatch = 10 * t, row_h = glyph_h + gap, pad = 2 * t + 2;
        const int box_w = pad + swatch + gap + legend_text_w + pad;
        const int box_h = pad + int(entries.size()) * row_h - gap + pad;
        const int inset = 3 * gap;
        const Rect corners[4] = {
            {area.x1 - inset - box_w, area.y0 + inset, area.x1 - inset, area.y0 + inset + box_h},  // top right
            {area.x0 + inset, area.y0 + inset, area.x0 + inset + box_w, area.y0 + inset + box_h},  // top left
            {area.x1 - inset - box_w, area.y1 - inset - box_h, area.x1 - inset, area.y1 - inset},  // bottom right
            {area.x0 + inset, area.y1 - inset - box_h, area.x0 + inset + box_w, area.y1 - inset},  // bottom left
        };
        int best = 0;
        std::size_t best_hidden = std::numeric_limits<std::size_t>::max();
        for (int c = 0; c < 4; ++c) {
            std::size_t hidden = 0;
            for (const PlotSeries& s : plot.series)
                for (std::size_t i = 0; i < s.x.size(); ++i) {
                    const double x = px(s.x[i]), y = py(s.y[i]);
                    hidden += x >= corners[c].x0 && x <= corners[c].x1 && y >= corners[c].y0 && y <= corners[c].y1;
                }
            if (hidden < best_hidden) {
                best_hidden = hidden;
                best = c;
            }
        }
        const Rect box = corners[best];
        fill_rect(img, box, {255, 255, 255});
        draw_rect(img, box, {190, 190, 190});
        for (std::size_t e = 0; e < entries.size(); ++e) {
            const int y = box.y0 + pad + int(e) * row_h;
            const double mid = y + glyph_h / 2.0;
            draw_segment(img, box.x0 + pad, mid, box.x0 + pad + swatch, mid, line_width, kPalette[entries[e] % 10],
                         box);
            draw_text(img, box.x0 + pad + swatch + gap, y, plot.series[entries[e]].label, ink, t);
        }
    }
    return img;
}

}  // namespace pnet
