#pragma once
// What the contact of an MPM-FEM coupled step needs beyond the mesh's (BFEMP, Li, Fang, Li,
// Jiang 2021; docs/methods.md), over v = [MPM grid velocities; FEM nodal velocities]:
//
//   CoupledVertices:       the contact's vertices, the mesh's nodes x_a = x_a^n + dt v_a and then
//                          the particles X_p = X_p^n + dt sum_i w_ip v_i (their B-spline stencils),
//                          for the one barrier form (contact/barrier_form.hpp) over the Contact
//                          whose stand-alone points are the particles (contact/collisions/contact.hpp);
//   ParticleFrictionForm:  dt D(v),  D = sum_k mu lambda_k f0(|T_k^T sum_j c_kj u_j(v)|),
//
// D the lagged particle-mesh friction (contact/friction.hpp): the velocity u_j of each vertex of
// a pair (the particle's, sum_i w_ip v_i; a facet node's, v_a), weighted as the pair's relative
// velocity (Contact::lagged_pairs: the particle minus the closest point of the facet), frozen with
// the normal force lambda_k and the tangent basis T_k at the start of the step. Its Hessian is kept
// per pair as the barrier's (VertexPairForm), with dt for dt^2.
#include <vector>

#include "pnet/contact/barrier_form.hpp"
#include "pnet/fem/fem_potential.hpp"
#include "pnet/mpm/incremental_potential.hpp"

namespace pnet {

template <int dim>
class CoupledVertices final : public ContactVertices<dim> {
public:
    CoupledVertices(const IncrementalPotential<dim>& mpm, const FemPotential<dim>& fem) : mpm_(mpm), fem_(fem) {}

    /// The contact's positions: the mesh's nodes x, then the particles X.
    static void join(const std::vector<Vec<dim>>& x, const std::vector<Vec<dim>>& X, std::vector<Vec<dim>>& out);

    double dt() const override { return mpm_.dt(); }
    void positions(const VecX& v, std::vector<Vec<dim>>& x) const override;
    void motion(const VecX& d, std::vector<Vec<dim>>& dx) const override;
    int unknowns(int vertex, Eigen::Index* index, double* weight) const override;

private:
    const IncrementalPotential<dim>& mpm_;
    const FemPotential<dim>& fem_;
    mutable VecX vg_, vf_;
    mutable std::vector<Vec<dim>> X_, x_;
};

template <int dim>
class ParticleFrictionForm final : public VertexPairForm<dim> {
public:
    using VertexPairForm<dim>::VertexPairForm;

    /// The step's lagged pairs (Contact::lagged_pairs() of the particle-mesh contact at its start),
    /// the Coulomb coefficient mu >= 0 and the slip velocity eps_v > 0 (m/s) below which it is
    /// smoothed. mu = 0: none.
    void set_pairs(std::vector<FrictionPair<dim>> pairs, double mu, double eps_v);
    std::size_t size() const { return pairs_.size(); }

    double value(const VecX& v) override;
    double add_gradient(const VecX& v, VecX& g) override;
    void prepare_hessian(const VecX& v) override;

private:
    /// The slip T^T sum_j c_j u_j(v) of pair k.
    Eigen::Matrix<double, dim - 1, 1> slip(std::size_t k, const VecX& v) const;

    std::vector<FrictionPair<dim>> pairs_;
    double mu_ = 0.0, eps_v_ = 1e-4;
};

}  // namespace pnet
