#include "pnet/material/material_json.hpp"

#include <nlohmann/json.hpp>
#include <set>
#include <stdexcept>

namespace pnet {

namespace {

using nlohmann::json;

[[noreturn]] void fail(const std::string& path, const std::string& problem) {
    throw std::invalid_argument(path + ": " + problem);
}

const json& require_object(const json& j, const std::string& path) {
    if (!j.is_object()) fail(path, std::string("expected an object, got ") + j.type_name());
    return j;
}

void reject_unknown_keys(const json& j, const std::string& path, const std::set<std::string>& known) {
    for (const auto& item : j.items())
        if (!known.count(item.key())) fail(path + "." + item.key(), "unknown field");
}

double number(const json& j, const std::string& key, const std::string& path, double fallback, bool required) {
    if (!j.contains(key)) {
        if (required) fail(path + "." + key, "missing (expected a number)");
        return fallback;
    }
    const json& v = j.at(key);
    if (!v.is_number()) fail(path + "." + key, std::string("expected a number, got ") + v.type_name());
    return v.get<double>();
}

std::string text(const json& j, const std::string& key, const std::string& path, const std::string& fallback,
                 bool required) {
    if (!j.contains(key)) {
        if (required) fail(path + "." + key, "missing (expected a string)");
        return fallback;
    }
    const json& v = j.at(key);
    if (!v.is_string()) fail(path + "." + key, std::string("expected a string, got ") + v.type_name());
    return v.get<std::string>();
}

/// Runs `parse`, prefixing an invalid_argument from a model-name lookup or a
/// parameter check with the JSON path of the field.
template <typename Fn>
auto at_path(const std::string& path, Fn&& parse) {
    try {
        return parse();
    } catch (const std::invalid_argument& e) {
        const std::string what = e.what();
        if (what.rfind(path, 0) == 0) throw;  // already names a path below this one
        throw std::invalid_argument(path + ": " + what);
    }
}

}  // namespace

MaterialDescription material_from_json(const json& j, const std::string& path) {
    require_object(j, path);
    reject_unknown_keys(j, path, {"name", "density", "initial_hardening", "elasticity", "plasticity"});
    MaterialDescription m;
    m.name = text(j, "name", path, "custom", false);
    m.density = number(j, "density", path, m.density, false);
    m.initial_hardening = number(j, "initial_hardening", path, m.initial_hardening, false);

    const std::string epath = path + ".elasticity";
    if (!j.contains("elasticity")) fail(epath, "missing (expected an object with model, E, nu)");
    const json& e = require_object(j.at("elasticity"), epath);
    reject_unknown_keys(e, epath, {"model", "E", "nu"});
    m.elasticity = at_path(epath + ".model", [&] { return elasticity_model_from_string(text(e, "model", epath, "", true)); });
    m.elastic.E = number(e, "E", epath, 0.0, true);
    m.elastic.nu = number(e, "nu", epath, 0.0, true);
    at_path(epath, [&] { m.elastic.validate(); return 0; });

    const std::string ppath = path + ".plasticity";
    const json p = j.contains("plasticity") ? j.at("plasticity") : json{{"model", "none"}};
    require_object(p, ppath);
    m.plasticity = at_path(ppath + ".model", [&] { return plasticity_model_from_string(text(p, "model", ppath, "", true)); });
    switch (m.plasticity) {
        case PlasticityModel::None: reject_unknown_keys(p, ppath, {"model"}); break;
        case PlasticityModel::DruckerPrager:
            reject_unknown_keys(p, ppath, {"model", "friction_angle_deg"});
            m.drucker_prager.friction_angle_deg =
                number(p, "friction_angle_deg", ppath, m.drucker_prager.friction_angle_deg, false);
            break;
        case PlasticityModel::CamClay:
            reject_unknown_keys(p, ppath, {"model", "friction_angle_deg", "xi", "beta", "variant"});
            m.cam_clay.friction_angle_deg = number(p, "friction_angle_deg", ppath, m.cam_clay.friction_angle_deg, false);
            m.cam_clay.xi = number(p, "xi", ppath, m.cam_clay.xi, false);
            m.cam_clay.beta = number(p, "beta", ppath, m.cam_clay.beta, false);
            m.cam_clay.variant = at_path(ppath + ".variant", [&] {
                return cam_clay_variant_from_string(text(p, "variant", ppath, "exact", false));
            });
            break;
        case PlasticityModel::VonMises:
            reject_unknown_keys(p, ppath, {"model", "hardening_coefficient"});
            m.von_mises.hardening_coefficient =
                number(p, "hardening_coefficient", ppath, m.von_mises.hardening_coefficient, false);
            break;
    }
    at_path(path, [&] { m.validate(); return 0; });
    return m;
}

json material_to_json(const MaterialDescription& m) {
    json plasticity = {{"model", to_string(m.plasticity)}};
    switch (m.plasticity) {
        case PlasticityModel::None: break;
        case PlasticityModel::DruckerPrager:
            plasticity["friction_angle_deg"] = m.drucker_prager.friction_angle_deg;
            break;
        case PlasticityModel::CamClay:
            plasticity["friction_angle_deg"] = m.cam_clay.friction_angle_deg;
            plasticity["xi"] = m.cam_clay.xi;
            plasticity["beta"] = m.cam_clay.beta;
            plasticity["variant"] = to_string(m.cam_clay.variant);
            break;
        case PlasticityModel::VonMises:
            plasticity["hardening_coefficient"] = m.von_mises.hardening_coefficient;
            break;
    }
    return {{"name", m.name},
            {"density", m.density},
            {"initial_hardening", m.initial_hardening},
            {"elasticity", {{"model", to_string(m.elasticity)}, {"E", m.elastic.E}, {"nu", m.elastic.nu}}},
            {"plasticity", plasticity}};
}

}  // namespace pnet
