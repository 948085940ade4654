#pragma once
// Per-frame distance between the meshes of two runs with meshes (FEM, or the bodies of a coupled run;
// docs/metrics.md): what `pnet compare` writes to nodal.csv, in the library so that Python calls the same.
//
// The compared body is run A's first mesh (run.json's mesh_first_node; a coupled run: every mesh node).
// Node i of one run is node i of the other (every frame keeps every node, io/ply.hpp), so the error of a
// frame is the distance of each node to its counterpart, its mean and maximum, and the same in percent
// of the body's size: A's run.json bbox_diagonal (FEM), else the diagonal of the body's bounding box in
// A's first compared frame. In a coupled run each frame also counts run B's particles inside B's body
// (the simulator's inside test, contact/collisions/point_facet.hpp), which must stay 0.
#include <cstddef>
#include <functional>
#include <string>
#include <vector>

#include "pnet/metrics/run_comparison.hpp"

namespace pnet {

struct FrameMeshError {
    int frame = 0;
    double time = 0.0;              // frame frame_dt, s
    double mean = 0.0, max = 0.0;   // nodal distance, m
    double mean_pct = 0.0, max_pct = 0.0;  // in % of MeshComparison::size
    long penetrations = -1;         // coupled runs: B's particles inside B's body (-1: not a coupled run)
};

struct MeshComparison {
    std::size_t nodes = 0;  // the body's nodes compared
    double size = 0.0;      // the body's size, m
    std::vector<FrameMeshError> frames;  // the common frames, ascending
};

/// Reads both runs' mesh frames of every common frame (pair_runs) and measures them. Throws RunInputError
/// for runs without meshes, a mesh frame missing, unreadable ("<ply path>: ..."), from another run, or
/// with fewer nodes than the body, and for a coupled frame without its particles.
MeshComparison compare_meshes(const RunPair& pair, const std::function<void(std::size_t, std::size_t)>& progress = {});

/// nodal.csv's text: frame, time_s, mean_m, max_m, mean_pct, max_pct, size_m (the body's size) and, in
/// coupled runs, penetrations.
std::string mesh_comparison_csv(const MeshComparison& c);

}  // namespace pnet
