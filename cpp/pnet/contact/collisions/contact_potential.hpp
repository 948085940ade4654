#pragma once
// The face of IPC contact (docs/methods.md): ContactPotential<dim>, the barrier energy of a
// mesh's nodal positions with its gradient, Hessian, CCD filter and lagged friction pairs, which
// the FEM problem adds as a form (contact/barrier_form.hpp); the half-spaces (the ground) and the
// lagged friction pair it hands to friction.hpp. Contact<dim> (contact.hpp) implements it for
// both dimensions.
#include <array>
#include <string>
#include <vector>

#include <Eigen/SparseCore>

#include "pnet/math/types.hpp"

namespace pnet {

/// The region n.(x - origin) < 0 is solid; n is a unit vector (default: the ground y < 0).
template <int dim>
struct HalfSpace {
    Vec<dim> origin = Vec<dim>::Zero();
    Vec<dim> normal = Vec<dim>::Unit(1);
};
using HalfSpace2d = HalfSpace<2>;

/// An active contact pair as lagged friction sees it (friction.hpp): the nodes and weights of
/// its relative velocity sum_j w_j v_j (the point minus the closest point of the other
/// primitive), its tangent basis (dim x (dim - 1), orthonormal columns, orthogonal to the
/// contact normal) and its normal force kappa |b'(s)| 2 d (N; per unit depth in 2D).
template <int dim>
struct FrictionPair {
    std::array<int, 4> node{};
    std::array<double, 4> weight{};
    int count = 0;
    Eigen::Matrix<double, dim, dim - 1> tangent = Eigen::Matrix<double, dim, dim - 1>::Zero();
    double normal_force = 0.0;
};

/// One active pair's barrier at x, without the stiffness kappa (ContactPotential::pair_terms()): its
/// vertices node[0..count) (a point-facet pair: the point, then the facet's nodes; edge-edge: the two
/// edges' nodes; point-plane: the node), its squared distance s, the barrier m b(s) (m: the edge-edge
/// mollifier, else 1) and, when asked, its gradient and Hessian in the stacked positions of its vertices.
template <int dim>
struct ContactPairTerms {
    static constexpr int kStacked = dim * (dim + 1);
    std::array<int, dim + 1> node{};
    int count = 0;
    double s = 0.0, value = 0.0;
    Eigen::Matrix<double, kStacked, 1> gradient;
    Eigen::Matrix<double, kStacked, kStacked> hessian;
};

/// The contact potential of positions x (all vertices: a mesh's nodes, then any stand-alone points, m), added to an
/// objective's value, gradient and Hessian with a scale (the chain rule of
/// x = x^n + dt v gives dt and dt^2).
template <int dim>
class ContactPotential {
public:
    virtual ~ContactPotential() = default;
    virtual double value(const std::vector<Vec<dim>>& x) const = 0;
    /// g += scale dB/dx (g: dim values per node); returns B(x), found in the same pass.
    virtual double add_gradient(const std::vector<Vec<dim>>& x, double scale, Eigen::VectorXd& g) const = 0;
    /// Triplets of scale d2B/dx2, PSD-projected per pair when project_psd.
    virtual void add_hessian(const std::vector<Vec<dim>>& x, double scale,
                             std::vector<Eigen::Triplet<double>>& triplets, bool project_psd) const = 0;
    /// Each pair active at x with its terms (order 0: value; 1: and gradient; 2: and Hessian,
    /// projected to PSD when project_psd), in the fixed order of the sums, into `terms` (resized).
    virtual void pair_terms(const std::vector<Vec<dim>>& x, int order, bool project_psd,
                            std::vector<ContactPairTerms<dim>>& terms) const = 0;
    /// The largest t in (0, 1] such that x + t dx keeps every pair apart (1 if nothing collides).
    virtual double max_step(const std::vector<Vec<dim>>& x, const std::vector<Vec<dim>>& dx) const = 0;
    /// The largest stable explicit step of the barrier forces at x (s), given each node's mass
    /// (0 for kinematic nodes); infinity when nothing is in contact.
    virtual double stable_time_step(const std::vector<Vec<dim>>& x, const std::vector<double>& free_mass) const = 0;
    /// The pairs active at x with their friction data, in a fixed order.
    virtual std::vector<FrictionPair<dim>> lagged_pairs(const std::vector<Vec<dim>>& x) const = 0;
    /// The smallest distance of any pair, m.
    virtual double min_distance(const std::vector<Vec<dim>>& x) const = 0;
    /// Pairs closer than dhat.
    virtual std::size_t active_pairs(const std::vector<Vec<dim>>& x) const = 0;
    /// An intersecting or touching pair at x as text naming its nodes, or "" (exact predicates).
    virtual std::string first_intersection(const std::vector<Vec<dim>>& x) const = 0;
    virtual double dhat() const = 0;
    virtual double kappa() const = 0;
    virtual void set_kappa(double kappa) = 0;

    /// Seconds spent in the broad phase and in narrow-phase CCD since the last reset, and the
    /// CCD pair queries (measured by the 3D contact; zero in 2D).
    struct Timing {
        double broad_phase_seconds = 0.0;
        double ccd_seconds = 0.0;
        long ccd_pairs = 0;
    };
    const Timing& timing() const { return timing_; }
    void reset_timing() const { timing_ = Timing{}; }

protected:
    mutable Timing timing_;
};

}  // namespace pnet
