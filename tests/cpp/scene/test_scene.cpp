// Scene files (docs/scenes.md) load, sample the expected particles and round-trip;
// every malformed input is rejected with "<file>: <json path>: <problem>".
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "pnet/material/material_json.hpp"
#include "pnet/scene/sampler.hpp"
#include "pnet/scene/scene.hpp"
#include "support/dims.hpp"

#ifndef PNET_SCENES_DIR
#define PNET_SCENES_DIR "/work/main/scenes"
#endif

namespace pnet {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

constexpr double kPi = 3.14159265358979323846;

/// Expects a SceneError whose message contains every fragment.
template <typename Fn>
void expect_scene_error(Fn&& fn, const std::vector<std::string>& fragments) {
    try {
        fn();
        ADD_FAILURE() << "no exception thrown; expected one with '" << fragments.front() << "'";
    } catch (const SceneError& e) {
        const std::string what = e.what();
        for (const std::string& fragment : fragments)
            EXPECT_NE(what.find(fragment), std::string::npos) << "message '" << what << "' lacks '" << fragment << "'";
    }
}

/// Every *.json under scenes/ (tiny/ included), sorted so failures read the same on every machine.
std::vector<fs::path> scene_files() {
    std::vector<fs::path> files;
    for (const auto& entry : fs::recursive_directory_iterator(PNET_SCENES_DIR))
        if (entry.is_regular_file() && entry.path().extension() == ".json") files.push_back(entry.path());
    std::sort(files.begin(), files.end());
    return files;
}

bool is_tiny(const fs::path& file) {
    return file.parent_path().filename() == "tiny";
}

/// A stiff variant (scenes/stiff/, issue 19): a canonical scene with Young's modulus x100.
bool is_stiff(const fs::path& file) {
    const fs::path relative = fs::relative(file, PNET_SCENES_DIR);
    return !relative.empty() && *relative.begin() == "stiff";
}

constexpr double kStiffFactor = 100.0;

// ---------------------------------------------------------------------------------------------------------------
// Independent particle counts: closed-form counts of lattice coordinates per axis (or per line of the lattice),
// not the sampler's point-in-shape loop.

/// Number of k in [0, n) with lo <= origin + (k + 1/2) h <= hi.
long count_1d(double lo, double hi, double origin, double h, long n) {
    const long first = std::max(0L, static_cast<long>(std::ceil((lo - origin) / h - 0.5)));
    const long last = std::min(n - 1, static_cast<long>(std::floor((hi - origin) / h - 0.5)));
    return std::max(0L, last - first + 1);
}

/// Lattice points inside the object, ignoring other objects (those of the scene files do not overlap).
long expected_count(const Scene& scene, const SceneObject& object) {
    const double h = scene.dx / scene.particles_per_cell;
    std::vector<long> n(scene.dim);
    for (int a = 0; a < scene.dim; ++a) n[a] = std::lround((scene.domain_max[a] - scene.domain_min[a]) / h);
    auto coordinate = [&](int axis, long k) { return scene.domain_min[axis] + (k + 0.5) * h; };
    const double r2 = object.radius * object.radius;
    long count = 0;
    switch (object.shape) {
        case SceneObject::Shape::Box:
            count = 1;
            for (int a = 0; a < scene.dim; ++a)
                count *= count_1d(object.min[a], object.max[a], scene.domain_min[a], h, n[a]);
            break;
        case SceneObject::Shape::Sphere:
            // Lines along y: the chord at (x[, z]) has half-length sqrt(r^2 - |offset|^2).
            for (long i = 0; i < n[0]; ++i)
                for (long k = 0; k < (scene.dim == 3 ? n[2] : 1); ++k) {
                    double offset2 = std::pow(coordinate(0, i) - object.center[0], 2);
                    if (scene.dim == 3) offset2 += std::pow(coordinate(2, k) - object.center[2], 2);
                    if (offset2 > r2) continue;
                    const double half = std::sqrt(r2 - offset2);
                    count += count_1d(object.center[1] - half, object.center[1] + half, scene.domain_min[1], h, n[1]);
                }
            break;
        case SceneObject::Shape::Cylinder: {
            long disk = 0;
            for (long i = 0; i < n[0]; ++i)
                for (long k = 0; k < n[2]; ++k) {
                    const double rx = coordinate(0, i) - object.center[0], rz = coordinate(2, k) - object.center[2];
                    if (rx * rx + rz * rz <= r2) ++disk;
                }
            count = disk * count_1d(object.center[1], object.center[1] + object.height, scene.domain_min[1], h, n[1]);
            break;
        }
    }
    return count;
}

/// Exact volume (area in 2D) of the shape, m^d.
double shape_volume(int dim, const SceneObject& object) {
    switch (object.shape) {
        case SceneObject::Shape::Box:
            return (object.max - object.min).prod();
        case SceneObject::Shape::Sphere:
            return dim == 2 ? kPi * object.radius * object.radius : 4.0 / 3.0 * kPi * std::pow(object.radius, 3);
        case SceneObject::Shape::Cylinder:
            return kPi * object.radius * object.radius * object.height;
    }
    return 0.0;
}

/// Checks the particles of a loaded scene: counts, mass, and the initial state of every particle.
template <int dim>
void check_sampling(const fs::path& file, const Scene& scene) {
    SCOPED_TRACE(file.string());
    const Particles<dim> particles = sample_particles<dim>(scene);
    const double h = scene.dx / scene.particles_per_cell;
    long expected_total = 0;
    for (std::size_t k = 0; k < scene.objects.size(); ++k) {
        const SceneObject& object = scene.objects[k];
        const long expected = expected_count(scene, object);
        const long sampled = std::count(particles.object.begin(), particles.object.end(), static_cast<int>(k));
        EXPECT_EQ(sampled, expected) << object.json_path;
        expected_total += expected;

        double mass = 0.0;
        for (std::size_t p = 0; p < particles.size(); ++p)
            if (particles.object[p] == static_cast<int>(k)) mass += particles.mass[p];
        const double exact = object.material.density * shape_volume(dim, object);  // kg
        // The lattice approximates the shape to within about a lattice spacing at its surface: 2% at the canonical
        // resolution of docs/scenes.md (sand_column_2d is the worst, 1.8% heavy: the cells of its outermost particles
        // reach 0.4 lattice spacings beyond x = 0.45 and 0.55). The tiny variants resolve a 0.1 m shape with 6-13
        // points across, so 10% there (5-8% measured); their exact counts above are the real test.
        const double tolerance = is_tiny(file) ? 0.1 : 0.02;
        EXPECT_NEAR(mass, exact, tolerance * exact) << object.json_path << ": " << sampled << " particles";
    }
    EXPECT_EQ(static_cast<long>(particles.size()), expected_total);

    const double rest_volume = std::pow(h, dim);
    for (std::size_t p = 0; p < particles.size(); ++p) {
        const SceneObject& object = scene.objects.at(particles.object[p]);
        ASSERT_DOUBLE_EQ(particles.rest_volume[p], rest_volume);
        ASSERT_DOUBLE_EQ(particles.mass[p], object.material.density * rest_volume);
        ASSERT_EQ(particles.v[p], Vec<dim>(object.velocity));
        ASSERT_EQ(particles.C[p], Mat<dim>::Zero());
        ASSERT_EQ(particles.F_elastic[p], Mat<dim>::Identity());
        ASSERT_EQ(particles.hardening[p], object.initial_hardening());
        for (int a = 0; a < dim; ++a) {
            ASSERT_GE(particles.x[p][a], scene.domain_min[a] + 2 * scene.dx);
            ASSERT_LE(particles.x[p][a], scene.domain_max[a] - 2 * scene.dx);
        }
    }
}

// ---------------------------------------------------------------------------------------------------------------
// The scene files in scenes/ and scenes/tiny/.

TEST(SceneFiles, EveryFileLoadsAndSamplesTheExpectedParticles) {
    const std::vector<fs::path> files = scene_files();
    EXPECT_GE(files.size(), 8u) << "scene files under " << PNET_SCENES_DIR;
    for (const fs::path& file : files) {
        const Scene scene = load_scene(file.string());
        EXPECT_EQ(scene.file, file.string());
        // docs/scenes.md, or the page of docs/ that uses the scene.
        EXPECT_NE(scene.description.find("docs/"), std::string::npos) << file << ": cite the source";
        if (scene.dim == 2)
            check_sampling<2>(file, scene);
        else
            check_sampling<3>(file, scene);
    }
}

TEST(SceneFiles, SandColumn2dParticleCountByHand) {
    // dx = 1/256, 2 particles per cell and axis: lattice spacing h = 1/512, coordinates (k + 1/2) / 512.
    // x in [0.45, 0.55]: k + 1/2 in [230.4, 281.6], k = 230..281, 52 columns.
    // y in [3 dx, 0.3] = [6, 153.6] / 512: k + 1/2 in [6, 153.6], k = 6..153, 148 rows.
    const Scene scene = load_scene(PNET_SCENES_DIR "/sand_column_2d.json");
    const Particles<2> particles = sample_particles<2>(scene);
    EXPECT_EQ(particles.size(), 52u * 148u);
    // Total mass: 7696 * 2200 kg/m^3 * (1/512)^2 m^2; the exact column 0.1 x 0.28828125 m^2 is 1.8% lighter.
    double mass = 0.0;
    for (double m : particles.mass) mass += m;
    EXPECT_NEAR(mass, 7696 * 2200.0 / (512.0 * 512.0), 1e-9);
}

TEST(SceneFiles, MaterialsAreTheDesignPresetsAndModelsExist) {
    const std::vector<std::string> presets = material_preset_names();
    int checked = 0;
    for (const fs::path& file : scene_files()) {
        const Scene scene = load_scene(file.string());
        for (const SceneObject& object : scene.objects) {
            SCOPED_TRACE(file.string() + ": " + object.json_path);
            // §5 gives the parameters; the presets hold the same numbers (material.cpp), so a typo in a file shows.
            if (std::find(presets.begin(), presets.end(), object.material.name) != presets.end()) {
                MaterialDescription preset = material_preset(object.material.name);
                if (is_stiff(file)) preset.elastic.E *= kStiffFactor;
                EXPECT_EQ(material_to_json(object.material), material_to_json(preset));
                ++checked;
            }
            if (object.model.empty()) continue;
            const std::string model_name = object.material.name + "_" + std::to_string(scene.dim) + "d.pt";
            EXPECT_EQ(fs::path(object.model).filename().string(), model_name);
            EXPECT_TRUE(fs::path(object.model).is_absolute()) << object.model;
            EXPECT_TRUE(fs::exists(object.model)) << object.model;
        }
        for (const SceneMesh& mesh : scene.meshes) {
            if (mesh.kinematic) continue;
            // An elastic body without a model beside particles (the coupling's disk, docs/scenes.md) is described in
            // the scene itself; every other mesh uses a preset and its model.
            if (scene.has_particles() && mesh.model.empty() && mesh.material.plasticity == PlasticityModel::None)
                continue;
            SCOPED_TRACE(file.string() + ": " + mesh.json_path);
            ASSERT_NE(std::find(presets.begin(), presets.end(), mesh.material.name), presets.end());
            EXPECT_EQ(material_to_json(mesh.material), material_to_json(material_preset(mesh.material.name)));
            ++checked;
            const std::string model_name = mesh.material.name + "_" + std::to_string(scene.dim) + "d.pt";
            EXPECT_EQ(fs::path(mesh.model).filename().string(), model_name);
            EXPECT_TRUE(fs::exists(mesh.model)) << mesh.model;
        }
        if (scene.integrator.name != "explicit") {
            // docs/scenes.md: implicit MPM at 1e-3 s, implicit FEM at the paper's 1e-2 s.
            // (MPM-FEM coupling: the particles' 1e-3 s.)
            EXPECT_EQ(scene.integrator.dt, scene.has_meshes() && !scene.has_particles() ? 1e-2 : 1e-3) << file;
        }
    }
    EXPECT_GE(checked, 12);
}

TEST(SceneFiles, StiffVariantsDifferFromTheirScenesOnlyInYoungsModulus) {
    int pairs = 0;
    for (const fs::path& file : scene_files()) {
        if (!is_stiff(file)) continue;
        SCOPED_TRACE(file.string());
        // scenes/stiff/x.json beside scenes/x.json, scenes/stiff/tiny/x.json beside scenes/tiny/x.json.
        const fs::path canonical = fs::path(PNET_SCENES_DIR) / fs::relative(file, fs::path(PNET_SCENES_DIR) / "stiff");
        ASSERT_TRUE(fs::exists(canonical)) << canonical;
        const Scene stiff = load_scene(file.string()), soft = load_scene(canonical.string());
        ASSERT_EQ(stiff.objects.size(), soft.objects.size());
        ASSERT_FALSE(stiff.objects.empty());
        json a = scene_to_json(stiff), b = scene_to_json(soft);
        for (std::size_t k = 0; k < stiff.objects.size(); ++k) {
            EXPECT_DOUBLE_EQ(stiff.objects[k].material.elastic.E, kStiffFactor * soft.objects[k].material.elastic.E);
            a["objects"][k]["material"]["elasticity"]["E"] = b["objects"][k]["material"]["elasticity"]["E"];
        }
        for (json* j : {&a, &b}) {
            j->erase("name");
            j->erase("description");
        }
        EXPECT_EQ(a, b);
        ++pairs;
    }
    EXPECT_GE(pairs, 4);  // sand_column_2d and snowball_2d, full and tiny
}

TEST(SceneFiles, TinyVariantsMatchTheirFullScenes) {
    int pairs = 0;
    for (const fs::path& file : scene_files()) {
        // Every scene runs in the test suite at tiny size (docs/architecture.md, testing), so each one needs a
        // tiny variant.
        if (!is_tiny(file)) {
            EXPECT_TRUE(fs::exists(file.parent_path() / "tiny" / file.filename())) << file << " has no tiny variant";
            continue;
        }
        const fs::path full_file = file.parent_path().parent_path() / file.filename();
        ASSERT_TRUE(fs::exists(full_file)) << file << " has no full-size scene " << full_file;
        SCOPED_TRACE(file.string());
        const Scene tiny = load_scene(file.string()), full = load_scene(full_file.string());
        EXPECT_EQ(tiny.dim, full.dim);
        EXPECT_EQ(tiny.frames, 2);
        if (full.has_meshes()) {
            // The same bodies, contact and material with coarser triangles (a few hundred elements).
            EXPECT_EQ(scene_to_json(tiny)["contact"], scene_to_json(full)["contact"]);
            EXPECT_EQ(scene_to_json(tiny)["ground"], scene_to_json(full)["ground"]);
            EXPECT_EQ(tiny.integrator.options, full.integrator.options);
            ASSERT_EQ(tiny.meshes.size(), full.meshes.size());
            for (std::size_t k = 0; k < tiny.meshes.size(); ++k) {
                const SceneMesh &a = tiny.meshes[k], &b = full.meshes[k];
                EXPECT_EQ(a.shape, b.shape);
                EXPECT_EQ(a.min, b.min);
                EXPECT_EQ(a.max, b.max);
                EXPECT_EQ(a.kinematic, b.kinematic);
                EXPECT_EQ(a.velocity, b.velocity);
                EXPECT_EQ(a.model, b.model);
                EXPECT_EQ(material_to_json(a.material), material_to_json(b.material));
                EXPECT_GE(a.element_size, b.element_size);
            }
            if (!full.has_particles()) {  // particles beside the meshes (MPM-FEM coupling): checked below too
                ++pairs;
                continue;
            }
        }
        EXPECT_GT(tiny.dx, full.dx);
        EXPECT_EQ(tiny.integrator.name, full.integrator.name);
        EXPECT_EQ(tiny.integrator.dt, full.integrator.dt);
        EXPECT_EQ(tiny.gravity, full.gravity);
        ASSERT_EQ(tiny.objects.size(), full.objects.size());
        for (std::size_t k = 0; k < tiny.objects.size(); ++k) {
            EXPECT_EQ(tiny.objects[k].shape, full.objects[k].shape);
            EXPECT_EQ(material_to_json(tiny.objects[k].material), material_to_json(full.objects[k].material));
            EXPECT_EQ(tiny.objects[k].velocity, full.objects[k].velocity);
            EXPECT_EQ(tiny.objects[k].model, full.objects[k].model);
        }
        // A few hundred particles, so that a test runs a few steps in well under a second.
        const std::size_t n = tiny.dim == 2 ? sample_particles<2>(tiny).size() : sample_particles<3>(tiny).size();
        EXPECT_GT(n, 20u);
        EXPECT_LT(n, 2000u);
        ++pairs;
    }
    EXPECT_GE(pairs, 6);
}

TEST(SceneFiles, ModelPathsResolveAgainstTheSceneFolder) {
    const Scene scene = load_scene(PNET_SCENES_DIR "/snowball_2d.json");
    const fs::path expected =
        fs::absolute(fs::path(PNET_SCENES_DIR) / ".." / "models" / "snow_2d.pt").lexically_normal();
    EXPECT_EQ(scene.objects.at(0).model, expected.string());
    EXPECT_EQ(scene.objects.at(0).json_path, "objects[0]");
}

// ---------------------------------------------------------------------------------------------------------------
// Round trip.

void expect_round_trip(const Scene& scene) {
    const json j = scene_to_json(scene);
    // Through text as well: numbers must survive printing (nlohmann writes the shortest exact form).
    const Scene back = scene_from_json(json::parse(j.dump()), scene.file, "/somewhere/else");
    EXPECT_EQ(scene_to_json(back), j);
    EXPECT_EQ(back.name, scene.name);
    EXPECT_EQ(back.dim, scene.dim);
    EXPECT_EQ(back.dx, scene.dx);
    EXPECT_EQ(back.domain_min, scene.domain_min);
    EXPECT_EQ(back.domain_max, scene.domain_max);
    EXPECT_EQ(back.integrator.options, scene.integrator.options);
    ASSERT_EQ(back.objects.size(), scene.objects.size());
    for (std::size_t k = 0; k < scene.objects.size(); ++k) {
        EXPECT_EQ(back.objects[k].model, scene.objects[k].model);
        EXPECT_EQ(back.objects[k].hardening, scene.objects[k].hardening);
        EXPECT_EQ(back.objects[k].velocity, scene.objects[k].velocity);
    }
}

TEST(SceneJson, EveryFileRoundTrips) {
    for (const fs::path& file : scene_files()) {
        SCOPED_TRACE(file.string());
        expect_round_trip(load_scene(file.string()));
    }
}

/// A valid 2D scene using the optional fields: a disk with a preset material, a box with a material object.
json example_2d() {
    return json::parse(R"({
        "name": "example",
        "description": "test scene",
        "dim": 2,
        "domain": {"min": [0, 0], "max": [2, 1]},
        "dx": 0.015625,
        "gravity": [0, -9.8],
        "frame_dt": 0.01,
        "frames": 3,
        "particles_per_cell": 2,
        "boundary": {"walls": "slip", "sticky_floor_cells": 3},
        "integrator": {"name": "plasticitynet", "dt": 1e-3, "cfl": 0.4, "newton_tol": 1e-6},
        "objects": [
            {"shape": "disk", "center": [0.5, 0.5], "radius": 0.1, "material": "snow", "velocity": [1, 0],
             "hardening": -0.2, "model": "models/snow_2d.pt"},
            {"shape": "box", "min": [1.2, 0.1], "max": [1.4, 0.3],
             "material": {"name": "sand", "density": 2200, "elasticity": {"model": "stvk_hencky", "E": 3.537e5,
                          "nu": 0.3}, "plasticity": {"model": "drucker_prager", "friction_angle_deg": 30}}}
        ]
    })");
}

