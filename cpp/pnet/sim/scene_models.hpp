#pragma once
// What a run of a scene needs besides the scene: the integrator settings (the
// scene's integrator block, optionally another integrator) and the energy
// models its objects name, loaded and checked. Shared by `pnet simulate` and
// the Python module; it is in pnet_torch because loading a model file needs
// LibTorch (this header and its .cpp include none of it).
#include <string>

#include "pnet/sim/mpm_simulation.hpp"
#include "pnet/scene/scene.hpp"

namespace pnet {

/// The scene's integrator settings; when `integrator` is not empty and differs
/// from the scene's, that integrator with its own default step (explicit: the
/// CFL step; the implicit ones: 1e-3 s for particles (with or without meshes), 1e-2 s for meshes
/// alone, docs/scenes.md), keeping the
/// scene's implicit options. Throws std::invalid_argument for an unknown
/// integrator name or a bad option in the scene.
IntegratorSettings integrator_settings(const Scene& scene, const std::string& integrator = "");

/// Loads every energy model the scene's objects and meshes name into settings.models (one
/// entry per object, then per mesh; null where none is named, and for every object when the
/// integrator reads no model: IntegratorInfo::reads_models). Each
/// must exist, be trusted (pinned by its folder's MANIFEST, or trusted_models)
/// and be an energy of the scene's dimension. Errors name
/// "<scene file>: objects[k].model: " (meshes[k].model) and keep their type: FileNotFoundError,
/// UntrustedModelError, otherwise SceneError.
void load_scene_models(const Scene& scene, bool trusted_models, IntegratorSettings& settings);

}  // namespace pnet
