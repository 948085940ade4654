#pragma once
// The integrators, one entry each: its name, what a step solves, which options apply, which model
// files it reads and the energy its steps sum (docs/solver.md, "The integrators"). The scene reader,
// `pnet simulate --integrator` and its --help, plasticitynet_sim, bench_table1 and the run's outputs all
// take the names and the checks from this list; no other place compares an integrator's name as a
// string. A new implicit integrator is a Method and its entry with its energy (integrators.cpp).
#include <string>
#include <vector>

#include "pnet/material/material.hpp"

namespace pnet {

template <int dim>
struct MethodEnergy;  // solver/method_energy.hpp
template <int dim>
struct EnergyRequest;
/// Builds the energy an integrator's steps sum (solver/method_energy.hpp); null for explicit.
template <int dim>
using EnergyFactory = MethodEnergy<dim> (*)(const EnergyRequest<dim>&);

/// What a step computes.
enum class Method {
    Explicit,       // symplectic Euler with the return mapping's stress: the ground truth
    PlasticityNet,  // backward Euler on the learned energy (paper eqs. 8, 10, 11): the network on every iteration
    ReturnMap,      // backward Euler with the return mapping's stress and consistent tangent (classical)
    Lagged,         // backward Euler on the elastic energy, plasticity applied after the step
    Analytic,       // FEM: backward Euler on the closed-form StVK-Hencky + von Mises energy (ECI)
};

/// One integrator: what the docs, the CLI's --help and the error messages say about it.
struct IntegratorInfo {
    Method method;
    const char* name;         // as in scenes, --integrator and run.json
    const char* solves;       // what one step solves, one line
    bool implicit;            // takes the implicit options and a fixed dt (1e-3 s MPM, 1e-2 s FEM by default)
    bool reads_models;        // needs an energy model per object (and deformable mesh)
    bool particles;           // runs MPM scenes (and coupling's particles)
    bool meshes;              // runs FEM scenes
    bool references;          // its energy has a reference F0 that the outer iteration moves to F(v)
    const char* options;      // the implicit options that apply beyond Newton's and the linear solve's
    /// Newton's lazy Hessian (NewtonOptions::lazy_hessian) that "auto" stands for, measured: a learned
    /// step's Hessian pass costs 2.6 of its trial passes, so plasticitynet keeps its Hessian longer
    /// (0.8; docs/integrators.md, "Keeping the Hessian"); return_map 0.1 (its work line search keeps a
    /// tangent only after a near-quadratic step: docs/solver.md, "The work line search's Hessian,
    /// owed"); the others 0.5 (0 for explicit: no Newton).
    double lazy_hessian;
    /// Whether "auto" starts an MPM or coupled step's Newton solve from the last step's velocity change
    /// (MpmOptions::newton_start "last_step", mpm/step_predictor.hpp) rather than from v*, measured
    /// (docs/solver.md, "Where Newton starts"): return_map and lagged take 26-40% fewer Newton
    /// iterations from it; plasticitynet's learned step, whose curvature along plastic flow is the
    /// network's smoothed one, converged far slower from it once the stiff column flowed (135 Newton
    /// iterations per step against 37 from v*), so it starts from v*.
    bool predicts_newton_start = false;
    /// The energy its steps sum, over MPM particles, FEM elements or both (null: explicit).
    EnergyFactory<2> energy_2d = nullptr;
    EnergyFactory<3> energy_3d = nullptr;
};

/// plasticitynet's settings per material family, measured (docs/integrators.md): the outer iteration
/// and the regularizer weight w of eq. 11 that "auto" stands for. With F0 following every iterate w
/// only damps Newton's steps (R is exact at the reference whatever w is), but w mu also adds to the
/// Hessian's diagonal, which weighs the residual a solve is stopped by: a larger w stops solves
/// earlier, biased toward v*. Von Mises metal: w = 0.05 (metal_frame_2d, 20 frames at 1e-2 s: 75
/// Newton iterations per step, 89 at 0.1, 153 at 0.3). Drucker-Prager sand: w = 0.1 (sand_column_2d,
/// 50 frames against explicit at 1e-5: deposit spread -0.5%, as return_map's -0.7%, against -2.6% at
/// w = 1; 8.2 Newton iterations per step over frames 0-10 against 9.6). Not every network converges
/// there: a 32-wide sand network took over 100 iterations per step at 0.1 and converged at 1 (with
/// -2.9%). Cam-Clay snow: the paper's w = 1 (snowball_2d at 0.3: 116 of 200 steps unconverged).
struct PlasticityNetDefaults {
    const char* outer_iteration;  // "newton" or "fixed_point"
    double regularizer_weight;
};
PlasticityNetDefaults plasticitynet_defaults(PlasticityModel family);

/// Every integrator, in the order the docs and --help list them.
const std::vector<IntegratorInfo>& integrators();
const IntegratorInfo& integrator_info(Method method);
/// "explicit, plasticitynet, return_map, lagged or analytic" (only those for particles or meshes, when
/// asked).
std::string integrator_names(bool particles = true, bool meshes = true);
/// The integrator called `name`; throws std::invalid_argument "<context>: unknown integrator "x"
/// (expected ...)" otherwise. `context` may be empty.
Method parse_integrator(const std::string& name, const std::string& context = "");
/// Whether `name` is an integrator's name.
bool is_integrator(const std::string& name);
inline const char* to_string(Method method) { return integrator_info(method).name; }

}  // namespace pnet
