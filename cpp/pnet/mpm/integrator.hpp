#pragma once
// What the simulation loop sees of an MPM time integrator (docs/methods.md):
// explicit (explicit_integrator.hpp), plasticitynet and lagged
// (implicit_integrator.hpp) all step the same particles on the same grid with
// the same transfers and boundary conditions, so runs differ only by the time
// integration.
#include <string>
#include <vector>

#include "pnet/math/types.hpp"
#include "pnet/mpm/particles.hpp"
#include "pnet/mpm/mpm_step_stats.hpp"

namespace pnet {

template <int dim>
class MpmIntegrator {
public:
    virtual ~MpmIntegrator() = default;

    /// "explicit", "plasticitynet" or "lagged".
    virtual std::string name() const = 0;

    /// Advances the particles by dt. `step_index` only names the step in errors.
    virtual MpmStepStats step(Particles<dim>& particles, double dt, long step_index) = 0;

    /// Called when the particles were set from outside (start of a run).
    virtual void reset(const Particles<dim>& /*particles*/) {}

    /// State beyond the particles that a bit-identical resume needs (explicit:
    /// the cached stresses), saved in checkpoints.
    virtual std::vector<Mat<dim>> checkpoint_state() const { return {}; }
    virtual void restore_checkpoint_state(std::vector<Mat<dim>> /*state*/) {}
    /// What the next step's solve starts from beyond the particles (implicit MPM: the Newton start's
    /// prediction, one matrix per grid node at most), kept by checkpoints beside checkpoint_state().
    virtual std::vector<Mat<dim>> checkpoint_prediction() const { return {}; }
    virtual void restore_checkpoint_prediction(const std::vector<Mat<dim>>& /*state*/) {}
};

}  // namespace pnet
