#pragma once
// The incremental potential of an implicit FEM step (docs/methods.md), over the
// nodal velocities v with x = x^n + dt v, so that FEM has the same unknowns
// (velocities, m/s) and the same Newton loop as MPM:
//
//   E(v) = sum_i m_i/2 |v_i - v*_i|^2 + sum_e V0_e psi_e(F^E_e(v)) + B(x(v)),
//   F^E_e(v) = F_e(x) (F^P_e)^-1 = sum_a x_a gt_ea^T,   gt_ea = (F^P_e)^-T g_ea,
//
// g_ea the rest gradients of element e's linear shape functions (g_a = row a-1
// of D_m^-1 for a >= 1, g_0 = -sum_a g_a; F_e(x) = D_s(x) D_m^-1 = sum_a x_a
// g_ea^T). psi_e is a ParticleEnergy (an element is a material point with a
// rest volume): elastic for `lagged`, the PlasticityNet energy for
// `plasticitynet`, with P = dpsi/dF^E and H = d2psi/dF^E2 (PSD). Then
//   dE/dv_a = m_a (v_a - v*_a) + dt sum_e V0_e P_e gt_ea,
//   d2E/dv_a dv_b = m_a delta_ab I + dt^2 sum_e V0_e B_eab,  (B_eab)_ik = sum_jl gt_ea[j] H_e(ij, kl) gt_eb[l].
// B is the contact potential (IPC barrier, contact/collisions/contact_potential.hpp; none if not
// set): its gradient enters as dt dB/dx, its Hessian as dt^2 d2B/dx2, and
// max_step() is its CCD filter on the motion x -> x + dt d.
// The Hessian is assembled as a sparse matrix (hessian_matrix()) for a direct
// solve by CHOLMOD; fixed components (Dirichlet nodes: targets reached by
// v = v*) keep only their mass on the diagonal. The mass and element part has
// the mesh's pattern, built once: each Hessian pass refills its values through
// a map from element entries to value slots, and contact and friction (whose
// pattern changes with the active pairs) are added as a second matrix. Sums
// run in element order, so results do not depend on the thread count.
#include <Eigen/SparseCore>
#include <vector>

#include "pnet/contact/friction.hpp"
#include "pnet/contact/collisions/contact_potential.hpp"
#include "pnet/energy/particle_energy.hpp"
#include "pnet/fem/mesh.hpp"
#include "pnet/solver/fixed_point.hpp"

namespace pnet {

/// Per-element rest quantities of a mesh.
template <int dim>
struct ElementRest {
    std::vector<double> volume;                          // V0_e, m^d
    std::vector<std::array<Vec<dim>, dim + 1>> grad;     // g_ea, 1/m
    std::vector<double> node_mass;                       // lumped: rho V0 / (d + 1) from each element, kg

    /// From the rest mesh and a density per element (kg/m^d).
    ElementRest(const Mesh<dim>& mesh, const std::vector<double>& density);
    ElementRest() = default;
};

/// F_e(x) = sum_a x_a g_ea^T of element e at positions x.
template <int dim>
Mat<dim> deformation_gradient(const Mesh<dim>& mesh, const ElementRest<dim>& rest, const std::vector<Vec<dim>>& x,
                              std::size_t e);

template <int dim>
class FemPotential final : public ReferencedObjective<dim> {
public:
    static constexpr int kElementNodes = dim + 1;
    static constexpr int kM = dim * dim;

    FemPotential(const Mesh<dim>& mesh, const ElementRest<dim>& rest, ParticleEnergy<dim>& energy)
        : mesh_(mesh), rest_(rest), energy_(energy) {}

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

    /// The contact potential (not owned; null: no contact).
    void set_contact(const ContactPotential<dim>* contact) { contact_ = contact; }

    /// Lagged friction (not owned; null: none): dt D(v) is added to E.
    void set_friction(const Friction<dim>* friction) { friction_ = friction; }

    /// x(v) = x^n + dt v.
    void positions(const VecX& v, std::vector<Vec<dim>>& x) const;

