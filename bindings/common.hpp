#pragma once
// Shared glue of the plasticitynet_sim module: one define_<topic>(m) per
// binding file, numpy <-> Eigen batch conversion with shape and dtype checks,
// and Python <-> JSON. No simulation logic lives in bindings/.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cstddef>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "pnet/math/types.hpp"
#include "pnet/metrics/iou.hpp"
#include "pnet/scene/scene.hpp"

namespace pnet::bindings {

namespace py = pybind11;

void define_errors(py::module_& m);
void define_scene(py::module_& m);
void define_simulation(py::module_& m);
void define_models(py::module_& m);
void define_materials(py::module_& m);
void define_metrics(py::module_& m);
void define_adjoint(py::module_& m);

/// A float64 array of the given trailing shape (n leading, any n unless n >= 0):
/// Python lists and tuples are converted to float64; numpy arrays must already
/// be float64 (a float32 or integer array is refused rather than silently
/// widened). Raises ValueError "<name>: expected a float64 array of shape
/// (n, 2, 2), got ...".
py::array_t<double, py::array::c_style> batch_array(const py::handle& obj, const std::string& name,
                                                     const std::vector<py::ssize_t>& tail, py::ssize_t n = -1);

/// Shape as text, e.g. "(n, 2, 2)" or "(5, 3)".
std::string shape_text(py::ssize_t n, const std::vector<py::ssize_t>& tail);

/// Rows of d-vectors as a new (count, d) float64 array.
template <int d>
py::array_t<double> rows(const std::vector<Vec<d>>& v) {
    py::array_t<double> a({static_cast<py::ssize_t>(v.size()), static_cast<py::ssize_t>(d)});
    double* out = a.mutable_data();
    for (std::size_t i = 0; i < v.size(); ++i)
        for (int k = 0; k < d; ++k) out[d * i + k] = v[i][k];
    return a;
}

/// A scene given as a Scene, a dict with the scene files' schema, or a path.
Scene scene_of(const py::object& scene);

/// Batch of dim x dim matrices from an (n, dim, dim) array (entry [p, i, j] = F_p(i, j)).
template <int dim>
std::vector<Mat<dim>> to_matrices(const py::array_t<double, py::array::c_style>& a) {
    const std::size_t n = static_cast<std::size_t>(a.shape(0));
    std::vector<Mat<dim>> out(n);
    const double* data = a.data();
    for (std::size_t p = 0; p < n; ++p)
        for (int i = 0; i < dim; ++i)
            for (int j = 0; j < dim; ++j) out[p](i, j) = data[(p * dim + i) * dim + j];
    return out;
}

/// (n, dim, dim) float64 array of the matrices.
template <int dim>
py::array_t<double> from_matrices(const std::vector<Mat<dim>>& F) {
    py::array_t<double> a({static_cast<py::ssize_t>(F.size()), static_cast<py::ssize_t>(dim),
                           static_cast<py::ssize_t>(dim)});
    double* data = a.mutable_data();
    for (std::size_t p = 0; p < F.size(); ++p)
        for (int i = 0; i < dim; ++i)
            for (int j = 0; j < dim; ++j) data[(p * dim + i) * dim + j] = F[p](i, j);
    return a;
}

/// A Python object (dict, list, numbers, strings) as JSON, through the json
/// module; ValueError naming `what` if it is not JSON-serializable.
nlohmann::json to_json(const py::handle& obj, const std::string& what);

/// A Python int or float as a double; TypeError "<what>: expected a number, got <type>" otherwise
/// (bool included).
double to_number(const py::handle& obj, const std::string& what);

/// A Python str; TypeError "<what>: expected a string, got <type>" otherwise.
std::string to_text(const py::handle& obj, const std::string& what);

/// JSON as Python objects (dict, list, float, int, str, bool, None).
py::object to_python(const nlohmann::json& j);

}  // namespace pnet::bindings

namespace pnet::bindings {

/// A str or os.PathLike as a path string (os.fspath).
std::string path_string(const py::handle& obj);

/// A nodal field as a new array of shape (nodes_x, nodes_y[, nodes_z]), index
/// [i, j(, k)] = node (i, j, k) (metrics.cpp).
py::array to_numpy(const GridField& field);

}  // namespace pnet::bindings
