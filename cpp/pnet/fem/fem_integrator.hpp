#pragma once
// FEM time integrators (docs/methods.md) on a simplicial mesh with per-element
// plasticity: the state is the nodal positions and velocities and, per
// element, the inverse plastic deformation (F^P)^-1 and the hardening state.
//
// Implicit (`plasticitynet`, `lagged`, `analytic`): one step minimizes the
// incremental potential over the nodal velocities (fem_potential.hpp) with the
// shared solve driver (solver/fixed_point.hpp: the fixed point on F0 for
// plasticitynet, one solve otherwise) and the one Newton loop, by CHOLMOD's
// direct solve; the start is v* as far as contact's CCD allows from x^n, so
// every iterate is intersection-free. plasticitynet first solves the step with
// the elastic energy (a predictor) and starts its fixed point from there,
// F0^0 = F^E(v_elastic): v* itself puts the whole motion of the kinematic
// nodes into the elements next to them (at dt 1e-2 a plate moving at 0.05 m/s
// crushes a 3 mm element by a sixth), far from where the network was trained. Then x += dt v, and per element
//   F^E_tr = F(x) (F^P)^-1,  F^E = Z(F^E_tr, h),  (F^P)^-1 = F^-1 F^E,  h updated
// (the materials' return mappings, the same as MPM's).
// BDF2 (ImplicitOptions::time_integrator "bdf2"): the same potential about x^ = (4 x^n - x^{n-1}) / 3
// with v* = (4 v^n - v^{n-1}) / 3 + beta dt g and the step beta dt, beta = 2/3: its minimizer satisfies
// v^{n+1} = v^ + beta dt a(x^{n+1}), x^{n+1} = x^ + beta dt v^{n+1}. A kinematic node's unknown is then
// the v that puts it on its target; the intersection-free start is the v that leaves x at x^n. A step
// without history (the first) is backward Euler. When dt differs from the last step's (a frame's
// clipped last step), the variable-step coefficients: with omega = dt / dt_prev,
// x^ = ((1 + omega)^2 x^n - omega^2 x^{n-1}) / (1 + 2 omega), the same for v^, beta = (1 + omega) / (1 + 2 omega).
// Explicit (the ground truth): symplectic Euler with the elastic stress of the
// admissible F^E and the same contact potential's force, then the same return
// mapping; a step whose motion CCD finds intersecting is a blow-up.
// Fixed nodes (kinematic: the pressing plate, clamps) move with a prescribed
// velocity in both. When contact's CCD holds the implicit start back from
// their targets, they become unknowns pulled to the targets by a stiff weight
// (x10 per stage, as IPC's augmented Lagrangian) until within 1e-9 m, then are
// put exactly on them (FemStepFields::kinematic_stages, kinematic_reached).
#include <memory>
#include <vector>

#include "pnet/contact/collisions/contact.hpp"
#include "pnet/energy/particle_energy.hpp"
#include "pnet/fem/fem_options.hpp"
#include "pnet/fem/fem_potential.hpp"
#include "pnet/fem/fem_step_stats.hpp"
#include "pnet/nn/learned_return_map.hpp"
#include "pnet/solver/fixed_point.hpp"
#include "pnet/solver/implicit_options.hpp"
#include "pnet/solver/integrators.hpp"

namespace pnet {

/// What does not change during a run.
template <int dim>
struct FemSystem {
    Mesh<dim> mesh;
    std::vector<int> element_object;          // material index per element
    std::vector<Material<dim>> materials;
    ElementRest<dim> rest;                    // from the mesh and the materials' densities (make_rest())
    Vec<dim> gravity = Vec<dim>::Zero();      // m/s^2
    /// Per object: a learned return mapping used instead of the material's
    /// (the one its learned energy was trained with, e.g. metal_nh_rm_2d.pt);
    /// empty or null: the material's own.
    std::vector<const LearnedReturnMap<dim>*> return_maps;
    std::vector<char> fixed_node;             // per node: kinematic (prescribed velocity)
    std::vector<Vec<dim>> prescribed_velocity;  // per node, used where fixed_node

    /// rest from mesh, element_object and the materials' densities.
    void make_rest();
    /// Lumped nodal masses of the free nodes, summed, kg (per unit depth in 2D).
    double free_mass() const;
};

template <int dim>
struct FemState {
    std::vector<Vec<dim>> x, v;                // nodes, m and m/s
    std::vector<Mat<dim>> plastic_inverse;     // (F^P)^-1 per element
    std::vector<double> hardening;             // per element
    // The previous step's start (BDF2's history; ImplicitOptions::time_integrator): written by every
    // implicit step, empty before the first one.
    std::vector<Vec<dim>> x_previous, v_previous;
    double dt_previous = 0.0;  // that step's dt (0: unknown, read as the next step's)

