#pragma once
// What every simulation (MPM, FEM, MPM-FEM coupling) shares (docs/architecture.md): the scene and
// its settings, where the run is in time, the frame loop (steps that land exactly on frame ends, the
// statistics of a frame, the energies and momentum of its bodies), and the common preamble of their
// checkpoints. Each method's class derives from SimulationBase, adds its state and its step, and
// answers what the run driver (run.hpp) and the Python bindings ask of any method: its step and
// frame, its checkpoints, its description in run.json, its frame files and its contact. Neither
// knows a method by its type; the bindings read the arrays of a method through its capabilities
// (WithParticles here, WithMesh in fem_simulation.hpp).
#include <chrono>
#include <cstdint>
#include <functional>
#include <istream>
#include <ostream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "pnet/math/types.hpp"
#include "pnet/mpm/particles.hpp"
#include "pnet/scene/scene.hpp"
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
FrameStats advance_one_frame(const int& frame, const double& time, std::vector<StepRecord>& frame_steps, Step&& step,
                             Finish&& finish, const std::function<void()>& after_step) {
    const auto start = std::chrono::steady_clock::now();
    FrameStats stats;
    const int target = frame + 1;
    stats.dt_min = 1e300;
    stats.min_distance = 1e300;
    frame_steps.clear();
    while (frame < target) {
        const StepRecord s = step();
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

class FrameFiles;  // sim/frame_files.hpp

/// The state every simulation keeps besides its method's, with its accessors, and the face every
/// method shows.
class SimulationBase {
public:
    virtual ~SimulationBase() = default;

    /// One step of the integrator's dt (or its stable step), shortened to land on the end of the
    /// current frame; frame() advances when it does. Throws SimulationError on a blow-up or a failed
    /// solve.
    virtual StepRecord step() = 0;
    /// Advances to the end of the next frame by step(), then checks what the method guarantees (no
    /// intersection). after_step, when given, runs after every step; an exception it throws (an
    /// interrupt) stops the frame between two steps, with the steps so far in last_frame_steps().
    virtual FrameStats advance_frame(const std::function<void()>& after_step = {}) = 0;
    /// Writes the whole state atomically; load_checkpoint() refuses a file of another scene,
    /// integrator or size (std::invalid_argument) and a missing file (FileNotFoundError).
    virtual void save_checkpoint(const std::string& path) const = 0;
    virtual void load_checkpoint(const std::string& path) = 0;
    /// The method's discretization for run.json (grid spacing, particles, mesh sizes, contact
    /// parameters, the step it takes).
    virtual nlohmann::json describe() const = 0;
    /// Writes the current frame's files (frame_NNNNN.ply, .png, .vtu, ...) into the run's folder.
    virtual void write_frame(const FrameFiles& files) const = 0;
    /// The barrier's activation distance dhat, m, of a method with contact (its run ends with a
    /// contact summary), 0 without contact.
    virtual double contact_dhat() const { return 0.0; }
    /// Contact now: dhat, kappa, the smallest distance, the pairs within dhat, ...; empty without
    /// contact.
    virtual nlohmann::json contact_state() const { return nlohmann::json::object(); }
    /// "N particles", "N nodes, M elements": the size of the discretization in words.
    virtual std::string size_text() const = 0;

    int dimension() const { return scene_.dim; }
    const Scene& scene() const { return scene_; }
    const IntegratorSettings& settings() const { return settings_; }
    int frame() const { return frame_; }
    double time() const { return time_; }
    long total_steps() const { return steps_; }
    /// Per-step statistics of the last advance_frame(), in step order.
    const std::vector<StepRecord>& last_frame_steps() const { return frame_steps_; }

protected:
    /// Throws std::invalid_argument for dt < 0 (0 is the CFL step) or cfl outside (0, 1].
    SimulationBase(const Scene& scene, const IntegratorSettings& settings);

    /// clip_to_frame() and count_step() on this run's clock.
    double clip_to_frame(double dt) const { return pnet::clip_to_frame(time_, dt, frame_, scene_.frame_dt); }
    void count_step(double dt) { pnet::count_step(dt, scene_.frame_dt, time_, frame_, steps_); }
    /// advance_one_frame() on this run's clock and step statistics.
    template <typename Step, typename Finish>
    FrameStats advance_one_frame(Step&& step, Finish&& finish, const std::function<void()>& after_step) {
        return pnet::advance_one_frame(frame_, time_, frame_steps_, step, finish, after_step);
    }

    /// A checkpoint's preamble: magic (8 bytes), the method's header integers, the time, the scene's
    /// digest and the integrator's name. read_checkpoint_preamble() checks the magic against
    /// `magics` (returning the index of the one found; "<path>: not a PlasticityNet <kind>
    /// checkpoint" otherwise), the scene and the integrator, and restores nothing: the caller
    /// validates the header and the state that follow, then commits them with restore_clock().
    void write_checkpoint_preamble(std::ostream& out, const char (&magic)[8], const std::vector<std::int64_t>& header,
                                   const std::string& integrator) const;
    int read_checkpoint_preamble(std::istream& in, const std::string& path, const std::vector<const char*>& magics,
                                 const std::string& kind, std::vector<std::int64_t>& header, double& time,
                                 const std::string& integrator) const;
    /// The clock of a loaded checkpoint (std::invalid_argument "<path>: corrupt checkpoint header ..."
    /// for a negative or non-finite value).
    void restore_clock(const std::string& path, std::int64_t frame, std::int64_t steps, double time);

    Scene scene_;
    std::string scene_digest_;  // sha256 of the scene's JSON: a checkpoint is only for its scene
    IntegratorSettings settings_;
    std::vector<StepRecord> frame_steps_;
    int frame_ = 0;
    long steps_ = 0;
    double time_ = 0.0;
};

/// A method with material points (MPM, coupling): their arrays, whose storage never moves for the
/// life of the simulation (load_checkpoint copies into it), so that views of it stay valid.
template <int dim>
class WithParticles {
public:
    static constexpr int kDim = dim;
    virtual ~WithParticles() = default;
    virtual const Particles<dim>& particles() const = 0;
};

}  // namespace pnet
