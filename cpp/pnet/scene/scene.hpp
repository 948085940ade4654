#pragma once
// The JSON scene format (docs/scenes.md), loaded and validated. A scene is data:
// every error names the file, the JSON path and what was expected, e.g.
//   "scenes/x.json: objects[0].radius: expected a positive number, got -1".
//
//   {
//     "name": "snowball_2d",                      // optional, default: the file's stem ("unnamed" for "<dict>")
//     "description": "any text",                  // optional (source of the parameters, deviations)
//     "dim": 2,                                   // required, 2 or 3
//     "domain": {"min": [0, 0], "max": [1, 1]},   // m, optional, default [0, 1]^dim
//     "view": {"min": [0.2, 0], "max": [0.8, 0.4]},  // m, optional, default the domain: the region the
//                                                 // frames' pictures show (content, not empty space)
//     "dx": 0.00390625,                           // m, required; a whole number (>= 8) of cells per axis
//     "gravity": [0, -9.8],                       // m/s^2, optional, default (0, -9.8[, 0])
//     "frame_dt": 0.02, "frames": 50,             // s, optional
//     "particles_per_cell": 2,                    // per axis, optional
//     "boundary": {"walls": "slip", "sticky_floor_cells": 3},          // optional ("walls": "slip" | "none";
//                                                                     //  "floor_friction": mu, a Coulomb floor)
//     "integrator": {"name": "plasticitynet", "dt": 1e-3, "cfl": 0.5, ...},
//         // optional, default explicit with the CFL step; "name" is required when the block is given;
//         // dt = 0 or absent: the CFL step; other keys are kept in Scene::Integrator::options
//     "objects": [{                               // particles (MPM); required unless "meshes" are given
//       "shape": "disk",                          // "box" (min, max), "sphere" (center, radius; a disk in 2D),
//                                                 // "disk" (2D only), "cylinder" (3D only, axis along y:
//                                                 // center of the bottom face, radius, height)
//       "center": [0.5, 0.4], "radius": 0.1,      // m
//       "material": "snow",                       // a preset name or a material object (material_json.hpp)
//       "model": "../models/snow_2d.pt",          // optional, relative to the scene file's folder
//       "velocity": [0, -3],                      // m/s, optional, default 0
//       "hardening": -0.1                         // optional, default material.initial_hardening
//     }]
//   }
//
// FEM scenes (2D and 3D; docs/methods.md, docs/scenes.md) hold meshes instead of (and, with
// coupling, beside) particle objects; "dx" and "objects" are then optional:
//
//     "meshes": [{
//       "shape": "frame",                         // "box" (min, max), "frame" (min, max: the outer
//                                                 // rectangle; thickness: its walls), "disk" (center,
//                                                 // radius; "sphere" in 3D), each meshed by gmsh
//                                                 // with triangles (tetrahedra) of ~element_size m;
//                                                 // or "file" (file: a gmsh .msh, or in 3D a closed
//                                                 // surface .obj/.stl/.ply tetrahedralized with
//                                                 // element_size; relative to the scene file's folder).
//                                                 // A 3D frame is the 2D frame (min, max in x-y)
//                                                 // extruded from min.z to max.z
//       "min": [0.45, 0.0001], "max": [0.55, 0.1801], "thickness": 0.012, "element_size": 0.003,
//       "material": "metal",                      // required unless kinematic
//       "model": "../models/metal_2d.pt",         // optional, as for objects
//       "velocity": [0, 0],                       // m/s, optional
//       "hardening": 0.05,                        // optional
//       "kinematic": false,                       // true: a rigid body moved at "velocity" (the plate)
//       "clamp": {"min": [0.1, 0], "max": [0.101, 0.05]}  // optional: the nodes in this box (or in any box
//                                                 // of an array of them) are held at rest (a cantilever's
//                                                 // root); FEM scenes only
//     }],
//     "ground": {"height": 0},                    // optional: the half-space y < height is solid
//     "contact": {"dhat": 0.00025,                // m, optional, default 1e-3 x the meshes' bounding-box diagonal
//                 "kappa": 2.2e12,                // J/m^4, optional, default kappa_scale x IPC's lower bound
//                 "kappa_scale": 100,             //   for a 1e-2 s step (contact/adaptive_stiffness.hpp)
//                 "friction": 0.3,                // Coulomb coefficient, default 0 (frictionless)
//                 "friction_eps_v": 1e-4,         // m/s, slip velocity below which friction is smoothed
//                 "particle_dhat": 0.00195,       // MPM-FEM coupling (particle objects beside meshes, 2D):
//                 "particle_kappa": 3e9}          //   the particle / mesh barrier (m, default dx / 2, at most
//                                                 //   that; J/m^4, default IPC's lower bound for
//                                                 //   the average particle mass at dt 1e-3 s)
//
// The integrator "analytic" (the closed-form StVK-Hencky + von Mises energy) is
// for meshes only.
//
// Unknown keys are rejected ("unknown field") everywhere except in the integrator
// block, whose extra keys belong to the implicit solvers. Every object must lie
// at least 2 cells inside the domain: the quadratic B-spline stencil of a
// particle reaches the nodes one cell on either side of its cell. Objects may
// overlap (the sampler gives a shared point to the first).
#include <Eigen/Core>
#include <nlohmann/json.hpp>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "pnet/material/material.hpp"

namespace pnet {

/// A malformed scene: "<file>: <json path>: <problem>".
class SceneError : public std::invalid_argument {
public:
    using std::invalid_argument::invalid_argument;
};

/// load_scene() on a path that is not a readable file: "<file>: no such file".
class SceneFileNotFound : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

struct SceneObject {
    enum class Shape { Box, Sphere, Cylinder };

