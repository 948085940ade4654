#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "pnet/io/plot.hpp"
#include "pnet/io/render.hpp"

namespace pnet {
namespace {

const Rgb kWhite{255, 255, 255};

/// Not white and not grey: a colormap or palette colour rather than background, frame or text.
bool coloured(Rgb c) {
    const int hi = std::max({c.r, c.g, c.b}), lo = std::min({c.r, c.g, c.b});
    return hi - lo > 30;
}

int count_coloured(const Image& img) {
    int n = 0;
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x) n += coloured(img.get(x, y));
    return n;
}

double luma(Rgb c) {
    return 0.2126 * c.r + 0.7152 * c.g + 0.0722 * c.b;
}

TEST(Viridis, EndsClampingAndMonotoneLightness) {
    EXPECT_EQ(viridis(0.0), (Rgb{68, 1, 84}));
    EXPECT_EQ(viridis(0.5), (Rgb{33, 144, 140}));
    EXPECT_EQ(viridis(1.0), (Rgb{253, 231, 37}));
    EXPECT_EQ(viridis(-3.0), viridis(0.0));
    EXPECT_EQ(viridis(7.0), viridis(1.0));
    EXPECT_FALSE(coloured(viridis(std::numeric_limits<double>::quiet_NaN())));  // NaN: grey
    // Perceptual ordering: lightness rises along the map.
    for (int k = 0; k < 100; ++k) EXPECT_LT(luma(viridis(k / 100.0)), luma(viridis((k + 1) / 100.0))) << k;
}

// Unit domain, 200 px wide, 4 px disks: margin m = 6, scale s = 188 px/m, image 200 x 200, and
// domain point (x, y) lands at pixel (6 + 188 x, 6 + 188 (1 - y)).
ParticleRenderOptions unit_options() {
    ParticleRenderOptions o;
    o.value_min = 0.0;
    o.value_max = 1.0;
    o.width_px = 200;
    o.radius_px = 4.0;
    return o;
}

TEST(Render2d, DisksWhereParticlesAreBackgroundElsewhere) {
    const std::vector<double> position = {0.5, 0.5, 0.25, 0.75};
    const std::vector<double> value = {0.0, 1.0};
    const Image img = render_particles_2d(position, value, unit_options());
    ASSERT_EQ(img.width, 200);
    ASSERT_EQ(img.height, 200);

    EXPECT_EQ(img.get(100, 100), viridis(0.0));  // centre of particle 0
    EXPECT_EQ(img.get(100, 102), viridis(0.0));  // inside its disk (pixel centre 2.5 px from it)
    EXPECT_EQ(img.get(53, 53), viridis(1.0));    // particle 1, upper left: y is up
    EXPECT_EQ(img.get(53, 147), kWhite);         // its mirror image below is empty
    EXPECT_EQ(img.get(100, 107), kWhite);        // just outside disk 0
    EXPECT_EQ(img.get(150, 150), kWhite);
    EXPECT_EQ(img.get(1, 1), kWhite);   // margin
    const Rgb frame = img.get(5, 100);  // frame just outside the domain's left edge
    EXPECT_FALSE(coloured(frame));
    EXPECT_LT(frame.r, 255);
}

TEST(Render2d, LegendBandHasScaleBarAndColourBar) {
    const std::vector<double> position = {0.5, 0.5, 0.25, 0.75};
    const std::vector<double> value = {0.0, 1.0};
    ParticleRenderOptions o = unit_options();
    const Image plain = render_particles_2d(position, value, o);
    o.legend = true;
    o.value_label = "speed (m/s)";
    const Image img = render_particles_2d(position, value, o);
    ASSERT_EQ(img.width, plain.width);
    ASSERT_EQ(img.height, plain.height + kLegendHeight);
    // The picture itself is unchanged.
    EXPECT_TRUE(std::equal(plain.rgb.begin(), plain.rgb.end(), img.rgb.begin()));
    // Colour bar: both ends of viridis appear in the band, left dark, right yellow.
    int first_dark = -1, last_yellow = -1;
    const int bar_y = plain.height + 4 + 9;
    for (int x = 0; x < img.width; ++x) {
        if (first_dark < 0 && img.get(x, bar_y) == viridis(0.0)) first_dark = x;
        if (img.get(x, bar_y) == viridis(1.0)) last_yellow = x;
    }
    ASSERT_GE(first_dark, 0);
    EXPECT_GT(last_yellow, first_dark);
    // Scale bar: the box is 1 m wide, so 0.2 m (the longest 1/2/5 x 10^k within a quarter):
    // a dark line from x = 8 over 0.2 m of the picture's scale.
    const double pixels_per_metre = (200 - 2.0 * 6) / 1.0;  // width minus margins of this radius
    int dark_end = 8;
    while (dark_end + 1 < img.width && img.get(dark_end + 1, bar_y) != kWhite) ++dark_end;
    EXPECT_NEAR(dark_end - 8, 0.2 * pixels_per_metre, 3.0);
}

TEST(Render2d, AutomaticRadiusLeavesNoGapsInABody) {
    std::vector<double> position;
    const double h = 1.0 / 64;  // lattice spacing
    for (int i = 0; i < 20; ++i)
        for (int j = 0; j < 10; ++j) {
            position.push_back(0.3 + i * h);
            position.push_back(0.1 + j * h);
        }
    ParticleRenderOptions o = unit_options();
    o.radius_px = 0.0;
    o.width_px = 400;
    const Image img = render_particles_2d(position, {}, o);
    EXPECT_EQ(img.width, 400);
    // The gaps most likely to show are the centres of lattice cells; all must be covered, at full
    // opacity (the splats' coverage sums to 1 inside the body). The margin of splats is 4 px, so
    // s = 392 px/m.
    const double s = (400 - 2 * 4) / 1.0;
    for (int i = 0; i < 19; ++i)
        for (int j = 0; j < 9; ++j) {
            const int x = int(4 + (0.3 + (i + 0.5) * h) * s), y = int(4 + (1 - (0.1 + (j + 0.5) * h)) * s);
            ASSERT_EQ(img.get(x, y), viridis(0.45)) << "gap at lattice cell " << i << ", " << j;
        }
    EXPECT_EQ(img.get(int(4 + 0.8 * s), int(4 + 0.5 * s)), kWhite);
}

TEST(Render2d, CaptionAndInputChecks) {
    ParticleRenderOptions o = unit_options();
    o.caption = "t = 1.00 s";
    const Image img = render_particles_2d({}, {}, o);
    int dark = 0;
    for (int y = 0; y < 30; ++y)
        for (int x = 0; x < 100; ++x) dark += img.get(x, y).r < 100;
    EXPECT_GT(dark, 20);

    EXPECT_THROW(render_particles_2d({0.1, 0.2, 0.3}, {}, o), std::invalid_argument);     // not n x 2
    EXPECT_THROW(render_particles_2d({0.1, 0.2}, {1.0, 2.0}, o), std::invalid_argument);  // value size
    o.domain_max[1] = o.domain_min[1];
    EXPECT_THROW(render_particles_2d({0.1, 0.2}, {}, o), std::invalid_argument);
    o = unit_options();
    o.width_px = 4;
    EXPECT_THROW(render_particles_2d({0.1, 0.2}, {}, o), std::invalid_argument);
}

TEST(Render3d, SizeAndColouredPixels) {
    std::vector<double> position, value;
    for (int i = 0; i < 10; ++i)
        for (int j = 0; j < 10; ++j)
            for (int k = 0; k < 10; ++k) {
                position.insert(position.end(), {0.35 + 0.03 * i, 0.35 + 0.03 * j, 0.35 + 0.03 * k});
                value.push_back(0.1 * j);
            }
    ParticleRenderOptions o = unit_options();
    o.width_px = 320;
    o.radius_px = 0.0;
    const Image img = render_particles_3d(position, value, o);
    EXPECT_EQ(img.width, 320);
    EXPECT_GT(img.height, 100);
    EXPECT_EQ(img.rgb.size(), std::size_t(3 * img.width * img.height));
    // The block, centred in the box, covers the image centre; corners stay background.
    EXPECT_TRUE(coloured(img.get(img.width / 2, img.height / 2)));
    EXPECT_GT(count_coloured(img), 2000);
    EXPECT_EQ(img.get(0, img.height - 1), kWhite);
}

// 3D legend: the scale bar holds for lengths parallel to the picture plane (orthographic), so it
// scales with the picture: twice the width, twice the bar.
TEST(Render3d, LegendScaleBarScalesWithThePicture) {
    const std::vector<double> position = {0.5, 0.5, 0.5, 0.4, 0.6, 0.5};
    ParticleRenderOptions o = unit_options();
    o.legend = true;
    o.radius_px = 3.0;
    auto bar_length = [&](int width) {
        o.width_px = width;
        const Image img = render_particles_3d(position, {}, o);
        const int bar_y = img.height - kLegendHeight + 4 + 9;
        int end = 8;
        while (end + 1 < img.width && img.get(end + 1, bar_y) != kWhite) ++end;
        return end - 8;
    };
    const int short_bar = bar_length(300), long_bar = bar_length(600);
    EXPECT_GT(short_bar, 20);
    EXPECT_NEAR(long_bar, 2 * short_bar, 3);
}

// With the grid spacing known, 3D spheres are at least 0.6 dx in radius: a lattice of spacing
// h = dx / 2 is drawn with r = 0.6 dx = 1.2 h instead of 0.75 h, covering more of the picture.
TEST(Render3d, GridSpacingSetsTheSmallestSphere) {
    std::vector<double> position;
    const double h = 0.02;
    for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j)
            for (int k = 0; k < 4; ++k) position.insert(position.end(), {0.45 + h * i, 0.45 + h * j, 0.45 + h * k});
    ParticleRenderOptions o = unit_options();
    o.width_px = 300;
    o.radius_px = 0.0;  // automatic
    const int plain = count_coloured(render_particles_3d(position, {}, o));
    o.grid_spacing_m = 2 * h;
    const int joined = count_coloured(render_particles_3d(position, {}, o));
    EXPECT_GT(joined, 1.3 * plain);
}

