#pragma once
// Software rendering of particle and mesh frames to an Image (png.hpp), for previews and videos,
// with no graphics library: partition-of-unity splats and disks (2D), shaded sphere impostors and
// z-buffered triangles (3D), a caption and a legend (raster.hpp draws; plot.hpp makes line plots).
#include <limits>
#include <string>
#include <vector>

#include "pnet/io/png.hpp"
#include "pnet/io/raster.hpp"

namespace pnet {

/// What to draw and how; shared by the 2D and 3D particle renderers.
struct ParticleRenderOptions {
    // Colour scale: value_min maps to dark blue, value_max to yellow, values outside are clamped.
    double value_min = 0.0;
    double value_max = 1.0;
    // The simulation box, m; it is framed and fills the image. In 2D only x and y are used.
    double domain_min[3] = {0.0, 0.0, 0.0};
    double domain_max[3] = {1.0, 1.0, 1.0};
    // Image width; the height follows from the box's (projected) aspect ratio.
    int width_px = 800;
    // Disk radius in pixels; <= 0 chooses the size from the particle spacing h (median
    // nearest-neighbour distance): in 2D partition-of-unity splats of half-width h (a body on a
    // lattice fills evenly at any pixel pitch, with no moire; render_particles_2d), in 3D spheres
    // of radius max(0.75 h, 0.6 grid_spacing_m), so that a body of particles looks solid, with no
    // gaps between lattice points.
    double radius_px = 0.0;
    // Automatic size: the simulation's grid spacing dx, m (0: unknown). 2D splats are then at
    // least dx wide, spreading each particle over the cells its mass goes to, as MPM's grid sees
    // the material (render_particles_2d); 3D spheres at least 0.6 dx in radius.
    double grid_spacing_m = 0.0;
    // 2D automatic size: the particles' spacing at rest (dx / particles per cell), m, the side of the
    // area each stands for (0: the median nearest-neighbour distance of the frame). The splats'
    // coverage is then the density over the rest density.
    double particle_spacing_m = 0.0;
    // Text drawn in the top-left corner (e.g. "t = 0.50 s"), none if empty.
    std::string caption;
    // A legend band below the picture: a colour bar from value_min to value_max named
    // value_label (e.g. "speed (m/s)"), and a scale bar (1, 2 or 5 x 10^k m, at most a quarter
    // of the box width; in 3D's orthographic view, for lengths parallel to the picture plane).
    // The image grows by kLegendHeight pixels.
    bool legend = false;
    std::string value_label;
};

/// Height in pixels of the legend band (ParticleRenderOptions::legend).
inline constexpr int kLegendHeight = 26;

/// 2D particles (position n x 2, row per particle, y up) on white inside a thin grey frame at the
/// domain (view) boundary, coloured by viridis of value[i] (value may be empty: one colour for
/// all): filled anti-aliased disks of radius_px, or with radius_px <= 0 partition-of-unity splats
/// (tents of half-width r = the larger of the particle spacing and grid_spacing_m in pixels, whose
/// coverage is 1 inside a body on a lattice; a pixel shows the weighted mean value). Domain point (x, y) is at pixel
///     col = m + (x - min_x) s,  row = m + (max_y - y) s,  s = (width_px - 2 m) / (max_x - min_x),
/// m = max(4, ceil(r) + 2) for disk radius r (4 for splats), and the image is
/// round((max_y - min_y) s) + 2 m pixels high. Throws std::invalid_argument for mismatched
/// sizes, an empty domain or a width outside [16, 16384].
Image render_particles_2d(const std::vector<double>& position, const std::vector<double>& value,
                          const ParticleRenderOptions& options);

/// A triangle surface in 3D (position n x 3, triangles m x 3 node indices, value per triangle
/// or empty for one colour), copied by value (small: a body's boundary).
struct SurfaceMesh {
    std::vector<double> position;
    std::vector<int> triangles;
    std::vector<double> value;
};

/// 3D particles (position n x 3, y up) in an orthographic view from direction (1, 0.8, 1.5)
/// towards the domain centre: the domain box as a grey wireframe, each particle a sphere
/// impostor (per-pixel depth against a depth buffer, so that overlapping particles intersect
/// correctly) drawn far to near, Lambert-shaded and darkened with depth, coloured by viridis of
/// value[i]. With a surface (MPM-FEM coupling: a mesh's boundary), its opaque triangles are
/// drawn as render_mesh_3d() does into the same depth buffer, so that each hides what lies
/// behind it. Same options and errors as render_particles_2d() (and render_mesh_3d() for the
/// surface).
Image render_particles_3d(const std::vector<double>& position, const std::vector<double>& value,
                          const ParticleRenderOptions& options, const SurfaceMesh* surface = nullptr);

/// A 2D triangle mesh (position n x 2, triangles m x 3 node indices) as filled triangles,
/// triangle k coloured by viridis of value[k] (may be empty: one colour), with thin dark edges,
/// framed by the domain like render_particles_2d (radius_px is unused). Throws
/// std::invalid_argument for mismatched sizes or a node index out of range.
Image render_mesh_2d(const std::vector<double>& position, const std::vector<int>& triangles,
                     const std::vector<double>& value, const ParticleRenderOptions& options);

/// A 3D triangle surface (position n x 3, triangles m x 3 node indices: a tetrahedral mesh's
/// boundary) in the view of render_particles_3d (the domain box as a wireframe): z-buffered
/// flat-shaded triangles, Lambert-lit from both sides with ambient light and darkened with
/// depth, with thin dark edges, triangle k coloured by viridis of value[k] (may be empty: one
/// colour). Same errors as render_mesh_2d.
Image render_mesh_3d(const std::vector<double>& position, const std::vector<int>& triangles,
                     const std::vector<double>& value, const ParticleRenderOptions& options);

}  // namespace pnet