    Shape shape = Shape::Box;
    Eigen::VectorXd min, max;  // box corners, m (size dim; empty for the other shapes)
    Eigen::VectorXd center;    // sphere/disk centre; cylinder: centre of its bottom face (axis along y), m
    double radius = 0.0;       // sphere/cylinder, m
    double height = 0.0;       // cylinder, m
    MaterialDescription material;
    std::string model;                // energy model file, absolute and normalized; "" if none
    Eigen::VectorXd velocity;         // initial velocity, m/s (size dim)
    std::optional<double> hardening;  // initial hardening; unset: material.initial_hardening
    std::string json_path;            // "objects[k]", for errors found later (e.g. loading the model)

    /// The hardening state particles start with.
    double initial_hardening() const { return hardening.value_or(material.initial_hardening); }
};

/// A FEM body: a procedural shape meshed by gmsh or a mesh file.
struct SceneMesh {
    enum class Shape { Box, Frame, Disk, File };

    Shape shape = Shape::Box;
    Eigen::VectorXd min, max;   // box and frame: the outer rectangle (3D: box; the frame's hole runs along z), m
    double thickness = 0.0;     // frame: wall thickness, m
    Eigen::VectorXd center;     // disk (2D) / sphere (3D), m
    double radius = 0.0;        // disk / sphere, m
    double element_size = 0.0;  // procedural shapes and surface files: target edge length, m (0: a .msh file)
    std::string file;           // File: a .msh, or (3D) a closed surface .obj/.stl/.ply, absolute and normalized
    bool kinematic = false;     // rigid, moved at `velocity` (no material)
    struct Box {
        Eigen::VectorXd min, max;
    };
    std::vector<Box> clamps;    // the nodes in any of these boxes (closed) are held at rest
    MaterialDescription material;  // unused when kinematic
    std::string model;             // energy model file, absolute; "" if none
    Eigen::VectorXd velocity;      // initial (kinematic: prescribed) velocity, m/s
    std::optional<double> hardening;
    std::string json_path;         // "meshes[k]"

    double initial_hardening() const { return hardening.value_or(material.initial_hardening); }
};

/// "box", "sphere" (also "disk" in 2D files) or "cylinder".
std::string to_string(SceneObject::Shape shape);

/// Lower and upper corners of the object's axis-aligned bounding box, m.
std::pair<Eigen::VectorXd, Eigen::VectorXd> bounding_box(const SceneObject& object);

struct Scene {
    std::string file;  // path it was loaded from, or the name given to scene_from_json
    std::string name;
    std::string description;
    int dim = 2;                             // 2 or 3
    Eigen::VectorXd domain_min, domain_max;  // m
    Eigen::VectorXd view_min, view_max;      // m, the region pictures show (default: the domain)
    double dx = 0.0;                         // grid spacing, m
    Eigen::VectorXd gravity;                 // m/s^2
    double frame_dt = 0.02;                  // s
    int frames = 50;
    int particles_per_cell = 2;  // per axis: 2^dim particles per cell

    struct Boundary {
        bool slip_walls = true;      // "walls": "slip" | "none"
        int sticky_floor_cells = 3;  // the floor layer: nodes within this many cells of the floor (docs/methods.md)
        double floor_friction = -1;  // absent (< 0): the layer is sticky; >= 0: a Coulomb floor of this mu
    } boundary;
    // "transfer": {"flip_relaxation_time": s}: 0 (absent), APIC; > 0, AFLIP (docs/methods.md)
    double flip_relaxation_time = 0.0;

    struct Integrator {
        std::string name = "explicit";                      // an integrator of solver/integrators.hpp
        double dt = 0.0;                                    // s; 0: the CFL step
        double cfl = 0.5;                                   // dt = cfl dx / (max wave speed + max |v|) when dt = 0
        nlohmann::json options = nlohmann::json::object();  // the block's other keys, for the implicit solvers
    } integrator;

    std::vector<SceneObject> objects;  // particles (MPM)
    std::vector<SceneMesh> meshes;     // FEM bodies

    /// Contact between meshes and with the ground (FEM).
    struct Contact {
        std::optional<double> ground_height;  // m; unset: no ground
        double dhat = 0.0;                    // m; 0: 1e-3 x the meshes' bounding-box diagonal
        double kappa = 0.0;                   // J/m^4; 0: kappa_scale x IPC's lower bound at dt = 1e-2 s
        double kappa_scale = 100.0;
        double friction = 0.0;                // Coulomb coefficient
        double friction_eps_v = 1e-4;         // m/s
        // MPM-FEM coupling (particles beside meshes, 2D): the particle / mesh barrier.
        double particle_dhat = 0.0;           // m; 0: half the grid spacing (at most that)
        double particle_kappa = 0.0;          // J/m^4; 0: IPC's lower bound for the particles at dt 1e-3 s
    } contact;

    bool has_meshes() const { return !meshes.empty(); }
    bool has_particles() const { return !objects.empty(); }

    /// Grid cells along `axis`: (domain_max - domain_min) / dx, validated to be a whole number.
    int cells(int axis) const;
};

/// Reads and validates a scene file. Throws SceneFileNotFound if it cannot be
/// read, SceneError for invalid JSON (with the parser's line and column) or an
/// invalid scene. Model paths are resolved relative to the file's folder.
Scene load_scene(const std::string& path);

/// Validates a scene given as JSON; `file` prefixes the error messages (e.g.
/// "<dict>") and relative model paths are resolved against `base_dir` (the
/// working directory if empty).
Scene scene_from_json(const nlohmann::json& j, const std::string& file, const std::string& base_dir);

/// Every field written out (materials as objects, model paths absolute), so that
/// scene_from_json(scene_to_json(s), ...) gives back s.
nlohmann::json scene_to_json(const Scene& scene);

}  // namespace pnet
