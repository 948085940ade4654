#pragma once
// Which integrator a run steps with and how: the scene's "integrator" block (name, dt, cfl and the
// options of every layer: the solver's, MPM's, FEM's and coupling's), and the one table of those
// options that the scene reader, `pnet simulate`'s flags and --help, and Python's solver= keys read
// (integrator_option_fields()). A new option is a member and a table entry in its layer's file.
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "pnet/coupling/coupling_options.hpp"
#include "pnet/fem/fem_options.hpp"
#include "pnet/mpm/mpm_options.hpp"
#include "pnet/nn/model_file.hpp"
#include "pnet/scene/scene.hpp"
#include "pnet/solver/implicit_options.hpp"
#include "pnet/solver/integrators.hpp"

namespace pnet {

/// Which integrator a Simulation runs and how.
struct IntegratorSettings {
    std::string name = "explicit";  // an integrator of solver/integrators.hpp
    /// The integrator's method (std::invalid_argument for a name not in the list).
    Method method() const { return parse_integrator(name); }
    double dt = 0.0;  // s; 0: the CFL step before every step
    double cfl = 0.5;
    ImplicitOptions implicit;  // the solver's: Newton, the outer iteration, the Hessian, the network
    MpmOptions mpm;            // implicit MPM's and coupling's particles': the advection limit, ...
    FemOptions fem;            // implicit FEM's: the kinematic stages, the predictor
    CouplingOptions coupling;  // the coupled solve's
    /// Energy model of each scene object, or of each mesh in a FEM scene
    /// (plasticitynet needs one for every object and deformable mesh; the
    /// others ignore them). Loading a model file needs LibTorch
    /// (load_model_file in pnet_torch), so the caller does it.
    std::vector<std::shared_ptr<const ModelFile>> models;

    /// The scene's "integrator" block: name, dt, cfl and the options (std::invalid_argument naming
    /// the file and key on a bad value). Models are not loaded.
    static IntegratorSettings from_scene(const Scene& scene);
    /// Sets the options an integrator block gives (the keys of integrator_option_fields(); name, dt
    /// and cfl are skipped); std::invalid_argument "<context>: integrator.<key>: <problem>".
    void read_options(const nlohmann::json& block, const std::string& context);
    /// {key: value} of every option (run.json's "solver", Python's solver dict).
    nlohmann::json options_json() const;
};

/// Every option of every layer, in the order --help lists them: the solver's, then MPM's, FEM's and
/// coupling's.
const std::vector<OptionField<IntegratorSettings>>& integrator_option_fields();
/// The option with this key or flag; nullptr if none.
const OptionField<IntegratorSettings>* find_option_field(const std::string& key_or_flag);

}  // namespace pnet
