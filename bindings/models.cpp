// Trained PlasticityNet model files: the energy Psi(F; F0, h) with its gradient
// and Hessian (the runtime the simulator uses), and learned return mappings.
// Loading follows the C++ trust rules (model_file.hpp).
#include <memory>
#include <optional>

#include "common.hpp"
#include "pnet/energy/neural_elastoplastic.hpp"
#include "pnet/material/material_json.hpp"
#include "pnet/nn/learned_return_map.hpp"
#include "pnet/nn/model_file.hpp"

namespace pnet::bindings {

namespace {

/// What PyModel::energy() returns.
enum class Output { Value, Gradient, Hessian, Stress };

class PyModel {
public:
    PyModel(const py::object& path, bool trusted, const py::object& E, const py::object& material) {
        LoadOptions options;
        options.trusted = trusted;
        const std::string file = path_string(path);
        {
            py::gil_scoped_release release;
            model_ = std::make_shared<const ModelFile>(load_model_file(file, options));
        }
        const ModelMetadata& meta = model_->metadata;
        E_ = E.is_none() ? meta.training_E : E.cast<double>();
        if (!(E_ > 0.0) || !std::isfinite(E_))
            throw py::value_error(file + ": E: expected a positive Young's modulus (Pa), got " + std::to_string(E_));
        if (!material.is_none()) {
            if (meta.kind != ModelKind::Energy) throw py::value_error(file + ": material: a return-map model takes none");
            MaterialDescription object = material_from_json(to_json(material, "material"), "material");
            object.validate();
            try {  // checked as the simulator checks an object's material
                material_for_object(meta, object, file);
            } catch (const std::invalid_argument& e) {
                throw py::value_error(e.what());
            }
            material_ = object;
        }
        if (meta.kind == ModelKind::ReturnMap) {
            if (meta.dim == 2)
                return_map_2_ = std::make_unique<LearnedReturnMap<2>>(*model_);
            else
                return_map_3_ = std::make_unique<LearnedReturnMap<3>>(*model_);
        }
    }

    const ModelFile& file() const { return *model_; }
    double E() const { return E_; }
    int dim() const { return model_->metadata.dim; }
    bool is_energy() const { return model_->metadata.kind == ModelKind::Energy; }

    py::object energy(const py::object& F, const py::object& F0, const py::object& h, double w, Output order,
                      bool project_psd) const {
        if (!is_energy())
            throw py::value_error(model_->path + ": a return-map model has no energy (use project())");
        return dim() == 2 ? energy_of<2>(F, F0, h, w, order, project_psd) : energy_of<3>(F, F0, h, w, order, project_psd);
    }

    py::object stress(const py::object& F, const py::object& h) const {
        return energy(F, F, h, 0.0, Output::Stress, false);
    }

    py::dict project(const py::object& Sigma, const py::object& h) const {
        if (is_energy()) throw py::value_error(model_->path + ": an energy model has no return mapping of its own");
        return dim() == 2 ? project_with<2>(*return_map_2_, Sigma, h) : project_with<3>(*return_map_3_, Sigma, h);
    }

private:
    std::vector<double> hardening(const py::object& h, py::ssize_t n) const {
        std::vector<double> out(static_cast<std::size_t>(n), model_->metadata.material.initial_hardening);
        if (!h.is_none()) {
            const auto a = batch_array(h, "h", {}, n);
            std::copy(a.data(), a.data() + n, out.begin());
        }
        return out;
    }

