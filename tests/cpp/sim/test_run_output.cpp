#include <gtest/gtest.h>

#include <set>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "pnet/sim/run_output.hpp"

namespace pnet {
namespace {

std::size_t cells(const std::string& line) {
    std::size_t n = 1;
    for (char c : line) n += c == ',';
    return n;
}

/// A one-row table (header and row) holds `cell` (the text) in each named column.
void expect_cells(const std::string& table, const std::vector<std::pair<std::string, std::string>>& columns) {
    for (const auto& [column, cell] : columns)
        EXPECT_EQ(csv_column(table, column), std::vector<std::string>{cell}) << column;
}

// The tables' columns as the evaluation scripts, notebooks and users' tools read them: a change here
// is a change of the output format.
TEST(RunOutput, HeadersAreTheDocumentedColumns) {
    EXPECT_EQ(stats_csv_header({2, false, "lagged"}),
              "frame,time_s,steps,dt_min_s,dt_max_s,wall_s,clamped,kinetic_J,potential_J,momentum_x,momentum_y,"
              "newton_iterations,cg_iterations,line_search_steps,fixed_point_iterations,network_evaluations,"
              "network_points,max_residual_m_per_s,converged,unconverged_steps,hardening_clamped,"
              "advection_capped_steps,floor_friction_retried_steps,prediction_rejected_steps\n");
    EXPECT_EQ(stats_csv_header({3, true, "lagged"}),
              "frame,time_s,steps,dt_min_s,dt_max_s,wall_s,clamped,kinetic_J,potential_J,momentum_x,momentum_y,"
              "momentum_z,newton_iterations,cg_iterations,line_search_steps,fixed_point_iterations,"
              "network_evaluations,network_points,max_residual_m_per_s,converged,unconverged_steps,"
              "hardening_clamped,advection_capped_steps,floor_friction_retried_steps,prediction_rejected_steps,"
              "contact_pairs,min_distance_m,"
              "ccd_queries,ccd_limited\n");
    // steps.csv: any step's columns (solver/step_stats.hpp), then MPM's, then FEM's and contact's (FEM and
    // coupled runs).
    EXPECT_EQ(
        steps_csv_header({2, false, "lagged"}),
        "frame,step,time_s,dt_s,wall_s,p2g_s,solve_s,g2p_s,energy_s,cg_s,newton_iterations,cg_iterations,"
        "line_search_steps,network_evaluations,network_points,fixed_point_iterations,fixed_point_change,"
        "initial_residual_m_per_s,residual_m_per_s,energy_J,converged,line_search_failed,"
        "hardening_clamped,fixed_point_converged,reference_updates,true_residual_m_per_s,clamped,advection_capped,"
        "floor_friction_retried,prediction_rejected,integrator\n");
    EXPECT_EQ(steps_csv_header({2, true, "lagged"}),
              steps_csv_header({2, false, "lagged"}).substr(0, steps_csv_header({2, false, "lagged"}).size() - 12) +
                  ",predictor_iterations,kinematic_stages,kinematic_reached,substeps,ccd_queries,ccd_limited,"
                  "contact_pairs,min_distance_m,broad_phase_s,ccd_s,integrator\n");
}

TEST(RunOutput, RowsMatchTheirHeaders) {
    FrameStats f;
    f.frame = 3;
    f.time = 0.06;
    f.steps = 20;
    f.wall_seconds = 1.23456;
    f.kinetic = 1.0 / 3.0;
    f.momentum[2] = -2.5;
    f.converged = false;
    f.contact_pairs = 7;
    StepRecord s;
    s.dt = 1e-3;
    s.energy = 1.0 / 3.0;
    s.converged = false;
    s.kinematic_reached = false;
    s.contact_pairs = 4;
    for (int dim : {2, 3})
        for (bool fem : {false, true}) {
            const RunColumns columns{dim, fem, "plasticitynet"};
            EXPECT_EQ(cells(stats_csv_row(f, columns)), cells(stats_csv_header(columns))) << dim << fem;
            EXPECT_EQ(cells(steps_csv_row(3, 41, 0.061, s, columns)), cells(steps_csv_header(columns))) << dim << fem;
        }
    const RunColumns fem3{3, true, "plasticitynet"};
    const std::string stats = stats_csv_header(fem3) + stats_csv_row(f, fem3);
    expect_cells(stats, {{"frame", "3"},
                         {"time_s", "0.060000"},
                         {"wall_s", "1.2346"},
                         {"kinetic_J", "0.333333333"},
                         {"momentum_z", "-2.5"},
                         {"converged", "0"},
                         {"contact_pairs", "7"}});
    const std::string steps = steps_csv_header(fem3) + steps_csv_row(3, 41, 0.061, s, fem3);
    expect_cells(steps, {{"step", "41"},
                         {"time_s", "0.061"},
                         {"dt_s", "0.001"},
                         {"energy_J", "0.333333333333"},
                         {"kinematic_reached", "0"},
                         {"integrator", "plasticitynet"}});

    EXPECT_THROW(csv_column(stats, "no_such_column"), std::invalid_argument);
    EXPECT_THROW(csv_column("a,b\n1\n", "b"), std::invalid_argument);
}

// Each method's integrator returns its own layer's record; the run keeps the union. A record widened
// to the union keeps every field it had and leaves the others at their defaults.
TEST(RunOutput, AStepRecordKeepsEachLayersFields) {
    MpmStepStats mpm;
    mpm.dt = 1e-3;
    mpm.newton_iterations = 4;
    mpm.clamped = 3;
    mpm.advection_capped = true;
    const StepRecord from_mpm = mpm;
    EXPECT_EQ(from_mpm.dt, 1e-3);
    EXPECT_EQ(from_mpm.newton_iterations, 4);
    EXPECT_EQ(from_mpm.clamped, 3u);
    EXPECT_TRUE(from_mpm.advection_capped);
    EXPECT_EQ(from_mpm.substeps, 1);
    EXPECT_EQ(from_mpm.ccd_queries, 0);

    FemStepStats fem;
    fem.residual = 2e-4;
    fem.kinematic_stages = 5;
    fem.kinematic_reached = false;
    fem.substeps = 7;
    fem.ccd_limited = 2;
    fem.min_distance = 1e-5;
    const StepRecord from_fem = fem;
    EXPECT_EQ(from_fem.residual, 2e-4);
    EXPECT_EQ(from_fem.kinematic_stages, 5);
    EXPECT_FALSE(from_fem.kinematic_reached);
    EXPECT_EQ(from_fem.substeps, 7);
    EXPECT_EQ(from_fem.ccd_limited, 2);
    EXPECT_EQ(from_fem.min_distance, 1e-5);
    EXPECT_EQ(from_fem.clamped, 0u);
    EXPECT_FALSE(from_fem.advection_capped);

    // Every layer's fields are in the record's list, once.
    std::set<std::string> keys;
    StepRecord::for_each_field([&](const StepField& field, auto) {
        if (field.key) keys.insert(field.key);
    });
    for (const char* key : {"dt", "newton_iterations", "clamped", "advection_capped", "kinematic_stages", "substeps",
                            "ccd_queries", "min_distance", "max_grid_speed"})
        EXPECT_TRUE(keys.count(key)) << key;
}

TEST(RunOutput, EveryStatisticHasOneNameInEachOutput) {
    std::set<std::string> columns, keys;
    std::size_t fields = 0;
    for_each_step_field([&](const StepField& field, auto) {
        ++fields;
        EXPECT_TRUE(field.column || field.key) << "a statistic shown nowhere";
        if (field.column) {
            EXPECT_TRUE(columns.insert(field.column).second) << field.column;
        }
        if (field.key) {
            EXPECT_TRUE(keys.insert(field.key).second) << field.key;
        }
    });
    EXPECT_EQ(keys.size(), fields) << "every step statistic reaches Python";
    columns.clear();
    keys.clear();
    for_each_frame_field([&](const FrameField& field, auto) {
        if (field.column) {
            EXPECT_TRUE(columns.insert(field.column).second) << field.column;
        }
        if (field.key) {
            EXPECT_TRUE(keys.insert(field.key).second) << field.key;
        }
    });
}

}  // namespace
}  // namespace pnet
