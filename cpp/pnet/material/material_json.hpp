#pragma once
// JSON form of a MaterialDescription, shared by scene files, test vectors and
// model metadata:
//   {"name": "snow", "density": 400, "initial_hardening": -0.1,
//    "elasticity": {"model": "neo_hookean_snow", "E": 1.4e5, "nu": 0.2},
//    "plasticity": {"model": "cam_clay", "friction_angle_deg": 45, "xi": 0.5,
//                   "beta": 0.3, "variant": "exact"}}
// Omitted optional fields take the defaults of the C++ structs.
#include <nlohmann/json_fwd.hpp>
#include <string>

#include "pnet/material/material.hpp"

namespace pnet {

/// Parses and validates; errors are std::invalid_argument naming the JSON
/// path (e.g. "material.elasticity.nu") and what was expected.
MaterialDescription material_from_json(const nlohmann::json& j, const std::string& path = "material");

nlohmann::json material_to_json(const MaterialDescription& description);

}  // namespace pnet
