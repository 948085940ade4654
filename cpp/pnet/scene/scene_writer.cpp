// scene_to_json (scene.hpp): a scene written in the scene file format, which load_scene reads back.
#include "pnet/scene/scene.hpp"

#include "pnet/material/material_json.hpp"

namespace pnet {

namespace {

using nlohmann::json;

json vector_json(const Eigen::VectorXd& v) {
    return json(std::vector<double>(v.data(), v.data() + v.size()));
}

}  // namespace

json scene_to_json(const Scene& scene) {
    json integrator = scene.integrator.options;
    integrator["name"] = scene.integrator.name;
    integrator["dt"] = scene.integrator.dt;
    integrator["cfl"] = scene.integrator.cfl;

    json objects = json::array();
    for (const SceneObject& object : scene.objects) {
        json o;
        switch (object.shape) {
            case SceneObject::Shape::Box:
                o["shape"] = "box";
                o["min"] = vector_json(object.min);
                o["max"] = vector_json(object.max);
                break;
            case SceneObject::Shape::Sphere:
                o["shape"] = scene.dim == 2 ? "disk" : "sphere";
                o["center"] = vector_json(object.center);
                o["radius"] = object.radius;
                break;
            case SceneObject::Shape::Cylinder:
                o["shape"] = "cylinder";
                o["center"] = vector_json(object.center);
                o["radius"] = object.radius;
                o["height"] = object.height;
                break;
        }
        o["material"] = material_to_json(object.material);
        if (!object.model.empty()) o["model"] = object.model;
        o["velocity"] = vector_json(object.velocity);
        if (object.hardening) o["hardening"] = *object.hardening;
        objects.push_back(o);
    }

    json j = {{"name", scene.name},
              {"dim", scene.dim},
              {"domain", {{"min", vector_json(scene.domain_min)}, {"max", vector_json(scene.domain_max)}}},
              {"view", {{"min", vector_json(scene.view_min)}, {"max", vector_json(scene.view_max)}}},
              {"gravity", vector_json(scene.gravity)},
              {"frame_dt", scene.frame_dt},
              {"frames", scene.frames},
              {"integrator", integrator}};
    if (scene.dx > 0.0) j["dx"] = scene.dx;
    if (scene.has_particles()) {
        j["particles_per_cell"] = scene.particles_per_cell;
        j["boundary"] = {{"walls", scene.boundary.slip_walls ? "slip" : "none"},
                         {"sticky_floor_cells", scene.boundary.sticky_floor_cells}};
        if (scene.boundary.floor_friction >= 0.0) j["boundary"]["floor_friction"] = scene.boundary.floor_friction;
        if (scene.flip_relaxation_time > 0.0) j["transfer"] = {{"flip_relaxation_time", scene.flip_relaxation_time}};
        j["objects"] = objects;
    }
    if (scene.has_meshes()) {
        json meshes = json::array();
        for (const SceneMesh& mesh : scene.meshes) {
            json m;
            switch (mesh.shape) {
                case SceneMesh::Shape::Box:
                case SceneMesh::Shape::Frame:
                    m["shape"] = mesh.shape == SceneMesh::Shape::Box ? "box" : "frame";
                    m["min"] = vector_json(mesh.min);
                    m["max"] = vector_json(mesh.max);
                    if (mesh.shape == SceneMesh::Shape::Frame) m["thickness"] = mesh.thickness;
                    break;
                case SceneMesh::Shape::Disk:
                    m["shape"] = scene.dim == 2 ? "disk" : "sphere";
                    m["center"] = vector_json(mesh.center);
                    m["radius"] = mesh.radius;
                    break;
                case SceneMesh::Shape::File:
                    m["shape"] = "file";
                    m["file"] = mesh.file;
                    break;
            }
            if (mesh.element_size > 0.0) m["element_size"] = mesh.element_size;
            m["kinematic"] = mesh.kinematic;
            if (!mesh.clamps.empty()) {
                json clamps = json::array();
                for (const SceneMesh::Box& box : mesh.clamps)
                    clamps.push_back({{"min", vector_json(box.min)}, {"max", vector_json(box.max)}});
                m["clamp"] = clamps;
            }
            if (!mesh.kinematic) m["material"] = material_to_json(mesh.material);
            if (!mesh.model.empty()) m["model"] = mesh.model;
            m["velocity"] = vector_json(mesh.velocity);
            if (mesh.hardening) m["hardening"] = *mesh.hardening;
            meshes.push_back(m);
        }
        j["meshes"] = meshes;
        json contact = {{"dhat", scene.contact.dhat},         {"kappa", scene.contact.kappa},
                        {"kappa_scale", scene.contact.kappa_scale}, {"friction", scene.contact.friction},
                        {"friction_eps_v", scene.contact.friction_eps_v}};
        // 0 means "the default" for dhat and kappa, which the reader refuses as a value.
        if (scene.contact.dhat == 0.0) contact.erase("dhat");
        if (scene.contact.kappa == 0.0) contact.erase("kappa");
        if (scene.contact.particle_dhat > 0.0) contact["particle_dhat"] = scene.contact.particle_dhat;
        if (scene.contact.particle_kappa > 0.0) contact["particle_kappa"] = scene.contact.particle_kappa;
        j["contact"] = contact;
        if (scene.contact.ground_height) j["ground"] = {{"height", *scene.contact.ground_height}};
    }
    if (!scene.description.empty()) j["description"] = scene.description;
    return j;
}

}  // namespace pnet