    /// The elements' object (material) indices and start-of-step hardening
    /// states, passed to the energy with every set_reference().
    void set_material_state(const std::vector<int>& object, const std::vector<double>& hardening) {
        object_ = object;
        hardening_ = hardening;
    }

    /// F^E_e(v) of every element.
    void deformation(const VecX& v, std::vector<Mat<dim>>& FE) const override;
    /// The energy's reference (plasticitynet: F0 per element; ignored by the
    /// elastic and analytic energies, which only record the material state).
    void set_reference(const std::vector<Mat<dim>>& F0) override;
    bool set_damping(double lambda) override { return energy_.set_damping(lambda); }

    const VecX& v_star() const { return v_star_; }
    /// m_i on free components, 0 on fixed ones (NewtonOptions::residual_mass).
    const VecX& residual_mass() const { return residual_mass_; }

    // Objective
    Eigen::Index size() const override { return v_star_.size(); }
    double value(const VecX& v) override;
    double value_gradient(const VecX& v, VecX& gradient) override;
    void prepare_hessian(const VecX& v) override;
    double value_gradient_hessian(const VecX& v, VecX& gradient) override;
    void hessian_multiply(const VecX& d, VecX& out) const override;
    void hessian_diagonal(VecX& diagonal) const override;
    int hessian_block_size() const override { return dim; }
    void hessian_block_diagonal(VecX& blocks) const override;
    const SparseMatrix* hessian_matrix() const override { return &hessian(); }
    double max_step(const VecX& v, const VecX& d) override;

    /// CCD queries of max_step() since the last begin_step(), and how many of them shortened the step.
    int ccd_queries() const { return ccd_queries_; }
    int ccd_limited() const { return ccd_limited_; }

    /// Project the element Hessians to PSD (default; false: the exact Hessian, for derivative checks).
    void set_project_psd(bool project) { project_psd_ = project; }

private:
    double inertia(const VecX& v) const;
    void evaluate(const VecX& v, typename ParticleEnergy<dim>::Order order);
    /// The gradient of E at v; returns the contact and friction part of E, evaluated in the same pass.
    double assemble_gradient(const VecX& v, VecX& gradient);
    double potential_sum() const;
    double contact_value(const VecX& v);
    /// Builds element_hessian_'s pattern (mass diagonal + element blocks) and the slot maps.
    void build_hessian_pattern();
    const SparseMatrix& hessian() const { return with_contact_ ? hessian_ : element_hessian_; }

    const Mesh<dim>& mesh_;
    const ElementRest<dim>& rest_;
    ParticleEnergy<dim>& energy_;
    const ContactPotential<dim>* contact_ = nullptr;
    const Friction<dim>* friction_ = nullptr;
    std::vector<Vec<dim>> x_start_, x_, dx_;
    std::vector<int> object_;
    std::vector<double> hardening_;
    double dt_ = 0.0;
    VecX v_star_, mass_, free_, residual_mass_, inertia_scale_;
    std::vector<char> fixed_;
    std::vector<std::array<Vec<dim>, dim + 1>> grad_;  // gt_ea = (F^P)^-T g_ea
    std::vector<Mat<dim>> FE_, P_;
    std::vector<double> psi_;
    std::vector<Tensor4<dim>> H_;
    SparseMatrix element_hessian_;        // mass + elements, the mesh's fixed pattern
    std::vector<int> element_slots_;      // per element, (dim+1)^2 dim^2 indices into its values
    std::vector<int> diagonal_slots_;     // per component, the index of its diagonal entry
    SparseMatrix contact_hessian_, hessian_;  // hessian_ = element_hessian_ + contact_hessian_
    bool with_contact_ = false;           // whether hessian_ (not element_hessian_) is the Hessian
    std::vector<Eigen::Triplet<double>> triplets_;
    bool project_psd_ = true;
    int ccd_queries_ = 0, ccd_limited_ = 0;
};

}  // namespace pnet
