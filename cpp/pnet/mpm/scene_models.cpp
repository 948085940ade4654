#include "pnet/mpm/scene_models.hpp"

#include <memory>

#include "pnet/nn/model_file.hpp"

namespace pnet {

IntegratorSettings integrator_settings(const Scene& scene, const std::string& integrator) {
    IntegratorSettings settings = IntegratorSettings::from_scene(scene);
    if (!integrator.empty() && integrator != scene.integrator.name) {
        // The scene's dt belongs to the scene's integrator.
        settings.name = integrator;
        settings.dt = integrator == "explicit" ? 0.0 : 1e-3;
    }
    if (settings.name != "explicit" && settings.name != "plasticitynet" && settings.name != "lagged")
        throw std::invalid_argument("integrator: expected explicit, plasticitynet or lagged, got \"" + settings.name +
                                    "\"");
    return settings;
}

void load_scene_models(const Scene& scene, bool trusted_models, IntegratorSettings& settings) {
    settings.models.clear();
    for (const SceneObject& object : scene.objects) {
        settings.models.emplace_back();
        if (object.model.empty()) continue;
        LoadOptions load;
        load.expected_dim = scene.dim;
        load.expected_kind = ModelKind::Energy;
        load.trusted = trusted_models;
        const std::string where = scene.file + ": " + object.json_path + ".model: ";
        try {
            settings.models.back() = std::make_shared<const ModelFile>(load_model_file(object.model, load));
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
