#pragma once
// `pnet compare DIR_A DIR_B [--out DIR] [--dx DX]`: per-frame grid-mass IoU of two simulation runs
// (docs/metrics.md, docs/architecture.md), written as iou.csv and iou.png.
namespace pnet::apps {

/// argv[0] is "compare". Reads DIR_A/run.json and DIR_B/run.json (dim, domain and frame_dt must agree),
/// pairs the frame_NNNNN.ply files present in both runs by frame number, rasterizes both runs' particle mass
/// on one grid (spacing --dx, else DIR_A's run.json dx) and computes the soft and binary IoU of every pair.
/// Writes <out>/iou.csv (frame,time_s,soft_iou,binary_iou) and <out>/iou.png, out defaulting to
/// DIR_B/compare_<basename of DIR_A>, and prints a summary.
/// Returns the process exit code: 0 done, 1 the results could not be written, 2 bad input (usage, a missing
/// or inconsistent run.json, no common frames, an unreadable frame); on 2 nothing is written.
int compare_command(int argc, char** argv);

}  // namespace pnet::apps

namespace pnet {
// pnet.cpp calls pnet::compare_command; keep that spelling working next to pnet::apps::simulate_command's.
using apps::compare_command;
}  // namespace pnet
