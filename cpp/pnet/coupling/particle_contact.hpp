#pragma once
// The barrier between MPM particles and the boundary of FEM bodies (BFEMP, Li,
// Fang, Li, Jiang 2021; docs/methods.md), in 2D and 3D: every particle (a point)
// against every boundary facet of the mesh (edges in 2D, triangles in 3D:
// contact/point_facet.hpp),
//   B(X, x) = kappa sum_{p, f: s < dhat^2} b(s(X_p, x_f)),
// with b the IPC log barrier (contact/barrier.hpp) and s the squared point-facet
// distance. X are particle positions, x the mesh's nodal positions. The coupled
// incremental potential (coupled_potential.hpp) evaluates it at
// X_p(v) = X_p^n + dt sum_i w_ip v_i (linear in the grid velocities), so CCD on the
// particles' linear motion keeps every iterate intersection-free.
//
// Friction (lagged, as IPC's, contact/friction.hpp): lagged_pairs() freezes, for each pair
// active at the start of a step, the closest point's barycentric weights on the facet, the
// tangent basis of the contact normal and the normal force kappa |b'(s)| 2 d; the coupled
// potential adds the dissipative potential of the particle's velocity relative to that point.
//
// Broad phase: only particles inside the mesh's bounding box grown by dhat (or,
// for CCD, by the motion) are tested, each against the facets whose boxes
// overlap its own; pairs are visited in (particle, facet) order, so every sum
// has a fixed order.
#include <array>
#include <string>
#include <vector>

#include "pnet/contact/barrier.hpp"
#include "pnet/contact/collisions/point_facet.hpp"
#include "pnet/math/types.hpp"

namespace pnet {

/// A particle-facet pair as lagged friction sees it: the particle's velocity minus that of the
/// facet's point sum_j weight_j v_j, projected on the tangent basis (dim x (dim - 1)); the
/// normal force (N; per unit depth in 2D).
template <int dim>
struct ParticleFrictionPair {
    int particle = 0, facet = 0;
    std::array<double, dim> weight{};
    Eigen::Matrix<double, dim, dim - 1> tangent = Eigen::Matrix<double, dim, dim - 1>::Zero();
    double normal_force = 0.0;
};

template <int dim>
class ParticleContact {
public:
    using Primitive = PointFacet<dim>;
    using Facet = typename Primitive::Facet;
    using Gradient = typename Primitive::Gradient;  // in the stacked (X_p, facet nodes)
    using Hessian = typename Primitive::Hessian;
    struct Pair {
        int particle, facet;
    };

    /// facets: the mesh's boundary facets (node pairs or triples, oriented outward); dhat > 0 (m);
    /// kappa > 0 (J/m^4; per unit depth in 2D).
    ParticleContact(const std::vector<Facet>& facets, double dhat, double kappa);

    double dhat() const { return dhat_; }
    double kappa() const { return kappa_; }
    void set_kappa(double kappa) { kappa_ = kappa; }
    const std::vector<Facet>& facets() const { return facets_; }

    /// The pairs closer than dhat at particle positions X and mesh positions x, in (particle, facet) order.
    std::vector<Pair> active(const std::vector<Vec<dim>>& X, const std::vector<Vec<dim>>& x) const;

    /// B(X, x).
    double value(const std::vector<Vec<dim>>& X, const std::vector<Vec<dim>>& x) const;

    /// B and, per active pair, dB/d(X_p, x_facet) in `pairs` order.
    double gradient(const std::vector<Vec<dim>>& X, const std::vector<Vec<dim>>& x, std::vector<Pair>& pairs,
                    std::vector<Gradient>& gradients) const;

    /// Per active pair the Hessian of kappa b(s) in (X_p, x_facet), projected to PSD when asked.
    void hessians(const std::vector<Vec<dim>>& X, const std::vector<Vec<dim>>& x, bool project_psd,
                  std::vector<Pair>& pairs, std::vector<Hessian>& hessians) const;

    /// The largest t in (0, 1] such that particles X + t dX and the mesh x + t dx keep every pair
    /// apart (additive CCD), 1 if nothing collides.
    double max_step(const std::vector<Vec<dim>>& X, const std::vector<Vec<dim>>& dX, const std::vector<Vec<dim>>& x,
                    const std::vector<Vec<dim>>& dx) const;

    /// The active pairs at (X, x) with their friction data (normal force > 0), in (particle, facet) order.
    std::vector<ParticleFrictionPair<dim>> lagged_pairs(const std::vector<Vec<dim>>& X,
                                                        const std::vector<Vec<dim>>& x) const;

    /// The smallest particle-facet distance of the particles near the mesh (m; infinity if none is
    /// within the mesh's box grown by dhat).
    double min_distance(const std::vector<Vec<dim>>& X, const std::vector<Vec<dim>>& x) const;

    /// A particle inside the body bounded by the facets, or on a facet, as text ("particle 12
    /// inside the mesh"), or "" (inside_boundary(): the body's boundary is closed).
    std::string first_penetration(const std::vector<Vec<dim>>& X, const std::vector<Vec<dim>>& x) const;
    /// How many particles are inside the body or on its boundary.
    std::size_t penetrations(const std::vector<Vec<dim>>& X, const std::vector<Vec<dim>>& x) const;

    /// The largest stable explicit step of the barrier forces (s): 1 / omega over the active pairs,
    /// omega^2 = k (1 / m_p + sum_j 1 / m_j), k = kappa |d^2 b / dd^2| the pair's normal stiffness;
    /// infinity when nothing is in contact.
    double stable_time_step(const std::vector<Vec<dim>>& X, const std::vector<Vec<dim>>& x,
                            const std::vector<double>& particle_mass, const std::vector<double>& node_mass) const;

private:
    /// Calls f(particle, facet) for the candidate pairs: particles within the mesh's box (swept by
    /// dx, grown by margin) and, of those, the facets whose boxes (likewise) overlap the particle's
    /// (swept by dX when given).
    template <typename F>
    void for_each_candidate(const std::vector<Vec<dim>>& X, const std::vector<Vec<dim>>* dX,
                            const std::vector<Vec<dim>>& x, const std::vector<Vec<dim>>* dx, double margin,
                            F&& f) const;

    std::vector<Facet> facets_;
    double dhat_, kappa_;
    Barrier barrier_;
    mutable std::vector<Vec<dim>> facet_lo_, facet_hi_;
};

using ParticleContact2d = ParticleContact<2>;
using ParticleContact3d = ParticleContact<3>;

}  // namespace pnet
