#pragma once
// Line plots drawn to an Image (png.hpp) without a plotting library, for the reports of
// `pnet compare`: "nice" ticks, grid, title, axis labels, legend, anti-aliased polylines.
#include <limits>
#include <string>
#include <vector>

#include "pnet/io/png.hpp"

namespace pnet {

/// One polyline of a line plot; points with a non-finite coordinate break the line.
struct PlotSeries {
    std::string label;  // legend entry; a plot whose labels are all empty has no legend
    std::vector<double> x, y;
};

struct LinePlot {
    std::string title, x_label, y_label;
    std::vector<PlotSeries> series;  // coloured in turn from a 10-colour palette (matplotlib tab10)
    int width_px = 800;
    int height_px = 500;
    // Fixed axis ranges (e.g. [0, 1] for IoU); NaN takes the range of the data.
    double x_min = std::numeric_limits<double>::quiet_NaN(), x_max = std::numeric_limits<double>::quiet_NaN();
    double y_min = std::numeric_limits<double>::quiet_NaN(), y_max = std::numeric_limits<double>::quiet_NaN();
};

/// A line plot: axes with "nice" (1, 2, 5 x 10^k) ticks and grid, title, axis labels, a legend
/// and one anti-aliased polyline per series. Throws std::invalid_argument naming the series if
/// its x and y differ in length, or if the size is outside [64, 8192] pixels.
Image render_line_plot(const LinePlot& plot);

}  // namespace pnet
