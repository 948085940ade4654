// Scenes (docs/scenes.md): loaded from a file or built from a dict with the same
// schema, validated by the C++ loader with the same messages.
#include "common.hpp"
#include "pnet/scene/scene.hpp"

namespace pnet::bindings {

void define_scene(py::module_& m) {
    py::class_<Scene>(m, "Scene", R"doc(A validated scene: grid, objects and materials, integrator block.

Build one with load_scene(path) or Scene.from_dict(d); Simulation also takes a
path or a dict directly. to_dict() gives every field back (materials written
out, model paths absolute).)doc")
        .def_static(
            "from_dict",
            [](const py::dict& d, const py::object& base_dir, const std::string& name) {
                const std::string base = base_dir.is_none() ? std::string() : path_string(base_dir);
                return scene_from_json(to_json(d, name), name, base);
            },
            py::arg("scene"), py::arg("base_dir") = py::none(), py::arg("name") = "<dict>",
            R"doc(Validate a scene given as a dict with the JSON schema of scene files.

base_dir: folder that relative model paths are resolved against (default: the
working directory). name: prefixes error messages (ValueError "<dict>: objects[0].radius:
expected a positive number, got -1").)doc")
        .def("to_dict", [](const Scene& s) { return to_python(scene_to_json(s)); },
             "Every field as a dict; Scene.from_dict(s.to_dict()) gives the same scene.")
        .def_readonly("file", &Scene::file, "Path it was loaded from, or the name given to from_dict.")
        .def_readonly("name", &Scene::name)
        .def_readonly("description", &Scene::description)
        .def_readonly("dim", &Scene::dim, "2 or 3.")
        .def_readonly("dx", &Scene::dx, "Grid spacing, m.")
        .def_readonly("frame_dt", &Scene::frame_dt, "Duration of a frame, s.")
        .def_readonly("frames", &Scene::frames, "Frames the scene asks for.")
        .def_property_readonly("domain_min", [](const Scene& s) { return std::vector<double>(s.domain_min.data(), s.domain_min.data() + s.dim); }, "m.")
        .def_property_readonly("domain_max", [](const Scene& s) { return std::vector<double>(s.domain_max.data(), s.domain_max.data() + s.dim); }, "m.")
        .def_property_readonly("cells", [](const Scene& s) {
            std::vector<int> c;
            for (int a = 0; a < s.dim; ++a) c.push_back(s.cells(a));
            return c;
        }, "Grid cells per axis.")
        .def_property_readonly("integrator", [](const Scene& s) { return s.integrator.name; },
                               "The scene's integrator: explicit, plasticitynet or lagged.")
        .def_property_readonly("dt", [](const Scene& s) { return s.integrator.dt; },
                               "The scene's time step, s (0: the CFL step).")
        .def("__repr__", [](const Scene& s) {
            return "<plasticitynet_sim.Scene " + s.name + ": " + std::to_string(s.dim) + "D, " +
                   std::to_string(s.objects.size()) + " object(s), " + s.integrator.name + ">";
        });

    m.def("load_scene", [](const py::object& path) { return load_scene(path_string(path)); }, py::arg("path"),
          R"doc(Read and validate a scene file (JSON). FileNotFoundError if it cannot be read,
ValueError naming the file, the JSON path and the problem otherwise.)doc");
}

}  // namespace pnet::bindings
