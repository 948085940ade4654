#pragma once
// IPC contact in 3D (docs/methods.md): the barrier B(x) = kappa sum_k m_k b(s_k(x))
// over the pairs of a closed boundary surface closer than dhat:
//   point-triangle  every boundary node against every boundary triangle it is not a corner of
//                   (7 distance cases, distance/point_triangle_edge_edge.hpp), m = 1;
//   edge-edge       every two boundary edges without a common node (9 cases), m IPC's
//                   mollifier of |e_a x e_b|^2 below 1e-3 |e_a|^2 |e_b|^2 (rest lengths), which
//                   keeps the energy C1 where nearly parallel edges change case;
//   point-plane     every boundary node against every half-space (the ground), m = 1.
// As in IPC, a node near a shared edge or corner of several triangles meets each of them: the
// duplicate pairs only scale the barrier there, and every one is an exact barrier.
// Each pair's Hessian (12 x 12) is projected to PSD before assembly; max_step() is the CCD
// filter (additive CCD, ccd/point_triangle_edge_edge.hpp) of the line search.
//
// Broad phase: uniform hash grids (broad_phase/hash_grid.hpp) of the triangles' and the edges' boxes
// grown by 3 dhat give a list of candidate pairs (a Verlet list), reused until some node has
// moved dhat: the active pairs and the CCD pairs (swept boxes overlapping) are filtered from
// it; a motion too long for it gets its own swept broad phase. The pairs are visited in a
// fixed order (nodes ascending, then triangles ascending; edges ascending) and the filters
// are exact, so every sum has the same bits on every run, whatever the list's age.
#include <array>
#include <string>
#include <vector>

#include "pnet/contact/barrier.hpp"
#include "pnet/contact/broad_phase/hash_grid.hpp"
#include "pnet/contact/collisions/contact_potential.hpp"

namespace pnet {

class Contact3d final : public ContactPotential<3> {
public:
    /// boundary_triangles: the mesh's outward boundary faces (Mesh<3>::boundary); its edges
    /// and nodes are derived. rest: the rest positions of all nodes (the mollifier's
    /// thresholds). dhat > 0 (m), kappa > 0 (J/m^4).
    Contact3d(const std::vector<std::array<int, 3>>& boundary_triangles, const std::vector<Vec<3>>& rest, double dhat,
              double kappa);

    void add_half_space(const HalfSpace<3>& half_space) {
        half_spaces_.push_back(half_space);
        active_valid_ = list_valid_ = false;
    }
    double dhat() const override { return dhat_; }
    double kappa() const override { return kappa_; }
    void set_kappa(double kappa) override { kappa_ = kappa; }

    double value(const std::vector<Vec<3>>& x) const override;
    double add_gradient(const std::vector<Vec<3>>& x, double scale, Eigen::VectorXd& g) const override;
    void add_hessian(const std::vector<Vec<3>>& x, double scale, std::vector<Eigen::Triplet<double>>& triplets,
                     bool project_psd) const override;
    double max_step(const std::vector<Vec<3>>& x, const std::vector<Vec<3>>& dx) const override;
    double stable_time_step(const std::vector<Vec<3>>& x, const std::vector<double>& free_mass) const override;
    std::vector<FrictionPair<3>> lagged_pairs(const std::vector<Vec<3>>& x) const override;
    /// The smallest distance of any pair (searched within dhat, then 10x farther until one is found).
    double min_distance(const std::vector<Vec<3>>& x) const override;
    std::size_t active_pairs(const std::vector<Vec<3>>& x) const override;
    /// A boundary edge crossing or touching a boundary triangle (no common node), a node on a
    /// triangle, two touching edges, or a node on or below a half-space, as text ("edge 3-4 and
    /// triangle 30-31-35"), or "". Orientation predicates without tolerance.
    std::string first_intersection(const std::vector<Vec<3>>& x) const override;

    const std::vector<std::array<int, 2>>& edges() const { return edges_; }
    const std::vector<std::array<int, 3>>& triangles() const { return triangles_; }

private:
    enum class Kind : unsigned char { PointTriangle, EdgeEdge, PointPlane };
    struct Pair {
        Kind kind;
        int a, b;  // PointTriangle: node, triangle; EdgeEdge: edge, edge; PointPlane: node, half-space
    };
    /// A pair's barrier at x: the value m b(s), and when asked its gradient and Hessian in the
    /// stacked positions of its nodes (node[0..count)).
    struct Terms {
        std::array<int, 4> node{};
        int count = 0;
        double s = 0.0, value = 0.0;
        Eigen::Matrix<double, 12, 1> gradient;
        Eigen::Matrix<double, 12, 12> hessian;
    };
    Terms terms(const Pair& pair, const std::vector<Vec<3>>& x, int order) const;

    /// Calls f(pair) for every candidate pair whose boxes (swept over dx when given, grown by
    /// margin) overlap, in the fixed order above.
    template <typename F>
    void for_each_candidate(const std::vector<Vec<3>>& x, const std::vector<Vec<3>>* dx, double margin, F&& f) const;
    /// The pairs closer than dhat at x (cached for the last x asked).
    const std::vector<Pair>& active(const std::vector<Vec<3>>& x) const;
    double energy(const std::vector<Vec<3>>& x, double scale, Eigen::VectorXd* g) const;

    std::vector<std::array<int, 3>> triangles_;
    std::vector<std::array<int, 2>> edges_;  // sorted (lo, hi), ascending
    std::vector<double> edge_rest_sq_;       // |e|^2 at rest
    std::vector<int> nodes_;                 // boundary nodes, ascending
    std::vector<HalfSpace<3>> half_spaces_;
    double dhat_, kappa_;
    Barrier barrier_;
    // Broad-phase work (a Contact3d is used by one thread at a time).
    mutable HashGrid<3> triangle_grid_, edge_grid_;
    mutable std::vector<Vec<3>> lo_, hi_, edge_lo_, edge_hi_, grown_lo_, grown_hi_;
    mutable std::vector<int> found_;
    mutable std::vector<Pair> candidates_;
    // A Verlet list: the candidate pairs within kListMargin dhat (box test) at list_x_, reused
    // while no node has moved far enough to bring a pair outside it into reach.
    static constexpr double kListMargin = 3.0;
    double displacement_since_list(const std::vector<Vec<3>>& x) const;
    void rebuild_list(const std::vector<Vec<3>>& x) const;
    mutable std::vector<Pair> list_;
    mutable std::vector<Vec<3>> list_x_;
    mutable bool list_valid_ = false;
    mutable std::vector<Pair> active_pairs_;
    mutable std::vector<Vec<3>> active_x_;
    mutable bool active_valid_ = false;
};

}  // namespace pnet
