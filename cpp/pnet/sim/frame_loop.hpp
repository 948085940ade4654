#pragma once
// The frame loop every simulation (MPM, FEM, coupling) runs: steps that land exactly on frame ends,
// the statistics of a frame, and the energies and momentum of its bodies (docs/architecture.md).
#include <chrono>
#include <functional>
#include <vector>

#include "pnet/math/types.hpp"
#include "pnet/sim/run_stats.hpp"

namespace pnet {

/// A step of dt from `time` shortened to end exactly on the end of the current frame (within
/// round-off), never past it.
inline double clip_to_frame(double time, double dt, int frame, double frame_dt) {
    const double frame_end = (frame + 1) * frame_dt;
    return time + dt > frame_end * (1.0 - 1e-12) ? frame_end - time : dt;
}

/// Counts a step of dt: the time, the steps, and the frame once its end is reached (the time is then
/// set to it exactly).
inline void count_step(double dt, double frame_dt, double& time, int& frame, long& steps) {
    const double frame_end = (frame + 1) * frame_dt;
    time += dt;
    ++steps;
    if (time >= frame_end * (1.0 - 1e-12)) {
        time = frame_end;
        ++frame;
    }
}

/// One frame: step() (which counts its step) until `frame` moves on, each step's statistics added to
/// the frame's and kept in frame_steps, after_step() after each; then finish(stats) adds what the
/// frame ends with (checks, energies). The wall time covers all of it.
template <typename Step, typename Finish>
FrameStats advance_one_frame(const int& frame, const double& time, std::vector<StepStats>& frame_steps, Step&& step,
                             Finish&& finish, const std::function<void()>& after_step) {
    const auto start = std::chrono::steady_clock::now();
    FrameStats stats;
    const int target = frame + 1;
    stats.dt_min = 1e300;
    stats.min_distance = 1e300;
    frame_steps.clear();
    while (frame < target) {
        const StepStats s = step();
        stats.add_step(s);
        frame_steps.push_back(s);
        if (after_step) after_step();
    }
    finish(stats);
    stats.frame = frame;
    stats.time = time;
    stats.wall_seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    return stats;
}

/// Adds a point mass's kinetic energy, potential energy in gravity g (zero at the origin) and
/// momentum to a frame's statistics.
template <int dim>
void add_point_mass(FrameStats& stats, double m, const Vec<dim>& x, const Vec<dim>& v, const Vec<dim>& g) {
    stats.kinetic += 0.5 * m * v.squaredNorm();
    stats.potential -= m * g.dot(x);
    for (int a = 0; a < dim; ++a) stats.momentum[a] += m * v[a];
}

}  // namespace pnet
