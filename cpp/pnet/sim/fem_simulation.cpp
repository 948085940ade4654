#include "pnet/sim/fem_simulation.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "pnet/contact/adaptive_stiffness.hpp"
#include "pnet/contact/collisions/contact.hpp"
#include "pnet/energy/analytic_elastoplastic.hpp"
#include "pnet/energy/neural_elastoplastic.hpp"
#include "pnet/fem/gmsh_mesher.hpp"
#include "pnet/io/atomic_file.hpp"
#include "pnet/io/checkpoint_arrays.hpp"
#include "pnet/sim/frame_files.hpp"
#include "pnet/solver/method_energy.hpp"

namespace pnet {

namespace {

constexpr double kKappaReferenceDt = 1e-2;  // s: the implicit FEM step of docs/scenes.md

template <int dim>
Mesh<dim> mesh_of(const Scene& scene, const SceneMesh& m) {
    const std::string context = scene.file + ": " + m.json_path;
    if (m.shape == SceneMesh::Shape::File) {
        try {
            if (m.element_size > 0.0) {
                if constexpr (dim == 3) return tetrahedralize_surface_file(m.file, m.element_size);
            }
            return read_mesh_file<dim>(m.file);
        } catch (const MeshError& e) {
            throw MeshError(context + ".file: " + e.what());
        }
    }
    if constexpr (dim == 2) {
        Shape2d shape;
        shape.element_size = m.element_size;
        switch (m.shape) {
            case SceneMesh::Shape::Box:
            case SceneMesh::Shape::Frame:
                shape.kind = m.shape == SceneMesh::Shape::Box ? Shape2d::Kind::Box : Shape2d::Kind::Frame;
                shape.min = Vec<2>(m.min[0], m.min[1]);
                shape.max = Vec<2>(m.max[0], m.max[1]);
                shape.thickness = m.thickness;
                break;
            case SceneMesh::Shape::Disk:
                shape.kind = Shape2d::Kind::Disk;
                shape.center = Vec<2>(m.center[0], m.center[1]);
                shape.radius = m.radius;
                break;
            case SceneMesh::Shape::File:
                break;
        }
        return mesh_shape(shape, context);
    } else {
        Shape3d shape;
        shape.element_size = m.element_size;
        switch (m.shape) {
            case SceneMesh::Shape::Box:
            case SceneMesh::Shape::Frame:
                shape.kind = m.shape == SceneMesh::Shape::Box ? Shape3d::Kind::Box : Shape3d::Kind::Frame;
                shape.min = Vec<3>(m.min[0], m.min[1], m.min[2]);
                shape.max = Vec<3>(m.max[0], m.max[1], m.max[2]);
                shape.thickness = m.thickness;
                break;
            case SceneMesh::Shape::Disk:
                shape.kind = Shape3d::Kind::Sphere;
                shape.center = Vec<3>(m.center[0], m.center[1], m.center[2]);
                shape.radius = m.radius;
                break;
            case SceneMesh::Shape::File:
                break;
        }
        return mesh_shape(shape, context);
    }
}

/// Whether p lies in the simplex `corner` (triangle or tetrahedron) or on its boundary:
/// the signs of the d + 1 sub-simplices' volumes agree (zeros allowed).
template <int dim>
bool in_simplex(const Vec<dim>& p, const std::array<Vec<dim>, dim + 1>& corner) {
    bool negative = false, positive = false;
    for (int k = 0; k <= dim; ++k) {
        Mat<dim> D;
        std::array<Vec<dim>, dim + 1> c = corner;
        c[k] = p;
        for (int a = 0; a < dim; ++a) D.col(a) = c[a + 1] - c[0];
        const double v = D.determinant();
        negative = negative || v < 0.0;
        positive = positive || v > 0.0;
    }
    return !(negative && positive);
}

/// An intersection of the meshes at positions x, as text naming the meshes, or "".
template <int dim>
std::string find_intersection(const FemSceneSystem<dim>& s, const ContactPotential<dim>& contact,
                              const std::vector<Vec<dim>>& x) {
    std::string pair = contact.first_intersection(x);
    const std::size_t meshes = s.first_node.size() - 1;
    if (pair.empty()) {
        // A body wholly inside another crosses no boundary: test one node of each.
        const Mesh<dim>& mesh = s.system.mesh;
        for (std::size_t k = 0; k < meshes && pair.empty(); ++k) {
            const Vec<dim>& p = x[s.first_node[k]];
            for (std::size_t e = 0; e < mesh.elements.size(); ++e) {
                const auto& el = mesh.elements[e];
                if (s.mesh_of_node(el[0]) == static_cast<int>(k)) continue;
                std::array<Vec<dim>, dim + 1> corner;
                for (int a = 0; a <= dim; ++a) corner[a] = x[el[a]];
                if (in_simplex<dim>(p, corner)) {
                    pair = "node " + std::to_string(s.first_node[k]) + " inside element " + std::to_string(e);
                    break;
                }
            }
        }
    }
    if (pair.empty()) return "";
    // Which mesh each node belongs to.
    std::string legend = " (nodes";
    for (std::size_t k = 0; k < meshes; ++k)
        legend += std::string(k ? ";" : "") + " " + std::to_string(s.first_node[k]) + "-" +
                  std::to_string(s.first_node[k + 1] - 1) + ": meshes[" + std::to_string(k) + "]";
    return pair + legend + ")";
}

template <int dim>
Vec<dim> to_vec(const Eigen::VectorXd& v) {
    return Vec<dim>(v.head<dim>());
}

}  // namespace

template <int dim>
std::unique_ptr<ContactPotential<dim>> make_fem_contact(const Scene& scene, const FemSceneSystem<dim>& s) {
    HalfSpace<dim> ground;
    if (scene.contact.ground_height) ground.origin[1] = *scene.contact.ground_height;
    auto contact = std::make_unique<Contact<dim>>(s.system.mesh.boundary, s.system.mesh.x, s.dhat, s.kappa);
    if (scene.contact.ground_height) contact->add_half_space(ground);
    return contact;
}

template std::unique_ptr<ContactPotential<2>> make_fem_contact<2>(const Scene&, const FemSceneSystem<2>&);
template std::unique_ptr<ContactPotential<3>> make_fem_contact<3>(const Scene&, const FemSceneSystem<3>&);

template <int dim>
int FemSceneSystem<dim>::mesh_of_node(int node) const {
    const auto it = std::upper_bound(first_node.begin(), first_node.end(), node);
    return static_cast<int>(it - first_node.begin()) - 1;
}

template <int dim>
FemSceneSystem<dim> make_fem_system(const Scene& scene) {
    if (scene.dim != dim)
        throw SceneError(scene.file + ": a " + std::to_string(scene.dim) + "D scene run as " + std::to_string(dim) + "D");
    if (!scene.has_meshes()) throw SceneError(scene.file + ": meshes: the scene has no meshes");
    FemSceneSystem<dim> out;
    FemSystem<dim>& s = out.system;
    // A kinematic mesh is rigid: its elements carry the first deformable mesh's
    // material (and model), under which a rigid translation has no energy.
    int deformable = -1;
    for (std::size_t k = 0; k < scene.meshes.size() && deformable < 0; ++k)
        if (!scene.meshes[k].kinematic) deformable = static_cast<int>(k);
    for (std::size_t k = 0; k < scene.meshes.size(); ++k) {
        const SceneMesh& m = scene.meshes[k];
        out.first_node.push_back(static_cast<int>(s.mesh.nodes()));
        out.first_element.push_back(static_cast<int>(s.mesh.elements.size()));
        s.mesh.append(mesh_of<dim>(scene, m));
        s.materials.emplace_back(scene.meshes[m.kinematic ? deformable : k].material);
        s.element_object.resize(s.mesh.elements.size(), static_cast<int>(k));
        s.fixed_node.resize(s.mesh.nodes(), m.kinematic ? 1 : 0);
        s.prescribed_velocity.resize(s.mesh.nodes(), m.kinematic ? to_vec<dim>(m.velocity) : Vec<dim>::Zero());
        for (std::size_t b = 0; b < m.clamps.size(); ++b) {  // held at rest (prescribed velocity 0)
            const Vec<dim> lo = to_vec<dim>(m.clamps[b].min), hi = to_vec<dim>(m.clamps[b].max);
            int held = 0;
            for (int i = out.first_node.back(); i < static_cast<int>(s.mesh.nodes()); ++i) {
                const Vec<dim>& x = s.mesh.x[i];
                if ((x.array() >= lo.array()).all() && (x.array() <= hi.array()).all()) {
                    s.fixed_node[i] = 1;
                    ++held;
                }
            }
            if (held == 0)
                throw SceneError(scene.file + ": " + m.json_path + ".clamp" +
                                 (m.clamps.size() > 1 ? "[" + std::to_string(b) + "]" : std::string()) +
                                 ": no node of the mesh lies in the box");
        }
    }
    out.first_node.push_back(static_cast<int>(s.mesh.nodes()));
    out.first_element.push_back(static_cast<int>(s.mesh.elements.size()));
    s.mesh.finalize(scene.file + ": meshes");
    s.gravity = to_vec<dim>(scene.gravity);
    s.make_rest();

    const auto [lo, hi] = s.mesh.bounding_box();
    out.diagonal = (hi - lo).norm();
    out.dhat = scene.contact.dhat > 0.0 ? scene.contact.dhat : 1e-3 * out.diagonal;
    if (scene.contact.kappa > 0.0) {
        out.kappa = scene.contact.kappa;
    } else {
        double mass = 0.0;
        for (double m : s.rest.node_mass) mass += m;
        const BarrierStiffness k = initial_barrier_stiffness(out.diagonal, out.dhat, mass / s.mesh.nodes(),
                                                             kKappaReferenceDt, Eigen::VectorXd::Zero(dim),
                                                             Eigen::VectorXd::Zero(dim));
        out.kappa = scene.contact.kappa_scale * k.kappa;
    }
    const std::unique_ptr<ContactPotential<dim>> contact = make_fem_contact<dim>(scene, out);
    const std::string pair = find_intersection(out, *contact, s.mesh.x);
    if (!pair.empty())
        throw SceneError(scene.file + ": meshes: the start state intersects or touches: " + pair +
                         (scene.contact.ground_height ? " (half-space 0 is the ground)" : ""));
    return out;
}

template <int dim>
FemSimulation<dim>::FemSimulation(const Scene& scene, const IntegratorSettings& settings)
    : SimulationBase(scene, settings), built_(make_fem_system<dim>(scene)) {
    const FemSystem<dim>& s = built_.system;
    contact_ = make_fem_contact<dim>(scene, built_);
    friction_ = std::make_unique<Friction<dim>>(scene.contact.friction, scene.contact.friction_eps_v);
    const bool frictional = scene.contact.friction > 0.0;

    state_ = FemState<dim>::at_rest(s);
    for (std::size_t k = 0; k < scene.meshes.size(); ++k) {
        const SceneMesh& m = scene.meshes[k];
        for (int i = built_.first_node[k]; i < built_.first_node[k + 1]; ++i) state_.v[i] = to_vec<dim>(m.velocity);
        if (m.hardening)
            for (int e = built_.first_element[k]; e < built_.first_element[k + 1]; ++e) state_.hardening[e] = *m.hardening;
    }

    if (settings.method() == Method::Explicit) {
        explicit_ = std::make_unique<FemExplicitIntegrator<dim>>(s, contact_.get());
        if (frictional) explicit_->set_friction(friction_.get(), contact_.get());
        dt_ = settings.dt > 0.0 ? settings.dt : explicit_->cfl_time_step(settings.cfl);
    } else {
        if (!(settings.dt > 0.0))
            throw std::invalid_argument("dt must be > 0 for the implicit integrator " + settings.name +
                                        " (the CFL step is explicit's)");
        dt_ = settings.dt;
        const Method method = settings.method();
        if (!integrator_info(method).meshes)
            throw std::invalid_argument("the " + settings.name + " integrator is not for meshes (expected " +
                                        integrator_names(false, true) + ")");
        std::vector<std::string> where;
        for (const SceneMesh& m : scene.meshes) where.push_back(scene.file + ": " + m.json_path);
        // settings.models: objects first, then meshes; under plasticitynet a kinematic mesh (the plate)
        // takes the first deformable mesh's model, which it never evaluates (its nodes are fixed).
        std::vector<std::shared_ptr<const ModelFile>> models(scene.meshes.size());
        const std::size_t offset = scene.objects.size();
        int deformable = -1;
        for (std::size_t k = 0; k < scene.meshes.size(); ++k) {
            if (offset + k < settings.models.size()) models[k] = settings.models[offset + k];
            if (deformable < 0 && !scene.meshes[k].kinematic) deformable = static_cast<int>(k);
        }
        for (std::size_t k = 0; k < scene.meshes.size(); ++k)
            if (method == Method::PlasticityNet && scene.meshes[k].kinematic && deformable >= 0) {
                models[k] = models[deformable];
                where[k] = where[deformable];
            }
        MethodEnergy<dim> made = make_method_energy<dim>(settings.method(), {settings.implicit, s.materials, models, where});
        std::unique_ptr<ParticleEnergy<dim>> energy = std::move(made.energy);
        built_.system.return_maps = made.return_maps;
        implicit_ = std::make_unique<FemImplicitIntegrator<dim>>(s, method, settings.implicit, std::move(energy),
                                                               contact_.get(), settings.fem);
        if (frictional) implicit_->set_friction(friction_.get(), contact_.get());
    }
}

template <int dim>
StepRecord FemSimulation<dim>::step() {
    const double dt = clip_to_frame(dt_);
    contact_->reset_timing();
    StepRecord s = implicit_ ? implicit_->step(state_, dt, steps_) : explicit_->step(state_, dt, steps_);
    s.broad_phase_seconds = contact_->timing().broad_phase_seconds;
    s.ccd_seconds = contact_->timing().ccd_seconds;
    s.contact_pairs = contact_->active_pairs(state_.x);
    s.min_distance = contact_->min_distance(state_.x);
    count_step(dt);
    return s;
}

template <int dim>
FrameStats FemSimulation<dim>::advance_frame(const std::function<void()>& after_step) {
    return advance_one_frame(
        [&] { return step(); },
        [&](FrameStats& stats) {
            const std::string pair = find_intersection(built_, *contact_, state_.x);
            if (!pair.empty())
                throw SimulationError("frame " + std::to_string(frame_) + ": the meshes intersect: " + pair);
            const FemSystem<dim>& s = built_.system;
            for (std::size_t i = 0; i < s.mesh.nodes(); ++i)
                if (!s.fixed_node[i])  // kinematic bodies carry no physical momentum here
                    add_point_mass<dim>(stats, s.rest.node_mass[i], state_.x[i], state_.v[i], s.gravity);
        },
        after_step);
}

namespace {

// Version 2 adds the BDF2 history (a flag, then the previous step's start positions and velocities);
// version 1 files (no history) still load.
constexpr char kMagic[8] = {'P', 'N', 'E', 'T', 'F', 'E', 'M', '2'};
constexpr char kMagicVersion1[8] = {'P', 'N', 'E', 'T', 'F', 'E', 'M', '1'};

}  // namespace

template <int dim>
void FemSimulation<dim>::save_checkpoint(const std::string& path) const {
    write_sealed_checkpoint(path, [&](std::ostream& out) {
        write_checkpoint_preamble(out, kMagic,
                                  {kDim, static_cast<std::int64_t>(state_.x.size()),
                                   static_cast<std::int64_t>(state_.hardening.size()), frame_, steps_},
                                  settings_.name);
        write_array(out, state_.x);
        write_array(out, state_.v);
        write_array(out, state_.plastic_inverse);
        write_array(out, state_.hardening);
        // The history flag: 0 none; 1 x^{n-1}, v^{n-1}; 2 those and the last step's dt (BDF2's variable steps).
        const std::int64_t history = state_.x_previous.size() != state_.x.size() ? 0 : state_.dt_previous > 0.0 ? 2 : 1;
        out.write(reinterpret_cast<const char*>(&history), sizeof history);
        if (history) {
            write_array(out, state_.x_previous);
            write_array(out, state_.v_previous);
        }
        if (history == 2) out.write(reinterpret_cast<const char*>(&state_.dt_previous), sizeof state_.dt_previous);
    });
}

template <int dim>
void FemSimulation<dim>::load_checkpoint(const std::string& path) {
    std::istringstream in = read_sealed_checkpoint(path);
    std::vector<std::int64_t> header(5);
    double time = 0.0;
    const bool version1 =
        read_checkpoint_preamble(in, path, {kMagic, kMagicVersion1}, "FEM", header, time, settings_.name) == 1;
    if (header[0] != kDim) throw std::invalid_argument(path + ": a " + std::to_string(header[0]) + "D checkpoint");
    if (header[1] != static_cast<std::int64_t>(state_.x.size()) ||
        header[2] != static_cast<std::int64_t>(state_.hardening.size()) || header[3] < 0 || header[4] < 0)
        throw std::invalid_argument(path + ": holds " + std::to_string(header[1]) + " nodes and " +
                                    std::to_string(header[2]) + " elements, the scene's mesh has " +
                                    std::to_string(state_.x.size()) + " and " + std::to_string(state_.hardening.size()));
    FemState<dim> s;
    read_array(in, s.x, state_.x.size(), path);
    read_array(in, s.v, state_.v.size(), path);
    read_array(in, s.plastic_inverse, state_.plastic_inverse.size(), path);
    read_array(in, s.hardening, state_.hardening.size(), path);
    std::int64_t history = 0;
    if (!version1) in.read(reinterpret_cast<char*>(&history), sizeof history);
    if (!in || history < 0 || history > 2) throw std::invalid_argument(path + ": corrupt checkpoint (the history flag)");
    if (history) {
        read_array(in, s.x_previous, state_.x.size(), path);
        read_array(in, s.v_previous, state_.x.size(), path);
    }
    if (history == 2) {
        in.read(reinterpret_cast<char*>(&s.dt_previous), sizeof s.dt_previous);
        if (!in || !(s.dt_previous > 0.0) || !std::isfinite(s.dt_previous))
            throw std::invalid_argument(path + ": corrupt checkpoint (the last step's dt is not a number > 0)");
    }
    in.peek();
    if (!in.eof()) throw std::invalid_argument(path + ": longer than its header says (corrupt checkpoint)");
    // A state no run could have written is refused naming the node or element (see the MPM loader).
    for (std::size_t i = 0; i < s.x.size(); ++i)
        if (!s.x[i].allFinite() || !s.v[i].allFinite() ||
            (history && (!s.x_previous[i].allFinite() || !s.v_previous[i].allFinite())))
            throw std::invalid_argument(path + ": node " + std::to_string(i) +
                                        "'s position or velocity is not finite (corrupt checkpoint state)");
    for (std::size_t e = 0; e < s.hardening.size(); ++e)
        if (!std::isfinite(s.hardening[e]) || !s.plastic_inverse[e].allFinite())
            throw std::invalid_argument(path + ": element " + std::to_string(e) +
                                        "'s plastic state is not finite (corrupt checkpoint state)");
    restore_clock(path, header[3], header[4], time);
    state_ = std::move(s);
}

template struct FemSceneSystem<2>;
template struct FemSceneSystem<3>;
template FemSceneSystem<2> make_fem_system<2>(const Scene&);
template FemSceneSystem<3> make_fem_system<3>(const Scene&);
template <int dim>
nlohmann::json FemSimulation<dim>::describe() const {
    return {{"nodes", mesh().nodes()},
            {"elements", mesh().elements.size()},
            {"mesh_first_node", built_.first_node},
            {"mesh_first_element", built_.first_element},
            {"bbox_diagonal", built_.diagonal},
            {"dhat", built_.dhat},
            {"kappa", built_.kappa},
            {"step", dt_}};
}

template <int dim>
void FemSimulation<dim>::write_frame(const FrameFiles& files) const {
    write_mesh_frame(files, state_, mesh(), frame(), time());
}

template <int dim>
nlohmann::json FemSimulation<dim>::contact_state() const {
    return {{"dhat", built_.dhat},
            {"kappa", built_.kappa},
            {"bbox_diagonal", built_.diagonal},
            {"min_distance", contact_->min_distance(state_.x)},
            {"active_pairs", contact_->active_pairs(state_.x)}};
}

template <int dim>
std::string FemSimulation<dim>::size_text() const {
    return std::to_string(mesh().nodes()) + " nodes, " + std::to_string(mesh().elements.size()) + " elements";
}

template class FemSimulation<2>;
template class FemSimulation<3>;

}  // namespace pnet