    template <int d>
    py::object energy_of(const py::object& F_obj, const py::object& F0_obj, const py::object& h_obj, double w,
                      Output order, bool project_psd) const {
        if (!(w >= 0.0) || !std::isfinite(w))
            throw py::value_error("w: expected a regularizer weight >= 0, got " + std::to_string(w));
        const auto F_array = batch_array(F_obj, "F", {d, d});
        const py::ssize_t n = F_array.shape(0);
        const std::vector<Mat<d>> F = to_matrices<d>(F_array);
        const std::vector<Mat<d>> F0 = to_matrices<d>(batch_array(F0_obj, "F0", {d, d}, n));
        const std::vector<double> h = hardening(h_obj, n);
        typename NeuralElastoplasticEnergy<d>::Options options;
        options.youngs_modulus = E_;
        options.regularizer_weight = w;
        options.material = material_;
        NeuralElastoplasticEnergy<d> energy(*model_, options);  // one per call: calls may run in parallel
        std::vector<double> psi(static_cast<std::size_t>(n));
        std::vector<Mat<d>> P(static_cast<std::size_t>(n));
        std::vector<Tensor4<d>> H(order == Output::Hessian ? static_cast<std::size_t>(n) : 0);
        {
            py::gil_scoped_release release;
            if (order == Output::Stress) {
                for (py::ssize_t p = 0; p < n; ++p) P[p] = energy.elastoplastic_stress(F[p], h[p]);
            } else {
                energy.set_reference(F0.data(), h.data(), static_cast<std::size_t>(n));
                if (order == Output::Value) energy.value(F.data(), psi.data());
                if (order == Output::Gradient) energy.value_gradient(F.data(), psi.data(), P.data());
                if (order == Output::Hessian) energy.value_gradient_hessian(F.data(), psi.data(), P.data(), H.data(), project_psd);
            }
        }
        if (order == Output::Value) return py::array_t<double>(n, psi.data());
        if (order == Output::Gradient || order == Output::Stress) return from_matrices<d>(P);
        constexpr int M = d * d;
        py::array_t<double> out({n, static_cast<py::ssize_t>(M), static_cast<py::ssize_t>(M)});
        double* data = out.mutable_data();
        for (py::ssize_t p = 0; p < n; ++p)
            for (int r = 0; r < M; ++r)
                for (int c = 0; c < M; ++c) data[(p * M + r) * M + c] = H[p](r, c);
        return out;
    }

    template <int d>
    py::dict project_with(const LearnedReturnMap<d>& map, const py::object& Sigma_obj, const py::object& h_obj) const {
        const auto S = batch_array(Sigma_obj, "Sigma", {d});
        const py::ssize_t n = S.shape(0);
        std::vector<Vec<d>> Sigma(static_cast<std::size_t>(n));
        for (py::ssize_t p = 0; p < n; ++p)
            for (int i = 0; i < d; ++i) Sigma[p][i] = S.data()[p * d + i];
        const std::vector<double> h = hardening(h_obj, n);
        std::vector<ReturnResult<d>> result(static_cast<std::size_t>(n));
        {
            py::gil_scoped_release release;
            map.return_map(Sigma.data(), h.data(), static_cast<std::size_t>(n), result.data());
        }
        py::array_t<double> Sigma_out({n, static_cast<py::ssize_t>(d)}), h_out(n);
        for (py::ssize_t p = 0; p < n; ++p) {
            for (int i = 0; i < d; ++i) Sigma_out.mutable_data()[p * d + i] = result[p].Sigma[i];
            h_out.mutable_data()[p] = result[p].hardening;
        }
        py::dict out;
        out["Sigma"] = Sigma_out;
        out["hardening"] = h_out;
        return out;
    }

