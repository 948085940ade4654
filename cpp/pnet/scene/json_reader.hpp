#pragma once
// Reading a scene file's JSON with errors that name the file, the field's path and the problem
// ("<file>: objects[0].velocity: expected an array of 2 numbers (dim = 2), got ..."), for
// scene.cpp's readers of each block.
#include <algorithm>
#include <cmath>
#include <sstream>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "pnet/scene/scene.hpp"

namespace pnet::scene_json {

using nlohmann::json;

/// A JSON value for "got ...": short, as written in the file.
inline std::string show(const json& value) {
    std::string text = value.dump();
    if (text.size() > 60) text = text.substr(0, 57) + "...";
    return text;
}

inline std::string show(double value) {
    std::ostringstream out;
    out.precision(10);  // enough to tell 3 dx = 0.01171875 from a rounded value in a message
    out << value;
    return out.str();
}

inline std::string show(const Eigen::VectorXd& v) {
    std::string text = "(";
    for (Eigen::Index i = 0; i < v.size(); ++i) text += (i ? ", " : "") + show(v[i]);
    return text + ")";
}

inline std::string join(const std::string& path, const std::string& key) {
    return path.empty() ? key : path + "." + key;
}

inline std::string index_path(const std::string& path, std::size_t i) {
    return path + "[" + std::to_string(i) + "]";
}

/// Reads JSON values and fails with "<file>: <path>: <problem>".
class Reader {
public:
    explicit Reader(std::string file) : file_(std::move(file)) {}

    [[noreturn]] void fail(const std::string& path, const std::string& problem) const {
        throw SceneError(file_ + ": " + path + ": " + problem);
    }

    const std::string& file() const { return file_; }

    void require_object(const json& j, const std::string& path) const {
        if (!j.is_object()) fail(path, "expected an object, got " + show(j));
    }

    /// `hint` lists the keys that are allowed, where the set depends on context (the shape).
    void reject_unknown_keys(const json& j, const std::string& path, const std::vector<std::string>& known,
                             const std::string& hint = "") const {
        for (const auto& item : j.items())
            if (std::find(known.begin(), known.end(), item.key()) == known.end())
                fail(join(path, item.key()), "unknown field" + hint);
    }

    /// The field, or nullptr when absent.
    static const json* find(const json& j, const std::string& key) {
        const auto it = j.find(key);
        return it == j.end() ? nullptr : &*it;
    }

    const json& require(const json& j, const std::string& key, const std::string& path,
                        const std::string& expected) const {
        const json* v = find(j, key);
        if (!v) fail(join(path, key), "missing (expected " + expected + ")");
        return *v;
    }

    /// A finite number (nlohmann lets NaN and infinity into JSON built in memory).
    double number(const json& v, const std::string& path, const std::string& expected = "a number") const {
        if (!v.is_number() || !std::isfinite(v.get<double>())) fail(path, "expected " + expected + ", got " + show(v));
        return v.get<double>();
    }

    double positive(const json& v, const std::string& path) const {
        const double x = number(v, path, "a positive number");
        if (!(x > 0.0)) fail(path, "expected a positive number, got " + show(v));
        return x;
    }

    double non_negative(const json& v, const std::string& path) const {
        const double x = number(v, path, "a number >= 0");
        if (x < 0.0) fail(path, "expected a number >= 0, got " + show(v));
        return x;
    }

    /// An integer >= `least`; 2.0 is accepted (some writers emit every number as a float).
    int integer(const json& v, const std::string& path, int least) const {
        const std::string expected = "an integer >= " + std::to_string(least);
        const double x = number(v, path, expected);
        if (x != std::floor(x) || x < least || x > 1e9) fail(path, "expected " + expected + ", got " + show(v));
        return static_cast<int>(x);
    }

    std::string text(const json& v, const std::string& path) const {
        if (!v.is_string()) fail(path, "expected a string, got " + show(v));
        return v.get<std::string>();
    }

    Eigen::VectorXd vector(const json& v, const std::string& path, int dim) const {
        if (!v.is_array() || static_cast<int>(v.size()) != dim)
            fail(path, "expected an array of " + std::to_string(dim) + " numbers (dim = " + std::to_string(dim) +
                           "), got " + show(v));
        Eigen::VectorXd x(dim);
        for (int i = 0; i < dim; ++i) x[i] = number(v[i], index_path(path, i));
        return x;
    }

private:
    std::string file_;
};

}  // namespace pnet::scene_json
