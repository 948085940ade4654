#include "pnet/io/raster.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>

namespace pnet {

namespace {

// ---------------------------------------------------------------------------------------------
// 5x7 bitmap font for ASCII 32..126. Each glyph is 5 columns, left to right; bit k of a column
// is row k, row 0 at the top. Lower-case descenders (g, j, p, q, y) use the bottom row.
constexpr std::uint8_t kFont[95][5] = {
    {0x00, 0x00, 0x00, 0x00, 0x00},  // ' '
    {0x00, 0x00, 0x5F, 0x00, 0x00},  // !
    {0x00, 0x07, 0x00, 0x07, 0x00},  // "
    {0x14, 0x7F, 0x14, 0x7F, 0x14},  // #
    {0x24, 0x2A, 0x7F, 0x2A, 0x12},  // $
    {0x23, 0x13, 0x08, 0x64, 0x62},  // %
    {0x36, 0x49, 0x55, 0x22, 0x50},  // &
    {0x00, 0x00, 0x07, 0x00, 0x00},  // '
    {0x00, 0x1C, 0x22, 0x41, 0x00},  // (
    {0x00, 0x41, 0x22, 0x1C, 0x00},  // )
    {0x14, 0x08, 0x3E, 0x08, 0x14},  // *
    {0x08, 0x08, 0x3E, 0x08, 0x08},  // +
    {0x00, 0x50, 0x30, 0x00, 0x00},  // ,
    {0x08, 0x08, 0x08, 0x08, 0x08},  // -
    {0x00, 0x60, 0x60, 0x00, 0x00},  // .
    {0x20, 0x10, 0x08, 0x04, 0x02},  // /
    {0x3E, 0x51, 0x49, 0x45, 0x3E},  // 0
    {0x00, 0x42, 0x7F, 0x40, 0x00},  // 1
    {0x42, 0x61, 0x51, 0x49, 0x46},  // 2
    {0x21, 0x41, 0x45, 0x4B, 0x31},  // 3
    {0x18, 0x14, 0x12, 0x7F, 0x10},  // 4
    {0x27, 0x45, 0x45, 0x45, 0x39},  // 5
    {0x3C, 0x4A, 0x49, 0x49, 0x30},  // 6
    {0x01, 0x71, 0x09, 0x05, 0x03},  // 7
    {0x36, 0x49, 0x49, 0x49, 0x36},  // 8
    {0x06, 0x49, 0x49, 0x29, 0x1E},  // 9
    {0x00, 0x36, 0x36, 0x00, 0x00},  // :
    {0x00, 0x56, 0x36, 0x00, 0x00},  // ;
    {0x08, 0x14, 0x22, 0x41, 0x00},  // <
    {0x14, 0x14, 0x14, 0x14, 0x14},  // =
    {0x00, 0x41, 0x22, 0x14, 0x08},  // >
    {0x02, 0x01, 0x51, 0x09, 0x06},  // ?
    {0x32, 0x49, 0x79, 0x41, 0x3E},  // @
    {0x7E, 0x11, 0x11, 0x11, 0x7E},  // A
    {0x7F, 0x49, 0x49, 0x49, 0x36},  // B
    {0x3E, 0x41, 0x41, 0x41, 0x22},  // C
    {0x7F, 0x41, 0x41, 0x22, 0x1C},  // D
    {0x7F, 0x49, 0x49, 0x49, 0x41},  // E
    {0x7F, 0x09, 0x09, 0x09, 0x01},  // F
    {0x3E, 0x41, 0x49, 0x49, 0x7A},  // G
    {0x7F, 0x08, 0x08, 0x08, 0x7F},  // H
    {0x00, 0x41, 0x7F, 0x41, 0x00},  // I
    {0x20, 0x40, 0x41, 0x3F, 0x01},  // J
    {0x7F, 0x08, 0x14, 0x22, 0x41},  // K
    {0x7F, 0x40, 0x40, 0x40, 0x40},  // L
    {0x7F, 0x02, 0x0C, 0x02, 0x7F},  // M
    {0x7F, 0x04, 0x08, 0x10, 0x7F},  // N
    {0x3E, 0x41, 0x41, 0x41, 0x3E},  // O
    {0x7F, 0x09, 0x09, 0x09, 0x06},  // P
    {0x3E, 0x41, 0x51, 0x21, 0x5E},  // Q
    {0x7F, 0x09, 0x19, 0x29, 0x46},  // R
    {0x46, 0x49, 0x49, 0x49, 0x31},  // S
    {0x01, 0x01, 0x7F, 0x01, 0x01},  // T
    {0x3F, 0x40, 0x40, 0x40, 0x3F},  // U
    {0x1F, 0x20, 0x40, 0x20, 0x1F},  // V
    {0x3F, 0x40, 0x38, 0x40, 0x3F},  // W
    {0x63, 0x14, 0x08, 0x14, 0x63},  // X
    {0x07, 0x08, 0x70, 0x08, 0x07},  // Y
    {0x61, 0x51, 0x49, 0x45, 0x43},  // Z
    {0x00, 0x7F, 0x41, 0x41, 0x00},  // [
    {0x02, 0x04, 0x08, 0x10, 0x20},  // backslash
    {0x00, 0x41, 0x41, 0x7F, 0x00},  // ]
    {0x04, 0x02, 0x01, 0x02, 0x04},  // ^
    {0x40, 0x40, 0x40, 0x40, 0x40},  // _
    {0x00, 0x01, 0x02, 0x04, 0x00},  // `
    {0x20, 0x54, 0x54, 0x54, 0x78},  // a
    {0x7F, 0x48, 0x44, 0x44, 0x38},  // b
    {0x38, 0x44, 0x44, 0x44, 0x20},  // c
    {0x38, 0x44, 0x44, 0x48, 0x7F},  // d
    {0x38, 0x54, 0x54, 0x54, 0x18},  // e
    {0x08, 0x7E, 0x09, 0x01, 0x02},  // f
    {0x0C, 0x52, 0x52, 0x52, 0x3E},  // g
    {0x7F, 0x08, 0x04, 0x04, 0x78},  // h
    {0x00, 0x44, 0x7D, 0x40, 0x00},  // i
    {0x20, 0x40, 0x44, 0x3D, 0x00},  // j
    {0x7F, 0x10, 0x28, 0x44, 0x00},  // k
    {0x00, 0x41, 0x7F, 0x40, 0x00},  // l
    {0x7C, 0x04, 0x18, 0x04, 0x78},  // m
    {0x7C, 0x08, 0x04, 0x04, 0x78},  // n
    {0x38, 0x44, 0x44, 0x44, 0x38},  // o
    {0x7C, 0x14, 0x14, 0x14, 0x08},  // p
    {0x08, 0x14, 0x14, 0x18, 0x7C},  // q
    {0x7C, 0x08, 0x04, 0x04, 0x08},  // r
    {0x48, 0x54, 0x54, 0x54, 0x20},  // s
    {0x04, 0x3F, 0x44, 0x40, 0x20},  // t
    {0x3C, 0x40, 0x40, 0x20, 0x7C},  // u
    {0x1C, 0x20, 0x40, 0x20, 0x1C},  // v
    {0x3C, 0x40, 0x30, 0x40, 0x3C},  // w
    {0x44, 0x28, 0x10, 0x28, 0x44},  // x
    {0x0C, 0x50, 0x50, 0x50, 0x3C},  // y
    {0x44, 0x64, 0x54, 0x4C, 0x44},  // z
    {0x00, 0x08, 0x36, 0x41, 0x00},  // {
    {0x00, 0x00, 0x7F, 0x00, 0x00},  // |
    {0x00, 0x41, 0x36, 0x08, 0x00},  // }
    {0x08, 0x04, 0x08, 0x10, 0x08},  // ~
};

const std::uint8_t* glyph(char c) {
    const int code = static_cast<unsigned char>(c);
    return kFont[(code >= 32 && code <= 126 ? code : '?') - 32];
}

}  // namespace

namespace raster {

// Text rotated 90 degrees counter-clockwise (reading upwards), for the y-axis label; (x, y) is
// the bottom-left corner of the rotated text box.
void draw_text_up(Image& img, int x, int y, const std::string& text, Rgb colour, int scale) {
    for (std::size_t k = 0; k < text.size(); ++k) {
        const std::uint8_t* g = glyph(text[k]);
        for (int col = 0; col < 5; ++col)
            for (int row = 0; row < 7; ++row) {
                if (!((g[col] >> row) & 1)) continue;
                const int along = int(k) * 6 * scale + col * scale;  // distance along the reading direction
                for (int i = 0; i < scale; ++i)
                    for (int j = 0; j < scale; ++j) img.set(x + row * scale + j, y - 1 - along - i, colour);
            }
    }
}

// ---------------------------------------------------------------------------------------------
// Anti-aliased primitives: a pixel's coverage is approximated by its centre's signed distance
// to the shape's edge, clamp(edge distance + 1/2, 0, 1), which is exact for a straight edge
// through the pixel at 0 or 90 degrees and close enough otherwise.

void draw_disk(Image& img, double cx, double cy, double r, Rgb colour) {
    const int x0 = int(std::floor(cx - r - 1)), x1 = int(std::ceil(cx + r + 1));
    const int y0 = int(std::floor(cy - r - 1)), y1 = int(std::ceil(cy + r + 1));
    for (int y = y0; y <= y1; ++y)
        for (int x = x0; x <= x1; ++x) {
            const double dx = x + 0.5 - cx, dy = y + 0.5 - cy;
            const double d = std::sqrt(dx * dx + dy * dy);
            img.blend(x, y, colour, std::min(1.0, r + 0.5 - d));
        }
}

// A segment of the given width (px) with round caps, drawn only inside clip.
void draw_segment(Image& img, double ax, double ay, double bx, double by, double width, Rgb colour, const Rect& clip,
                  double opacity) {
    const double h = 0.5 * width;
    const int x0 = std::max(clip.x0, int(std::floor(std::min(ax, bx) - h - 1)));
    const int x1 = std::min(clip.x1, int(std::ceil(std::max(ax, bx) + h + 1)));
    const int y0 = std::max(clip.y0, int(std::floor(std::min(ay, by) - h - 1)));
    const int y1 = std::min(clip.y1, int(std::ceil(std::max(ay, by) + h + 1)));
    const double ex = bx - ax, ey = by - ay, length2 = ex * ex + ey * ey;
    for (int y = y0; y <= y1; ++y)
        for (int x = x0; x <= x1; ++x) {
            const double px = x + 0.5 - ax, py = y + 0.5 - ay;
            const double t = length2 > 0 ? std::clamp((px * ex + py * ey) / length2, 0.0, 1.0) : 0.0;
            const double d = std::sqrt((px - t * ex) * (px - t * ex) + (py - t * ey) * (py - t * ey));
            img.blend(x, y, colour, opacity * std::min(1.0, h + 0.5 - d));
        }
}

// One-pixel axis-aligned rectangle outline through the given pixel bounds.
void draw_rect(Image& img, const Rect& r, Rgb colour) {
    for (int x = r.x0; x <= r.x1; ++x) {
        img.set(x, r.y0, colour);
        img.set(x, r.y1, colour);
    }
    for (int y = r.y0; y <= r.y1; ++y) {
        img.set(r.x0, y, colour);
        img.set(r.x1, y, colour);
    }
}

void fill_rect(Image& img, const Rect& r, Rgb colour) {
    for (int y = r.y0; y <= r.y1; ++y)
        for (int x = r.x0; x <= r.x1; ++x) img.set(x, y, colour);
}

Rgb scaled(Rgb c, double factor) {
    auto channel = [&](std::uint8_t v) { return std::uint8_t(std::lround(std::clamp(v * factor, 0.0, 255.0))); };
    return {channel(c.r), channel(c.g), channel(c.b)};
}

}  // namespace raster

// ---------------------------------------------------------------------------------------------

Rgb viridis(double t) {
    // viridis(k / 8), k = 0..8, as listed by viridisLite::viridis(9).
    static constexpr Rgb kStops[9] = {{68, 1, 84},    {71, 45, 123}, {59, 82, 139},  {44, 114, 142}, {33, 144, 140},
                                      {39, 173, 129}, {93, 200, 99}, {170, 220, 50}, {253, 231, 37}};
    if (std::isnan(t)) return {150, 150, 150};
    t = std::clamp(t, 0.0, 1.0) * 8.0;
    const int k = std::min(7, int(t));
    const double f = t - k;
    auto mix = [&](std::uint8_t a, std::uint8_t b) { return std::uint8_t(std::lround(a + f * (double(b) - a))); };
    return {mix(kStops[k].r, kStops[k + 1].r), mix(kStops[k].g, kStops[k + 1].g), mix(kStops[k].b, kStops[k + 1].b)};
}

void draw_text(Image& img, int x, int y, const std::string& text, Rgb colour, int scale) {
    for (std::size_t k = 0; k < text.size(); ++k) {
        const std::uint8_t* g = glyph(text[k]);
        const int left = x + int(k) * 6 * scale;
        for (int col = 0; col < 5; ++col)
            for (int row = 0; row < 7; ++row) {
                if (!((g[col] >> row) & 1)) continue;
                for (int i = 0; i < scale; ++i)
                    for (int j = 0; j < scale; ++j) img.set(left + col * scale + j, y + row * scale + i, colour);
            }
    }
}

int text_width(const std::string& text, int scale) {
    return text.empty() ? 0 : (6 * int(text.size()) - 1) * scale;
}
}  // namespace pnet
