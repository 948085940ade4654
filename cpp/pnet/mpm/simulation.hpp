#pragma once
// An MPM run of a scene: the system built from the scene, the particles, the
// integrator, frame-by-frame advance, and checkpoints that resume
// bit-identically (they hold every array a step reads, including the
// integrator's cached stresses).
#include <memory>
#include <string>

#include "pnet/mpm/explicit_integrator.hpp"
#include "pnet/mpm/mpm_system.hpp"
#include "pnet/mpm/particles.hpp"
#include "pnet/scene/scene.hpp"

namespace pnet {

/// The MPM system of a scene (materials per object, grid, gravity, boundary).
template <int dim>
MpmSystem<dim> make_mpm_system(const Scene& scene);

struct FrameStats {
    int frame = 0;        // frame reached
    double time = 0.0;    // s
    long steps = 0;       // steps in this frame
    double dt_min = 0.0, dt_max = 0.0;
    std::size_t clamped = 0;
    double wall_seconds = 0.0;
    double kinetic = 0.0, potential = 0.0;  // J
    double momentum[3] = {0.0, 0.0, 0.0};   // kg m/s
};

template <int dim>
class Simulation {
public:
    /// dt: the step (s); 0 selects the CFL step cfl dx / (c + max |v|) before every step.
    Simulation(const Scene& scene, double dt, double cfl);

    /// Advances to the end of the next frame (the last step is shortened to
    /// land on it). Throws SimulationError on a blow-up.
    FrameStats advance_frame();

    const Particles<dim>& particles() const { return particles_; }
    const MpmSystem<dim>& system() const { return system_; }
    int frame() const { return frame_; }
    double time() const { return time_; }
    long total_steps() const { return steps_; }

    /// Writes the whole state atomically; load_checkpoint() refuses a file of
    /// another scene (sha of its JSON), dimension or particle count.
    void save_checkpoint(const std::string& path) const;
    void load_checkpoint(const std::string& path);

private:
    Scene scene_;
    std::string scene_digest_;
    MpmSystem<dim> system_;
    Particles<dim> particles_;
    std::unique_ptr<ExplicitIntegrator<dim>> integrator_;
    double dt_, cfl_;
    int frame_ = 0;
    long steps_ = 0;
    double time_ = 0.0;
};

}  // namespace pnet
