#pragma once
// What `pnet compare` writes about two runs (docs/metrics.md): for particles iou.csv (per frame: the
// soft, binary and PlasticineLab IoU, the soft IoU at 4 dx, each run's deposit spread and height) and
// iou.png (the IoU curves); for meshes nodal.csv (per frame: the body's nodal distance, and in a coupled
// run the particles inside it); the printed summary, and compare.png (the last common frame of both runs
// side by side and, for particles in 2D, overlaid). The command line (cpp/apps/compare_command.cpp) only
// parses its arguments.
#include <filesystem>
#include <string>

#include "pnet/io/png.hpp"
#include "pnet/metrics/mesh_comparison.hpp"
#include "pnet/metrics/run_comparison.hpp"

namespace pnet {

/// iou.csv's text.
std::string comparison_csv(const RunComparison& c);
/// iou.png: the soft, binary and coarse soft IoU against time.
Image comparison_plot(const RunComparison& c, const std::string& name_a, const std::string& name_b);
/// iou.csv and iou.png into `out` (created); throws what the writes throw.
void write_comparison(const std::filesystem::path& out, const RunComparison& c, const std::string& name_a,
                      const std::string& name_b);
/// The summary `pnet compare` prints: frames compared, each IoU's minimum (and where) and mean, the
/// last frame's deposit against DIR_A's.
std::string comparison_summary(const RunPair& pair, const RunComparison& c);
/// nodal.csv into `out` (created); throws what the write throws.
void write_mesh_comparison(const std::filesystem::path& out, const MeshComparison& c);
/// The lines `pnet compare` prints about the meshes: the body's nodal distance at the last frame and its
/// worst mean, in m and % of its size; the most particles inside it in one frame (coupled runs).
std::string mesh_comparison_summary(const MeshComparison& c);
/// compare.png: both runs' pictures of `frame` (those that exist) and, in 2D, their particles overlaid
/// (A only blue, B only orange, both grey; runs with particles).
Image comparison_picture(const RunPair& pair, int frame);

}  // namespace pnet
