#pragma once
// One run of a scene into a folder, whatever the method (docs/architecture.md): the frame loop, the
// frames (PLY, PNG, optionally VTU), run.json, stats.csv and steps.csv (sim/run_output.hpp),
// checkpoints and resume, the progress line and the closing summary. `pnet simulate` and
// plasticitynet_sim's Simulation.run() both call run_to_folder(), so a Python run writes the same
// folder as the command line and either can resume the other's run.
//
// make_simulation() is the one place that decides the method from the scene: particles and
// meshes -> MPM-FEM coupling, meshes -> FEM, particles -> MPM; each in 2D or 3D.
#include <functional>
#include <memory>
#include <string>

#include "pnet/scene/scene.hpp"
#include "pnet/sim/run_stats.hpp"
#include "pnet/sim/simulation_base.hpp"

namespace pnet {

/// A simulation of any method and dimension, seen through the face every method shows
/// (SimulationBase).
using AnySimulation = std::unique_ptr<SimulationBase>;

/// The simulation the scene calls for, set up with `settings` (models loaded by the caller).
AnySimulation make_simulation(const Scene& scene, const IntegratorSettings& settings);

/// Where and how a run writes.
struct RunOptions {
    std::string out;              // the run's folder (io/run_folder.hpp: one run per folder)
    int frames = -1;              // the frame to reach; <= 0: the scene's frame count
    int checkpoint_every = 10;    // frames between checkpoints (0: none)
    bool resume = false;          // continue the run in `out` from its checkpoint
    bool overwrite = false;       // replace the run in `out` (its files only) instead of refusing
    bool vtu = false;             // also frame_NNNNN.vtu (ParaView) for particles and 2D meshes
    std::string color = "speed";  // what the pictures colour: "speed" or "hardening"
    // Called after every step (e.g. Python's check for Ctrl-C); an exception it throws stops the
    // run between two steps, with every frame written so far complete.
    std::function<void()> after_step;
};

/// Advances `sim` (at its first frame, or at its checkpoint with options.resume) to options.frames,
/// writing every frame, the tables, run.json and the checkpoints into options.out, with a progress
/// line on stderr and a summary on stdout. A step that fails throws SimulationError, its message
/// ending with the frames that are complete (the tables are written up to them first). Throws
/// RunFolderError if options.out holds another run (without overwrite), and std::invalid_argument
/// for a bad option or a missing or mismatched checkpoint.
void run_to_folder(SimulationBase& sim, const Scene& scene, const IntegratorSettings& settings,
                   const RunOptions& options);

}  // namespace pnet