// Two particles on one line of sight: the one nearer the camera (direction (1, 0.8, 1.5) from the
// centre) must be the one seen, whichever comes first in the input.
TEST(Render3d, NearerParticleHidesFartherOne) {
    const double n = std::sqrt(1.0 + 0.64 + 2.25);
    const double e[3] = {1.0 / n, 0.8 / n, 1.5 / n};
    const std::vector<double> near = {0.5 + 0.2 * e[0], 0.5 + 0.2 * e[1], 0.5 + 0.2 * e[2]};
    const std::vector<double> far = {0.5 - 0.2 * e[0], 0.5 - 0.2 * e[1], 0.5 - 0.2 * e[2]};
    ParticleRenderOptions o = unit_options();
    o.width_px = 200;
    o.radius_px = 8.0;
    for (bool near_first : {true, false}) {
        std::vector<double> position = near_first ? near : far;
        const std::vector<double>& second = near_first ? far : near;
        position.insert(position.end(), second.begin(), second.end());
        const std::vector<double> value = near_first ? std::vector<double>{1.0, 0.0} : std::vector<double>{0.0, 1.0};
        const Image img = render_particles_3d(position, value, o);
        // The box is centrally symmetric, so its centre projects to the image centre.
        const Rgb seen = img.get(img.width / 2, img.height / 2);
        EXPECT_GT(seen.g, 2 * seen.b) << "near_first " << near_first;  // shaded yellow, not purple
    }
}

