#pragma once
// Where an implicit MPM step's Newton solve starts (MpmOptions::newton_start): v*, or v* plus the last
// step's implicit velocity change scaled to this step,
//
//   v_0,i = v*_i + w_i dt (v_i - v*_i)^{last} / dt_last,   w_i = m_i / (m_i + kFade max_j m_j),
//
// m_i the lighter of node i's masses in the last step and in this one,
//
// on the grid nodes both steps share (the grid is Eulerian: a node keeps its place). (v - v*) / dt is
// the acceleration the step's stress and contacts gave each node beyond gravity; where the material
// moves smoothly it changes little from one step to the next, and most of it is the stress that holds
// resting material against gravity, which a start at v* (free fall for one step) leaves to Newton.
// On the sand column (return_map) this start's residual is 5x smaller than v*'s and the step takes 28%
// fewer Newton iterations and half the Krylov products (docs/solver.md, "Where Newton starts").
//
// Two kinds of node take less of it:
// - nodes with a held component (the Coulomb or sticky floor's normal, fixed this step) start at v*: the
//   floor's friction switches between stick and slip from step to step, and started at the last step's
//   slip the one solve's semi-smooth Newton took 15% more iterations (2.31 against 2.01 per step);
// - light nodes are faded by w_i: a node reached only by the tails of a few particles' stencils carries
//   their stiffness and little mass, so its converged velocity holds the solve's error at full size;
//   carried forward step after step, that error grew on the stiff column until steps ran into their
//   iteration cap (kFade measured: docs/solver.md).
//
// A solve from the prediction that fails is solved again from v* (StepPredictor::solve), and a step
// that did not converge leaves no prediction. The prediction is state: checkpoints keep it
// (MpmIntegrator::checkpoint_prediction, CoupledImplicitIntegrator::predictor), so a resumed run equals
// an uninterrupted one.
#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "pnet/mpm/incremental_potential.hpp"
#include "pnet/solver/integrators.hpp"
#include "pnet/solver/step_stats.hpp"

namespace pnet {

/// Whether a step of `method` starts from the prediction: MpmOptions::newton_start "last_step", or
/// "auto" where the integrator's entry says so (IntegratorInfo::predicts_newton_start).
bool predicts_newton_start(const std::string& newton_start, Method method);

/// A solve from the prediction that ends unconverged above this many Newton tolerances, or fails, is
/// solved again from v* (StepPredictor::solve).
inline constexpr double kRejectedPredictionResidual = 10.0;

template <int dim>
class StepPredictor {
public:
    /// The fraction of the heaviest node's mass at which a node's prediction is halved.
    static constexpr double kFade = 0.01;

    /// Adds the recorded prediction to `v` (v* on entry) on this step's unknowns: dt times each shared
    /// node's last rate, faded by its mass, except on nodes with a held component. No-op when empty.
    void predict(const IncrementalPotential<dim>& potential, double dt, VecX& v) const;
    /// Records the step just solved: (v - v*) / dt on the potential's unknowns.
    void record(const IncrementalPotential<dim>& potential, const VecX& v, double dt);
    void clear() {
        nodes_.clear();
        rates_.clear();
        masses_.clear();
    }
    bool empty() const { return nodes_.empty(); }

    /// A step's solve (ImplicitIntegrator, CoupledImplicitIntegrator): `solve(from_prediction, stats)` solves
    /// it from the prediction, or from v*, into `stats` and `v`. `predicts`: whether the step's integrator
    /// starts from the prediction (predicts_newton_start); it does once there is one. From the prediction,
    /// a solve that throws SimulationError or ends unconverged above kRejectedPredictionResidual x
    /// `tolerance` is what failed, not the step (a node's rate recorded where its velocity was
    /// ill-determined, now pulling on stiff material): the step is solved again from v*, both solves'
    /// Newton, Krylov, line-search and fixed-point counts summed, and marked prediction_rejected. Then a
    /// converged step is recorded (the next step's prediction); otherwise the prediction is dropped.
    template <typename Stats, typename Solve>
    void solve(bool predicts, double tolerance, const IncrementalPotential<dim>& potential, const VecX& v, double dt,
               Stats& stats, Solve&& solve_from);

    /// The recorded prediction as matrices for a checkpoint: per node, the rate in column 0, the node's
    /// grid storage index in (0, 1) and its mass then in (1, 1).
    std::vector<Mat<dim>> state() const;
    /// Restores state(); `storage_size` bounds the node indices. Throws std::invalid_argument naming
    /// `where`, the entry and the problem for an index off the grid or a rate that is not finite, and
    /// then keeps what it held.
    void restore(const std::vector<Mat<dim>>& state, std::int64_t storage_size, const std::string& where);

private:
    std::vector<std::int64_t> nodes_;  // grid storage indices
    std::vector<Vec<dim>> rates_;      // (v - v*) / dt at each
    std::vector<double> masses_;       // each node's mass then
};

template <int dim>
template <typename Stats, typename Solve>
void StepPredictor<dim>::solve(bool predicts, double tolerance, const IncrementalPotential<dim>& potential,
                               const VecX& v, double dt, Stats& stats, Solve&& solve_from) {
    const bool predicted = predicts && !empty();
    bool rejected = false;
    try {
        solve_from(predicted, stats);
        rejected = predicted && !stats.converged && !(stats.residual <= kRejectedPredictionResidual * tolerance);
    } catch (const SimulationError&) {
        if (!predicted) throw;
        rejected = true;
    }
    if (rejected) {
        Stats again;
        again.dt = stats.dt;
        solve_from(false, again);
        again.newton_iterations += stats.newton_iterations;
        again.cg_iterations += stats.cg_iterations;
        again.line_search_steps += stats.line_search_steps;
        again.fixed_point_iterations += stats.fixed_point_iterations;
        again.hardening_clamped = std::max(again.hardening_clamped, stats.hardening_clamped);
        stats = again;
        stats.prediction_rejected = true;
    }
    if (predicts && stats.converged)
        record(potential, v, dt);
    else
        clear();
}

}  // namespace pnet