    /// At rest in the mesh's rest shape, with each element's material's initial hardening.
    static FemState at_rest(const FemSystem<dim>& system);
};

/// The implicit FEM methods: plasticitynet, return_map, lagged, analytic (solver/integrators.hpp).
using FemMethod = Method;

template <int dim>
class FemImplicitIntegrator {
public:
    /// energy: the element energy of the method (NeuralParticleEnergy,
    /// ElasticParticleEnergy or AnalyticElastoplasticEnergy); contact may be null.
    FemImplicitIntegrator(const FemSystem<dim>& system, FemMethod method, const ImplicitOptions& options,
                          std::unique_ptr<ParticleEnergy<dim>> energy, const ContactPotential<dim>* contact,
                          const FemOptions& fem_options = {});

    /// Lagged friction on the pairs of `contact`, lagged at the start of every step.
    void set_friction(Friction<dim>* friction, const ContactPotential<dim>* contact);

    /// Throws SimulationError naming the step on a failed solve.
    FemStepStats step(FemState<dim>& state, double dt, long step_index);

    FemPotential<dim>& potential() { return potential_; }

private:
    const FemSystem<dim>& system_;
    FemMethod method_;
    ImplicitOptions options_;
    FemOptions fem_options_;
    // F0 is an unknown of the step: plasticitynet, or analytic regularized about F0 (a diagnostic).
    bool iterates_reference_;
    std::unique_ptr<ParticleEnergy<dim>> energy_;
    FemPotential<dim> potential_;
    ElasticParticleEnergy<dim> elastic_energy_;
    FemPotential<dim> predictor_;  // plasticitynet: the elastic solve that starts the fixed point
    ReferenceSolveWork<dim> work_;
    std::vector<char> fixed_components_;
    bool has_kinematic_ = false;
    Friction<dim>* friction_ = nullptr;
    const ContactPotential<dim>* friction_contact_ = nullptr;
};

template <int dim>
class FemExplicitIntegrator {
public:
    FemExplicitIntegrator(const FemSystem<dim>& system, const ContactPotential<dim>* contact)
        : system_(system), contact_(contact) {}

    /// The same lagged friction pairs as the implicit integrators (normal forces,
    /// tangents and weights of the start of the step), applied as Coulomb impulses after
    /// the other forces (Friction::apply_impulses): exact sticking, and stable at any
    /// step, where the smoothed force of the potential at the start-of-step velocity is
    /// stable only for mu lambda dt / (m eps_v) < 2.
    void set_friction(Friction<dim>* friction, const ContactPotential<dim>* contact) {
        friction_ = friction;
        friction_contact_ = contact;
    }

    /// One step of dt, in as many substeps as stability needs: a contact pair closing in
    /// stiffens without bound (k ~ kappa dhat^4 / d^2), and crushed elements stiffen and
    /// shrink, so a fixed explicit step that is stable at the start fails once the plate
    /// presses (measured: metal_frame_2d at 1e-5 s failed at frame 47, at 2e-5 s and at the
    /// rest CFL step at frame 7). Each substep is at most 1 / sqrt(omega_e^2 + omega_c^2)
    /// (element_frequency() of the step's start, Contact::stable_time_step of the
    /// substep's) and closes no gap by more than about a fifth (CCD).
    /// FemStepFields::substeps counts them. Throws SimulationError naming the step if a value is
    /// not finite or no substep avoids intersection.
    FemStepStats step(FemState<dim>& state, double dt, long step_index);

    /// Nodal forces (N, per unit depth in 2D) added to the elastic and contact forces of every
    /// substep (not owned; null: none): the MPM-FEM coupling's barrier forces.
    void set_external_force(const std::vector<Vec<dim>>* force) { external_force_ = force; }

    /// The largest stable step of the elements: cfl h_min / c with c the fastest wave speed.
    double cfl_time_step(double cfl = 0.5) const;

private:
    /// The highest frequency of the free elements at positions x, 1/s.
    double element_frequency(const std::vector<Vec<dim>>& x) const;
    /// Symplectic Euler over at most h; returns the time advanced.
    double substep(FemState<dim>& state, double h, long step_index, FemStepStats& stats);

    const FemSystem<dim>& system_;
    const ContactPotential<dim>* contact_;
    Friction<dim>* friction_ = nullptr;
    const ContactPotential<dim>* friction_contact_ = nullptr;
    std::vector<double> free_mass_;     // node masses, 0 on kinematic nodes
    std::vector<double> inverse_mass_;  // 1 / mass, 0 on kinematic nodes
    std::vector<Mat<dim>> stress_;      // per element V0 P (F^P)^-T, the substep's work array
    const std::vector<Vec<dim>>* external_force_ = nullptr;
};

/// The return mapping of every element after a step: F^E_tr = F(x) (F^P)^-1 -> Z, (F^P)^-1, h
/// (the object's learned return mapping where FemSystem::return_maps gives one).
template <int dim>
void fem_return_mapping(const FemSystem<dim>& system, FemState<dim>& state);

}  // namespace pnet
