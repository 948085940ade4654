#pragma once
// The barrier between MPM particles and the boundary of FEM bodies (BFEMP, Li,
// Fang, Li, Jiang 2021; docs/methods.md), in 2D: every particle (a point) against
// every boundary edge of the mesh,
//   B(X, x) = kappa sum_{p, e: s < dhat^2} b(s(X_p, x_a, x_b)),
// with b the IPC log barrier (contact/barrier.hpp) and s the squared point-edge
// distance (contact/distance.hpp, three cases). X are particle positions, x the
// mesh's nodal positions. The coupled incremental potential
// (coupled_potential.hpp) evaluates it at X_p(v) = X_p^n + dt sum_i w_ip v_i
// (linear in the grid velocities), so CCD on the particles' linear motion keeps
// every iterate intersection-free.
//
// Broad phase: only particles inside the mesh's bounding box grown by dhat (or,
// for CCD, by the motion) are tested, each against the edges whose boxes
// overlap its own; pairs are visited in (particle, edge) order, so every sum
// has a fixed order.
#include <array>
#include <string>
#include <vector>

#include "pnet/contact/barrier.hpp"
#include "pnet/contact/distance.hpp"
#include "pnet/math/types.hpp"

namespace pnet {

class ParticleContact2d {
public:
    struct Pair {
        int particle, edge;
    };

    /// edges: the mesh's boundary edges (node pairs, counter-clockwise around
    /// the body); dhat > 0 (m); kappa > 0 (J/m^4 per unit depth).
    ParticleContact2d(const std::vector<std::array<int, 2>>& edges, double dhat, double kappa);

    double dhat() const { return dhat_; }
    double kappa() const { return kappa_; }
    void set_kappa(double kappa) { kappa_ = kappa; }
    const std::vector<std::array<int, 2>>& edges() const { return edges_; }

    /// The pairs closer than dhat at particle positions X and mesh positions x, in (particle, edge) order.
    std::vector<Pair> active(const std::vector<Vec<2>>& X, const std::vector<Vec<2>>& x) const;

    /// B(X, x).
    double value(const std::vector<Vec<2>>& X, const std::vector<Vec<2>>& x) const;

    /// B and, per active pair, dB/d(X_p, x_a, x_b) (6 values) in `pairs` order.
    double gradient(const std::vector<Vec<2>>& X, const std::vector<Vec<2>>& x, std::vector<Pair>& pairs,
                    std::vector<Vec6>& gradients) const;

    /// Per active pair the Hessian of kappa b(s) in (X_p, x_a, x_b), projected to PSD when asked.
    void hessians(const std::vector<Vec<2>>& X, const std::vector<Vec<2>>& x, bool project_psd,
                  std::vector<Pair>& pairs, std::vector<Mat6>& hessians) const;

    /// The largest t in (0, 1] such that particles X + t dX and the mesh x + t dx keep every pair
    /// apart (additive CCD, ccd.hpp), 1 if nothing collides.
    double max_step(const std::vector<Vec<2>>& X, const std::vector<Vec<2>>& dX, const std::vector<Vec<2>>& x,
                    const std::vector<Vec<2>>& dx) const;

    /// The smallest particle-edge distance of the particles near the mesh (m; infinity if none is
    /// within the mesh's box grown by dhat).
    double min_distance(const std::vector<Vec<2>>& X, const std::vector<Vec<2>>& x) const;

    /// A particle inside the body bounded by the edges, or on an edge, as text ("particle 12 inside the
    /// mesh"), or "": a crossing count of the ray along +x and a collinearity test (the body's
    /// boundary is closed).
    std::string first_penetration(const std::vector<Vec<2>>& X, const std::vector<Vec<2>>& x) const;
    /// How many particles are inside the body or on its boundary.
    std::size_t penetrations(const std::vector<Vec<2>>& X, const std::vector<Vec<2>>& x) const;

    /// The largest stable explicit step of the barrier forces (s): 1 / omega over the active pairs,
    /// omega^2 = k (1 / m_p + 1 / m_a + 1 / m_b), k = kappa |d^2 b / dd^2| the pair's normal stiffness;
    /// infinity when nothing is in contact.
    double stable_time_step(const std::vector<Vec<2>>& X, const std::vector<Vec<2>>& x,
                            const std::vector<double>& particle_mass, const std::vector<double>& node_mass) const;

private:
    /// Calls f(particle, edge) for the candidate pairs: particles within the mesh's box (swept by
    /// dx, grown by margin) and, of those, the edges whose boxes (likewise) overlap the particle's
    /// (swept by dX when given).
    template <typename F>
    void for_each_candidate(const std::vector<Vec<2>>& X, const std::vector<Vec<2>>* dX, const std::vector<Vec<2>>& x,
                            const std::vector<Vec<2>>* dx, double margin, F&& f) const;
    bool inside(const Vec<2>& p, const std::vector<Vec<2>>& x, int* edge_on) const;

    std::vector<std::array<int, 2>> edges_;
    double dhat_, kappa_;
    Barrier barrier_;
    mutable std::vector<Vec<2>> edge_lo_, edge_hi_;
};

}  // namespace pnet