/// A valid FEM scene: a frame on the ground under a kinematic plate.
json example_fem() {
    return json::parse(R"({
        "dim": 2,
        "integrator": {"name": "analytic", "dt": 1e-2},
        "meshes": [
            {"shape": "frame", "min": [0.45, 0.0003], "max": [0.55, 0.1803], "thickness": 0.012,
             "element_size": 0.008, "material": "metal", "hardening": 0.06},
            {"shape": "box", "min": [0.42, 0.1813], "max": [0.58, 0.1913], "element_size": 0.01,
             "kinematic": true, "velocity": [0, -0.05]}
        ],
        "ground": {"height": 0},
        "contact": {"friction": 0.3, "kappa_scale": 10}
    })");
}

/// A valid 3D scene: a cylinder and a sphere.
json example_3d() {
    return json::parse(R"({
        "dim": 3,
        "dx": 0.0625,
        "objects": [
            {"shape": "cylinder", "center": [0.5, 0.2, 0.5], "radius": 0.1, "height": 0.3, "material": "sand"},
            {"shape": "sphere", "center": [0.5, 0.7, 0.5], "radius": 0.1, "material": "metal"}
        ]
    })");
}

TEST(SceneJson, OptionalFieldsAndDefaults) {
    const Scene scene = scene_from_json(example_2d(), "<dict>", "/base");
    EXPECT_EQ(scene.name, "example");
    EXPECT_EQ(scene.cells(0), 128);
    EXPECT_EQ(scene.cells(1), 64);
    EXPECT_EQ(scene.integrator.cfl, 0.4);
    EXPECT_EQ(scene.integrator.options, json({{"newton_tol", 1e-6}}));
    EXPECT_EQ(scene.objects[0].model, "/base/models/snow_2d.pt");
    EXPECT_EQ(scene.objects[0].initial_hardening(), -0.2);
    EXPECT_EQ(scene.objects[1].initial_hardening(), 0.0);
    EXPECT_EQ(scene.objects[1].model, "");
    EXPECT_EQ(scene.objects[1].json_path, "objects[1]");
    expect_round_trip(scene);

    const Scene defaults = scene_from_json(example_3d(), "<dict>", "");
    EXPECT_EQ(defaults.name, "unnamed");
    EXPECT_EQ(defaults.domain_min, Eigen::Vector3d::Zero());
    EXPECT_EQ(defaults.domain_max, Eigen::Vector3d::Ones());
    EXPECT_EQ(defaults.gravity, Eigen::Vector3d(0, -9.8, 0));
    EXPECT_EQ(defaults.frame_dt, 0.02);
    EXPECT_EQ(defaults.frames, 50);
    EXPECT_EQ(defaults.particles_per_cell, 2);
    EXPECT_TRUE(defaults.boundary.slip_walls);
    EXPECT_EQ(defaults.boundary.sticky_floor_cells, 3);
    EXPECT_EQ(defaults.integrator.name, "explicit");
    EXPECT_EQ(defaults.integrator.dt, 0.0);
    EXPECT_EQ(defaults.objects[1].velocity, Eigen::Vector3d::Zero());
    EXPECT_EQ(defaults.objects[1].initial_hardening(), material_preset("metal").initial_hardening);
    expect_round_trip(defaults);

    json none = example_3d();
    none["boundary"] = {{"walls", "none"}, {"sticky_floor_cells", 0}};
    const Scene no_walls = scene_from_json(none, "<dict>", "");
    EXPECT_FALSE(no_walls.boundary.slip_walls);
    EXPECT_EQ(no_walls.boundary.sticky_floor_cells, 0);
    EXPECT_LT(no_walls.boundary.floor_friction, 0.0) << "sticky unless floor_friction is given";
    expect_round_trip(no_walls);

    json coulomb = example_3d();
    coulomb["boundary"] = {{"sticky_floor_cells", 2}, {"floor_friction", 0.4}};
    const Scene on_coulomb = scene_from_json(coulomb, "<dict>", "");
    EXPECT_EQ(on_coulomb.boundary.floor_friction, 0.4);
    EXPECT_EQ(on_coulomb.boundary.sticky_floor_cells, 2);
    EXPECT_EQ(on_coulomb.flip_relaxation_time, 0.0) << "APIC unless transfer is given";
    expect_round_trip(on_coulomb);

    json aflip = example_3d();
    aflip["transfer"] = {{"flip_relaxation_time", 0.01}};
    const Scene with_aflip = scene_from_json(aflip, "<dict>", "");
    EXPECT_EQ(with_aflip.flip_relaxation_time, 0.01);
    expect_round_trip(with_aflip);
}

