#pragma once
// IPC contact between meshes and with the ground, in 2D and 3D (docs/methods.md): the barrier
//   B(x) = kappa sum_k m_k b(s_k(x)),   b the log barrier (barrier.hpp), s_k squared distances,
// over the pairs of a boundary closer than dhat:
//   point-facet  every boundary node against every boundary facet it is not a node of: an edge
//                in 2D (3 distance cases), a triangle in 3D (7 cases; collisions/point_facet.hpp
//                gives both), m = 1;
//   edge-edge    (3D) every two boundary edges without a common node (9 cases), m IPC's
//                mollifier of |e_a x e_b|^2 below 1e-3 |e_a|^2 |e_b|^2 (rest lengths), which
//                keeps the energy C1 where nearly parallel edges change case;
//   point-plane  every boundary node against every half-space (the ground), m = 1;
//   points       the stand-alone points (ContactPoints: MPM particles, as ipc-toolkit treats
//                codimensional vertices) as point-facet pairs against every boundary facet,
//                m = 1; a point meets no half-space and no other point.
// As in IPC, a node near a shared edge or corner of several facets meets each of them: the
// duplicate pairs only scale the barrier there, and every one is an exact barrier. Each pair's
// Hessian is projected to PSD before assembly; max_step() is the CCD filter (additive CCD,
// ccd/) of the line search: the largest step fraction that keeps every pair apart.
//
// Broad phase: uniform grids (broad_phase/hash_grid.hpp) of the facets' and the edges' boxes
// grown by 3 dhat give a list of candidate pairs (a Verlet list), reused until some node has
// moved dhat: the active pairs and the CCD pairs (swept boxes overlapping) are filtered from it;
// a motion too long for it gets its own swept broad phase. The pairs are visited in a fixed
// order (nodes ascending, each with its facets ascending and then its half-spaces; then edge
// pairs ascending) and the filters are exact, so every sum has the same bits on every run,
// whatever the list's age.
#include <array>
#include <string>
#include <vector>

#include "pnet/contact/barrier.hpp"
#include "pnet/contact/broad_phase/hash_grid.hpp"
#include "pnet/contact/collisions/contact_potential.hpp"
#include "pnet/contact/collisions/point_facet.hpp"

namespace pnet {

/// Stand-alone points: the positions of x from index `first` on (after the mesh's nodes), on no
/// facet, as many as x holds. Each meets every boundary facet and nothing else. `only`: the
/// Contact forms their pairs and no others (the particles of a coupled step against a body whose
/// contact with itself and the ground is another Contact's). first < 0: no points.
struct ContactPoints {
    int first = -1;
    bool only = false;
};

template <int dim>
class Contact final : public ContactPotential<dim> {
public:
    using Facet = typename PointFacet<dim>::Facet;
    using Terms = ContactPairTerms<dim>;

    /// facets: the mesh's outward boundary facets (Mesh<dim>::boundary: edges in 2D, triangles
    /// in 3D); its edges and nodes are derived. rest: the rest positions of all nodes (3D: the
    /// edge-edge mollifier's thresholds; unused in 2D and with points.only, may be empty). dhat > 0 (m), kappa > 0
    /// (the barrier stiffness, J/m^4: b is in m^4). points: the stand-alone points, if any.
    Contact(const std::vector<Facet>& facets, const std::vector<Vec<dim>>& rest, double dhat, double kappa,
            ContactPoints points = {});
    /// 2D: no rest positions needed.
    Contact(const std::vector<Facet>& facets, double dhat, double kappa) : Contact(facets, {}, dhat, kappa) {}

    void add_half_space(const HalfSpace<dim>& half_space) {
        half_spaces_.push_back(half_space);
        active_valid_ = list_valid_ = false;
    }
    double dhat() const override { return dhat_; }
    double kappa() const override { return kappa_; }
    void set_kappa(double kappa) override { kappa_ = kappa; }

    double value(const std::vector<Vec<dim>>& x) const override;
    double add_gradient(const std::vector<Vec<dim>>& x, double scale, Eigen::VectorXd& g) const override;
    void add_hessian(const std::vector<Vec<dim>>& x, double scale, std::vector<Eigen::Triplet<double>>& triplets,
                     bool project_psd) const override;
    void pair_terms(const std::vector<Vec<dim>>& x, int order, bool project_psd,
                    std::vector<Terms>& terms) const override;
    double max_step(const std::vector<Vec<dim>>& x, const std::vector<Vec<dim>>& dx) const override;

