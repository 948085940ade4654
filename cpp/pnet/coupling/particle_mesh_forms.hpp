#pragma once
// The particle-mesh forms of an MPM-FEM coupled step (BFEMP, Li, Fang, Li, Jiang 2021;
// docs/methods.md), over v = [MPM grid velocities; FEM nodal velocities]:
//
//   ParticleBarrierForm:   B(X(v_g), x(v_f)),  X_p = X_p^n + dt sum_i w_ip v_i,  x_a = x_a^n + dt v_a,
//   ParticleFrictionForm:  dt D(v),  D = sum_k mu lambda_k f0(|T_k^T (sum_i w_ip v_i - sum_j c_kj v_j)|),
//
// B the particle / boundary-facet barrier (particle_contact.hpp), D the lagged particle-mesh
// friction (contact/friction.hpp: the particle's velocity relative to the closest point of the
// facet, c_kj its weights, frozen with the normal force lambda_k and the tangent basis T_k at the
// start of the step). Both are sums over pairs (particle p, facet) with terms in the stacked
// (X_p, facet nodes): a pair's gradient reaches the particle's stencil nodes as dt w_ip dB/dX_p
// and the facet's nodes as dt dB/dx_a; its Hessian dt^2 J^T H J (J: the weights w_ip on the
// stencil and the identity on the facet's nodes) couples the stencil to the facet's nodes. A
// friction pair has the same shape with dt for dt^2. Each pair's Hessian is PSD (projected), and
// the fixed components' rows and columns are left out.
#include <vector>

#include "pnet/coupling/particle_contact.hpp"
#include "pnet/fem/fem_potential.hpp"
#include "pnet/mpm/incremental_potential.hpp"
#include "pnet/solver/form.hpp"

namespace pnet {

/// What the barrier and friction pairs share: their terms, how they reach the unknowns, and
/// their Hessian's products.
template <int dim>
class ParticleMeshForm : public Form {
public:
    using Contact = ParticleContact<dim>;
    using Pair = typename Contact::Pair;
    using Gradient = typename Contact::Gradient;
    using Hessian = typename Contact::Hessian;
    static constexpr int kPairNodes = IncrementalPotential<dim>::kStencil + dim;  // stencil + facet nodes

    /// `free`: the coupled problem's 1 / 0 mask of free components (referenced).
    ParticleMeshForm(const IncrementalPotential<dim>& mpm, const FemPotential<dim>& fem, const Contact& contact,
                     const VecX& free)
        : mpm_(mpm), fem_(fem), contact_(contact), free_(free) {}

    void add_hessian_multiply(const VecX& d, VecX& out) const override;
    void add_hessian_diagonal(VecX& diagonal) const override;
    void add_hessian_block_diagonal(VecX& blocks) const override;
    void add_hessian_triplets(std::vector<Triplet>& triplets) const override;
    bool changing_pattern() const override { return true; }

    /// The pairs at the last evaluation, and those of the Hessian prepared last.
    const std::vector<Pair>& pairs() const { return pairs_; }
    const std::vector<Pair>& hessian_pairs() const { return hessian_pairs_; }
    /// f(H, scale, count, index, weight, slot) for every pair with a Hessian: its stacked
    /// Hessian, the factor of its Hessian in v, and its unknown components (the particle's
    /// stencil, weight w_ip, slot 0; the facet's nodes, weight 1, slots 1 .. dim).
    template <typename F>
    void for_each_pair_hessian(F&& f) const;

protected:
    /// v's grid and mesh parts into vg_, vf_.
    void split(const VecX& v) const;
    /// The particles' and the mesh's positions at v (after split(v)).
    void positions(const VecX& v) const;
    /// g += dt J^T gradient of each pair.
    void scatter_gradient(VecX& g) const;
    int pair_nodes(const Pair& pair, Eigen::Index* index, double* weight, int* slot) const;

    const IncrementalPotential<dim>& mpm_;
    const FemPotential<dim>& fem_;
    const Contact& contact_;
    const VecX& free_;
    std::vector<Pair> pairs_, hessian_pairs_;
    std::vector<Gradient> gradients_;
    std::vector<Hessian> hessians_;
    double hessian_scale_ = 0.0;  // dt^2 for the barrier (terms in positions), dt for friction
    mutable VecX vg_, vf_;
    mutable std::vector<Vec<dim>> X_, x_;
};

template <int dim>
class ParticleBarrierForm final : public ParticleMeshForm<dim> {
public:
    using ParticleMeshForm<dim>::ParticleMeshForm;

    /// A new step: no pairs, no CCD queries.
    void begin_step();
    double value(const VecX& v) override;
    double add_gradient(const VecX& v, VecX& g) override;
    void prepare_hessian(const VecX& v) override;
    /// The CCD of the particles' linear motion against the mesh's, so every iterate is
    /// intersection-free.
    double max_step(const VecX& v, const VecX& d) override;

    /// Project the pair Hessians to PSD (default; false: exact, for derivative checks).
    void set_project_psd(bool project) { project_psd_ = project; }
    const CcdCount& ccd() const { return ccd_; }

private:
    std::vector<Vec<dim>> dX_, dx_;
    bool project_psd_ = true;
    CcdCount ccd_;
};

template <int dim>
class ParticleFrictionForm final : public ParticleMeshForm<dim> {
public:
    using ParticleMeshForm<dim>::ParticleMeshForm;

    /// The step's lagged pairs (ParticleContact::lagged_pairs() at its start), the Coulomb
    /// coefficient mu >= 0 and the slip velocity eps_v > 0 (m/s) below which it is smoothed.
    /// mu = 0: none.
    void set_pairs(std::vector<ParticleFrictionPair<dim>> pairs, double mu, double eps_v);
    std::size_t size() const { return friction_pairs_.size(); }

    double value(const VecX& v) override;
    double add_gradient(const VecX& v, VecX& g) override;
    void prepare_hessian(const VecX& v) override;

private:
    /// The slip T^T (v_p - sum_j c_j v_j) of pair k at the velocities in vg_, vf_.
    Eigen::Matrix<double, dim - 1, 1> slip(std::size_t k) const;

    std::vector<ParticleFrictionPair<dim>> friction_pairs_;
    double mu_ = 0.0, eps_v_ = 1e-4;
};

template <int dim>
template <typename F>
void ParticleMeshForm<dim>::for_each_pair_hessian(F&& f) const {
    Eigen::Index index[kPairNodes];
    double weight[kPairNodes];
    int slot[kPairNodes];
    for (std::size_t k = 0; k < hessians_.size(); ++k) {
        const int count = pair_nodes(hessian_pairs_[k], index, weight, slot);
        f(hessians_[k], hessian_scale_, count, index, weight, slot);
    }
}

}  // namespace pnet