// ---------------------------------------------------------------------------------------------------------------
// Malformed scenes: one case per rule, each checking the file, the JSON path and the problem.

struct MalformedCase {
    std::string name;
    int dim;                          // 2: example_2d() (objects[0] disk, objects[1] box); 3: example_3d()
    std::function<void(json&)> edit;  // turns the valid example into the malformed one
    std::vector<std::string> fragments;
};

std::ostream& operator<<(std::ostream& out, const MalformedCase& c) {
    return out << c.name;
}

class MalformedScene : public ::testing::TestWithParam<MalformedCase> {};

TEST_P(MalformedScene, IsRejectedNamingFilePathAndProblem) {
    const MalformedCase& c = GetParam();
    json j = c.dim == 2 ? example_2d() : example_3d();
    c.edit(j);
    expect_scene_error([&] { scene_from_json(j, "scenes/x.json", "/base"); }, c.fragments);
}

// One case per line, as a table.
// clang-format off
const std::vector<MalformedCase> kMalformedCases = {
    // Required keys.
    {"MissingDim", 2, [](json& j) { j.erase("dim"); }, {"scenes/x.json: dim: missing (expected 2 or 3)"}},
    {"MissingDx", 2, [](json& j) { j.erase("dx"); }, {"scenes/x.json: dx: missing (expected a positive number"}},
    {"MissingObjects", 2, [](json& j) { j.erase("objects"); },
     {"scenes/x.json: objects: missing (expected a non-empty array of objects (or meshes))"}},
    {"MissingShape", 2, [](json& j) { j["objects"][0].erase("shape"); },
     {"scenes/x.json: objects[0].shape: missing (expected box, sphere, disk or cylinder)"}},
    {"MissingMaterial", 2, [](json& j) { j["objects"][1].erase("material"); },
     {"scenes/x.json: objects[1].material: missing"}},
    {"MissingRadius", 3, [](json& j) { j["objects"][0].erase("radius"); },
     {"scenes/x.json: objects[0].radius: missing (expected a positive number)"}},
    {"MissingIntegratorName", 2, [](json& j) { j["integrator"].erase("name"); },
     {"scenes/x.json: integrator.name: missing (expected explicit, plasticitynet, return_map, lagged or analytic)"}},
    // Wrong types.
    {"TopLevelNotObject", 2, [](json& j) { j = json::array(); }, {"scenes/x.json: (top level): expected an object"}},
    {"DxString", 2, [](json& j) { j["dx"] = "fine"; }, {"scenes/x.json: dx: expected a positive number, got \"fine\""}},
    {"DimString", 2, [](json& j) { j["dim"] = "2"; }, {"scenes/x.json: dim: expected 2 or 3, got \"2\""}},
    {"NameNumber", 2, [](json& j) { j["name"] = 7; }, {"scenes/x.json: name: expected a string, got 7"}},
    {"DescriptionNumber", 2, [](json& j) { j["description"] = 3; },
     {"scenes/x.json: description: expected a string, got 3"}},
    {"ObjectsNotArray", 2, [](json& j) { j["objects"] = json::object(); },
     {"scenes/x.json: objects: expected a non-empty array of objects, got {}"}},
    {"ObjectNotObject", 2, [](json& j) { j["objects"][1] = 3; },
     {"scenes/x.json: objects[1]: expected an object, got 3"}},
    {"VelocityElementString", 2, [](json& j) { j["objects"][0]["velocity"][1] = "down"; },
     {"scenes/x.json: objects[0].velocity[1]: expected a number, got \"down\""}},
    {"ModelNumber", 2, [](json& j) { j["objects"][0]["model"] = 5; },
     {"scenes/x.json: objects[0].model: expected a string, got 5"}},
    {"ModelEmpty", 2, [](json& j) { j["objects"][0]["model"] = ""; },
     {"scenes/x.json: objects[0].model: expected a file path"}},
    {"HardeningString", 2, [](json& j) { j["objects"][0]["hardening"] = "soft"; },
     {"scenes/x.json: objects[0].hardening: expected a number, got \"soft\""}},
    {"BoundaryNotObject", 2, [](json& j) { j["boundary"] = "slip"; },
     {"scenes/x.json: boundary: expected an object, got \"slip\""}},
    {"IntegratorNotObject", 2, [](json& j) { j["integrator"] = "explicit"; },
     {"scenes/x.json: integrator: expected an object, got \"explicit\""}},
    // Unknown keys.
    {"UnknownTopLevelField", 2, [](json& j) { j["dxx"] = 0.01; }, {"scenes/x.json: dxx: unknown field"}},
    {"UnknownObjectField", 2, [](json& j) { j["objects"][1]["colour"] = "red"; },
     {"scenes/x.json: objects[1].colour: unknown field",
      "(a box takes shape, min, max, material, model, velocity, hardening)"}},
    {"RadiusOnBox", 2, [](json& j) { j["objects"][1]["radius"] = 0.1; },
     {"scenes/x.json: objects[1].radius: unknown field (a box takes"}},
    {"HeightOnSphere", 3, [](json& j) { j["objects"][1]["height"] = 0.1; },
     {"scenes/x.json: objects[1].height: unknown field (a sphere takes shape, center, radius,"}},
    {"UnknownDomainField", 2, [](json& j) { j["domain"]["size"] = 1; }, {"scenes/x.json: domain.size: unknown field"}},
    {"UnknownBoundaryField", 2, [](json& j) { j["boundary"]["floor"] = "sticky"; },
     {"scenes/x.json: boundary.floor: unknown field"}},
    {"UnknownMaterialField", 2, [](json& j) { j["objects"][1]["material"]["colour"] = "beige"; },
     {"scenes/x.json: objects[1].material.colour: unknown field"}},
    // Values.
    {"DimFour", 2, [](json& j) { j["dim"] = 4; }, {"scenes/x.json: dim: expected 2 or 3, got 4"}},
    {"GravitySize", 2, [](json& j) { j["gravity"] = {0, -9.8, 0}; },
     {"scenes/x.json: gravity: expected an array of 2 numbers (dim = 2), got [0,-9.8,0]"}},
    {"BoxMinSize", 2, [](json& j) { j["objects"][1]["min"] = {1.2, 0.1, 0.0}; },
     {"scenes/x.json: objects[1].min: expected an array of 2 numbers"}},
    {"CenterSize3d", 3, [](json& j) { j["objects"][1]["center"] = {0.5, 0.7}; },
     {"scenes/x.json: objects[1].center: expected an array of 3 numbers (dim = 3), got [0.5,0.7]"}},
    {"DomainMinSize", 2, [](json& j) { j["domain"]["min"] = {0}; },
     {"scenes/x.json: domain.min: expected an array of 2 numbers"}},
    {"DomainEmpty", 2, [](json& j) { j["domain"]["max"] = {2, -1}; },
     {"scenes/x.json: domain.max[1]: must exceed domain.min[1] = 0, got -1"}},
    {"NegativeDx", 2, [](json& j) { j["dx"] = -0.01; }, {"scenes/x.json: dx: expected a positive number, got -0.01"}},
    {"ZeroDx", 2, [](json& j) { j["dx"] = 0; }, {"scenes/x.json: dx: expected a positive number, got 0"}},
    {"TooFewCells", 3, [](json& j) { j["dx"] = 0.25; },
     {"scenes/x.json: dx: the domain must hold at least 8 cells per axis, got 4 along x"}},
    {"DomainNotWholeCells", 2, [](json& j) { j["dx"] = 0.03; },
     {"scenes/x.json: dx: the domain extent along x (2 m) is not a whole number of cells of dx = 0.03 m"}},
    {"ZeroFrames", 2, [](json& j) { j["frames"] = 0; }, {"scenes/x.json: frames: expected an integer >= 1, got 0"}},
    {"FractionalFrames", 2, [](json& j) { j["frames"] = 2.5; },
     {"scenes/x.json: frames: expected an integer >= 1, got 2.5"}},
    {"ZeroFrameDt", 2, [](json& j) { j["frame_dt"] = 0; },
     {"scenes/x.json: frame_dt: expected a positive number, got 0"}},
    {"NegativeFrameDt", 2, [](json& j) { j["frame_dt"] = -0.02; },
     {"scenes/x.json: frame_dt: expected a positive number, got -0.02"}},
    {"ZeroParticlesPerCell", 2, [](json& j) { j["particles_per_cell"] = 0; },
     {"scenes/x.json: particles_per_cell: expected an integer >= 1, got 0"}},
    {"UnknownWalls", 2, [](json& j) { j["boundary"]["walls"] = "sticky"; },
     {"scenes/x.json: boundary.walls: expected \"slip\" or \"none\", got \"sticky\""}},
    {"NegativeStickyFloor", 2, [](json& j) { j["boundary"]["sticky_floor_cells"] = -1; },
     {"scenes/x.json: boundary.sticky_floor_cells: expected an integer >= 0, got -1"}},
    {"StickyFloorTooHigh", 2, [](json& j) { j["boundary"]["sticky_floor_cells"] = 64; },
     {"scenes/x.json: boundary.sticky_floor_cells: must be less than the 64 cells along y, got 64"}},
    {"NegativeFloorFriction", 2, [](json& j) { j["boundary"]["floor_friction"] = -0.1; },
     {"scenes/x.json: boundary.floor_friction: expected a number >= 0, got -0.1"}},
    {"FloorFrictionWithoutAFloor", 2,
     [](json& j) { j["boundary"] = {{"sticky_floor_cells", 0}, {"floor_friction", 0.3}}; },
     {"scenes/x.json: boundary.floor_friction: needs a floor layer (boundary.sticky_floor_cells > 0)"}},
    {"NegativeFlipRelaxationTime", 2, [](json& j) { j["transfer"] = {{"flip_relaxation_time", -1}}; },
     {"scenes/x.json: transfer.flip_relaxation_time: expected a number >= 0, got -1"}},
    {"UnknownTransferKey", 2, [](json& j) { j["transfer"] = {{"flip", 0.95}}; },
     {"scenes/x.json: transfer", "flip"}},
    {"UnknownIntegrator", 2, [](json& j) { j["integrator"]["name"] = "implicit_euler"; },
     {"scenes/x.json: integrator.name: unknown integrator 'implicit_euler'",
      "(expected explicit, plasticitynet, return_map, lagged or analytic)"}},
    // Found by the fuzz harness: a dx far below the domain's size made a grid of 1e12 nodes (a hang).
    {"GridTooLarge", 2, [](json& j) { j["dx"] = 1.0 / 65536; },
     {"scenes/x.json: dx: the grid would have", "nodes, more than the 67108864 a run may allocate"}},
    {"TooManyParticlesPerCell", 2, [](json& j) { j["particles_per_cell"] = 100; },
     {"scenes/x.json: particles_per_cell: expected at most 16 per axis, got 100"}},
    {"NegativeDt", 2, [](json& j) { j["integrator"]["dt"] = -1e-3; },
     {"scenes/x.json: integrator.dt: expected a number >= 0, got -0.001"}},
    {"CflAboveOne", 2, [](json& j) { j["integrator"]["cfl"] = 2; },
     {"scenes/x.json: integrator.cfl: expected a number in (0, 1], got 2"}},
    // Shapes.
    {"UnknownShape", 2, [](json& j) { j["objects"][0]["shape"] = "cone"; },
     {"scenes/x.json: objects[0].shape: unknown shape 'cone' (expected box, sphere, disk or cylinder)"}},
    {"CylinderIn2d", 2, [](json& j) { j["objects"][0]["shape"] = "cylinder"; },
     {"scenes/x.json: objects[0].shape: 'cylinder' is 3D only"}},
    {"DiskIn3d", 3, [](json& j) { j["objects"][1]["shape"] = "disk"; },
     {"scenes/x.json: objects[1].shape: 'disk' is 2D only; in 3D use 'sphere'"}},
    {"NegativeRadius", 2, [](json& j) { j["objects"][0]["radius"] = -1; },
     {"scenes/x.json: objects[0].radius: expected a positive number, got -1"}},
    {"ZeroHeight", 3, [](json& j) { j["objects"][0]["height"] = 0; },
     {"scenes/x.json: objects[0].height: expected a positive number, got 0"}},
    {"BoxInsideOut", 2, [](json& j) { j["objects"][1]["max"][0] = 1.1; },
     {"scenes/x.json: objects[1].max[0]: must exceed min[0] = 1.2, got 1.1"}},
    // Materials.
    {"UnknownPreset", 2, [](json& j) { j["objects"][0]["material"] = "sandd"; },
     {"scenes/x.json: objects[0].material: unknown material preset 'sandd'",
      "(expected sand, snow, metal or metal_nh)"}},
    {"MaterialNumber", 2, [](json& j) { j["objects"][0]["material"] = 2200; },
     {"scenes/x.json: objects[0].material: expected a material object or a preset name", "got 2200"}},
    {"InvalidPoissonRatio", 2, [](json& j) { j["objects"][1]["material"]["elasticity"]["nu"] = 0.6; },
     {"scenes/x.json: objects[1].material.elasticity: ", "nu = 0.6 must be finite with -1 < nu < 0.5"}},
    {"MaterialFieldType", 2, [](json& j) { j["objects"][1]["material"]["density"] = "heavy"; },
     {"scenes/x.json: objects[1].material.density: expected a number, got string"}},
    {"InvalidHardeningForMaterial", 3, [](json& j) { j["objects"][1]["hardening"] = -0.5; },
     {"scenes/x.json: objects[1].hardening: material 'metal': initial_hardening = -0.5 must be >= 0"}},
    // The domain and its 2-cell margin.
    {"BoxOutsideDomain", 2, [](json& j) { j["objects"][1]["max"][0] = 2.5; },
     {"scenes/x.json: objects[1]: extends outside the domain [(0, 0), (2, 1)]",
      "along x it spans [1.2, 2.5], allowed [0.03125, 1.96875]"}},
    {"DiskWithinTwoCellsOfTheFloor", 2, [](json& j) { j["objects"][0]["center"][1] = 0.12; },
     {"scenes/x.json: objects[0]: extends outside the domain",
      "less its 2-cell margin (2 dx = 0.03125 m, for the quadratic B-spline stencil)",
      "along y it spans [0.02, 0.22], allowed [0.03125, 0.96875]"}},
    {"CylinderTooTall", 3, [](json& j) { j["objects"][0]["height"] = 0.7; },
     {"scenes/x.json: objects[0]: extends outside the domain [(0, 0, 0), (1, 1, 1)]",
      "along y it spans [0.2, 0.9], allowed [0.125, 0.875]"}},
    {"SphereOutsideAlongZ", 3, [](json& j) { j["objects"][1]["center"][2] = 0.8; },
     {"scenes/x.json: objects[1]: extends outside the domain", "along z it spans [0.7, 0.9]"}},
    // FEM meshes (edits of example_fem()).
    {"MeshUnknownShape", 2, [](json& j) { j = example_fem(); j["meshes"][0]["shape"] = "torus"; },
     {"scenes/x.json: meshes[0].shape: unknown mesh shape 'torus' (expected box, frame, disk or file)"}},
    {"MeshWithoutMaterial", 2, [](json& j) { j = example_fem(); j["meshes"][0].erase("material"); },
     {"scenes/x.json: meshes[0].material: missing (expected a material object or a preset name)"}},
    {"KinematicMeshWithMaterial", 2, [](json& j) { j = example_fem(); j["meshes"][1]["material"] = "metal"; },
     {"scenes/x.json: meshes[1].material: a kinematic mesh is rigid"}},
    {"KinematicNotBoolean", 2, [](json& j) { j = example_fem(); j["meshes"][1]["kinematic"] = 1; },
     {"scenes/x.json: meshes[1].kinematic: expected true or false, got 1"}},
    {"EveryMeshKinematic", 2, [](json& j) { j = example_fem(); j["meshes"].erase(0); },
     {"scenes/x.json: meshes: every mesh is kinematic"}},
    {"FrameWithoutHole", 2, [](json& j) { j = example_fem(); j["meshes"][0]["thickness"] = 0.05; },
     {"scenes/x.json: meshes[0].thickness: two walls of 0.05 m leave no hole in a frame 0.1 m wide"}},
    {"MeshMissingElementSize", 2, [](json& j) { j = example_fem(); j["meshes"][0].erase("element_size"); },
     {"scenes/x.json: meshes[0].element_size: missing (expected a positive number (m))"}},
    {"MeshFileMissing", 2, [](json& j) { j = example_fem(); j["meshes"][0] = {{"shape", "file"}, {"file", "nope.msh"},
                                                                         {"material", "metal"}}; },
     {"scenes/x.json: meshes[0].file: /base/nope.msh: no such file"}},
    {"TwoDimensionalMeshesIn3d", 3, [](json& j) { j = example_fem(); j["dim"] = 3; },
     {"scenes/x.json: meshes[0].min: expected an array of 3 numbers (dim = 3), got [0.45,0.0003]"}},
    {"DiskMeshIn3d", 3, [](json& j) { j = example_fem(); j["dim"] = 3; j["gravity"] = {0, -9.8, 0};
                                      j["meshes"][0] = {{"shape", "disk"}, {"center", {0.5, 0.5, 0.5}}, {"radius", 0.1},
                                                        {"element_size", 0.01}, {"material", "metal"}}; },
     {"scenes/x.json: meshes[0].shape: 'disk' is 2D only; in 3D use 'sphere'"}},
    {"SphereMeshIn2d", 2, [](json& j) { j = example_fem(); j["meshes"][0]["shape"] = "sphere"; },
     {"scenes/x.json: meshes[0].shape: 'sphere' is 3D only; in 2D use 'disk'"}},
    {"MshFileWithElementSize", 2, [](json& j) { j = example_fem(); j["meshes"][0] = {{"shape", "file"},
        {"file", std::string(PNET_TEST_DATA_DIR) + "/meshes/triangle.msh"}, {"element_size", 0.01}, {"material", "metal"}}; },
     {"scenes/x.json: meshes[0].element_size: a .msh file is used as it is meshed"}},
    {"NegativeFriction", 2, [](json& j) { j = example_fem(); j["contact"]["friction"] = -0.1; },
     {"scenes/x.json: contact.friction: expected a number >= 0, got -0.1"}},
    {"UnknownContactField", 2, [](json& j) { j = example_fem(); j["contact"]["stiffness"] = 1; },
     {"scenes/x.json: contact.stiffness: unknown field"}},
    {"GroundWithoutMeshes", 2, [](json& j) { j["ground"] = {{"height", 0}}; },
     {"scenes/x.json: ground: applies to FEM meshes; this scene has none"}},
    {"AnalyticForParticles", 2, [](json& j) { j["integrator"]["name"] = "analytic"; },
     {"scenes/x.json: integrator.name: 'analytic' is for FEM meshes; particle scenes use explicit, plasticitynet, "
      "return_map or lagged"}},
    {"ParticlesAndKinematicMesh", 2, [](json& j) { j["meshes"] = example_fem()["meshes"]; },
     {"scenes/x.json: meshes[1].kinematic: kinematic meshes are not supported beside particles (MPM-FEM coupling)"}},
    {"ClampOnAKinematicMesh", 2, [](json& j) { j = example_fem();
                                               j["meshes"][1]["clamp"] = {{"min", {0.4, 0.18}}, {"max", {0.5, 0.2}}}; },
     {"scenes/x.json: meshes[1].clamp: a kinematic mesh moves as a whole"}},
    {"ClampInsideOut", 2, [](json& j) { j = example_fem();
                                        j["meshes"][0]["clamp"] = {{"min", {0.4, 0.1}}, {"max", {0.5, 0.0}}}; },
     {"scenes/x.json: meshes[0].clamp.max[1]: must be at least min[1] = 0.1, got 0"}},
    {"ClampUnknownField", 2, [](json& j) { j = example_fem();
                                           j["meshes"][0]["clamp"] = json::array({{{"min", {0, 0}}, {"max", {1, 0.01}}},
                                                                                  {{"center", {0, 0}}}}); },
     {"scenes/x.json: meshes[0].clamp[1].center: unknown field"}},
    {"ClampEmptyArray", 2, [](json& j) { j = example_fem(); j["meshes"][0]["clamp"] = json::array(); },
     {"scenes/x.json: meshes[0].clamp: expected a box"}},
    {"ParticlesAndClampedMesh", 2, [](json& j) { j["meshes"] = {example_fem()["meshes"][0]};
                                                 j["meshes"][0]["clamp"] = {{"min", {0.4, 0}}, {"max", {0.6, 0.01}}}; },
     {"scenes/x.json: meshes[0].clamp: clamps are not supported beside particles (MPM-FEM coupling)"}},
    {"ParticleDhatAboveHalfACell", 2, [](json& j) { j["meshes"] = {example_fem()["meshes"][0]};
                                                    j["contact"] = {{"particle_dhat", 0.6 * j["dx"].get<double>()}}; },
     {"scenes/x.json: contact.particle_dhat: expected at most half the grid spacing"}},
    {"ParticleKappaWithoutParticles", 2, [](json& j) { j = example_fem(); j["contact"]["particle_kappa"] = 1e9; },
     {"scenes/x.json: contact.particle_kappa: applies to particles meeting meshes (MPM-FEM coupling)"}},
};
// clang-format on

