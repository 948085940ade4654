// Bad input gives a clear std::invalid_argument, never NaN or a crash.
#include <gtest/gtest.h>

#include <limits>
#include <nlohmann/json.hpp>

#include "pnet/material/material.hpp"
#include "pnet/material/material_json.hpp"

namespace pnet {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

/// Expects std::invalid_argument whose message contains every fragment.
template <typename Fn>
void expect_error(Fn&& fn, std::initializer_list<const char*> fragments) {
    try {
        fn();
        ADD_FAILURE() << "no exception thrown";
    } catch (const std::invalid_argument& e) {
        const std::string what = e.what();
        for (const char* fragment : fragments)
            EXPECT_NE(what.find(fragment), std::string::npos) << "message '" << what << "' lacks '" << fragment << "'";
    }
}

TEST(MaterialValidation, RejectsBadElasticParameters) {
    for (double E : {0.0, -1.0, kNaN, kInf}) {
        MaterialDescription m = material_preset("sand");
        m.elastic.E = E;
        expect_error([&] { Material<2>{m}; }, {"material 'sand'", "E = "});
    }
    for (double nu : {0.5, 0.7, -1.0, kNaN}) {
        MaterialDescription m = material_preset("snow");
        m.elastic.nu = nu;
        expect_error([&] { Material<3>{m}; }, {"material 'snow'", "nu = ", "< 0.5"});
    }
}

TEST(MaterialValidation, RejectsBadPlasticityParameters) {
    MaterialDescription sand = material_preset("sand");
    sand.drucker_prager.friction_angle_deg = 90.0;
    expect_error([&] { sand.validate(); }, {"friction_angle_deg = 90"});
    MaterialDescription snow = material_preset("snow");
    snow.cam_clay.beta = -0.1;
    expect_error([&] { snow.validate(); }, {"beta = -0.1"});
    snow = material_preset("snow");
    snow.cam_clay.xi = kNaN;
    expect_error([&] { snow.validate(); }, {"xi = nan"});
    MaterialDescription metal = material_preset("metal");
    metal.von_mises.hardening_coefficient = -1.0;
    expect_error([&] { metal.validate(); }, {"hardening_coefficient = -1"});
    metal = material_preset("metal");
    metal.initial_hardening = -0.1;
    expect_error([&] { metal.validate(); }, {"initial_hardening = -0.1"});
}

TEST(MaterialValidation, RejectsUnsupportedPairs) {
    MaterialDescription m = material_preset("sand");
    m.elasticity = ElasticityModel::NeoHookeanSnow;
    expect_error([&] { Material<2>{m}; }, {"drucker_prager", "requires elasticity 'stvk_hencky'"});
    m = material_preset("snow");
    m.elasticity = ElasticityModel::StvkHencky;
    expect_error([&] { Material<3>{m}; }, {"cam_clay", "neo_hookean_snow"});
}

TEST(MaterialValidation, RejectsNonFiniteDeformationAndHardening) {
    const Material<3> snow(material_preset("snow"));
    Mat<3> F = Mat<3>::Identity();
    F(1, 2) = kNaN;
    expect_error([&] { snow.elastoplastic_stress(F, -0.1); }, {"deformation gradient F", "(1, 2)"});
    expect_error([&] { snow.elasticity().P(F); }, {"non-finite"});
    expect_error([&] { snow.elastoplastic_stress(Mat<3>::Identity(), kNaN); }, {"hardening state is not finite"});
    const Material<2> metal(material_preset("metal_nh"));
    expect_error([&] { metal.elastoplastic_stress(Mat<2>::Identity(), -0.5); }, {"h = -0.5", ">= 0"});
}

TEST(MaterialJson, RoundTripsEveryPreset) {
    for (const std::string& name : material_preset_names()) {
        const MaterialDescription m = material_preset(name);
        const MaterialDescription back = material_from_json(material_to_json(m));
        EXPECT_EQ(material_to_json(back), material_to_json(m)) << name;
    }
}

TEST(MaterialJson, ErrorsNameThePath) {
    using nlohmann::json;
    json j = material_to_json(material_preset("snow"));
    j["elasticity"]["nu"] = "0.2";
    expect_error([&] { material_from_json(j); }, {"material.elasticity.nu", "expected a number, got string"});
    j = material_to_json(material_preset("snow"));
    j["elasticity"]["nu"] = 0.5;
    expect_error([&] { material_from_json(j, "objects[0].material"); }, {"objects[0].material.elasticity", "nu = 0.5"});
    j = material_to_json(material_preset("snow"));
    j["plasticity"]["model"] = "mohr_coulomb";
    expect_error([&] { material_from_json(j); }, {"material.plasticity.model", "unknown plasticity model 'mohr_coulomb'"});
    j = material_to_json(material_preset("snow"));
    j["plasticity"]["variant"] = "fast";
    expect_error([&] { material_from_json(j); }, {"material.plasticity.variant", "'fast'"});
    j = material_to_json(material_preset("sand"));
    j["plasticity"]["xi"] = 0.5;
    expect_error([&] { material_from_json(j); }, {"material.plasticity.xi", "unknown field"});
    j = material_to_json(material_preset("sand"));
    j.erase("elasticity");
    expect_error([&] { material_from_json(j); }, {"material.elasticity", "missing"});
    expect_error([&] { material_from_json(json::array()); }, {"material", "expected an object, got array"});
}

}  // namespace
}  // namespace pnet
