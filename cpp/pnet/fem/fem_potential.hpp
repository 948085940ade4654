#pragma once
// The incremental potential of an implicit FEM step (docs/methods.md), over the
// nodal velocities v with x = x^n + dt v, so that FEM has the same unknowns
// (velocities, m/s) and the same Newton loop as MPM: a Problem (solver/problem.hpp)
// of up to four forms,
//
//   E(v) = sum_i m_i/2 |v_i - v*_i|^2 + sum_e V0_e psi_e(F^E_e(v)) + B(x(v)) + dt D(v),
//          (InertiaForm)              (ElementEnergyForm)        (BarrierForm) (FrictionForm)
//   F^E_e(v) = F_e(x) (F^P_e)^-1 = sum_a x_a gt_ea^T,   gt_ea = (F^P_e)^-T g_ea,
//
// g_ea the rest gradients of element e's linear shape functions (g_a = row a-1
// of D_m^-1 for a >= 1, g_0 = -sum_a g_a; F_e(x) = D_s(x) D_m^-1 = sum_a x_a
// g_ea^T). B is the IPC contact potential (contact/collisions/contact_potential.hpp;
// none if not set), D lagged friction (none if not set). The Hessian is assembled
// as a sparse matrix (hessian_matrix()) for a direct solve by CHOLMOD: the mass
// and element part has the mesh's pattern, built once and refilled through a map
// from entries to value slots at each Hessian pass; contact and friction (whose
// pattern changes with the active pairs) are added as a second matrix. Fixed
// components (Dirichlet nodes: targets reached by v = v*) keep only their mass on
// the diagonal. Sums run in element order, so results do not depend on the thread count.
#include <Eigen/SparseCore>
#include <vector>

#include <memory>

#include "pnet/contact/barrier_form.hpp"
#include "pnet/contact/friction_form.hpp"
#include "pnet/energy/particle_energy.hpp"
#include "pnet/fem/element_energy_form.hpp"
#include "pnet/fem/mesh.hpp"
#include "pnet/solver/form_sum.hpp"
#include "pnet/solver/inertia_form.hpp"
#include "pnet/solver/problem.hpp"

namespace pnet {

/// Per-element rest quantities of a mesh.
template <int dim>
struct ElementRest {
    std::vector<double> volume;                       // V0_e, m^d
    std::vector<std::array<Vec<dim>, dim + 1>> grad;  // g_ea, 1/m
    std::vector<double> node_mass;                    // lumped: rho V0 / (d + 1) from each element, kg

    /// From the rest mesh and a density per element (kg/m^d).
    ElementRest(const Mesh<dim>& mesh, const std::vector<double>& density);
    ElementRest() = default;
};

/// F_e(x) = sum_a x_a g_ea^T of element e at positions x.
template <int dim>
Mat<dim> deformation_gradient(const Mesh<dim>& mesh, const ElementRest<dim>& rest, const std::vector<Vec<dim>>& x,
                              std::size_t e);

template <int dim>
class FemPotential final : public Problem<dim> {
public:
    FemPotential(const Mesh<dim>& mesh, const ElementRest<dim>& rest, ParticleEnergy<dim>& energy);
    FemPotential(const FemPotential&) = delete;  // its forms refer to its members
    FemPotential& operator=(const FemPotential&) = delete;

    /// Sets up one step: positions x^n, v* (= v^n + dt g on free nodes, the
    /// prescribed velocity on fixed ones), per element (F^P)^-1, and which
    /// velocity components are fixed (size dim n; empty: none).
    void begin_step(const std::vector<Vec<dim>>& x_start, const VecX& v_star, double dt,
                    const std::vector<Mat<dim>>& plastic_inverse, const std::vector<char>& fixed);

    /// Soft kinematic constraints (IPC's approach to prescribed motion under
    /// contact): the components fixed at begin_step() become unknowns whose
    /// inertia term, pulling them to their v*, is weighted by `weight` (>> 1),
    /// so that Newton moves them together with what they push.
    /// harden_fixed() makes them fixed again.
    void soften_fixed(double weight);
    void harden_fixed();

    /// The contact potential (not owned; null: no contact): the barrier form B(x(v)).
    void set_contact(const ContactPotential<dim>* contact);
    /// Lagged friction (not owned; null: none): the form dt D(v).
    void set_friction(const Friction<dim>* friction);

    /// x(v) = x^n + dt v.
    void positions(const VecX& v, std::vector<Vec<dim>>& x) const;

    /// The elements' object (material) indices and start-of-step hardening
    /// states, passed to the energy with every set_reference().
    void set_material_state(const std::vector<int>& object, const std::vector<double>& hardening) {
        object_ = object;
        hardening_ = hardening;
    }

    /// F^E_e(v) of every element.
    void deformation(const VecX& v, std::vector<Mat<dim>>& FE) const override { elements_.deformation(v, FE); }
    /// The energy's reference (plasticitynet: F0 per element; ignored by the
    /// elastic and analytic energies, which only record the material state).
    void set_reference(const std::vector<Mat<dim>>& F0) override;
    bool set_damping(double lambda) override { return elements_.energy().set_damping(lambda); }

    const VecX& v_star() const { return inertia_.target(); }
    /// m_i on free components, 0 on fixed ones (NewtonOptions::residual_mass).
    const VecX& residual_mass() const { return residual_mass_; }

    const Mesh<dim>& mesh() const { return mesh_; }
    const ElementRest<dim>& rest() const { return rest_; }
    const std::vector<Vec<dim>>& start_positions() const { return x_start_; }
    double dt() const { return dt_; }

    /// CCD queries of max_step() since the last begin_step(), and how many of them shortened the step.
    int ccd_queries() const { return barrier_ ? barrier_->ccd().queries : 0; }
    int ccd_limited() const { return barrier_ ? barrier_->ccd().limited : 0; }

    /// Project the element and contact Hessians to PSD (default; false: the exact Hessian, for
    /// derivative checks).
    void set_project_psd(bool project);

private:
    /// The forms in their summation order: inertia, elements, then contact (barrier + friction) if set.
    void update_forms();

    const Mesh<dim>& mesh_;
    const ElementRest<dim>& rest_;
    InertiaForm inertia_;
    ElementEnergyForm<dim> elements_;
    MeshVertices<dim> vertices_;  // the barrier's: x^n + dt v
    std::unique_ptr<BarrierForm<dim>> barrier_;
    std::unique_ptr<FrictionForm<dim>> friction_;
    FormSum contact_;  // the barrier and friction, summed as one (their value, then the others')
    bool project_psd_ = true;
    std::vector<Vec<dim>> x_start_;
    std::vector<int> object_;
    std::vector<double> hardening_;
    double dt_ = 0.0;
    VecX residual_mass_;
    std::vector<char> fixed_;
};

}  // namespace pnet