INSTANTIATE_TEST_SUITE_P(Scene, MalformedScene, ::testing::ValuesIn(kMalformedCases),
                         [](const ::testing::TestParamInfo<MalformedCase>& info) { return info.param.name; });

TEST(Scene, FemSceneRoundTripsAndNeedsNoGrid) {
    const Scene scene = scene_from_json(example_fem(), "fem.json", "/base");
    EXPECT_FALSE(scene.has_particles());
    ASSERT_EQ(scene.meshes.size(), 2u);
    EXPECT_EQ(scene.dx, 0.0);
    EXPECT_EQ(scene.meshes[0].shape, SceneMesh::Shape::Frame);
    EXPECT_EQ(scene.meshes[0].initial_hardening(), 0.06);
    EXPECT_TRUE(scene.meshes[1].kinematic);
    EXPECT_EQ(*scene.contact.ground_height, 0.0);
    EXPECT_EQ(scene.contact.friction, 0.3);
    EXPECT_EQ(scene.contact.kappa_scale, 10.0);
    EXPECT_EQ(scene.contact.dhat, 0.0);  // the default: 1e-3 x the diagonal
    const json written = scene_to_json(scene);
    EXPECT_EQ(scene_to_json(scene_from_json(written, "again.json", "")), written);
}

// ---------------------------------------------------------------------------------------------------------------
// Reading files.

