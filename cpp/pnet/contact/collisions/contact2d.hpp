#pragma once
// IPC contact as an energy in the nodal positions (docs/methods.md):
//   B(x) = kappa sum_k b(s_k(x)),   b the log barrier (barrier.hpp), s_k squared distances,
// over the pairs of a 2D boundary: every boundary node against every boundary
// edge it is not an endpoint of (contact between bodies and self-contact), and
// every boundary node against every half-space (the ground). A pair only
// counts while s < dhat^2. The Hessian of each pair, kappa (b'' ds ds^T +
// b' d2s), is projected to PSD before assembly. max_step() is the CCD filter
// of the line search: the largest step fraction that keeps every pair apart.
//
// Pairs are found by a sort-and-sweep broad phase along x over the edges'
// (swept, for CCD) bounding boxes, visiting each node's candidate edges in
// ascending order so that every sum keeps the order of an all-pairs loop.
// (Measured on metal_frame_2d: the all-pairs test was 14% of a plasticitynet
// run's time, and CCD 5%.)
#include <array>
#include <string>
#include <vector>

#include "pnet/contact/barrier.hpp"
#include "pnet/contact/collisions/contact_potential.hpp"

namespace pnet {

class Contact2d final : public ContactPotential<2> {
public:
    /// boundary_edges: the mesh's boundary facets (node pairs). dhat > 0 (m),
    /// kappa > 0 (the barrier stiffness, J/m^4: b is in m^4).
    Contact2d(const std::vector<std::array<int, 2>>& boundary_edges, double dhat, double kappa);

    void add_half_space(const HalfSpace2d& half_space) { half_spaces_.push_back(half_space); }
    double dhat() const override { return dhat_; }
    double kappa() const override { return kappa_; }
    void set_kappa(double kappa) override { kappa_ = kappa; }

    double value(const std::vector<Vec<2>>& x) const override;
    double add_gradient(const std::vector<Vec<2>>& x, double scale, Eigen::VectorXd& g) const override;
    void add_hessian(const std::vector<Vec<2>>& x, double scale, std::vector<Eigen::Triplet<double>>& triplets,
                     bool project_psd) const override;
    double max_step(const std::vector<Vec<2>>& x, const std::vector<Vec<2>>& dx) const override;

    /// The largest stable explicit step of the barrier at x, s: 1 / omega_max over the active
    /// pairs, omega^2 = k sum_j 1/m_j with k = kappa |d^2 b(d^2)/dd^2| the pair's normal stiffness
    /// and j its free nodes (mass > 0; kinematic nodes have mass 0 here). Half the limit 2/omega
    /// of symplectic Euler for a lone spring. Infinity when no pair is active.
    double stable_time_step(const std::vector<Vec<2>>& x, const std::vector<double>& free_mass) const override;

    /// The smallest distance of any pair (node-edge, node-plane), m.
    double min_distance(const std::vector<Vec<2>>& x) const override;
    std::size_t active_pairs(const std::vector<Vec<2>>& x) const override;
    /// Node-edge pairs: the node minus the closest point of the edge; node-plane: the node.
    std::vector<FrictionPair<2>> lagged_pairs(const std::vector<Vec<2>>& x) const override;

    /// A node-edge pair (or node inside a half-space) that intersects or touches at x, or two
    /// boundary edges that cross, as text ("node 12 and edge 30-31", "edge 3-4 and edge 30-31"),
    /// or empty if none: a start state must have none. (A body wholly inside another crosses no
    /// edge: the caller tests containment.) Exact predicates, all pairs: O(edges^2).
    std::string first_intersection(const std::vector<Vec<2>>& x) const override;

private:
    struct Pair {
        int node, edge;  // edge < 0: half-space -edge - 1
    };
    /// The pairs closer than dhat at x, in a fixed order.
    std::vector<Pair> active(const std::vector<Vec<2>>& x) const;
    /// B(x), and g += scale dB/dx when g is given: one pass over the active pairs.
    double energy(const std::vector<Vec<2>>& x, double scale, Eigen::VectorXd* g) const;

    /// Calls f(node, edges) for every boundary node with the edges (ascending, the node's own
    /// excluded) whose boxes, swept over dx when given and grown by margin, overlap its own.
    template <typename F>
    void for_each_candidate(const std::vector<Vec<2>>& x, const std::vector<Vec<2>>* dx, double margin, F&& f) const;

    std::vector<std::array<int, 2>> edges_;
    std::vector<int> nodes_;  // boundary nodes, ascending
    // Broad-phase work arrays (a Contact2d is used by one thread at a time).
    mutable std::vector<Vec<2>> box_lo_, box_hi_;
    mutable std::vector<int> order_, found_;
    mutable std::vector<double> sorted_lo_;
    std::vector<HalfSpace<2>> half_spaces_;
    double dhat_, kappa_;
    Barrier barrier_;
};

}  // namespace pnet
