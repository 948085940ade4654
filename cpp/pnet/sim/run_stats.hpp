#pragma once
// What each step and frame of a run did, for every method (MPM, FEM, coupling): the record of a step
// (StepRecord: every layer's step fields, for_each_step_field) and the frame statistics, which a run
// writes to steps.csv and stats.csv and Python reads as dicts, declared once with their column names
// (for_each_frame_field). What the run is set up with: sim/integrator_settings.hpp.
#include <algorithm>
#include <memory>
#include <string>
#include <vector>

#include "pnet/contact/contact_step_stats.hpp"
#include "pnet/fem/fem_step_stats.hpp"
#include "pnet/mpm/mpm_step_stats.hpp"
#include "pnet/sim/integrator_settings.hpp"
#include "pnet/solver/step_stats.hpp"

namespace pnet {

/// What one step of any method did: the solver's fields and those of MPM, FEM and contact (each method's
/// integrator returns its own part of it: MpmStepStats, FemStepStats, CoupledStepStats).
using StepRecord = StepStatsWith<MpmStepFields, FemStepFields, ContactStepFields>;

/// Calls f(StepField, member pointer) for every StepRecord field, in steps.csv's column order: the one list
/// behind steps.csv (sim/run_output.hpp) and Python's step statistics (bindings).
template <typename F>
void for_each_step_field(F&& f) {
    StepRecord::for_each_field(f);
}

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
    long network_evaluations = 0;  // plasticitynet: passes of the energy network (StepStats::network_evaluations)
    long network_points = 0;       // ... and the points they evaluated (StepStats::network_points)
    double max_residual = 0.0;
    bool converged = true;
    long unconverged_steps = 0;          // steps whose solve ended above the Newton tolerance
    long fixed_point_capped_steps = 0;   // plasticitynet: steps whose fixed point on F0 stopped above its tolerance
    long advection_capped_steps = 0;     // implicit MPM, coupling: steps the advection limit cut below the scene's dt
    long floor_friction_retried_steps = 0;  // implicit MPM, coupling: steps whose one solve on the Coulomb floor failed
                                            // and the passes solved again (MpmStepFields::floor_friction_retried)
    long prediction_rejected_steps = 0;     // implicit MPM, coupling: steps solved again from v* (MpmStepFields::
                                            // prediction_rejected)
    std::size_t hardening_clamped = 0;   // most particles with a clamped hardening input in one step
    // FEM contact: the most contact pairs closer than dhat at the end of a step, the smallest pair
    // distance at the end of any step (m), and CCD queries / those that shortened a step.
    std::size_t contact_pairs = 0;
    double min_distance = 0.0;
    long ccd_queries = 0, ccd_limited = 0;

    /// Adds one step of the frame: counts sum, extremes (dt, residual, clamped hardening, contact
    /// pairs, smallest distance) are kept, failures stick. dt_min and min_distance start where the
    /// caller set them (1e300 to take the frame's smallest).
    void add_step(const StepRecord& s) {
        ++steps;
        clamped += s.clamped;
        dt_min = std::min(dt_min, s.dt);
        dt_max = std::max(dt_max, s.dt);
        newton_iterations += s.newton_iterations;
        cg_iterations += s.cg_iterations;
        line_search_steps += s.line_search_steps;
        fixed_point_iterations += s.fixed_point_iterations;
        network_evaluations += s.network_evaluations;
        network_points += s.network_points;
        max_residual = std::max(max_residual, s.residual);
        converged = converged && s.converged;
        unconverged_steps += !s.converged;
        fixed_point_capped_steps += !s.fixed_point_converged;
        advection_capped_steps += s.advection_capped;
        floor_friction_retried_steps += s.floor_friction_retried;
        prediction_rejected_steps += s.prediction_rejected;
        hardening_clamped = std::max(hardening_clamped, s.hardening_clamped);
        contact_pairs = std::max(contact_pairs, s.contact_pairs);
        min_distance = std::min(min_distance, s.min_distance);
        ccd_queries += s.ccd_queries;
        ccd_limited += s.ccd_limited;
    }
};

/// How one FrameStats value is shown: its stats.csv column (nullptr: not in the file), its key in
/// Python's frame dicts (nullptr: not shown there), the printf format of its CSV value, and which
/// runs have the column (FEM and coupled runs only; 3D runs only).
struct FrameField {
    const char* column;
    const char* key;
    const char* format;
    bool fem = false;
    bool three_d = false;
};

