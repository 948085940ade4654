#pragma once
// The elements' energy form of an implicit FEM step (docs/methods.md), over the nodal velocities
// v of its FEM problem (fem_potential.hpp), x = x^n + dt v:
//
//   E(v) = sum_e V0_e psi_e(F^E_e(v)),   F^E_e(v) = F_e(x) (F^P_e)^-1 = sum_a x_a gt_ea^T,
//   dE/dv_a = dt sum_e V0_e P_e gt_ea,
//   d2E/dv_a dv_b = dt^2 sum_e V0_e B_eab,  (B_eab)_ik = sum_jl gt_ea[j] H_e(ij, kl) gt_eb[l],
//
// gt_ea = (F^P_e)^-T g_ea, g_ea the rest gradients of element e's linear shape functions. psi_e
// is a ParticleEnergy (an element is a material point with a rest volume): elastic for
// `lagged`, the PlasticityNet energy for `plasticitynet`, its Hessian projected to PSD. Sums
// run in element order, so results do not depend on the thread count. Its triplets cover every
// entry an element touches (0 between fixed components), so the assembled pattern is the mesh's,
// the same at every step.
#include <array>
#include <vector>

#include "pnet/energy/particle_energy.hpp"
#include "pnet/solver/form.hpp"

namespace pnet {

template <int dim>
class FemPotential;

template <int dim>
class ElementEnergyForm final : public Form {
public:
    ElementEnergyForm(const FemPotential<dim>& problem, ParticleEnergy<dim>& energy)
        : problem_(problem), energy_(energy) {}

    /// This step's gt_ea = (F^P_e)^-T g_ea from each element's (F^P)^-1.
    void begin_step(const std::vector<Mat<dim>>& plastic_inverse);
    ParticleEnergy<dim>& energy() { return energy_; }

    /// F^E_e(v) of every element.
    void deformation(const VecX& v, std::vector<Mat<dim>>& FE) const;

    double value(const VecX& v) override;
    double add_gradient(const VecX& v, VecX& g) override;
    void prepare_hessian(const VecX& v) override;
    double add_gradient_hessian(const VecX& v, VecX& g) override;
    void add_hessian_multiply(const VecX& d, VecX& out) const override;
    void add_hessian_diagonal(VecX& diagonal) const override;
    void add_hessian_block_diagonal(VecX& blocks) const override;
    void add_hessian_triplets(std::vector<Triplet>& triplets) const override;
    bool symmetric_hessian() const override { return energy_.symmetric_hessian(); }
    void add_hessian_values(double* values, const int* slots) const override;

    /// Project the element Hessians to PSD (default; false: the exact Hessian, for derivative checks).
    void set_project_psd(bool project) { project_psd_ = project; }

private:
    void evaluate(const VecX& v, typename ParticleEnergy<dim>::Order order);
    double potential_sum() const;
    void scatter_gradient(VecX& g) const;
    /// f(row, col, value) for each entry of element e's Hessian block in v (value 0 where a fixed
    /// component is involved), in the order a, b, i, k.
    template <typename F>
    void for_each_entry(std::size_t e, F&& f) const;

    const FemPotential<dim>& problem_;
    ParticleEnergy<dim>& energy_;
    std::vector<std::array<Vec<dim>, dim + 1>> grad_;  // gt_ea = (F^P)^-T g_ea
    std::vector<Mat<dim>> FE_, P_;
    std::vector<double> psi_;
    std::vector<Tensor4<dim>> H_;
    bool project_psd_ = true;
};

}  // namespace pnet
