#pragma once
// What `pnet compare` writes about two runs (docs/metrics.md): iou.csv (per frame: the soft, binary
// and PlasticineLab IoU, the soft IoU at 4 dx, each run's deposit spread and height), iou.png (the IoU
// curves), the printed summary, and compare.png (the last common frame of both runs side by side and,
// in 2D, overlaid). The command line (cpp/apps/compare_command.cpp) only parses its arguments.
#include <filesystem>
#include <string>

#include "pnet/io/png.hpp"
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
/// compare.png: both runs' pictures of `frame` (those that exist) and, in 2D, their particles overlaid
/// (A only blue, B only orange, both grey).
Image comparison_picture(const RunPair& pair, int frame);

}  // namespace pnet