/// A fresh folder under the system temp directory, removed at the end of the test.
class SceneFileTest : public ::testing::Test {
protected:
    void SetUp() override {
        const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
        dir_ = fs::temp_directory_path() / ("pnet_test_scene_" + std::string(info->name()));
        fs::remove_all(dir_);
        fs::create_directories(dir_);
    }
    void TearDown() override { fs::remove_all(dir_); }

    std::string write(const std::string& name, const std::string& text) const {
        const fs::path path = dir_ / name;
        std::ofstream(path) << text;
        return path.string();
    }

    fs::path dir_;
};

TEST_F(SceneFileTest, MissingFileIsSceneFileNotFound) {
    const std::string path = (dir_ / "nope.json").string();
    try {
        load_scene(path);
        ADD_FAILURE() << "no exception thrown";
    } catch (const SceneFileNotFound& e) {
        EXPECT_EQ(std::string(e.what()), path + ": no such file");
    }
    EXPECT_THROW(load_scene(dir_.string()), SceneFileNotFound);  // a folder is not a scene file
}

TEST_F(SceneFileTest, InvalidJsonNamesLineAndColumn) {
    const std::string path = write("broken.json", "{\n    \"dim\": 2,\n    \"dx\": 0.01,,\n}\n");
    expect_scene_error([&] { load_scene(path); }, {path + ": invalid JSON: parse error at line 3, column"});
}

