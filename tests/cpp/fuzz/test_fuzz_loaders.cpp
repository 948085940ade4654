// Mutation fuzzing of the loaders (issue 21): scene files, PLY frames, simulation checkpoints and
// gmsh mesh files, each mutated from valid inputs (truncations, bit flips, byte overwrites,
// inserted and deleted runs; for JSON also type swaps, huge numbers, removed keys and deep
// nesting) with a fixed seed. Every case must end in a valid load or the loader's documented
// error, never a crash, a hang or another exception. The counts per outcome are printed (the
// README's "what we guarantee" table). PNET_FUZZ_CASES=N runs N cases per loader instead of the
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
#include "support/temp_dir.hpp"

namespace pnet {
namespace {

namespace fs = std::filesystem;

int fuzz_cases(int suite_default) {
    if (const char* env = std::getenv("PNET_FUZZ_CASES")) return std::max(1, std::atoi(env));
    return suite_default;
}

/// Deterministic mutations of a byte string or a JSON document.
class Mutator {
public:
    explicit Mutator(std::uint64_t seed) : rng_(seed) {}

    int below(int n) { return std::uniform_int_distribution<int>(0, n - 1)(rng_); }

    std::string bytes(std::string s) {
        const int rounds = 1 + below(3);
        for (int r = 0; r < rounds && !s.empty(); ++r) {
            const std::size_t at = std::size_t(below(int(s.size())));
            switch (below(6)) {
                case 0: s.resize(at); break;                                        // truncation
                case 1: s[at] = char(s[at] ^ (1 << below(8))); break;                 // bit flip
                case 2: s[at] = char("\x00\xff\x7f\x80\x01"[below(5)]); break;         // interesting byte
                case 3: s.insert(at, std::string(1 + below(16), char(below(256)))); break;  // inserted run
                case 4: s.erase(at, 1 + below(64)); break;                           // deleted run
                case 5: {                                                           // duplicated run
                    const std::string run = s.substr(at, 1 + below(64));
                    s.insert(std::size_t(below(int(s.size()))), run);
                    break;
                }
            }
        }
        return s;
    }

    std::string json(const nlohmann::json& doc) {
        if (below(4) == 0) return bytes(doc.dump(1));  // text-level damage
        nlohmann::json j = doc;
        const int rounds = 1 + below(3);
        for (int r = 0; r < rounds; ++r) mutate_node(pick(j));
        return j.dump(1);
    }

private:
    /// A random node of j (the root included), by a random walk down.
    nlohmann::json& pick(nlohmann::json& j) {
        nlohmann::json* node = &j;
        while ((node->is_object() || node->is_array()) && !node->empty() && below(3) != 0) {
            auto it = node->begin();
            std::advance(it, below(int(node->size())));
            node = &*it;
        }
        return *node;
    }

    void mutate_node(nlohmann::json& node) {
        static const double huge[] = {1e308, -1e308, 1e300, -1e-320, 4294967297.0, -1.0, 0.0, 1e9, 2147483648.0};
        switch (below(8)) {
            case 0: node = "a string"; break;
            case 1: node = nlohmann::json::array({1, 2, 3}); break;
            case 2: node = nullptr; break;
            case 3: node = nlohmann::json::object({{"unexpected", true}}); break;
            case 4: node = huge[below(9)]; break;
            case 5: node = below(2) == 0; break;
            case 6:
                if (node.is_object() && !node.empty()) {  // a key removed
                    auto it = node.begin();
                    std::advance(it, below(int(node.size())));
                    node.erase(it);
                }
                break;
            case 7: {  // deep nesting
                nlohmann::json deep = 1;
                for (int d = 0; d < 2000; ++d) deep = nlohmann::json::array({std::move(deep)});
                node = std::move(deep);
                break;
            }
        }
    }

    std::mt19937_64 rng_;
};

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
    Mutator mutate(2101);
    Tally t;
    const int cases = fuzz_cases(1500);
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
    Mutator mutate(2102);
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
    const int cases = fuzz_cases(1500);
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
    Mutator mutate(2103);
    Tally t;
    const int cases = fuzz_cases(1000);
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
    Mutator mutate(2104);
    Tally t;
    const int cases = fuzz_cases(300);
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