TEST(LinePlot, SizeAxesAndAKnownLine) {
    LinePlot plot;
    plot.title = "IoU per frame";
    plot.x_label = "frame";
    plot.y_label = "IoU";
    plot.width_px = 640;
    plot.height_px = 400;
    plot.y_min = 0.0;
    plot.y_max = 1.0;
    PlotSeries flat;  // no label: no legend, so the only palette pixels are the line's
    for (int f = 0; f <= 50; ++f) {
        flat.x.push_back(f);
        flat.y.push_back(0.5);
    }
    plot.series = {flat};
    const Image img = render_line_plot(plot);
    ASSERT_EQ(img.width, 640);
    ASSERT_EQ(img.height, 400);

    // A horizontal line at y = 0.5: palette-coloured pixels in a band a few rows high, half-way
    // down the plot area, spanning most of the width.
    int xmin = img.width, xmax = -1, ymin = img.height, ymax = -1;
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x)
            if (coloured(img.get(x, y))) {
                xmin = std::min(xmin, x);
                xmax = std::max(xmax, x);
                ymin = std::min(ymin, y);
                ymax = std::max(ymax, y);
            }
    ASSERT_GE(xmax, 0) << "no line drawn";
    EXPECT_GT(xmax - xmin, img.width / 2);
    EXPECT_LE(ymax - ymin, 5);
    EXPECT_NEAR(0.5 * (ymin + ymax), img.height / 2.0, img.height / 8.0);
    const Rgb on_line = img.get((xmin + xmax) / 2, (ymin + ymax) / 2);
    EXPECT_EQ(on_line, (Rgb{31, 119, 180}));  // first palette colour, fully covered at the centre

    // Text and axes: dark pixels in the title strip and left of the plot.
    int dark = 0;
    for (int y = 0; y < 30; ++y)
        for (int x = 0; x < img.width; ++x) dark += img.get(x, y).r < 100;
    EXPECT_GT(dark, 30);
}