    /// The largest stable explicit step of the barrier at x, s: 1 / omega_max over the active
    /// pairs, omega^2 = k sum_j 1/m_j with k = kappa |d^2 b(d^2)/dd^2| the pair's normal stiffness
    /// and j its free nodes (mass > 0; kinematic nodes have mass 0 here). Half the limit 2/omega
    /// of symplectic Euler for a lone spring. Infinity when no pair is active.
    double stable_time_step(const std::vector<Vec<dim>>& x, const std::vector<double>& free_mass) const override;
    /// Point-facet pairs: the node minus the closest point of the facet; edge-edge: the closest
    /// points' difference; point-plane: the node.
    std::vector<FrictionPair<dim>> lagged_pairs(const std::vector<Vec<dim>>& x) const override;
    /// The smallest distance of any pair (searched within dhat, then 10x farther until one is found).
    double min_distance(const std::vector<Vec<dim>>& x) const override;
    std::size_t active_pairs(const std::vector<Vec<dim>>& x) const override;
    /// A node on a facet, two touching edges (3D), a node on or below a half-space, or a boundary
    /// edge crossing a facet (no common node), as text ("node 12 and edge 30-31", "edge 3-4 and
    /// triangle 30-31-35", "point 4 and edge 2-3": a stand-alone point, counted from the first),
    /// or "": a start state must have none. (A body wholly inside another
    /// crosses no facet: the caller tests containment.) Orientation predicates without tolerance.
    std::string first_intersection(const std::vector<Vec<dim>>& x) const override;

    const std::vector<std::array<int, 2>>& edges() const { return edges_; }
    const std::vector<Facet>& facets() const { return facets_; }
    const ContactPoints& points() const { return points_; }

private:
    static constexpr int kStacked = dim * (dim + 1);  // a point-facet or edge-edge pair's positions
    enum class Kind : unsigned char { PointFacet, EdgeEdge, PointPlane };
    struct Pair {
        Kind kind;
        int a, b;  // PointFacet: node, facet; EdgeEdge: edge, edge; PointPlane: node, half-space
    };
    /// A pair's barrier at x: the value m b(s), and when asked (order 1, 2) its gradient and
    /// Hessian in the stacked positions of its nodes (node[0..count)); order 2 with project_psd:
    /// the Hessian projected to PSD.
    Terms terms(const Pair& pair, const std::vector<Vec<dim>>& x, int order, bool project_psd = false) const;
    /// f(vertex, is_point) for the vertices that meet facets: the boundary nodes (unless
    /// points_.only), then the stand-alone points of x.
    template <typename F>
    void for_each_query_vertex(const std::vector<Vec<dim>>& x, F&& f) const;
    /// f(vertex) for every vertex whose motion moves a pair: the boundary nodes and the points.
    template <typename F>
    void for_each_moving_vertex(const std::vector<Vec<dim>>& x, F&& f) const;

    /// Calls f(pair) for every candidate pair whose boxes (swept over dx when given, grown by
    /// margin) overlap, in the fixed order above.
    template <typename F>
    void for_each_candidate(const std::vector<Vec<dim>>& x, const std::vector<Vec<dim>>* dx, double margin,
                            F&& f) const;
    /// The pairs closer than dhat at x (cached for the last x asked).
    const std::vector<Pair>& active(const std::vector<Vec<dim>>& x) const;
    double energy(const std::vector<Vec<dim>>& x, double scale, Eigen::VectorXd* g) const;

    std::vector<Facet> facets_;
    std::vector<std::array<int, 2>> edges_;  // sorted (lo, hi), ascending (2D: the facets)
    std::vector<double> edge_rest_sq_;       // |e|^2 at rest (3D)
    std::vector<int> nodes_;                 // boundary nodes, ascending
    std::vector<HalfSpace<dim>> half_spaces_;
    ContactPoints points_;
    double dhat_, kappa_;
    Barrier barrier_;
    // Broad-phase work (a Contact is used by one thread at a time).
    mutable HashGrid<dim> facet_grid_, edge_grid_;
    mutable std::vector<Vec<dim>> lo_, hi_, edge_lo_, edge_hi_, grown_lo_, grown_hi_;
    mutable std::vector<int> found_;
    mutable std::vector<Pair> candidates_;
    // A Verlet list: the candidate pairs within kListMargin dhat (box test) at list_x_, reused
    // while no node has moved far enough to bring a pair outside it into reach.
    static constexpr double kListMargin = 3.0;
    double displacement_since_list(const std::vector<Vec<dim>>& x) const;
    void rebuild_list(const std::vector<Vec<dim>>& x) const;
    mutable std::vector<Pair> list_;
    mutable std::vector<Vec<dim>> list_x_;
    mutable bool list_valid_ = false;
    mutable std::vector<Pair> active_pairs_;
    mutable std::vector<Vec<dim>> active_x_;
    mutable bool active_valid_ = false;
};

using Contact2d = Contact<2>;
using Contact3d = Contact<3>;

}  // namespace pnet
