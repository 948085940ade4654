#include "pnet/scene/scene.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "pnet/material/material_json.hpp"
#include "pnet/scene/json_reader.hpp"
#include "pnet/solver/integrators.hpp"

namespace pnet {

namespace {

using nlohmann::json;
using namespace scene_json;
namespace fs = std::filesystem;

constexpr const char* kAxisNames[] = {"x", "y", "z"};
constexpr int kMinCells = 8;     // fewer cells than this cannot resolve an object 2 cells from every wall
constexpr int kMarginCells = 2;  // quadratic B-spline stencil: base node one below the cell, three nodes wide

/// An optional box {"min": [...], "max": [...]} at key `name` (either bound may be left out: it keeps
/// the value given); each bound finite, max > min on every axis.
void read_box(const Reader& r, const json& j, const std::string& name, int dim, Eigen::VectorXd& min,
              Eigen::VectorXd& max) {
    const json* box = Reader::find(j, name);
    if (!box) return;
    r.require_object(*box, name);
    r.reject_unknown_keys(*box, name, {"min", "max"});
    if (const json* v = Reader::find(*box, "min")) min = r.vector(*v, name + ".min", dim);
    if (const json* v = Reader::find(*box, "max")) max = r.vector(*v, name + ".max", dim);
    for (int a = 0; a < dim; ++a)
        if (!(max[a] > min[a]))
            r.fail(index_path(name + ".max", a), "must exceed " + name + ".min[" + std::to_string(a) + "] = " +
                                                     show(min[a]) + ", got " + show(max[a]));
}

void read_domain(const Reader& r, const json& j, Scene& scene) {
    scene.domain_min = Eigen::VectorXd::Zero(scene.dim);
    scene.domain_max = Eigen::VectorXd::Ones(scene.dim);
    read_box(r, j, "domain", scene.dim, scene.domain_min, scene.domain_max);
}

/// "view": the region pictures show (optional; default the domain).
void read_view(const Reader& r, const json& j, Scene& scene) {
    scene.view_min = scene.domain_min;
    scene.view_max = scene.domain_max;
    read_box(r, j, "view", scene.dim, scene.view_min, scene.view_max);
}

/// The grid has nodes at domain_min + i dx up to domain_max, so the extent must
/// be a whole number of cells; enough of them to leave room inside the margins.
void check_cells(const Reader& r, const Scene& scene) {
    // Grid nodes a run may allocate (about 2 GiB of grid in 3D): far above every scene here, and a
    // refusal instead of an allocation that takes the machine down.
    constexpr double kMaxGridNodes = 67108864.0;  // 2^26
    double nodes = 1.0;
    for (int a = 0; a < scene.dim; ++a) nodes *= std::floor((scene.domain_max[a] - scene.domain_min[a]) / scene.dx) + 1.0;
    if (!(nodes <= kMaxGridNodes))
        r.fail("dx", "the grid would have " + show(nodes) + " nodes, more than the 67108864 a run may allocate (dx = " +
                         show(scene.dx) + " m is too small for the domain)");
    for (int a = 0; a < scene.dim; ++a) {
        const double extent = scene.domain_max[a] - scene.domain_min[a];
        const double cells = extent / scene.dx;
        const double whole = std::round(cells);
        if (std::abs(cells - whole) > 1e-6 * std::max(1.0, whole))
            r.fail("dx", "the domain extent along " + std::string(kAxisNames[a]) + " (" + show(extent) +
                             " m) is not a whole number of cells of dx = " + show(scene.dx) + " m (" + show(cells) +
                             " cells)");
        if (whole < kMinCells)
            r.fail("dx", "the domain must hold at least " + std::to_string(kMinCells) + " cells per axis, got " +
                             show(whole) + " along " + kAxisNames[a] + " (extent " + show(extent) +
                             " m, dx = " + show(scene.dx) + " m)");
    }
}

void read_boundary(const Reader& r, const json& j, Scene& scene) {
    const json* boundary = Reader::find(j, "boundary");
    if (!boundary) return;
    r.require_object(*boundary, "boundary");
    r.reject_unknown_keys(*boundary, "boundary", {"walls", "sticky_floor_cells", "floor_friction"});
    if (const json* v = Reader::find(*boundary, "walls")) {
        const std::string walls = v->is_string() ? v->get<std::string>() : "";
        if (walls != "slip" && walls != "none")
            r.fail("boundary.walls", "expected \"slip\" or \"none\", got " + show(*v));
        scene.boundary.slip_walls = walls == "slip";
    }
    if (const json* v = Reader::find(*boundary, "sticky_floor_cells")) {
        const int cells = r.integer(*v, "boundary.sticky_floor_cells", 0);
        if (cells >= scene.cells(1))
            r.fail("boundary.sticky_floor_cells", "must be less than the " + std::to_string(scene.cells(1)) +
                                                      " cells along y, got " + std::to_string(cells));
        scene.boundary.sticky_floor_cells = cells;
    }
    if (const json* v = Reader::find(*boundary, "floor_friction")) {
        scene.boundary.floor_friction = r.non_negative(*v, "boundary.floor_friction");
        if (scene.boundary.sticky_floor_cells == 0)
            r.fail("boundary.floor_friction", "needs a floor layer (boundary.sticky_floor_cells > 0)");
    }
}

void read_integrator(const Reader& r, const json& j, Scene& scene) {
    const json* integrator = Reader::find(j, "integrator");
    if (!integrator) return;
    r.require_object(*integrator, "integrator");
    // A block without a name would silently mean "explicit", whose stable step is far below the implicit ones'.
    const json& name = r.require(*integrator, "name", "integrator", integrator_names());
    scene.integrator.name = r.text(name, "integrator.name");
    if (!is_integrator(scene.integrator.name))
        r.fail("integrator.name",
               "unknown integrator '" + scene.integrator.name + "' (expected " + integrator_names() + ")");
    scene.integrator.options = json::object();
    for (const auto& item : integrator->items()) {
        const std::string path = join("integrator", item.key());
        if (item.key() == "name") continue;
        if (item.key() == "dt") {
            scene.integrator.dt = r.non_negative(item.value(), path);
        } else if (item.key() == "cfl") {
            const double cfl = r.number(item.value(), path, "a number in (0, 1]");
            if (!(cfl > 0.0 && cfl <= 1.0)) r.fail(path, "expected a number in (0, 1], got " + show(item.value()));
            scene.integrator.cfl = cfl;
        } else {
            scene.integrator.options[item.key()] = item.value();
        }
    }
}

MaterialDescription read_material(const Reader& r, const json& v, const std::string& path) {
    if (v.is_string()) {
        try {
            return material_preset(v.get<std::string>());
        } catch (const std::invalid_argument& e) {
            r.fail(path, e.what());
        }
    }
    if (!v.is_object())
        r.fail(path, "expected a material object or a preset name (sand, snow, metal, metal_nh), got " + show(v));
    try {
        return material_from_json(v, path);
    } catch (const std::invalid_argument& e) {
        throw SceneError(r.file() + ": " + e.what());  // material_from_json already names the path
    }
}

std::string resolve_model_path(const std::string& model, const std::string& base_dir) {
    fs::path path(model);
    if (path.is_relative() && !base_dir.empty()) path = fs::path(base_dir) / path;
    // Absolute, so that scene_to_json() output reads the same from any folder.
    return fs::absolute(path).lexically_normal().string();
}

SceneObject read_object(const Reader& r, const json& v, const std::string& path, const Scene& scene,
                        const std::string& base_dir) {
    const int dim = scene.dim;
    r.require_object(v, path);
    SceneObject object;
    object.json_path = path;

    const std::string shape_path = join(path, "shape");
    const std::string shape = r.text(r.require(v, "shape", path, "box, sphere, disk or cylinder"), shape_path);
    std::vector<std::string> keys = {"shape", "material", "model", "velocity", "hardening"};
    if (shape == "box") {
        object.shape = SceneObject::Shape::Box;
        keys.insert(keys.begin() + 1, {"min", "max"});
    } else if (shape == "sphere" || shape == "disk") {
        if (shape == "disk" && dim == 3) r.fail(shape_path, "'disk' is 2D only; in 3D use 'sphere'");
        object.shape = SceneObject::Shape::Sphere;
        keys.insert(keys.begin() + 1, {"center", "radius"});
    } else if (shape == "cylinder") {
        if (dim == 2) r.fail(shape_path, "'cylinder' is 3D only (axis along y); in 2D use 'box'");
        object.shape = SceneObject::Shape::Cylinder;
        keys.insert(keys.begin() + 1, {"center", "radius", "height"});
    } else {
        r.fail(shape_path, "unknown shape '" + shape + "' (expected box, sphere, disk or cylinder)");
    }
    std::string hint = " (a " + shape + " takes";
    for (std::size_t i = 0; i < keys.size(); ++i) hint += (i ? ", " : " ") + keys[i];
    r.reject_unknown_keys(v, path, keys, hint + ")");

    const std::string vec_expected = "an array of " + std::to_string(dim) + " numbers";
    switch (object.shape) {
        case SceneObject::Shape::Box:
            object.min = r.vector(r.require(v, "min", path, vec_expected), join(path, "min"), dim);
            object.max = r.vector(r.require(v, "max", path, vec_expected), join(path, "max"), dim);
            for (int a = 0; a < dim; ++a)
                if (!(object.max[a] > object.min[a]))
                    r.fail(index_path(join(path, "max"), a), "must exceed min[" + std::to_string(a) + "] = " +
                                                                 show(object.min[a]) + ", got " + show(object.max[a]));
            break;
        case SceneObject::Shape::Sphere:
        case SceneObject::Shape::Cylinder:
            object.center = r.vector(r.require(v, "center", path, vec_expected), join(path, "center"), dim);
            object.radius = r.positive(r.require(v, "radius", path, "a positive number"), join(path, "radius"));
            if (object.shape == SceneObject::Shape::Cylinder)
                object.height = r.positive(r.require(v, "height", path, "a positive number"), join(path, "height"));
            break;
    }

    object.material =
        read_material(r, r.require(v, "material", path, "a material object or a preset name"), join(path, "material"));
    if (const json* model = Reader::find(v, "model")) {
        const std::string file = r.text(*model, join(path, "model"));
        if (file.empty()) r.fail(join(path, "model"), "expected a file path, got \"\"");
        object.model = resolve_model_path(file, base_dir);
    }
    object.velocity = Eigen::VectorXd::Zero(dim);
    if (const json* velocity = Reader::find(v, "velocity"))
        object.velocity = r.vector(*velocity, join(path, "velocity"), dim);
    if (const json* hardening = Reader::find(v, "hardening")) {
        object.hardening = r.number(*hardening, join(path, "hardening"));
        // The material's own check (e.g. von Mises h >= 0) applies to the state the particles start in.
        MaterialDescription start = object.material;
        start.initial_hardening = *object.hardening;
        try {
            start.validate();
        } catch (const std::invalid_argument& e) {
            r.fail(join(path, "hardening"), e.what());
        }
    }
    return object;
}

SceneMesh read_mesh(const Reader& r, const json& v, const std::string& path, const Scene& scene,
                    const std::string& base_dir) {
    const int dim = scene.dim;
    r.require_object(v, path);
    SceneMesh mesh;
    mesh.json_path = path;
    const std::string shape_path = join(path, "shape");
    const std::string shape =
        r.text(r.require(v, "shape", path, dim == 2 ? "box, frame, disk or file" : "box, frame, sphere or file"),
               shape_path);
    std::vector<std::string> keys = {"shape", "material", "model", "velocity", "hardening", "kinematic", "clamp"};
    if (shape == "box") {
        mesh.shape = SceneMesh::Shape::Box;
        keys.insert(keys.begin() + 1, {"min", "max", "element_size"});
    } else if (shape == "frame") {
        mesh.shape = SceneMesh::Shape::Frame;
        keys.insert(keys.begin() + 1, {"min", "max", "thickness", "element_size"});
    } else if (shape == "disk" || shape == "sphere") {
        if (shape == "disk" && dim == 3) r.fail(shape_path, "'disk' is 2D only; in 3D use 'sphere'");
        if (shape == "sphere" && dim == 2) r.fail(shape_path, "'sphere' is 3D only; in 2D use 'disk'");
        mesh.shape = SceneMesh::Shape::Disk;
        keys.insert(keys.begin() + 1, {"center", "radius", "element_size"});
    } else if (shape == "file") {
        mesh.shape = SceneMesh::Shape::File;
        keys.insert(keys.begin() + 1, {"file", "element_size"});
    } else {
        r.fail(shape_path, "unknown mesh shape '" + shape + "' (expected box, frame, " +
                               (dim == 2 ? "disk" : "sphere") + " or file)");
    }
    std::string hint = " (a " + shape + " mesh takes";
    for (std::size_t i = 0; i < keys.size(); ++i) hint += (i ? ", " : " ") + keys[i];
    r.reject_unknown_keys(v, path, keys, hint + ")");

    const std::string vec_expected = "an array of " + std::to_string(dim) + " numbers";
    if (mesh.shape == SceneMesh::Shape::Box || mesh.shape == SceneMesh::Shape::Frame) {
        mesh.min = r.vector(r.require(v, "min", path, vec_expected), join(path, "min"), dim);
        mesh.max = r.vector(r.require(v, "max", path, vec_expected), join(path, "max"), dim);
        for (int a = 0; a < dim; ++a)
            if (!(mesh.max[a] > mesh.min[a]))
                r.fail(index_path(join(path, "max"), a), "must exceed min[" + std::to_string(a) + "] = " +
                                                             show(mesh.min[a]) + ", got " + show(mesh.max[a]));
    }
    if (mesh.shape == SceneMesh::Shape::Frame) {
        mesh.thickness = r.positive(r.require(v, "thickness", path, "a positive number"), join(path, "thickness"));
        const double narrowest = (mesh.max - mesh.min).head<2>().minCoeff();  // 3D: the hole runs along z
        if (!(2.0 * mesh.thickness < narrowest * (1.0 - 1e-6)))  // not a hole of round-off width
            r.fail(join(path, "thickness"), "two walls of " + show(mesh.thickness) + " m leave no hole in a frame " +
                                                show(narrowest) + " m wide");
    }
    if (mesh.shape == SceneMesh::Shape::Disk) {
        mesh.center = r.vector(r.require(v, "center", path, vec_expected), join(path, "center"), dim);
        mesh.radius = r.positive(r.require(v, "radius", path, "a positive number"), join(path, "radius"));
    }
    if (mesh.shape == SceneMesh::Shape::File) {
        const std::string expected = dim == 2 ? "a mesh file (.msh)" : "a mesh file (.msh) or a closed surface (.obj, .stl)";
        const std::string file = r.text(r.require(v, "file", path, expected), join(path, "file"));
        if (file.empty()) r.fail(join(path, "file"), "expected a file path, got \"\"");
        mesh.file = resolve_model_path(file, base_dir);
        std::error_code error;
        if (!fs::is_regular_file(mesh.file, error)) r.fail(join(path, "file"), mesh.file + ": no such file");
        const std::string extension = fs::path(mesh.file).extension().string();
        const bool surface = extension == ".obj" || extension == ".stl" || extension == ".ply";
        if (surface && dim == 2) r.fail(join(path, "file"), mesh.file + ": a surface file is 3D only; 2D takes a .msh");
        if (surface) {
            mesh.element_size = r.positive(r.require(v, "element_size", path, "a positive number (m): a surface file is "
                                                                              "tetrahedralized with elements of that size"),
                                           join(path, "element_size"));
        } else if (Reader::find(v, "element_size")) {
            r.fail(join(path, "element_size"), "a .msh file is used as it is meshed; element_size is for shapes and "
                                               "surface files");
        }
    } else {
        mesh.element_size =
            r.positive(r.require(v, "element_size", path, "a positive number (m)"), join(path, "element_size"));
    }
    if (const json* k = Reader::find(v, "kinematic")) {
        if (!k->is_boolean()) r.fail(join(path, "kinematic"), "expected true or false, got " + show(*k));
        mesh.kinematic = k->get<bool>();
    }
    if (const json* clamp = Reader::find(v, "clamp")) {
        const std::string clamp_path = join(path, "clamp");
        if (mesh.kinematic) r.fail(clamp_path, "a kinematic mesh moves as a whole; a clamp holds part of a deformable one");
        const bool many = clamp->is_array();
        if (many && clamp->empty()) r.fail(clamp_path, "expected a box {\"min\", \"max\"} or a non-empty array of them");
        for (std::size_t b = 0; b < (many ? clamp->size() : 1); ++b) {
            const json& box = many ? (*clamp)[b] : *clamp;
            const std::string box_path = many ? index_path(clamp_path, b) : clamp_path;
            r.require_object(box, box_path);
            r.reject_unknown_keys(box, box_path, {"min", "max"}, " (a clamp is a box: min, max)");
            SceneMesh::Box out{r.vector(r.require(box, "min", box_path, vec_expected), join(box_path, "min"), dim),
                               r.vector(r.require(box, "max", box_path, vec_expected), join(box_path, "max"), dim)};
            for (int a = 0; a < dim; ++a)
                if (!(out.max[a] >= out.min[a]))
                    r.fail(index_path(join(box_path, "max"), a), "must be at least min[" + std::to_string(a) +
                                                                     "] = " + show(out.min[a]) + ", got " +
                                                                     show(out.max[a]));
            mesh.clamps.push_back(out);
        }
    }
    if (mesh.kinematic) {
        for (const char* key : {"material", "model", "hardening"})
            if (Reader::find(v, key))
                r.fail(join(path, key), "a kinematic mesh is rigid: it takes no material, model or hardening");
    } else {
        mesh.material = read_material(r, r.require(v, "material", path, "a material object or a preset name"),
                                      join(path, "material"));
    }
    if (const json* model = Reader::find(v, "model")) {
        const std::string file = r.text(*model, join(path, "model"));
        if (file.empty()) r.fail(join(path, "model"), "expected a file path, got \"\"");
        mesh.model = resolve_model_path(file, base_dir);
    }
    mesh.velocity = Eigen::VectorXd::Zero(dim);
    if (const json* velocity = Reader::find(v, "velocity")) mesh.velocity = r.vector(*velocity, join(path, "velocity"), dim);
    if (const json* hardening = Reader::find(v, "hardening")) {
        mesh.hardening = r.number(*hardening, join(path, "hardening"));
        MaterialDescription start = mesh.material;
        start.initial_hardening = *mesh.hardening;
        try {
            start.validate();
        } catch (const std::invalid_argument& e) {
            r.fail(join(path, "hardening"), e.what());
        }
    }
    return mesh;
}

void read_contact(const Reader& r, const json& j, Scene& scene) {
    if (const json* ground = Reader::find(j, "ground")) {
        r.require_object(*ground, "ground");
        r.reject_unknown_keys(*ground, "ground", {"height"});
        scene.contact.ground_height = r.number(r.require(*ground, "height", "ground", "a number (m)"), "ground.height");
    }
    const json* contact = Reader::find(j, "contact");
    if (!contact) return;
    r.require_object(*contact, "contact");
    r.reject_unknown_keys(*contact, "contact",
                          {"dhat", "kappa", "kappa_scale", "friction", "friction_eps_v", "particle_dhat", "particle_kappa"});
    if (const json* v = Reader::find(*contact, "dhat")) scene.contact.dhat = r.positive(*v, "contact.dhat");
    if (const json* v = Reader::find(*contact, "kappa")) scene.contact.kappa = r.positive(*v, "contact.kappa");
    if (const json* v = Reader::find(*contact, "kappa_scale"))
        scene.contact.kappa_scale = r.positive(*v, "contact.kappa_scale");
    const bool coupled = !scene.objects.empty();
    for (const char* key : {"particle_dhat", "particle_kappa"})
        if (!coupled && Reader::find(*contact, key))
            r.fail(std::string("contact.") + key, "applies to particles meeting meshes (MPM-FEM coupling); this scene "
                                                   "has no particle objects");
    if (const json* v = Reader::find(*contact, "particle_dhat")) {
        scene.contact.particle_dhat = r.positive(*v, "contact.particle_dhat");
        if (scene.contact.particle_dhat > 0.5 * scene.dx)
            r.fail("contact.particle_dhat", "expected at most half the grid spacing (" + std::to_string(0.5 * scene.dx) +
                                                " m), got " + show(*v));
    }
    if (const json* v = Reader::find(*contact, "particle_kappa"))
        scene.contact.particle_kappa = r.positive(*v, "contact.particle_kappa");
    if (const json* v = Reader::find(*contact, "friction")) scene.contact.friction = r.non_negative(*v, "contact.friction");
    if (const json* v = Reader::find(*contact, "friction_eps_v"))
        scene.contact.friction_eps_v = r.positive(*v, "contact.friction_eps_v");
}

/// Particles within 2 cells of a wall would spread onto nodes outside the grid.
void check_inside_domain(const Reader& r, const Scene& scene, const SceneObject& object) {
    const auto [lo, hi] = bounding_box(object);
    const double margin = kMarginCells * scene.dx;
    const double tolerance = 1e-9 * scene.dx;  // an object exactly 2 cells in is fine whatever the rounding
    for (int a = 0; a < scene.dim; ++a) {
        const double allowed_lo = scene.domain_min[a] + margin, allowed_hi = scene.domain_max[a] - margin;
        if (lo[a] < allowed_lo - tolerance || hi[a] > allowed_hi + tolerance)
            r.fail(object.json_path, "extends outside the domain [" + show(scene.domain_min) + ", " +
                                         show(scene.domain_max) + "] less its 2-cell margin (2 dx = " + show(margin) +
                                         " m, for the quadratic B-spline stencil): along " + kAxisNames[a] +
                                         " it spans [" + show(lo[a]) + ", " + show(hi[a]) + "], allowed [" +
                                         show(allowed_lo) + ", " + show(allowed_hi) + "]");
    }
}

}  // namespace

std::string to_string(SceneObject::Shape shape) {
    switch (shape) {
        case SceneObject::Shape::Box:
            return "box";
        case SceneObject::Shape::Sphere:
            return "sphere";
        case SceneObject::Shape::Cylinder:
            return "cylinder";
    }
    return "unknown";
}

std::pair<Eigen::VectorXd, Eigen::VectorXd> bounding_box(const SceneObject& object) {
    switch (object.shape) {
        case SceneObject::Shape::Box:
            return {object.min, object.max};
        case SceneObject::Shape::Sphere:
            return {object.center.array() - object.radius, object.center.array() + object.radius};
        case SceneObject::Shape::Cylinder: {
            Eigen::VectorXd lo = object.center.array() - object.radius, hi = object.center.array() + object.radius;
            lo[1] = object.center[1];
            hi[1] = object.center[1] + object.height;
            return {lo, hi};
        }
    }
    return {};
}

int Scene::cells(int axis) const {
    return static_cast<int>(std::lround((domain_max[axis] - domain_min[axis]) / dx));
}

Scene scene_from_json(const json& j, const std::string& file, const std::string& base_dir) {
    const Reader r(file);
    r.require_object(j, "(top level)");
    r.reject_unknown_keys(j, "",
                          {"name", "description", "dim", "domain", "view", "dx", "gravity", "frame_dt", "frames",
                           "particles_per_cell", "boundary", "transfer", "integrator", "objects", "meshes", "ground",
                           "contact"});
    Scene scene;
    scene.file = file;

    // dim first: it gives the sizes of every vector below.
    const json& dim = r.require(j, "dim", "", "2 or 3");
    if (!dim.is_number() || (dim.get<double>() != 2.0 && dim.get<double>() != 3.0))
        r.fail("dim", "expected 2 or 3, got " + show(dim));
    scene.dim = static_cast<int>(dim.get<double>());

    const std::string stem = fs::path(file).stem().string();
    scene.name = stem.empty() || file == "<dict>" ? "unnamed" : stem;
    if (const json* v = Reader::find(j, "name")) scene.name = r.text(*v, "name");
    if (const json* v = Reader::find(j, "description")) scene.description = r.text(*v, "description");

    read_domain(r, j, scene);
    read_view(r, j, scene);
    // A grid (dx) is needed for particles; a scene of meshes only may leave it out.
    const bool particles = Reader::find(j, "objects") != nullptr || Reader::find(j, "meshes") == nullptr;
    if (particles || Reader::find(j, "dx")) {
        scene.dx = r.positive(r.require(j, "dx", "", "a positive number, the grid spacing in m"), "dx");
        check_cells(r, scene);
    }

    scene.gravity = Eigen::VectorXd::Zero(scene.dim);
    scene.gravity[1] = -9.8;  // m/s^2
    if (const json* v = Reader::find(j, "gravity")) scene.gravity = r.vector(*v, "gravity", scene.dim);
    if (const json* v = Reader::find(j, "frame_dt")) scene.frame_dt = r.positive(*v, "frame_dt");
    if (const json* v = Reader::find(j, "frames")) scene.frames = r.integer(*v, "frames", 1);
    if (const json* v = Reader::find(j, "particles_per_cell"))
        scene.particles_per_cell = r.integer(*v, "particles_per_cell", 1);
    if (scene.particles_per_cell > 16)
        r.fail("particles_per_cell", "expected at most 16 per axis, got " + std::to_string(scene.particles_per_cell));
    if (particles) read_boundary(r, j, scene);
    else if (Reader::find(j, "boundary")) r.fail("boundary", "grid boundary conditions need particle objects");
    if (const json* transfer = Reader::find(j, "transfer")) {
        if (!particles) r.fail("transfer", "particle-grid transfers need particle objects");
        r.require_object(*transfer, "transfer");
        r.reject_unknown_keys(*transfer, "transfer", {"flip_relaxation_time"});
        if (const json* v = Reader::find(*transfer, "flip_relaxation_time"))
            scene.flip_relaxation_time = r.non_negative(*v, "transfer.flip_relaxation_time");
    }
    read_integrator(r, j, scene);

    if (particles) {
        const json& objects = r.require(j, "objects", "", "a non-empty array of objects (or meshes)");
        if (!objects.is_array() || objects.empty())
            r.fail("objects", "expected a non-empty array of objects, got " + show(objects));
        for (std::size_t k = 0; k < objects.size(); ++k) {
            scene.objects.push_back(read_object(r, objects[k], index_path("objects", k), scene, base_dir));
            check_inside_domain(r, scene, scene.objects.back());
        }
    }
    if (const json* meshes = Reader::find(j, "meshes")) {
        if (!meshes->is_array() || meshes->empty())
            r.fail("meshes", "expected a non-empty array of meshes, got " + show(*meshes));
        for (std::size_t k = 0; k < meshes->size(); ++k)
            scene.meshes.push_back(read_mesh(r, (*meshes)[k], index_path("meshes", k), scene, base_dir));
        if (std::all_of(scene.meshes.begin(), scene.meshes.end(), [](const SceneMesh& m) { return m.kinematic; }))
            r.fail("meshes", "every mesh is kinematic: at least one must be a deformable body with a material");
        if (!scene.objects.empty()) {
            for (std::size_t k = 0; k < scene.meshes.size(); ++k)
                if (scene.meshes[k].kinematic)
                    r.fail(index_path("meshes", k) + ".kinematic",
                           "kinematic meshes are not supported beside particles (MPM-FEM coupling)");
                else if (!scene.meshes[k].clamps.empty())
                    r.fail(index_path("meshes", k) + ".clamp",
                           "clamps are not supported beside particles (MPM-FEM coupling)");
        }
    }
    if (!scene.has_meshes()) {
        for (const char* key : {"ground", "contact"})
            if (Reader::find(j, key)) r.fail(key, "applies to FEM meshes; this scene has none (particles meet the "
                                                  "domain's walls and floor, see boundary)");
        if (!integrator_info(parse_integrator(scene.integrator.name)).particles)
            r.fail("integrator.name", "'" + scene.integrator.name + "' is for FEM meshes; particle scenes use " +
                                          integrator_names(true, false));
    } else {
        read_contact(r, j, scene);
    }
    return scene;
}

Scene load_scene(const std::string& path) {
    std::error_code error;
    if (!fs::exists(path, error)) throw SceneFileNotFound(path + ": no such file");
    if (!fs::is_regular_file(path, error)) throw SceneFileNotFound(path + ": not a regular file");
    std::ifstream in(path);
    if (!in) throw SceneFileNotFound(path + ": cannot be opened");
    json j;
    try {
        j = json::parse(in);
    } catch (const json::exception& e) {
        // A syntax error or a number out of a double's range. Drop nlohmann's "[json.exception.parse_error.101] "
        // tag; keep "parse error at line L, column C: ..." or "number overflow parsing '...'".
        std::string what = e.what();
        const std::size_t tag_end = what.find("] ");
        if (what.rfind("[json.exception", 0) == 0 && tag_end != std::string::npos) what = what.substr(tag_end + 2);
        throw SceneError(path + ": invalid JSON: " + what);
    }
    return scene_from_json(j, path, fs::path(path).parent_path().string());
}

}  // namespace pnet
