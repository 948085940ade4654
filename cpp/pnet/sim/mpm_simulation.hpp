#pragma once
// An MPM run of a scene: the system built from the scene, the particles, the
// integrator, frame-by-frame advance, and checkpoints that resume
// bit-identically (they hold every array a step reads, including the
// integrator's cached stresses).
#include <algorithm>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "pnet/mpm/explicit_integrator.hpp"
#include "pnet/mpm/implicit_integrator.hpp"
#include "pnet/mpm/integrator.hpp"
#include "pnet/mpm/mpm_system.hpp"
#include "pnet/mpm/particles.hpp"
#include "pnet/nn/model_file.hpp"
#include "pnet/scene/scene.hpp"

namespace pnet {

/// The MPM system of a scene (materials per object, grid, gravity, boundary).
template <int dim>
MpmSystem<dim> make_mpm_system(const Scene& scene);

/// Which integrator a Simulation runs and how.
struct IntegratorSettings {
    std::string name = "explicit";  // "explicit" | "plasticitynet" | "lagged" | "analytic" (FEM)
    double dt = 0.0;                // s; 0: the CFL step before every step
    double cfl = 0.5;
    ImplicitOptions implicit;       // plasticitynet, lagged
    /// Energy model of each scene object, or of each mesh in a FEM scene
    /// (plasticitynet needs one for every object and deformable mesh; the
    /// others ignore them). Loading a model file needs LibTorch
    /// (load_model_file in pnet_torch), so the caller does it.
    std::vector<std::shared_ptr<const ModelFile>> models;

    /// The scene's "integrator" block: name, dt, cfl and the implicit options
    /// (std::invalid_argument naming the file and key on a bad value). Models
    /// are not loaded.
    static IntegratorSettings from_scene(const Scene& scene);
};

struct FrameStats {
    int frame = 0;        // frame reached
    double time = 0.0;    // s
    long steps = 0;       // steps in this frame
    double dt_min = 0.0, dt_max = 0.0;
    std::size_t clamped = 0;
    double wall_seconds = 0.0;
    double kinetic = 0.0, potential = 0.0;  // J
    double momentum[3] = {0.0, 0.0, 0.0};   // kg m/s
    // Implicit integrators: totals over the frame's steps, the largest final
    // Newton residual (m/s), and whether every solve converged.
    long newton_iterations = 0, cg_iterations = 0, line_search_steps = 0, fixed_point_iterations = 0;
    double max_residual = 0.0;
    bool converged = true;
    long unconverged_steps = 0;          // steps whose solve ended above the Newton tolerance
    long fixed_point_capped_steps = 0;   // plasticitynet: steps whose fixed point on F0 stopped above its tolerance
    std::size_t hardening_clamped = 0;   // most particles with a clamped hardening input in one step
    // FEM contact: the most contact pairs closer than dhat at the end of a step, the smallest pair
    // distance at the end of any step (m), and CCD queries / those that shortened a step.
    std::size_t contact_pairs = 0;
    double min_distance = 0.0;
    long ccd_queries = 0, ccd_limited = 0;

    /// Adds one step of the frame: counts sum, extremes (dt, residual, clamped hardening, contact
    /// pairs, smallest distance) are kept, failures stick. dt_min and min_distance start where the
    /// caller set them (1e300 to take the frame's smallest).
    void add_step(const StepStats& s) {
        ++steps;
        clamped += s.clamped;
        dt_min = std::min(dt_min, s.dt);
        dt_max = std::max(dt_max, s.dt);
        newton_iterations += s.newton_iterations;
        cg_iterations += s.cg_iterations;
        line_search_steps += s.line_search_steps;
        fixed_point_iterations += s.fixed_point_iterations;
        max_residual = std::max(max_residual, s.residual);
        converged = converged && s.converged;
        unconverged_steps += !s.converged;
        fixed_point_capped_steps += !s.fixed_point_converged;
        hardening_clamped = std::max(hardening_clamped, s.hardening_clamped);
        contact_pairs = std::max(contact_pairs, s.contact_pairs);
        min_distance = std::min(min_distance, s.min_distance);
        ccd_queries += s.ccd_queries;
        ccd_limited += s.ccd_limited;
    }
};

template <int dim>
class Simulation {
public:
    static constexpr int kDim = dim;

    /// Explicit MPM; dt: the step (s); 0 selects the CFL step cfl dx / (c + max |v|) before every step.
    Simulation(const Scene& scene, double dt, double cfl);

    /// Any integrator. Throws std::invalid_argument for an unknown name, a bad
    /// dt or cfl, or missing or unfit models (naming "<scene file>: objects[k].model").
    Simulation(const Scene& scene, const IntegratorSettings& settings);

    /// One step of the integrator's dt (or the CFL step), shortened to land on
    /// the end of the current frame; frame() advances when it does. Throws
    /// SimulationError on a blow-up.
    StepStats step();

    /// Advances to the end of the next frame by step(). Throws SimulationError
    /// on a blow-up. after_step, when given, runs after every step; an
    /// exception it throws (e.g. an interrupt) stops the frame between two
    /// steps, with a consistent state and the steps so far in last_frame_steps().
    FrameStats advance_frame(const std::function<void()>& after_step = {});

    /// The particle arrays. Their storage never moves for the life of the
    /// simulation (load_checkpoint copies into it), so views of it stay valid.
    const Particles<dim>& particles() const { return particles_; }
    const MpmSystem<dim>& system() const { return system_; }
    int frame() const { return frame_; }
    double time() const { return time_; }
    long total_steps() const { return steps_; }
    const IntegratorSettings& settings() const { return settings_; }
    /// Per-step statistics of the last advance_frame(), in step order.
    const std::vector<StepStats>& last_frame_steps() const { return frame_steps_; }

    /// Writes the whole state atomically; load_checkpoint() refuses a file of
    /// another scene (sha of its JSON), integrator, dimension or particle count
    /// (std::invalid_argument) and a missing file (FileNotFoundError).
    void save_checkpoint(const std::string& path) const;
    void load_checkpoint(const std::string& path);

private:
    Scene scene_;
    std::string scene_digest_;
    MpmSystem<dim> system_;
    Particles<dim> particles_;
    IntegratorSettings settings_;
    std::unique_ptr<MpmIntegrator<dim>> integrator_;
    std::vector<StepStats> frame_steps_;
    int frame_ = 0;
    long steps_ = 0;
    double time_ = 0.0;
};

}  // namespace pnet
