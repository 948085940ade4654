#pragma once
// The C++ side of the material cross-check: evaluates one test-vector case
// (tests/data/material_vectors_*.json) and compares two "expect" objects.
//
// A case is {"name", "dim", "material": <description>, "F": [d*d row-major],
// "hardening": h, "expect": {...}} with expect = Sigma, branch, Z_Sigma,
// hardening_new, F_elastic, Ptilde (the elastoplastic material) and psi, tau,
// P, dPdF (its elasticity alone, at F).
#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "pnet/material/material.hpp"
#include "pnet/material/material_json.hpp"

namespace pnet::test {

using nlohmann::json;

template <int dim>
Mat<dim> matrix_from_json(const json& values, const std::string& what) {
    if (!values.is_array() || values.size() != dim * dim)
        throw std::invalid_argument(what + ": expected " + std::to_string(dim * dim) + " numbers");
    Mat<dim> F;
    for (int i = 0; i < dim; ++i)
        for (int j = 0; j < dim; ++j) F(i, j) = values.at(i * dim + j).get<double>();
    return F;
}

template <typename Derived>
json to_json_array(const Eigen::MatrixBase<Derived>& m) {
    // Row-major order, as every flattened quantity in the vectors.
    json out = json::array();
    for (int i = 0; i < m.rows(); ++i)
        for (int j = 0; j < m.cols(); ++j) out.push_back(m(i, j));
    return out;
}

template <int dim>
json evaluate_case(const MaterialDescription& description, const Mat<dim>& F, double hardening) {
    const Material<dim> material(description);
    const Elasticity<dim>& elasticity = material.elasticity();
    const PolarSVD<dim> svd = clamped_svd<dim>(F);
    const PolarSVD<dim> raw = polar_svd<dim>(F);
    const ReturnResult<dim> Z = material.return_map(svd.Sigma, hardening);
    return {{"Sigma", to_json_array(raw.Sigma)},
            {"branch", to_string(Z.branch)},
            {"Z_Sigma", to_json_array(Z.Sigma)},
            {"hardening_new", Z.hardening},
            {"F_elastic", to_json_array(svd.compose(Z.Sigma))},
            {"Ptilde", to_json_array(material.elastoplastic_stress(F, hardening))},
            {"psi", elasticity.psi(svd.Sigma)},
            {"tau", to_json_array(elasticity.tau(svd.Sigma))},
            {"P", to_json_array(elasticity.P(F))},
            {"dPdF", to_json_array(elasticity.dPdF(svd))}};
}

inline json evaluate_case(const json& c) {
    const int dim = c.at("dim").get<int>();
    const MaterialDescription description = material_from_json(c.at("material"), "material");
    const double h = c.at("hardening").get<double>();
    if (dim == 2) return evaluate_case<2>(description, matrix_from_json<2>(c.at("F"), "F"), h);
    if (dim == 3) return evaluate_case<3>(description, matrix_from_json<3>(c.at("F"), "F"), h);
    throw std::invalid_argument("dim must be 2 or 3");
}

/// Largest relative discrepancy per quantity between `actual` and `expected`
/// (max|a - b| / max(max|b|, floor)); a branch mismatch is reported as +inf.
struct Discrepancy {
    std::string quantity;
    double relative = 0.0;
};

inline std::vector<Discrepancy> compare_expect(const json& actual, const json& expected, double mu) {
    std::vector<Discrepancy> out;
    for (const auto& item : expected.items()) {
        const std::string& key = item.key();
        if (!actual.contains(key)) throw std::runtime_error("quantity '" + key + "' is not computed by C++");
        if (key == "branch") {
            out.push_back({key, actual.at(key) == item.value() ? 0.0 : INFINITY});
            continue;
        }
        std::vector<double> a, b;
        if (item.value().is_array()) {
            a = actual.at(key).get<std::vector<double>>();
            b = item.value().get<std::vector<double>>();
        } else {
            a = {actual.at(key).get<double>()};
            b = {item.value().get<double>()};
        }
        if (a.size() != b.size()) throw std::runtime_error("quantity '" + key + "' has the wrong length");
        // Stresses are measured against a floor of mu 1e-6 so that a stress-free
        // state compares in absolute terms; hardening against 1e-6.
        double floor = 1e-300;
        if (key == "tau" || key == "P" || key == "Ptilde" || key == "dPdF") floor = mu * 1e-6;
        if (key == "psi") floor = mu * 1e-12;
        if (key == "hardening_new") floor = 1e-6;
        double max_b = 0.0, max_diff = 0.0;
        for (size_t i = 0; i < a.size(); ++i) {
            max_b = std::max(max_b, std::abs(b[i]));
            max_diff = std::max(max_diff, std::abs(a[i] - b[i]));
        }
        out.push_back({key, max_diff / std::max(max_b, floor)});
    }
    return out;
}

}  // namespace pnet::test