// A number too large for a double (found by Fuzz.SceneLoader once scenes/elastic_ball_2d.json joined its
// seeds: "0.0078125" mutated into "0.007e8125") is a scene error naming the file, not nlohmann's exception.
TEST_F(SceneFileTest, NumberOverflowIsAnInvalidJsonError) {
    const std::string path = write("overflow.json", "{\n    \"dim\": 2,\n    \"dx\": 0.007e8125\n}\n");
    expect_scene_error([&] { load_scene(path); }, {path + ": invalid JSON: number overflow parsing '0.007e8125'"});
}

TEST_F(SceneFileTest, ErrorsNameTheFileGiven) {
    json j = example_2d();
    j["objects"][0]["radius"] = -1;
    const std::string path = write("x.json", j.dump(4));
    expect_scene_error([&] { load_scene(path); }, {path + ": objects[0].radius: expected a positive number, got -1"});
}

TEST_F(SceneFileTest, ModelPathsAreRelativeToTheFile) {
    fs::create_directories(dir_ / "scenes");
    const std::string path = write("scenes/a.json", example_2d().dump());
    const Scene scene = load_scene(path);
    EXPECT_EQ(scene.name, "example");
    EXPECT_EQ(scene.objects[0].model, (dir_ / "scenes" / "models" / "snow_2d.pt").string());
    json unnamed = example_2d();
    unnamed.erase("name");
    EXPECT_EQ(load_scene(write("scenes/b.json", unnamed.dump())).name, "b");  // default: the file's stem
}

