#pragma once
// Drawing on an Image (png.hpp) without a graphics library: the viridis colormap, a built-in 5x7
// bitmap font, and anti-aliased primitives (disks, segments, rectangles) whose pixel coverage is
// approximated by the pixel centre's signed distance to the shape's edge, clamp(d + 1/2, 0, 1):
// exact for a straight edge through the pixel at 0 or 90 degrees and close enough otherwise.
// The particle and mesh renderers (render.hpp) and the line plots (plot.hpp) draw with these.
#include <string>

#include "pnet/io/png.hpp"

namespace pnet {

/// The viridis colormap (van der Walt and Smith, matplotlib 1.5): perceptually uniform and
/// readable in greyscale and by colour-blind viewers. t is clamped to [0, 1]; NaN gives grey.
/// Piecewise linear through the 9 colours viridis(k / 8), k = 0..8.
Rgb viridis(double t);

/// Draws ASCII text (32..126; other bytes as '?') in the built-in 5x7 font, each font pixel a
/// scale x scale block, with (x, y) the top-left corner of the first 6 x 8 character cell.
void draw_text(Image& img, int x, int y, const std::string& text, Rgb colour, int scale = 1);

/// Width in pixels of text drawn by draw_text() (6 x scale per character, no trailing gap).
int text_width(const std::string& text, int scale = 1);

namespace raster {

struct Rect {
    int x0, y0, x1, y1;  // inclusive pixel bounds
};

/// Text rotated 90 degrees counter-clockwise (reading upwards), for a y-axis label; (x, y) is the
/// bottom-left corner of the rotated text box.
void draw_text_up(Image& img, int x, int y, const std::string& text, Rgb colour, int scale);
/// A filled anti-aliased disk of radius r (px) centred at (cx, cy).
void draw_disk(Image& img, double cx, double cy, double r, Rgb colour);
/// A segment of the given width (px) with round caps, drawn only inside clip.
void draw_segment(Image& img, double ax, double ay, double bx, double by, double width, Rgb colour, const Rect& clip,
                  double opacity = 1.0);
/// A one-pixel axis-aligned rectangle outline through the given pixel bounds.
void draw_rect(Image& img, const Rect& r, Rgb colour);
void fill_rect(Image& img, const Rect& r, Rgb colour);
/// c with each channel times factor, clamped to [0, 255].
Rgb scaled(Rgb c, double factor);

}  // namespace raster

}  // namespace pnet
