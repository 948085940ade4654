#include "pnet/nn/model_file.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>

#include "pnet/material/material_json.hpp"

namespace pnet {

namespace {

using nlohmann::json;
namespace fs = std::filesystem;

constexpr const char* kFormat = "plasticitynet-model";
constexpr int kFormatVersion = 1;
constexpr const char* kManifestFormat = "plasticitynet-manifest";

[[noreturn]] void fail(const std::string& context, const std::string& field, const std::string& problem) {
    throw std::invalid_argument(context + ": metadata." + field + ": " + problem);
}

const json& field(const json& j, const std::string& key, const std::string& context) {
    if (!j.contains(key)) fail(context, key, "missing");
    return j.at(key);
}

int integer(const json& j, const std::string& key, const std::string& context) {
    const json& v = field(j, key, context);
    if (!v.is_number_integer()) fail(context, key, std::string("expected an integer, got ") + v.dump());
    return v.get<int>();
}

std::string text(const json& j, const std::string& key, const std::string& context) {
    const json& v = field(j, key, context);
    if (!v.is_string()) fail(context, key, std::string("expected a string, got ") + v.dump());
    return v.get<std::string>();
}

std::string widths_string(const std::vector<int>& widths) {
    std::string s = "[";
    for (std::size_t k = 0; k < widths.size(); ++k) s += (k ? ", " : "") + std::to_string(widths[k]);
    return s + "]";
}

}  // namespace

std::string to_string(ModelKind kind) { return kind == ModelKind::Energy ? "energy" : "return_map"; }

std::string to_string(EnergyRepresentation representation) {
    return representation == EnergyRepresentation::Raw ? "raw" : "principal";
}

std::string to_string(EnergyForm form) {
    switch (form) {
        case EnergyForm::Eq8: return "eq8";
        case EnergyForm::LocalIdentity: return "local_identity";
        case EnergyForm::GlobalIdentity: return "global_identity";
        case EnergyForm::Global: return "global";
    }
    return "?";
}

ModelMetadata parse_model_metadata(const json& j, const std::string& context) {
    if (!j.is_object()) throw std::invalid_argument(context + ": metadata.json is not a JSON object");
    ModelMetadata meta;
    meta.json = j;

    const std::string format = text(j, "format", context);
    if (format != kFormat) fail(context, "format", "\"" + format + "\" is not \"" + kFormat + "\"");
    const int version = integer(j, "format_version", context);
    if (version != kFormatVersion)
        fail(context, "format_version",
             std::to_string(version) + " is not supported (this build reads version " +
                 std::to_string(kFormatVersion) + ")");

    const std::string kind = text(j, "kind", context);
    if (kind == "energy")
        meta.kind = ModelKind::Energy;
    else if (kind == "return_map")
        meta.kind = ModelKind::ReturnMap;
    else
        fail(context, "kind", "\"" + kind + "\" is not \"energy\" or \"return_map\"");

    meta.dim = integer(j, "dim", context);
    if (meta.dim != 2 && meta.dim != 3) fail(context, "dim", std::to_string(meta.dim) + " is not 2 or 3");
    const int d = meta.dim;

    const json& widths = field(j, "widths", context);
    if (!widths.is_array() || widths.size() < 2) fail(context, "widths", "expected a list of at least 2 widths");
    for (const json& w : widths) {
        if (!w.is_number_integer() || w.get<int>() <= 0) fail(context, "widths", "expected positive integers");
        meta.widths.push_back(w.get<int>());
    }
    if (meta.widths.back() != 1) fail(context, "widths", widths_string(meta.widths) + " must end in 1");
    const int input_width = integer(j, "input_width", context);
    if (input_width != meta.widths.front())
        fail(context, "input_width",
             std::to_string(input_width) + " differs from widths " + widths_string(meta.widths));

    if (meta.kind == ModelKind::Energy) {
        const json& h = field(j, "has_hardening", context);
        if (!h.is_boolean()) fail(context, "has_hardening", "expected true or false");
        meta.has_hardening = h.get<bool>();
        if (j.contains("representation")) {  // files written before it existed are raw
            const std::string representation = text(j, "representation", context);
            if (representation == "raw")
                meta.representation = EnergyRepresentation::Raw;
            else if (representation == "principal")
                meta.representation = EnergyRepresentation::Principal;
            else
                fail(context, "representation", "\"" + representation + "\" is not \"raw\" or \"principal\"");
        }
        if (j.contains("energy_form")) {  // files written before it existed are eq. 8
            const std::string form = text(j, "energy_form", context);
            bool known = false;
            for (EnergyForm f : {EnergyForm::Eq8, EnergyForm::LocalIdentity, EnergyForm::GlobalIdentity,
                                 EnergyForm::Global})
                if (form == to_string(f)) meta.energy_form = f, known = true;
            if (!known)
                fail(context, "energy_form",
                     "\"" + form + "\" is not \"eq8\", \"local_identity\", \"global_identity\" or \"global\"");
        }
        const bool raw = meta.representation == EnergyRepresentation::Raw;
        // A parametric energy's inputs follow (checked with the material below).
        const int parameters =
            j.contains("parameters") && j.at("parameters").is_array() ? static_cast<int>(j.at("parameters").size()) : 0;
        const int expected = (raw ? 2 * d * d : d * d + d) + (meta.has_hardening ? 1 : 0) + parameters;
        if (input_width != expected)
            fail(context, "input_width",
                 std::to_string(input_width) + ": a " + std::to_string(d) + "D " + to_string(meta.representation) +
                     " energy " + (meta.has_hardening ? "with" : "without") + " hardening takes [" +
                     (raw ? "vec F, vec F0" : "vec G, Sigma0") + (meta.has_hardening ? ", h" : "") +
                     (parameters ? ", " + std::to_string(parameters) + " parameters" : std::string()) + "], " +
                     std::to_string(expected) + " inputs");
    } else if (input_width != d + 1) {
        fail(context, "input_width",
             std::to_string(input_width) + ": a " + std::to_string(d) + "D return map takes [Sigma, h], " +
                 std::to_string(d + 1) + " inputs");
    }

    const std::string activation = text(j, "activation", context);
    if (activation != "silu") fail(context, "activation", "\"" + activation + "\" is not supported (only \"silu\")");

    const json& params = field(j, "layer_parameters", context);
    if (!params.is_array() || params.size() != meta.widths.size() - 1)
        fail(context, "layer_parameters",
             "expected " + std::to_string(meta.widths.size() - 1) + " [weight, bias] name pairs");
    for (const json& pair : params)
        if (!pair.is_array() || pair.size() != 2 || !pair[0].is_string() || !pair[1].is_string())
            fail(context, "layer_parameters", "expected [weight name, bias name] pairs, got " + pair.dump());

    const json& E = field(j, "training_E", context);
    if (!E.is_number() || !(E.get<double>() > 0.0)) fail(context, "training_E", "expected a positive number");
    meta.training_E = E.get<double>();

    const json& material = field(j, "material", context);
    try {
        meta.material = material_from_json(material, "metadata.material");
        meta.material.validate();
        if (d == 2)
            Material<2>{meta.material};
        else
            Material<3>{meta.material};
    } catch (const std::invalid_argument& e) {
        throw std::invalid_argument(context + ": " + e.what());
    }
    if (meta.material.elastic.E != meta.training_E)
        fail(context, "material.elasticity.E", "differs from training_E");

    // The hardening range the network saw in training: recipe.distribution.h_range.
    const bool takes_hardening = meta.kind == ModelKind::ReturnMap || meta.has_hardening;
    if (takes_hardening) {
        if (meta.material.plasticity == PlasticityModel::CamClay) {
            meta.hardening_min = d == 2 ? -0.5 : -1.0;  // docs/physics.md, for files that do not say
            meta.hardening_max = 0.0;
        } else {
            meta.hardening_min = 0.0;
            meta.hardening_max = 1.0;
        }
        const json* range = nullptr;
        if (j.contains("recipe") && j.at("recipe").is_object() && j.at("recipe").contains("distribution") &&
            j.at("recipe").at("distribution").is_object() && j.at("recipe").at("distribution").contains("h_range"))
            range = &j.at("recipe").at("distribution").at("h_range");
        if (range) {
            if (!range->is_array() || range->size() != 2 || !(*range)[0].is_number() || !(*range)[1].is_number() ||
                !std::isfinite((*range)[0].get<double>()) || !std::isfinite((*range)[1].get<double>()) ||
                !((*range)[0].get<double>() <= (*range)[1].get<double>()))
                fail(context, "recipe.distribution.h_range",
                     "expected [low, high] with finite low <= high, got " + range->dump());
            meta.hardening_min = (*range)[0].get<double>();
            meta.hardening_max = (*range)[1].get<double>();
        }
    }

    if (j.contains("parameters")) {
        if (meta.kind != ModelKind::Energy) fail(context, "parameters", "only an energy can be parametric");
        const json& list = j.at("parameters");
        if (!list.is_array() || list.empty()) fail(context, "parameters", "expected a non-empty list");
        for (std::size_t k = 0; k < list.size(); ++k) {
            const json& e = list[k];
            const std::string at = "parameters[" + std::to_string(k) + "]";
            if (!e.is_object() || !e.contains("field") || !e.at("field").is_string() || !e.contains("min") ||
                !e.at("min").is_number() || !e.contains("max") || !e.at("max").is_number())
                fail(context, at, "expected {\"field\": string, \"min\": number, \"max\": number}, got " + e.dump());
            ModelParameter p{e.at("field").get<std::string>(), e.at("min").get<double>(), e.at("max").get<double>()};
            if (!material_parameter(meta.material, p.field))
                fail(context, at + ".field",
                     "\"" + p.field + "\" is not a parameter of the material's models (" +
                         to_string(meta.material.elasticity) + ", " + to_string(meta.material.plasticity) + ")");
            if (!(std::isfinite(p.min) && std::isfinite(p.max) && p.min < p.max))
                fail(context, at, "the range [" + e.at("min").dump() + ", " + e.at("max").dump() +
                                      "] must be finite with min < max");
            for (const ModelParameter& q : meta.parameters)
                if (q.field == p.field) fail(context, at + ".field", "\"" + p.field + "\" is listed twice");
            meta.parameters.push_back(std::move(p));
        }
    }

    if (meta.kind == ModelKind::Energy && j.contains("return_map")) {
        const json& rm = j.at("return_map");
        if (!rm.is_object() || !rm.contains("type") || !rm.at("type").is_string())
            fail(context, "return_map", "expected {\"type\": \"analytic\"} or {\"type\": \"learned\", ...}");
        const std::string type = rm.at("type").get<std::string>();
        if (type == "learned") {
            meta.return_map_file = text(rm, "file", context + ": metadata.return_map");
            meta.return_map_sha256 = text(rm, "sha256", context + ": metadata.return_map");
            if (meta.return_map_file.empty()) fail(context, "return_map.file", "empty");
        } else if (type != "analytic") {
            fail(context, "return_map.type", "\"" + type + "\" is not \"analytic\" or \"learned\"");
        }
    }
    return meta;
}

MaterialDescription material_for_object(const ModelMetadata& meta, const MaterialDescription& object,
                                        const std::string& model_path) {
    // A model is used only for the materials it was trained for: the correction c uses the model's return
    // mapping, G2P the scene's, so any other difference would mix two materials (docs/methods.md).
    auto refuse_differences = [&](const MaterialDescription& model) {
        const std::vector<MaterialDifference> differences = constitutive_differences(model, object);
        if (differences.empty()) return;
        const MaterialDifference& d = differences.front();
        throw std::invalid_argument(model_path + " was trained for material." + d.field + " = " + d.first +
                                    ", the object's material has " + d.second +
                                    (meta.parametric() ? " (of its material, only the model's parameters may vary)"
                                                       : " (a model is used only for the material it was trained for)"));
    };
    if (object.elasticity != meta.material.elasticity || object.plasticity != meta.material.plasticity)
        refuse_differences(meta.material);
    MaterialDescription out = meta.material;  // at the training E
    for (const ModelParameter& p : meta.parameters) {
        const double value = *material_parameter(object, p.field);  // same models: the field exists
        if (!(value >= p.min && value <= p.max))
            throw std::invalid_argument(model_path + ": material." + p.field + " = " + json(value).dump() +
                                        " is outside the range [" + json(p.min).dump() + ", " + json(p.max).dump() +
                                        "] this parametric model was trained for");
        *material_parameter(out, p.field) = value;
    }
    refuse_differences(out);
    return out;
}

std::vector<double> parameter_inputs(const ModelMetadata& meta, const MaterialDescription& material) {
    std::vector<double> u;
    for (const ModelParameter& p : meta.parameters) u.push_back(p.input(*material_parameter(material, p.field)));
    return u;
}

double ModelMetadata::network_hardening(double state, bool* clamped) const {
    const double h = material.plasticity == PlasticityModel::CamClay ? std::min(state, 0.0) : state;
    const double c = std::clamp(h, hardening_min, hardening_max);
    if (clamped) *clamped = c != h;
    return c;
}

std::optional<std::string> manifest_sha256(const std::string& model_path) {
    const fs::path path(model_path);
    const fs::path manifest = path.parent_path().empty() ? fs::path("MANIFEST") : path.parent_path() / "MANIFEST";
    if (!fs::is_regular_file(manifest)) return std::nullopt;
    std::ifstream in(manifest);
    json j;
    try {
        j = json::parse(in);
    } catch (const json::exception& e) {
        throw std::invalid_argument(manifest.string() + ": not valid JSON (" + e.what() + ")");
    }
    auto bad = [&](const std::string& problem) {
        throw std::invalid_argument(manifest.string() + ": " + problem);
    };
    if (!j.is_object() || j.value("format", "") != kManifestFormat)
        bad(std::string("expected an object with \"format\": \"") + kManifestFormat + "\"");
    if (!j.contains("models") || !j.at("models").is_array()) bad("\"models\": expected a list");
    const std::string name = path.filename().string();
    for (std::size_t i = 0; i < j.at("models").size(); ++i) {
        const json& entry = j.at("models")[i];
        if (!entry.is_object() || !entry.contains("file") || !entry.at("file").is_string() ||
            !entry.contains("sha256") || !entry.at("sha256").is_string())
            bad("models[" + std::to_string(i) + "]: expected {\"file\": ..., \"sha256\": ...}");
        if (entry.at("file").get<std::string>() == name) return entry.at("sha256").get<std::string>();
    }
    return std::nullopt;
}

}  // namespace pnet