// ---------------------------------------------------------------------------------------------------------------
// The sampler, in 2D and 3D.

PNET_TYPED_TEST_SUITE_2D_3D(Sampler);

/// [0, 1]^dim, dx = 1/32 (lattice spacing 1/64), with the given objects.
json unit_scene(int dim, const std::vector<json>& objects) {
    return {{"dim", dim}, {"dx", 1.0 / 32}, {"objects", objects}};
}

json box(int dim, double lo, double hi, const json& material = "sand") {
    return {{"shape", "box"},
            {"min", std::vector<double>(dim, lo)},
            {"max", std::vector<double>(dim, hi)},
            {"material", material}};
}

json sphere(int dim, double center, double radius, const json& material = "snow") {
    return {
        {"shape", "sphere"}, {"center", std::vector<double>(dim, center)}, {"radius", radius}, {"material", material}};
}

TYPED_TEST(Sampler, BoxOnCellFacesGetsExactlyItsLatticePoints) {
    constexpr int dim = TypeParam::value;
    // [0.25, 0.5] = [16, 32] / 64: lattice k + 1/2 in [16, 32], k = 16..31, 16 points per axis.
    json j = unit_scene(dim, {box(dim, 0.25, 0.5)});
    j["objects"][0]["velocity"] = std::vector<double>(dim, 0.5);
    j["objects"][0]["hardening"] = 0.25;
    const Particles<dim> particles = sample_particles<dim>(scene_from_json(j, "<dict>", ""));
    ASSERT_EQ(particles.size(), static_cast<std::size_t>(std::pow(16, dim)));
    double mass = 0.0;
    for (double m : particles.mass) mass += m;
    EXPECT_NEAR(mass, 2200.0 * std::pow(0.25, dim), 1e-9);  // kg: the box is exactly covered by the lattice cells
    EXPECT_EQ(particles.x.front(), Vec<dim>::Constant(16.5 / 64));
    EXPECT_EQ(particles.x.back(), Vec<dim>::Constant(31.5 / 64));
    for (std::size_t p = 0; p < particles.size(); ++p) {
        EXPECT_EQ(particles.v[p], Vec<dim>::Constant(0.5));
        EXPECT_EQ(particles.hardening[p], 0.25);
        EXPECT_EQ(particles.object[p], 0);
    }
}

