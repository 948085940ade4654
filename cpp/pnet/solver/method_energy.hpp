#pragma once
// The energy each implicit integrator sums, for MPM particles, FEM elements and coupling alike: what an
// integrator's entry in the registry builds (IntegratorInfo::energy, solver/integrators.cpp).
//
//   plasticitynet  NeuralParticleEnergy: the objects' learned energies, the network's Hessian
//                  (+ w mu I), their learned return mappings where a model ships one
//   return_map     ReturnMappingEnergy: the material library's stress and consistent tangent, no model
//   lagged         ElasticParticleEnergy: the elasticity model alone
//   analytic       AnalyticElastoplasticEnergy (FEM, StVK-Hencky + von Mises)
#include <memory>
#include <string>
#include <vector>

#include "pnet/energy/particle_energy.hpp"
#include "pnet/material/material.hpp"
#include "pnet/nn/learned_return_map.hpp"
#include "pnet/nn/model_file.hpp"
#include "pnet/solver/implicit_options.hpp"
#include "pnet/solver/integrators.hpp"

namespace pnet {

template <int dim>
struct MethodEnergy {
    std::unique_ptr<ParticleEnergy<dim>> energy;
    /// Per object: the learned return mapping the step applies after the solve, or null for the
    /// material library's (plasticitynet with ImplicitOptions::learned_return_map only).
    std::vector<const LearnedReturnMap<dim>*> return_maps;
};

/// What an integrator's energy is built from: the solver's options, the objects' materials, models[k]
/// object k's model (plasticitynet needs one per object) and where[k] its place for messages
/// ("scene.json: objects[0]", to which ".model" or ".material" is added).
template <int dim>
struct EnergyRequest {
    const ImplicitOptions& options;
    const std::vector<Material<dim>>& materials;
    const std::vector<std::shared_ptr<const ModelFile>>& models;
    const std::vector<std::string>& where;
};

/// The energy of `method` (its registry entry's factory). Throws std::invalid_argument naming the place
/// for a missing or mismatched model or an unsupported material, and for explicit (no energy).
template <int dim>
MethodEnergy<dim> make_method_energy(Method method, const EnergyRequest<dim>& request);

/// The energy of a method that reads no model (return_map, lagged, analytic) over `materials`: make_method_energy's,
/// for what builds its own steps without a scene (the adjoints; plasticitynet throws, naming the missing model).
template <int dim>
std::unique_ptr<ParticleEnergy<dim>> model_free_energy(Method method, const ImplicitOptions& options,
                                                       const std::vector<Material<dim>>& materials) {
    const std::vector<std::shared_ptr<const ModelFile>> no_models(materials.size());
    std::vector<std::string> where;
    for (std::size_t k = 0; k < materials.size(); ++k) where.push_back("materials[" + std::to_string(k) + "]");
    return make_method_energy<dim>(method, EnergyRequest<dim>{options, materials, no_models, where}).energy;
}

}  // namespace pnet
