#pragma once
// The tables a run writes beside its frames (docs/architecture.md): stats.csv, one row per frame,
// and steps.csv, one row per step. Their columns come from the field lists declared beside the
// statistics (for_each_frame_field in run_stats.hpp, for_each_step_field in
// solver/step_stats.hpp), so a new statistic is added in one place and reaches the files and
// Python alike.
#include <string>
#include <vector>

#include "pnet/sim/run_stats.hpp"

namespace pnet {

/// Which columns a run's tables have: the 3D momentum, and the FEM contact columns (meshes).
struct RunColumns {
    int dim = 2;
    bool fem = false;
    std::string integrator;  // steps.csv's last column, the same in every row (solver/integrators.hpp)
};

/// stats.csv's header line (with its newline) and the row of one frame.
std::string stats_csv_header(const RunColumns& columns);
std::string stats_csv_row(const FrameStats& frame, const RunColumns& columns);

/// steps.csv's header line and the row of one step: its frame, its number in the run and the time
/// at its end (s), then its statistics, then the integrator that took it.
std::string steps_csv_header(const RunColumns& columns);
std::string steps_csv_row(int frame, long step, double time, const StepRecord& stats, const RunColumns& columns);

/// The values of column `name` in the rows of a CSV text written by the functions above (header
/// first), as text. Throws std::invalid_argument if the header has no such column or a row is short.
std::vector<std::string> csv_column(const std::string& csv, const std::string& name);

}  // namespace pnet