    std::shared_ptr<const ModelFile> model_;
    double E_ = 1.0;
    std::optional<MaterialDescription> material_;  // the object's material (a parametric model's parameters)
    std::unique_ptr<LearnedReturnMap<2>> return_map_2_;
    std::unique_ptr<LearnedReturnMap<3>> return_map_3_;
};

}  // namespace

void define_models(py::module_& m) {
    py::class_<PyModel>(m, "Model", R"doc(A trained PlasticityNet model file, evaluated by the simulator's C++ runtime.

    model = pns.load_model("models/sand_2d.pt", E=3.537e5)
    model.psi(F, F0, h)            # Psi(F; F0, h), J/m^3, (n,)
    model.gradient(F, F0, h)       # dPsi/dF, Pa, (n, d, d)
    model.hessian(F, F0, h)        # d2Psi/dF2, Pa, (n, d*d, d*d), row-major vec(F)

Psi(F; F0, h) = E [N(F, F0, h) - c : F + w mu/2 ||F - F0||^2] (paper eqs. 8 and 11)
with c chosen so that dPsi/dF(F0) = E Ptilde(F0, h); the same function as
plasticitynet.load_model(...).psi in torch. A return-map model (kind
"return_map") offers project(Sigma, h) instead.)doc")
        .def_property_readonly("path", [](const PyModel& m) { return m.file().path; })
        .def_property_readonly("sha256", [](const PyModel& m) { return m.file().sha256; })
        .def_property_readonly("pinned", [](const PyModel& m) { return m.file().pinned; },
                               "Whether a MANIFEST beside the file pins its sha256.")
        .def_property_readonly("kind", [](const PyModel& m) { return to_string(m.file().metadata.kind); },
                               "\"energy\" or \"return_map\".")
        .def_property_readonly("dim", &PyModel::dim)
        .def_property_readonly("E", &PyModel::E, "Young's modulus the energy is scaled by, Pa.")
        .def_property_readonly("training_E", [](const PyModel& m) { return m.file().metadata.training_E; })
        .def_property_readonly("widths", [](const PyModel& m) { return m.file().metadata.widths; })
        .def_property_readonly("has_hardening", [](const PyModel& m) { return m.file().metadata.has_hardening; },
                               "Whether the energy takes the hardening state h as an input.")
        .def_property_readonly("parameters",
                               [](const PyModel& m) {
                                   py::list out;
                                   for (const ModelParameter& p : m.file().metadata.parameters)
                                       out.append(py::make_tuple(p.field, p.min, p.max));
                                   return out;
                               },
                               "A parametric energy's inputs: (field, min, max) per material parameter, in input "
                               "order; empty for a model of one material.")
        .def_property_readonly("energy_form", [](const PyModel& m) { return to_string(m.file().metadata.energy_form); },
                               "\"eq8\" (the paper's energy), or a form it rejected (sec. 5.2, Fig. 11; models/ablation/): "
                               "\"local_identity\", \"global_identity\", \"global\".")
        .def_property_readonly("learned_return_map", [](const PyModel& m) { return m.file().metadata.learned_return_map(); },
                               "Whether the energy was trained with (and uses) a learned return mapping.")
        .def_property_readonly("metadata", [](const PyModel& m) { return to_python(m.file().metadata.json); },
                               "The file's metadata entry (material, recipe, measured error, ...).")
        .def("psi",
             [](const PyModel& m, const py::object& F, const py::object& F0, const py::object& h, double w) {
                 return m.energy(F, F0, h, w, Output::Value, false);
             },
             py::arg("F"), py::arg("F0"), py::arg("h") = py::none(), py::arg("w") = 0.0,
             R"doc(Psi(F; F0, h), J/m^3, shape (n,).

F, F0: (n, d, d) float64; h: (n,) hardening states (default: the training
material's initial hardening; ignored by models without a hardening input);
w: the stability regularizer weight of eq. 11 (the simulator's default is 1).)doc")
        .def("gradient",
             [](const PyModel& m, const py::object& F, const py::object& F0, const py::object& h, double w) {
                 return m.energy(F, F0, h, w, Output::Gradient, false);
             },
             py::arg("F"), py::arg("F0"), py::arg("h") = py::none(), py::arg("w") = 0.0,
             "dPsi/dF, Pa, shape (n, d, d); arguments as psi().")
        .def("hessian",
             [](const PyModel& m, const py::object& F, const py::object& F0, const py::object& h, double w,
                bool project_psd) { return m.energy(F, F0, h, w, Output::Hessian, project_psd); },
             py::arg("F"), py::arg("F0"), py::arg("h") = py::none(), py::arg("w") = 0.0,
             py::arg("project_psd") = false,
             R"doc(d2Psi/dF2, Pa, shape (n, d*d, d*d), entry (i*d + j, k*d + l) = d2Psi / dF_ij dF_kl.

project_psd: clamp negative eigenvalues to zero, as Newton in the simulator
does (default: the raw Hessian). Other arguments as psi().)doc")
        .def("stress", &PyModel::stress, py::arg("F"), py::arg("h") = py::none(),
             "E Ptilde(F, h), Pa, (n, d, d): the elastoplastic stress the energy was trained to reproduce, with the "
             "model's return mapping (analytic, or the learned one it was trained with).")
        .def("project", &PyModel::project, py::arg("Sigma"), py::arg("h") = py::none(),
             "Return-map models: the learned return mapping of singular values Sigma (n, d) and hardening h (n,); "
             "a dict with Sigma (n, d) and hardening (n,).")
        .def("__repr__", [](const PyModel& m) {
            return "<plasticitynet_sim.Model " + m.file().path + " (" + to_string(m.file().metadata.kind) + ", " +
                   std::to_string(m.dim()) + "D)>";
        });

    m.def(
        "load_model",
        [](const py::object& path, bool trusted, const py::object& E, const py::object& material) {
            return PyModel(path, trusted, E, material);
        },
        py::arg("path"), py::arg("trusted") = false, py::arg("E") = py::none(), py::arg("material") = py::none(),
        R"doc(Load a model file (TorchScript written by train.py).

Files are code to LibTorch: one is read only if a MANIFEST in its folder pins
its sha256, or trusted=True. E: Young's modulus to scale the energy by, Pa
(default: the training E). material: the material description (a dict, as in a
scene) the energy is evaluated for: a parametric model takes its parameters
from it (each within the range it was trained for), a model of one material
checks it has the same constitutive model (default: the model's own).
FileNotFoundError, UntrustedModelError, or ValueError naming the file and the
problem.)doc");
}

}  // namespace pnet::bindings
