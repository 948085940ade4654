#include "pnet/sim/scene_models.hpp"

#include <memory>

#include "pnet/nn/model_file.hpp"

namespace pnet {

IntegratorSettings integrator_settings(const Scene& scene, const std::string& integrator) {
    IntegratorSettings settings = IntegratorSettings::from_scene(scene);
    if (!integrator.empty() && integrator != scene.integrator.name) {
        // The scene's dt belongs to the scene's integrator.
        settings.name = integrator;
        // docs/scenes.md: implicit MPM (and particles beside meshes, the coupling) at 1e-3 s, implicit FEM
        // at 1e-2 s (the paper's).
        settings.dt = integrator_info(parse_integrator(integrator, "integrator")).implicit
                          ? (scene.has_particles() ? 1e-3 : 1e-2)
                          : 0.0;
    }
    const IntegratorInfo& info = integrator_info(parse_integrator(settings.name, "integrator"));
    const bool particles = scene.has_particles(), meshes = scene.has_meshes();
    if ((particles && !info.particles) || (meshes && !info.meshes))
        throw std::invalid_argument("integrator: \"" + settings.name + "\" is for " +
                                    (info.meshes ? "FEM meshes" : "particles") + "; this scene takes " +
                                    integrator_names(particles, meshes && !particles));
    return settings;
}

void load_scene_models(const Scene& scene, bool trusted_models, IntegratorSettings& settings) {
    settings.models.clear();
    std::vector<std::pair<std::string, std::string>> models;  // (file, json path) per object or mesh
    for (const SceneObject& object : scene.objects) models.emplace_back(object.model, object.json_path);
    for (const SceneMesh& mesh : scene.meshes) models.emplace_back(mesh.model, mesh.json_path);
    // Only an integrator that reads models opens them (solver/integrators.hpp: plasticitynet);
    // return_map, lagged, analytic and explicit compute the same with any model file or none.
    const bool reads = integrator_info(settings.method()).reads_models;
    for (const auto& [model, json_path] : models) {
        settings.models.emplace_back();
        if (model.empty() || !reads) continue;
        LoadOptions load;
        load.expected_dim = scene.dim;
        load.expected_kind = ModelKind::Energy;
        load.trusted = trusted_models;
        const std::string where = scene.file + ": " + json_path + ".model: ";
        try {
            settings.models.back() = std::make_shared<const ModelFile>(load_model_file(model, load));
        } catch (const FileNotFoundError& e) {
            throw FileNotFoundError(where + e.what());
        } catch (const UntrustedModelError& e) {
            throw UntrustedModelError(where + e.what());
        } catch (const std::exception& e) {
            throw SceneError(where + e.what());
        }
    }
}

}  // namespace pnet
