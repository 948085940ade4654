// The Simulation driver on the tiny scenes: every one runs, frames land on
// their times, checkpoints resume bit-identically and refuse foreign files.
#include <gtest/gtest.h>

#include <filesystem>

#include "pnet/scene/scene.hpp"
#include "pnet/sim/mpm_simulation.hpp"
#include "support/identical_states.hpp"
#include "support/temp_dir.hpp"

namespace pnet {
namespace {

namespace fs = std::filesystem;

using test::expect_identical;

template <int dim>
void run_tiny_scene(const Scene& scene) {
    Simulation<dim> sim(scene, 0.0, 0.5);  // CFL step
    const std::size_t n = sim.particles().size();
    for (int frame = 1; frame <= 2; ++frame) {
        const FrameStats stats = sim.advance_frame();
        EXPECT_EQ(stats.frame, frame);
        EXPECT_DOUBLE_EQ(sim.time(), frame * scene.frame_dt);
        EXPECT_GE(stats.steps, 1);
        EXPECT_LE(stats.dt_max, scene.frame_dt);
    }
    ASSERT_EQ(sim.particles().size(), n);
    for (std::size_t p = 0; p < n; ++p) {
        ASSERT_TRUE(sim.particles().x[p].allFinite());
        ASSERT_TRUE(sim.particles().F_elastic[p].allFinite());
    }
    // Gravity acted: the centre of mass went down (the scenes start above the floor or move down).
    double y0 = 0.0, y1 = 0.0;
    const Simulation<dim> fresh(scene, 0.0, 0.5);
    for (std::size_t p = 0; p < n; ++p) {
        y0 += fresh.particles().x[p][1];
        y1 += sim.particles().x[p][1];
    }
    EXPECT_LT(y1, y0);
}

TEST(Simulation, EveryTinySceneRunsTwoFrames) {
    int ran = 0;
    for (const auto& entry : fs::directory_iterator(PNET_SCENES_DIR "/tiny")) {
        SCOPED_TRACE(entry.path().string());
        const Scene scene = load_scene(entry.path().string());
        if (scene.has_meshes()) continue;  // FEM: test_fem_simulation.cpp
        if (scene.dim == 2)
            run_tiny_scene<2>(scene);
        else
            run_tiny_scene<3>(scene);
        ++ran;
    }
    EXPECT_EQ(ran, 5);  // sand_column and snowball in 2D and 3D, elastic_ball_2d
}

template <int dim>
void checkpoint_round_trip(const char* file) {
    const Scene scene = load_scene(file);
    Simulation<dim> uninterrupted(scene, 0.0, 0.5), first(scene, 0.0, 0.5), resumed(scene, 0.0, 0.5);
    test::resume_from_checkpoint(uninterrupted, first, resumed, 2, 4);
    expect_identical(resumed.particles(), uninterrupted.particles());
}

// The advection limit (MpmOptions::advection_cfl): the implicit steps of a disk thrown down at
// 8 m/s are cut to C dx / max_p |v_p| (the velocities at each step's start), frames still land on
// their times, each cut step says so (StepStats::advection_capped), and with the limit off the
// scene's dt is kept.
TEST(Simulation, AdvectionLimitCapsTheImplicitStepByTheFastestParticle) {
    nlohmann::json j = scene_to_json(load_scene(PNET_SCENES_DIR "/tiny/snowball_2d.json"));
    j["objects"][0]["velocity"] = {0.0, -8.0};
    const Scene scene = scene_from_json(j, "fast.json", PNET_SCENES_DIR "/tiny");
    IntegratorSettings settings = IntegratorSettings::from_scene(scene);
    settings.name = "lagged";
    settings.dt = 2e-3;
    settings.mpm.advection_cfl = 0.0;
    Simulation<2> off(scene, settings);
    const FrameStats whole = off.advance_frame();
    EXPECT_DOUBLE_EQ(whole.dt_max, 2e-3);
    EXPECT_DOUBLE_EQ(whole.dt_min, 2e-3);
    EXPECT_EQ(whole.advection_capped_steps, 0);
    for (const StepRecord& s : off.last_frame_steps()) EXPECT_FALSE(s.advection_capped);

    const double cfl = 0.25;
    settings.mpm.advection_cfl = cfl;
    Simulation<2> capped(scene, settings);
    const double dx = capped.system().dx;
    auto fastest = [&] {
        double v = 0.0;
        for (const Vec<2>& vp : capped.particles().v) v = std::max(v, vp.norm());
        return v;
    };
    double v_max = fastest(), t = 0.0;
    ASSERT_GT(2e-3 * v_max, cfl * dx) << "the test needs steps the limit cuts";
    long steps = 0;
    const FrameStats cut = capped.advance_frame([&] {
        const double dt = capped.time() - t;
        EXPECT_LE(dt, cfl * dx / v_max * (1.0 + 1e-12)) << "step " << steps;
        t = capped.time();
        v_max = fastest();
        ++steps;
    });
    EXPECT_EQ(cut.steps, steps);
    EXPECT_GT(cut.steps, whole.steps);
    EXPECT_DOUBLE_EQ(capped.time(), scene.frame_dt);
    // Every step but the frame's last (which may be clipped to the frame's end instead) was cut by
    // the limit below the scene's dt.
    long flagged = 0;
    for (const StepRecord& s : capped.last_frame_steps()) flagged += s.advection_capped;
    EXPECT_GE(flagged, cut.steps - 1);
    EXPECT_EQ(cut.advection_capped_steps, flagged);
}

// The limit is on by default (0.2 cells: docs/solver.md, "The advection limit"): the shipped scene
// taken as it is, thrown fast, is cut; an explicit run is not (its own CFL step governs it).
TEST(Simulation, AdvectionLimitIsOnByDefault) {
    EXPECT_EQ(MpmOptions{}.advection_cfl, kDefaultAdvectionCfl);
    EXPECT_EQ(kDefaultAdvectionCfl, 0.2);
    nlohmann::json j = scene_to_json(load_scene(PNET_SCENES_DIR "/tiny/snowball_2d.json"));
    j["objects"][0]["velocity"] = {0.0, -8.0};
    const Scene scene = scene_from_json(j, "fast.json", PNET_SCENES_DIR "/tiny");
    IntegratorSettings settings = IntegratorSettings::from_scene(scene);
    EXPECT_EQ(settings.mpm.advection_cfl, 0.2);
    settings.name = "lagged";
    settings.dt = 2e-3;
    Simulation<2> sim(scene, settings);
    const FrameStats frame = sim.advance_frame();
    EXPECT_GT(frame.advection_capped_steps, 0);
    EXPECT_LT(frame.dt_min, 2e-3);
}

TEST(Simulation, CheckpointThenResumeEqualsAnUninterruptedRun2d) {
    checkpoint_round_trip<2>(PNET_SCENES_DIR "/tiny/snowball_2d.json");
}

TEST(Simulation, CheckpointThenResumeEqualsAnUninterruptedRun3d) {
    checkpoint_round_trip<3>(PNET_SCENES_DIR "/tiny/sand_column_3d.json");
}

TEST(Simulation, CheckpointOfAnotherSceneOrATruncatedFileIsRefused) {
    test::TempDir dir;
    Simulation<2> sand(load_scene(PNET_SCENES_DIR "/tiny/sand_column_2d.json"), 0.0, 0.5);
    Simulation<2> snow(load_scene(PNET_SCENES_DIR "/tiny/snowball_2d.json"), 0.0, 0.5);
    sand.save_checkpoint(dir.file("sand.bin"));
    test::expect_error<std::invalid_argument>([&] { snow.load_checkpoint(dir.file("sand.bin")); },
                                              dir.file("sand.bin"), "different scene");
    const std::string bytes = test::read_file(dir.file("sand.bin"));
    test::write_file(dir.file("short.bin"), bytes.substr(0, bytes.size() / 2));
    test::expect_error<std::invalid_argument>([&] { sand.load_checkpoint(dir.file("short.bin")); },
                                              dir.file("short.bin"), "truncated");
    test::write_file(dir.file("junk.bin"), "not a checkpoint at all, just some text long enough");
    test::expect_error<std::invalid_argument>([&] { sand.load_checkpoint(dir.file("junk.bin")); },
                                              dir.file("junk.bin"), "not a PlasticityNet checkpoint");
    // A refused load leaves the simulation as it was.
    EXPECT_EQ(sand.frame(), 0);
    EXPECT_EQ(sand.particles().size(), Simulation<2>(load_scene(PNET_SCENES_DIR "/tiny/sand_column_2d.json"), 0.0, 0.5)
                                           .particles()
                                           .size());
}

}  // namespace
}  // namespace pnet
