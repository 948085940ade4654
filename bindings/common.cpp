#include "common.hpp"

#include <cmath>

namespace pnet::bindings {

std::string shape_text(py::ssize_t n, const std::vector<py::ssize_t>& tail) {
    std::string s = "(" + (n >= 0 ? std::to_string(n) : std::string("n"));
    for (py::ssize_t t : tail) s += ", " + std::to_string(t);
    return s + (tail.empty() ? ",)" : ")");
}

py::array_t<double, py::array::c_style> batch_array(const py::handle& obj, const std::string& name,
                                                     const std::vector<py::ssize_t>& tail, py::ssize_t n) {
    const std::string expected = name + ": expected a float64 array of shape " + shape_text(n, tail);
    py::array array;
    if (py::isinstance<py::array>(obj)) {
        array = py::reinterpret_borrow<py::array>(obj);
        if (!array.dtype().is(py::dtype::of<double>()))
            throw py::value_error(expected + ", got dtype " + py::str(array.dtype()).cast<std::string>());
    } else {
        try {
            array = py::array_t<double>::ensure(obj);
        } catch (const py::error_already_set&) {
            array = py::array();
        }
        if (!array) throw py::value_error(expected + ", got " + py::str(py::type::of(obj)).cast<std::string>());
    }
    bool ok = array.ndim() == static_cast<py::ssize_t>(tail.size() + 1) && (n < 0 || array.shape(0) == n);
    for (std::size_t k = 0; ok && k < tail.size(); ++k) ok = array.shape(static_cast<py::ssize_t>(k + 1)) == tail[k];
    if (!ok) {
        std::vector<py::ssize_t> got(array.shape(), array.shape() + array.ndim());
        std::string text = "(";
        for (std::size_t k = 0; k < got.size(); ++k) text += (k ? ", " : "") + std::to_string(got[k]);
        throw py::value_error(expected + ", got shape " + text + (got.size() == 1 ? ",)" : ")"));
    }
    // A C-contiguous float64 copy only when the array is strided.
    return py::array_t<double, py::array::c_style>::ensure(array);
}

namespace {

/// JSON has no NaN or infinity (Python's json.dumps would write them anyway, and the parser then
/// fails without naming the field): refuse them here, naming the path of the value.
void require_finite(const py::handle& obj, const std::string& path) {
    if (py::isinstance<py::float_>(obj)) {
        const double v = obj.cast<double>();
        if (!std::isfinite(v))
            throw py::value_error(path + ": expected a finite number, got " + py::repr(obj).cast<std::string>());
    } else if (py::isinstance<py::dict>(obj)) {
        for (const auto& [key, value] : obj.cast<py::dict>())
            require_finite(value, path + "." + py::str(key).cast<std::string>());
    } else if (py::isinstance<py::list>(obj) || py::isinstance<py::tuple>(obj)) {
        std::size_t i = 0;
        for (const py::handle item : obj) require_finite(item, path + "[" + std::to_string(i++) + "]");
    }
}

}  // namespace

double to_number(const py::handle& obj, const std::string& what) {
    // bool is an int in Python, but True as a time step is a mistake, not 1 s.
    if (py::isinstance<py::bool_>(obj) || !(py::isinstance<py::float_>(obj) || py::isinstance<py::int_>(obj)))
        throw py::type_error(what + ": expected a number, got " + py::str(py::type::of(obj)).cast<std::string>());
    return obj.cast<double>();
}

std::string to_text(const py::handle& obj, const std::string& what) {
    if (!py::isinstance<py::str>(obj))
        throw py::type_error(what + ": expected a string, got " + py::str(py::type::of(obj)).cast<std::string>());
    return obj.cast<std::string>();
}

nlohmann::json to_json(const py::handle& obj, const std::string& what) {
    require_finite(obj, what);
    std::string text;
    try {
        text = py::module_::import("json").attr("dumps")(obj).cast<std::string>();
    } catch (const py::error_already_set& e) {
        throw py::value_error(what + ": not JSON-serializable (" + std::string(e.what()) + ")");
    }
    return nlohmann::json::parse(text);
}

py::object to_python(const nlohmann::json& j) {
    return py::module_::import("json").attr("loads")(j.dump());
}

}  // namespace pnet::bindings

namespace pnet::bindings {

Scene scene_of(const py::object& scene) {
    if (py::isinstance<Scene>(scene)) return scene.cast<Scene>();
    if (py::isinstance<py::dict>(scene)) return scene_from_json(to_json(scene, "<dict>"), "<dict>", "");
    return load_scene(path_string(scene));
}

std::string path_string(const py::handle& obj) {
    return py::module_::import("os").attr("fspath")(obj).cast<std::string>();
}

}  // namespace pnet::bindings
