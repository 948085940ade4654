#include "pnet/sim/run_stats.hpp"

namespace pnet {

IntegratorSettings IntegratorSettings::from_scene(const Scene& scene) {
    IntegratorSettings s;
    s.name = scene.integrator.name;
    s.dt = scene.integrator.dt;
    s.cfl = scene.integrator.cfl;
    s.implicit = ImplicitOptions::from_json(scene.integrator.options, scene.file);
    return s;
}

}  // namespace pnet
