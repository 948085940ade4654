#pragma once
// The particles' energy form of an implicit MPM step (docs/methods.md; Gast et al. 2015; paper
// sec. 3.1, 4.2), over the grid velocities v of its MPM problem (incremental_potential.hpp):
//
//   E(v) = sum_p V0_p psi_p(F_p(v)),   F_p(v) = (I + dt G_p(v)) F^E_p,   G_p(v) = sum_i v_i grad w_ip^T,
//   dE/dv_i = sum_p V0_p dt P_p F^E_p^T grad w_ip,
//   H d |_i = sum_p K_p[dG_p] grad w_ip,  dG_p = sum_i d_i grad w_ip^T,
//   K_p = V0_p dt^2 T_p^T (d2psi/dF2) T_p,  T_p: dG -> dG F^E_p,
//
// with psi_p a ParticleEnergy (elastic for `lagged`, the PlasticityNet energy for
// `plasticitynet`) and its Hessian projected to PSD. K_p (d^2 x d^2) is formed once per Newton
// iteration; a Hessian-vector product is then a gather, a small matrix product and a scatter
// per particle. The stencils, the unknowns' numbering and the fixed components are the
// problem's; the form's Hessian leaves the fixed components' rows and columns out. Scatters run
// in the grid's block-colour order (or per node in a fixed entry order), so every sum has a
// fixed order and results do not depend on the thread count.
#include <vector>

#include "pnet/energy/particle_energy.hpp"
#include "pnet/solver/form.hpp"

namespace pnet {

template <int dim>
class IncrementalPotential;

template <int dim>
class ParticleEnergyForm final : public Form {
public:
    static constexpr int kStencil = dim == 2 ? 9 : 27;
    static constexpr int kM = dim * dim;

    ParticleEnergyForm(const IncrementalPotential<dim>& problem, ParticleEnergy<dim>& energy)
        : problem_(problem), energy_(energy) {}

    /// Sizes the per-particle state for this step's particles (after the problem's begin_step).
    void begin_step(std::size_t particles);
    ParticleEnergy<dim>& energy() { return energy_; }

    double value(const VecX& v) override;
    double add_gradient(const VecX& v, VecX& g) override;
    /// The particles' Hessians d^2 psi / dF^2 given (one per particle, F-space, row-major: what the energy's
    /// Hessian pass leaves), instead of that pass: the Hessian products and diagonal at the iterate they were taken
    /// at (the MPM adjoint's solve, which has them).
    void set_hessians(const std::vector<Tensor4<dim>>& hessians);
    void prepare_hessian(const VecX& v) override;
    double add_gradient_hessian(const VecX& v, VecX& g) override;
    void add_hessian_multiply(const VecX& d, VecX& out) const override;
    void add_hessian_diagonal(VecX& diagonal) const override;
    /// The d x d block of each node: sum_p over the particles it reaches of
    /// B_ab = g^T K_p[(a, .), (b, .)] g (g = grad w_ip), masked on fixed components.
    void add_hessian_block_diagonal(VecX& blocks) const override;
    /// Node-pair blocks summed first (in the colour order, so the result does not depend on the
    /// thread count): (2 dx + 1)^d neighbours per node, one triplet per entry between free components.
    void add_hessian_triplets(std::vector<Triplet>& triplets) const override;
    bool symmetric_hessian() const override { return energy_.symmetric_hessian(); }

    /// Project the particles' Hessians to PSD (default; false gives the exact Hessian of E, for
    /// derivative checks).
    void set_project_psd(bool project) { project_psd_ = project; }

    /// Seconds spent in the particle energies (evaluate) and in Hessian-vector products since
    /// the last begin_step().
    double energy_seconds() const { return energy_seconds_; }
    double multiply_seconds() const { return multiply_seconds_; }

    /// The nodes within two of a node along each axis: 5^d offsets.
    static constexpr int kPairOffsets = dim == 2 ? 25 : 125;
    /// The Hessian prepared last by node pairs (fixed components included; what add_hessian_triplets
    /// emits without them): for node k and offset o, pair_dofs()[k kPairOffsets + o] is the other
    /// node (-1: none) and pair_blocks() holds the d x d block H(node k, that node) at
    /// (k kPairOffsets + o) d^2, row-major. Valid until the next call.
    void compute_pair_blocks() const;
    const std::vector<int>& pair_dofs() const { return pair_dof_; }
    /// The last product's rows on the fixed components (H d there, d masked to the free ones), which
    /// add_hessian_multiply leaves out of `out`: how a held component's reaction changes along d (the
    /// Coulomb floor's normal impulse, FloorFrictionForm::begin_newton). Entries on free components
    /// are stale.
    const VecX& held_product() const { return held_product_; }
    const std::vector<double>& pair_blocks() const { return pair_block_; }

private:
    /// sum_p V0_p psi_p, in particle order, serially: the sum must not depend on the thread count.
    double potential_sum() const;
    /// The unmasked d x d diagonal block of each node, summed over the particles it reaches.
    void node_blocks(VecX& blocks) const;
    /// Their diagonal entries alone (d per node), for Jacobi and the residual's scaling.
    void node_diagonal(VecX& diagonal) const;
    /// Both: the blocks, or their diagonals when kDiagonalOnly.
    template <bool kDiagonalOnly>
    void node_entries(VecX& out) const;
    /// g += sum_p V0 dt P_p F^E_p^T grad w_ip.
    void scatter_gradient(VecX& g) const;
    /// K_p = V0 dt^2 T_p^T H_p T_p in place of the Hessians H_p.
    void transform_hessians();

    const IncrementalPotential<dim>& problem_;
    ParticleEnergy<dim>& energy_;
    // Per particle, at the last evaluation.
    std::vector<Mat<dim>> F_, P_;
    std::vector<double> psi_;
    std::vector<Tensor4<dim>> K_;  // the Hessian of psi, then K_p (prepare_hessian)
    mutable VecX masked_, scratch_, held_product_;
    mutable std::vector<Eigen::Matrix<double, kM, 1>> particle_product_;  // K_p dG_p
    mutable std::vector<Mat<dim>> particle_force_;                        // V0 dt P_p F^E_p^T
    // compute_pair_blocks(): per node and neighbour offset, the neighbour's dof and the d x d block.
    mutable std::vector<int> pair_dof_;
    mutable std::vector<double> pair_block_;
    bool project_psd_ = true;
    double energy_seconds_ = 0.0;
    mutable double multiply_seconds_ = 0.0;
};

}  // namespace pnet