TYPED_TEST(Sampler, LatticeOrderHasXFastest) {
    constexpr int dim = TypeParam::value;
    const Particles<dim> particles =
        sample_particles<dim>(scene_from_json(unit_scene(dim, {sphere(dim, 0.5, 0.2)}), "<dict>", ""));
    ASSERT_GT(particles.size(), 100u);
    for (std::size_t p = 1; p < particles.size(); ++p) {
        // Compare (z, y, x) lexicographically: the last axis is the slowest.
        const Vec<dim> a = particles.x[p - 1].reverse(), b = particles.x[p].reverse();
        ASSERT_TRUE(std::lexicographical_compare(a.data(), a.data() + dim, b.data(), b.data() + dim)) << p;
    }
}

TYPED_TEST(Sampler, OverlapBelongsToTheFirstObject) {
    constexpr int dim = TypeParam::value;
    // A sphere about the box's upper corner: the box keeps its 16^dim points, the sphere gets the rest of its own.
    const std::vector<json> objects = {box(dim, 0.25, 0.5), sphere(dim, 0.5, 0.125)};
    const Particles<dim> both = sample_particles<dim>(scene_from_json(unit_scene(dim, objects), "<dict>", ""));
    const Particles<dim> alone =
        sample_particles<dim>(scene_from_json(unit_scene(dim, {sphere(dim, 0.5, 0.125)}), "<dict>", ""));
    // The corner's share of the sphere: its points with every coordinate <= 0.5 (2^-dim of them, by symmetry).
    std::size_t shared = 0;
    for (const Vec<dim>& x : alone.x) shared += (x.array() <= 0.5).all();
    EXPECT_EQ(shared * (1u << dim), alone.size());
    const std::size_t in_box = std::count(both.object.begin(), both.object.end(), 0);
    EXPECT_EQ(in_box, static_cast<std::size_t>(std::pow(16, dim)));
    EXPECT_EQ(both.size() - in_box, alone.size() - shared);
    for (std::size_t p = in_box; p < both.size(); ++p) {
        EXPECT_EQ(both.object[p], 1);
        EXPECT_FALSE((both.x[p].array() <= 0.5).all()) << "a box point went to the sphere";
        EXPECT_DOUBLE_EQ(both.mass[p], 400.0 * std::pow(1.0 / 64, dim));  // kg: snow density
        EXPECT_EQ(both.hardening[p], -0.1);                               // the snow preset's initial hardening
    }
}

TYPED_TEST(Sampler, ObjectWithoutParticlesIsNamed) {
    constexpr int dim = TypeParam::value;
    // A sphere about a lattice-cell corner, smaller than the distance to the nearest point (sqrt(dim) / 128 m).
    expect_scene_error(
        [&] {
            sample_particles<dim>(
                scene_from_json(unit_scene(dim, {box(dim, 0.25, 0.5), sphere(dim, 0.75, 0.005)}), "scenes/x.json", ""));
        },
        {"scenes/x.json: objects[1]: no particles: the sphere holds no lattice point (spacing dx / "
         "particles_per_cell = 0.015625 m)"});
    // A sphere inside an earlier box has no points of its own either.
    expect_scene_error(
        [&] {
            sample_particles<dim>(
                scene_from_json(unit_scene(dim, {box(dim, 0.25, 0.5), sphere(dim, 0.375, 0.05)}), "scenes/x.json", ""));
        },
        {"scenes/x.json: objects[1]: no particles", "not already in an earlier object"});
}

TYPED_TEST(Sampler, RejectsASceneOfTheOtherDimension) {
    constexpr int dim = TypeParam::value;
    constexpr int other = 5 - dim;
    const Scene scene = scene_from_json(unit_scene(other, {box(other, 0.25, 0.5)}), "scenes/x.json", "");
    try {
        sample_particles<dim>(scene);
        ADD_FAILURE() << "no exception thrown";
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("scenes/x.json: sample_particles<" + std::to_string(dim) +
                                             ">: the scene is " + std::to_string(other) + "D"),
                  std::string::npos)
            << e.what();
    }
}

TEST(Sampler3d, CylinderHasAxisAlongY) {
    // Radius 0.1 about x = z = 0.5, y in [0.2, 0.5]: every point within the radius of the axis and the y range,
    // and the y extent is the height, not the diameter.
    const Particles<3> particles = sample_particles<3>(scene_from_json(example_3d(), "<dict>", ""));
    double y_min = 1, y_max = 0;
    for (std::size_t p = 0; p < particles.size(); ++p) {
        if (particles.object[p] != 0) continue;
        const Vec<3>& x = particles.x[p];
        EXPECT_LE(std::hypot(x[0] - 0.5, x[2] - 0.5), 0.1);
        y_min = std::min(y_min, x[1]);
        y_max = std::max(y_max, x[1]);
    }
    EXPECT_NEAR(y_min, 0.2, 1.0 / 32);
    EXPECT_NEAR(y_max, 0.5, 1.0 / 32);
}

}  // namespace
}  // namespace pnet
