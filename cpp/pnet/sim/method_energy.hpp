#pragma once
// The energy face each implicit method sums (docs/architecture.md, solver/integrators.hpp): one place
// that maps an integrator to its ParticleEnergy, for MPM particles, FEM elements and coupling alike.
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
#include "pnet/sim/run_stats.hpp"

namespace pnet {

template <int dim>
struct MethodEnergy {
    std::unique_ptr<ParticleEnergy<dim>> energy;
    /// Per object: the learned return mapping the step applies after the solve, or null for the
    /// material library's (plasticitynet with ImplicitOptions::learned_return_map only).
    std::vector<const LearnedReturnMap<dim>*> return_maps;
};

/// The energy of `settings`'s implicit method over objects with `materials`; models[k] is object k's
/// model (plasticitynet needs one per object), where[k] its place for messages ("scene.json:
/// objects[0]", to which ".model" or ".material" is added). Throws std::invalid_argument naming the
/// place for a missing or mismatched model or an unsupported material, and for explicit.
template <int dim>
MethodEnergy<dim> make_method_energy(const IntegratorSettings& settings, const std::vector<Material<dim>>& materials,
                                     const std::vector<std::shared_ptr<const ModelFile>>& models,
                                     const std::vector<std::string>& where);

}  // namespace pnet