/// Calls f(FrameField, getter) for every frame statistic, in stats.csv's column order: the one list
/// behind stats.csv (sim/run_output.hpp) and Python's frame statistics (bindings).
template <typename F>
void for_each_frame_field(F&& f) {
    f(FrameField{"frame", "frame", "%d"}, [](const FrameStats& s) { return s.frame; });
    f(FrameField{"time_s", "time", "%.6f"}, [](const FrameStats& s) { return s.time; });
    f(FrameField{"steps", "steps", "%ld"}, [](const FrameStats& s) { return s.steps; });
    f(FrameField{"dt_min_s", "dt_min", "%.6g"}, [](const FrameStats& s) { return s.dt_min; });
    f(FrameField{"dt_max_s", "dt_max", "%.6g"}, [](const FrameStats& s) { return s.dt_max; });
    f(FrameField{"wall_s", "wall_s", "%.4f"}, [](const FrameStats& s) { return s.wall_seconds; });
    f(FrameField{"clamped", "clamped", "%zu"}, [](const FrameStats& s) { return s.clamped; });
    f(FrameField{"kinetic_J", "kinetic_energy", "%.9g"}, [](const FrameStats& s) { return s.kinetic; });
    f(FrameField{"potential_J", "potential_energy", "%.9g"}, [](const FrameStats& s) { return s.potential; });
    f(FrameField{"momentum_x", nullptr, "%.9g"}, [](const FrameStats& s) { return s.momentum[0]; });
    f(FrameField{"momentum_y", nullptr, "%.9g"}, [](const FrameStats& s) { return s.momentum[1]; });
    f(FrameField{"momentum_z", nullptr, "%.9g", false, true}, [](const FrameStats& s) { return s.momentum[2]; });
    f(FrameField{"newton_iterations", "newton_iterations", "%ld"},
      [](const FrameStats& s) { return s.newton_iterations; });
    f(FrameField{"cg_iterations", "cg_iterations", "%ld"}, [](const FrameStats& s) { return s.cg_iterations; });
    f(FrameField{"line_search_steps", "line_search_steps", "%ld"},
      [](const FrameStats& s) { return s.line_search_steps; });
    f(FrameField{"fixed_point_iterations", "fixed_point_iterations", "%ld"},
      [](const FrameStats& s) { return s.fixed_point_iterations; });
    f(FrameField{"network_evaluations", "network_evaluations", "%ld"},
      [](const FrameStats& s) { return s.network_evaluations; });
    f(FrameField{"network_points", "network_points", "%ld"}, [](const FrameStats& s) { return s.network_points; });
    f(FrameField{"max_residual_m_per_s", "max_residual", "%.6g"}, [](const FrameStats& s) { return s.max_residual; });
    f(FrameField{"converged", "converged", "%d"}, [](const FrameStats& s) { return s.converged; });
    f(FrameField{"unconverged_steps", "unconverged_steps", "%ld"},
      [](const FrameStats& s) { return s.unconverged_steps; });
    f(FrameField{"hardening_clamped", "hardening_clamped", "%zu"},
      [](const FrameStats& s) { return s.hardening_clamped; });
    f(FrameField{"advection_capped_steps", "advection_capped_steps", "%ld"},
      [](const FrameStats& s) { return s.advection_capped_steps; });
    f(FrameField{"floor_friction_retried_steps", "floor_friction_retried_steps", "%ld"},
      [](const FrameStats& s) { return s.floor_friction_retried_steps; });
    f(FrameField{"prediction_rejected_steps", "prediction_rejected_steps", "%ld"},
      [](const FrameStats& s) { return s.prediction_rejected_steps; });
    f(FrameField{"contact_pairs", "contact_pairs", "%zu", true}, [](const FrameStats& s) { return s.contact_pairs; });
    f(FrameField{"min_distance_m", "min_distance", "%.6g", true}, [](const FrameStats& s) { return s.min_distance; });
    f(FrameField{"ccd_queries", nullptr, "%ld", true}, [](const FrameStats& s) { return s.ccd_queries; });
    f(FrameField{"ccd_limited", nullptr, "%ld", true}, [](const FrameStats& s) { return s.ccd_limited; });
}

}  // namespace pnet
