#pragma once
// Per-frame grid-mass IoU of two `pnet simulate` runs (docs/metrics.md): what `pnet compare` computes,
// in the library so that the Python bindings can call it too.
//
// A run directory holds run.json and the frames frame_NNNNN.ply (io/ply.hpp), NNNNN the frame number in
// 5 to 9 digits: particles (MPM), the meshes (FEM), or particles with the meshes beside them in
// frame_NNNNN_mesh.ply (coupling). From run.json only dim (2 or 3), domain_min and domain_max (dim numbers
// each, m; view_min and view_max, the pictures' region, if present), dx (m; runs with particles),
// frame_dt (s), and for runs with meshes "elements" (their presence), mesh_first_node and bbox_diagonal
// (FEM) are read; frame k is the state at time k frame_dt. Frames are paired by number. Particles: both
// runs' mass is rasterized on one grid over the common domain and the two mass fields are compared with
// iou() (metrics/iou.hpp). Meshes: metrics/mesh_comparison.hpp.
#include <array>
#include <cstddef>
#include <functional>
#include <map>
#include <stdexcept>
#include <string>
#include <vector>

namespace pnet {

/// A run directory, run.json or frame file that cannot be read, or two runs that cannot be compared.
/// The message names the file or directory and the field where there is one: "<dir>/run.json: dx: ...".
class RunInputError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

/// What a comparison needs from one run directory.
struct RunInfo {
    std::string dir;        // as given
    std::string name;       // base name of dir, ignoring a trailing separator ("runs/sand/" -> "sand")
    std::string json_file;  // dir/run.json
    int dim = 0;            // 2 or 3
    std::array<double, 3> domain_min{}, domain_max{};  // m, first dim entries used; max > min on every axis
    std::array<double, 3> view_min{}, view_max{};      // m, the region its pictures show (default: the domain)
    double dx = 0.0;                                   // the simulation's grid spacing, m (0: no particles)
    double frame_dt = 0.0;                             // time between frames, s
    bool particles = true;                             // the frames hold particles (MPM, coupling)
    bool meshes = false;                               // the run has meshes (FEM, coupling)
    std::size_t body_nodes = 0;     // meshes: the nodes of the first mesh (the compared body; 0: every node)
    double body_size = 0.0;         // meshes: run.json's bbox_diagonal (m; 0: absent, FEM runs only)
    std::map<int, std::string> frames;       // frame number -> particle PLY (dir/frame_NNNNN.ply)
    std::map<int, std::string> mesh_frames;  // frame number -> mesh PLY (FEM: frame_NNNNN.ply; coupling: _mesh)
    std::string run_id;  // run.json's run_id: every frame must carry it; "" (runs before run ids): not checked
};

/// Reads dir/run.json and lists dir's frame files without opening them; temporary files of an interrupted
/// atomic write (frame_NNNNN.ply.tmp.<pid>) are not frames. Throws RunInputError if dir is missing or not
/// a directory, or run.json is unreadable, not JSON, or lacks or has an invalid dim, domain_min,
/// domain_max, dx (runs with particles) or frame_dt; std::filesystem::filesystem_error if listing dir
/// fails partway.
RunInfo read_run_info(const std::string& dir);

/// Two runs checked to be comparable, before any frame file is read.
struct RunPair {
    RunInfo a, b;
    double dx = 0.0;                  // spacing of the comparison grid, m
    std::vector<int> common;          // frames in both runs, ascending; never empty
    std::vector<int> only_a, only_b;  // frames in one run only (not compared), ascending
};

/// Reads both runs (read_run_info) and checks that they can be compared frame by frame: same dim, same
/// domain and same frame_dt (to 1e-9 relative), the same kind of frames (particles, meshes), and at least
/// one common frame (of particles; FEM: of meshes). dx <= 0 takes DIR_A's
/// run.json dx. Throws RunInputError if a run cannot be read, if the runs differ (naming DIR_B's run.json
/// and the field), if no frame is common (listing both runs' frames), or if the grid would exceed 2^27
/// nodes (compare_runs holds two such grids, 8 bytes a node: 2 GiB).
RunPair pair_runs(const std::string& dir_a, const std::string& dir_b, double dx = 0.0);

/// IoU of one pair of frames (see IouResult), the Jaccard index of the mass deposited at 4 dx, and
/// the shape of each deposit (docs/metrics.md).
struct FrameIou {
    int frame = 0;
    double time = 0.0;  // frame frame_dt, s
    double soft = 0.0, binary = 0.0, plasticinelab = 0.0;
    /// soft IoU of the mass fields rasterized at 4 dx (coarse-grained: insensitive to a film one cell
    /// thick moving by a cell).
    double soft_coarse = 0.0;
    double spread_a = 0.0, spread_b = 0.0;  // deposit_shape().spread of each run, m
    double height_a = 0.0, height_b = 0.0;  // deposit_shape().height of each run, m
};

/// The comparison grid is coarsened by this factor for FrameIou::soft_coarse.
constexpr int kCoarseFactor = 4;

/// What compare_runs found: the IoU of every common frame, and what it could not compare exactly.
struct RunComparison {
    std::string dir_a, dir_b, name_a, name_b;  // directories as given and their base names
    int dim = 0;
    double dx = 0.0;                  // spacing of the comparison grid, m
    std::vector<int> only_a, only_b;  // frames in one run only (not compared), ascending
    // Particles, summed over the frames, whose B-spline stencil would leave the grid (outside the domain or
    // within about dx of its boundary); rasterize_mass splats them at the nearest admissible position.
    std::size_t clamped_a = 0, clamped_b = 0;
    std::vector<FrameIou> frames;  // the common frames, ascending
};

/// Runs with particles: reads every common frame of both runs, requiring the dim of run.json, rasterizes each frame's particle
/// mass with rasterize_mass on the grid with spacing pair.dx (and kCoarseFactor pair.dx) and origin
/// domain_min, computes iou() of each pair and deposit_shape() of each frame. All frames are compared before returning. progress(k, n), when given, is called after the
/// k-th of n frames. Throws RunInputError "<ply path>: ..." for a frame that cannot be read, contradicts
/// run.json's dim, has no mass or a non-finite position or mass, and "<ply A> vs <ply B>: ..." if iou()
/// refuses the pair.
RunComparison compare_runs(const RunPair& pair, const std::function<void(std::size_t, std::size_t)>& progress = {});

/// compare_runs(pair_runs(dir_a, dir_b, dx), progress).
RunComparison compare_runs(const std::string& dir_a, const std::string& dir_b, double dx = 0.0,
                           const std::function<void(std::size_t, std::size_t)>& progress = {});

/// "3, 7-9, 12" for the sorted frame numbers {3, 7, 8, 9, 12} (for messages).
std::string frame_ranges(const std::vector<int>& frames);

}  // namespace pnet
