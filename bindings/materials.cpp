// The analytic materials (docs/physics.md): elastoplastic stress Ptilde(F, h) and
// the return mapping, evaluated for batches of deformation gradients.
#include <variant>

#include "common.hpp"
#include "pnet/material/material.hpp"
#include "pnet/material/material_json.hpp"

namespace pnet::bindings {

namespace {

/// A material of either dimension.
class PyMaterial {
public:
    PyMaterial(const py::object& spec, int dim) {
        if (dim != 2 && dim != 3) throw py::value_error("dim: expected 2 or 3, got " + std::to_string(dim));
        if (py::isinstance<py::str>(spec))
            description_ = material_preset(spec.cast<std::string>());
        else if (py::isinstance<py::dict>(spec))
            description_ = material_from_json(to_json(spec, "material"), "material");
        else
            throw py::value_error("material: expected a preset name or a dict, got " +
                                  py::str(py::type::of(spec)).cast<std::string>());
        if (dim == 2)
            material_.emplace<Material<2>>(description_);
        else
            material_.emplace<Material<3>>(description_);
    }

    int dim() const { return material_.index() == 1 ? 2 : 3; }
    const MaterialDescription& description() const { return description_; }

    py::array_t<double> stress(const py::object& F, const py::object& h) const {
        return dim() == 2 ? stress_of<2>(F, h) : stress_of<3>(F, h);
    }
    py::dict return_map(const py::object& F, const py::object& h) const {
        return dim() == 2 ? return_map_of<2>(F, h) : return_map_of<3>(F, h);
    }

private:
    template <int d>
    std::pair<std::vector<Mat<d>>, std::vector<double>> inputs(const py::object& F_obj, const py::object& h_obj) const {
        const auto F = batch_array(F_obj, "F", {d, d});
        std::vector<double> h(static_cast<std::size_t>(F.shape(0)), description_.initial_hardening);
        if (!h_obj.is_none()) {
            const auto a = batch_array(h_obj, "h", {}, F.shape(0));
            std::copy(a.data(), a.data() + a.size(), h.begin());
        }
        return {to_matrices<d>(F), std::move(h)};
    }

    template <int d>
    py::array_t<double> stress_of(const py::object& F_obj, const py::object& h_obj) const {
        auto [F, h] = inputs<d>(F_obj, h_obj);
        std::vector<Mat<d>> P(F.size());
        {
            py::gil_scoped_release release;
            const Material<d>& material = std::get<Material<d>>(material_);
            for (std::size_t p = 0; p < F.size(); ++p) P[p] = material.elastoplastic_stress(F[p], h[p]);
        }
        return from_matrices<d>(P);
    }

    template <int d>
    py::dict return_map_of(const py::object& F_obj, const py::object& h_obj) const {
        auto [F, h] = inputs<d>(F_obj, h_obj);
        std::vector<Mat<d>> Fe(F.size());
        py::array_t<double> hardening(static_cast<py::ssize_t>(F.size()));
        py::array_t<int> branch(static_cast<py::ssize_t>(F.size()));
        double* h_out = hardening.mutable_data();
        int* b_out = branch.mutable_data();
        {
            py::gil_scoped_release release;
            const Material<d>& material = std::get<Material<d>>(material_);
            for (std::size_t p = 0; p < F.size(); ++p) {
                const auto r = material.project(F[p], h[p]);
                Fe[p] = r.F_elastic;
                h_out[p] = r.hardening;
                b_out[p] = static_cast<int>(r.branch);
            }
        }
        py::dict out;
        out["F_elastic"] = from_matrices<d>(Fe);
        out["hardening"] = hardening;
        out["branch"] = branch;
        return out;
    }

    MaterialDescription description_;
    std::variant<std::monostate, Material<2>, Material<3>> material_;
};

}  // namespace

void define_materials(py::module_& m) {
    py::class_<PyMaterial>(m, "Material", R"doc(An analytic elastoplastic material (elasticity + return mapping).

    mat = pns.Material("sand", dim=2)          # a preset: sand, snow, metal, metal_nh
    mat = pns.Material({...}, dim=3)           # or a material dict as in scene files
    P = mat.stress(F, h)                       # Ptilde(F, h), Pa, (n, d, d)
    r = mat.return_map(F, h)                   # dict: F_elastic (n, d, d), hardening (n,), branch (n,))doc")
        .def(py::init<const py::object&, int>(), py::arg("material"), py::arg("dim") = 2,
             "material: a preset name or a material dict; dim: 2 or 3. ValueError naming the field on bad input.")
        .def_property_readonly("dim", &PyMaterial::dim)
        .def_property_readonly("name", [](const PyMaterial& m) { return m.description().name; })
        .def("to_dict", [](const PyMaterial& m) { return to_python(material_to_json(m.description())); },
             "The material description as a dict (the schema of scene files).")
        .def("stress", &PyMaterial::stress, py::arg("F"), py::arg("h") = py::none(),
             R"doc(Elastoplastic first Piola-Kirchhoff stress Ptilde(F, h) = P(Z(F, h)), Pa.

F: (n, d, d) trial deformation gradients; h: (n,) hardening states (default:
the material's initial hardening). Returns (n, d, d).)doc")
        .def("return_map", &PyMaterial::return_map, py::arg("F"), py::arg("h") = py::none(),
             R"doc(The return mapping Z in F space: a dict with F_elastic (n, d, d), the
projected elastic deformation; hardening (n,), the updated state; branch (n,)
int32, the branch taken (see BRANCHES).)doc")
        .def("__repr__", [](const PyMaterial& m) {
            return "<plasticitynet_sim.Material " + m.description().name + " (" + std::to_string(m.dim()) + "D)>";
        });
    py::list branches;
    for (int b = 0; b <= static_cast<int>(ReturnBranch::Yield); ++b) branches.append(to_string(ReturnBranch(b)));
    m.attr("BRANCHES") = branches;
    m.def("material_presets", &material_preset_names, "Names of the preset materials.");
}

}  // namespace pnet::bindings
