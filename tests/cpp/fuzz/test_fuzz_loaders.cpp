// Mutation fuzzing of the loaders (issue 21): scene files, PLY frames, simulation checkpoints and
// gmsh mesh files, each mutated from valid inputs (truncations, bit flips, byte overwrites,
// inserted and deleted runs; for JSON also type swaps, huge numbers, removed keys and deep
// nesting) with a fixed seed. Every case must end in a valid load or the loader's documented
// error, never a crash, a hang or another exception. The counts per outcome are printed (the
// "what we guarantee" table of docs/development.md). PNET_FUZZ_CASES=N runs N cases per loader instead of the
// suite's default (a few thousand in all, seconds).
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <random>
#include <string>
#include <vector>

#include "pnet/fem/gmsh_mesher.hpp"
#include "pnet/fem/mesh.hpp"
#include "pnet/io/ply.hpp"
#include "pnet/scene/scene.hpp"
#include "pnet/sim/mpm_simulation.hpp"
#include "support/mutator.hpp"
#include "support/temp_dir.hpp"

namespace pnet {
namespace {

namespace fs = std::filesystem;

/// Outcomes of one loader over its cases.
struct Tally {
    int valid = 0, refused = 0;
    std::vector<std::string> messages;  // of the refusals
};

void report(const char* loader, int cases, const Tally& t) {
    std::printf("[fuzz] %-28s %5d cases: %5d valid loads, %5d clean errors, 0 crashes / hangs / other exceptions\n",
                loader, cases, t.valid, t.refused);
}

/// Runs load(); a documented error E counts as refused, anything else fails the test naming the case.
template <typename E, typename Fn>
void run_case(Tally& t, const std::string& what, Fn&& load) {
    try {
        load();
        ++t.valid;
    } catch (const E& e) {
        ++t.refused;
        t.messages.push_back(e.what());
    } catch (const std::exception& e) {
        ADD_FAILURE() << what << ": undocumented exception " << typeid(e).name() << ": " << e.what();
    } catch (...) {
        ADD_FAILURE() << what << ": a non-standard exception";
    }
}

/// The scene files shipped, with model paths made absolute so that a mutated copy loads anywhere.
std::vector<nlohmann::json> shipped_scenes() {
    std::vector<nlohmann::json> scenes;
    for (const char* sub : {"", "/tiny", "/stiff"})
        for (const auto& entry : fs::directory_iterator(std::string(PNET_SCENES_DIR) + sub)) {
            if (entry.path().extension() != ".json") continue;
            nlohmann::json j = nlohmann::json::parse(test::read_file(entry.path().string()));
            for (const char* list : {"objects", "meshes"})
                if (j.contains(list))
                    for (auto& o : j[list])
                        if (o.contains("model") && o["model"].is_string())
                            o["model"] = fs::absolute(entry.path().parent_path() / o["model"].get<std::string>()).string();
            scenes.push_back(std::move(j));
        }
    return scenes;
}

TEST(Fuzz, SceneLoader) {
    const std::vector<nlohmann::json> scenes = shipped_scenes();
    ASSERT_GE(scenes.size(), 15u);
    test::TempDir dir;
    test::Mutator mutate(2101);
    Tally t;
    const int cases = test::fuzz_cases(1500);
    for (int c = 0; c < cases; ++c) {
        const std::string path = dir.file("scene_" + std::to_string(c % 8) + ".json");
        test::write_file(path, mutate.json(scenes[std::size_t(c) % scenes.size()]));
        // SceneError (an std::invalid_argument) for every invalid file.
        run_case<SceneError>(t, "scene case " + std::to_string(c), [&] { load_scene(path); });
    }
    report("scene files (load_scene)", cases, t);
    EXPECT_GT(t.refused, 0);
}

TEST(Fuzz, PlyReaders) {
    test::TempDir dir;
    test::Mutator mutate(2102);
    std::mt19937 rng(7);
    std::uniform_real_distribution<double> u(0.0, 1.0);
    std::vector<std::string> files;
    for (int dim : {2, 3}) {
        PlyParticles p;
        p.dim = dim;
        for (int i = 0; i < 40; ++i) {
            for (int a = 0; a < dim; ++a) {
                p.position.push_back(u(rng));
                p.velocity.push_back(u(rng));
            }
            p.mass.push_back(1e-3);
            p.hardening.push_back(0.0);
        }
        const std::string path = dir.file("particles_" + std::to_string(dim) + ".ply");
        write_particles_ply(path, p);
        files.push_back(test::read_file(path));
    }
    PlyMesh m;
    m.position = {0, 0, 1, 0, 0, 1, 1, 1};
    m.velocity = std::vector<double>(8, 0.0);
    m.triangles = {0, 1, 2, 1, 3, 2};
    m.hardening = {0.0, 0.1};
    write_mesh_ply(dir.file("mesh.ply"), m);
    const std::string mesh_bytes = test::read_file(dir.file("mesh.ply"));

    Tally particles, meshes;
    const int cases = test::fuzz_cases(1500);
    for (int c = 0; c < cases; ++c) {
        const std::string path = dir.file("case.ply");
        test::write_file(path, mutate.bytes(files[std::size_t(c) % 2]));
        run_case<std::runtime_error>(particles, "particle PLY case " + std::to_string(c),
                                     [&] { read_particles_ply(path); });
        test::write_file(path, mutate.bytes(mesh_bytes));
        run_case<std::runtime_error>(meshes, "mesh PLY case " + std::to_string(c), [&] { read_mesh_ply(path); });
    }
    report("particle PLY frames", cases, particles);
    report("mesh PLY frames", cases, meshes);
}

TEST(Fuzz, CheckpointReader) {
    const Scene scene = load_scene(PNET_SCENES_DIR "/tiny/snowball_2d.json");
    test::TempDir dir;
    Simulation<2> sim(scene, 0.0, 0.5);
    sim.advance_frame();
    sim.save_checkpoint(dir.file("good.bin"));
    const std::string good = test::read_file(dir.file("good.bin"));
    Simulation<2> target(scene, 0.0, 0.5);
    test::Mutator mutate(2103);
    Tally t;
    const int cases = test::fuzz_cases(1000);
    int unchanged = 0;
    for (int c = 0; c < cases; ++c) {
        const std::string bytes = mutate.bytes(good);
        unchanged += bytes == good;
        test::write_file(dir.file("case.bin"), bytes);
        run_case<std::invalid_argument>(t, "checkpoint case " + std::to_string(c),
                                        [&] { target.load_checkpoint(dir.file("case.bin")); });
    }
    report("MPM checkpoints", cases, t);
    // The checksum refuses every changed file: only byte-identical mutations load.
    EXPECT_EQ(t.valid, unchanged);
}

TEST(Fuzz, GmshMeshReader) {
    const std::string good = test::read_file(PNET_TEST_DATA_DIR "/meshes/triangle.msh");
    test::TempDir dir;
    test::Mutator mutate(2104);
    Tally t;
    const int cases = test::fuzz_cases(300);
    for (int c = 0; c < cases; ++c) {
        const std::string path = dir.file("case.msh");
        test::write_file(path, mutate.bytes(good));
        run_case<MeshError>(t, "msh case " + std::to_string(c), [&] { read_mesh_file<2>(path); });
    }
    report("gmsh mesh files (2D)", cases, t);
    int crashed = 0;
    for (const std::string& m : t.messages) crashed += m.find("gmsh crashed reading it") != std::string::npos;
    std::printf("[fuzz] of which gmsh's own reader crashed on %d (contained in its child process)\n", crashed);
}

}  // namespace
}  // namespace pnet