TEST(LinePlot, LegendGapsAndChecks) {
    LinePlot plot;
    PlotSeries a{"neural", {0, 1, 2, 3}, {0.9, 0.8, std::numeric_limits<double>::quiet_NaN(), 0.7}};
    PlotSeries b{"analytic", {0, 1, 2, 3}, {0.95, 0.9, 0.85, 0.8}};
    plot.series = {a, b};
    const Image img = render_line_plot(plot);
    EXPECT_EQ(img.width, 800);
    EXPECT_EQ(img.height, 500);
    EXPECT_GT(count_coloured(img), 200);

    EXPECT_NO_THROW(render_line_plot(LinePlot{}));  // no data: axes only
    plot.series[1].y.pop_back();
    try {
        render_line_plot(plot);
        ADD_FAILURE() << "mismatched series accepted";
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("analytic"), std::string::npos) << e.what();
    }
    plot.series.clear();
    plot.width_px = 10;
    EXPECT_THROW(render_line_plot(plot), std::invalid_argument);
}

TEST(Text, WidthAndExtent) {
    EXPECT_EQ(text_width(""), 0);
    EXPECT_EQ(text_width("ab"), 11);
    EXPECT_EQ(text_width("ab", 2), 22);
    Image img(40, 20);
    draw_text(img, 3, 4, "Hi!", {0, 0, 0}, 1);
    int inside = 0, outside = 0;
    for (int y = 0; y < img.height; ++y)
        for (int x = 0; x < img.width; ++x) {
            const bool ink = img.get(x, y) != kWhite;
            const bool in_box = x >= 3 && x < 3 + text_width("Hi!") && y >= 4 && y < 11;
            (in_box ? inside : outside) += ink;
        }
    EXPECT_GT(inside, 15);
    EXPECT_EQ(outside, 0);
    // 'H': full left column.
    for (int y = 4; y < 11; ++y) EXPECT_NE(img.get(3, y), kWhite);
}

}  // namespace
}  // namespace pnet
