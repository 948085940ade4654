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
#include "pnet/sim/run_stats.hpp"
#include "pnet/sim/simulation_base.hpp"

namespace pnet {

/// The MPM system of a scene (materials per object, grid, gravity, boundary).
template <int dim>
MpmSystem<dim> make_mpm_system(const Scene& scene);

template <int dim>
class Simulation : public SimulationBase, public WithParticles<dim> {
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
    StepRecord step() override;

    /// Advances to the end of the next frame by step(). Throws SimulationError
    /// on a blow-up. after_step, when given, runs after every step; an
    /// exception it throws (e.g. an interrupt) stops the frame between two
    /// steps, with a consistent state and the steps so far in last_frame_steps().
    FrameStats advance_frame(const std::function<void()>& after_step = {}) override;

    /// The particle arrays. Their storage never moves for the life of the
    /// simulation (load_checkpoint copies into it), so views of it stay valid.
    const Particles<dim>& particles() const override { return particles_; }
    const MpmSystem<dim>& system() const { return system_; }

    /// Writes the whole state atomically; load_checkpoint() refuses a file of
    /// another scene (sha of its JSON), integrator, dimension or particle count
    /// (std::invalid_argument) and a missing file (FileNotFoundError).
    void save_checkpoint(const std::string& path) const override;
    void load_checkpoint(const std::string& path) override;

    /// dx and the particle count.
    nlohmann::json describe() const override;
    void write_frame(const FrameFiles& files) const override;
    std::string size_text() const override;

private:
    MpmSystem<dim> system_;
    Particles<dim> particles_;
    std::unique_ptr<MpmIntegrator<dim>> integrator_;
};

}  // namespace pnet
