#include "pnet/coupling/particle_contact.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "pnet/math/psd.hpp"

namespace pnet {

template <int dim>
ParticleContact<dim>::ParticleContact(const std::vector<Facet>& facets, double dhat, double kappa)
    : facets_(facets), dhat_(dhat), kappa_(kappa) {
    if (!(dhat > 0.0) || !std::isfinite(dhat)) throw std::invalid_argument("ParticleContact: dhat must be > 0");
    if (!(kappa > 0.0) || !std::isfinite(kappa)) throw std::invalid_argument("ParticleContact: kappa must be > 0");
    barrier_.s_hat = dhat * dhat;
}

template <int dim>
template <typename F>
void ParticleContact<dim>::for_each_candidate(const std::vector<Vec<dim>>& X, const std::vector<Vec<dim>>* dX,
                                              const std::vector<Vec<dim>>& x, const std::vector<Vec<dim>>* dx,
                                              double margin, F&& f) const {
    const std::size_t nf = facets_.size();
    facet_lo_.resize(nf);
    facet_hi_.resize(nf);
    Vec<dim> mesh_lo = Vec<dim>::Constant(std::numeric_limits<double>::infinity()), mesh_hi = -mesh_lo;
    for (std::size_t e = 0; e < nf; ++e) {
        Vec<dim> lo = x[facets_[e][0]], hi = x[facets_[e][0]];
        for (int k = 1; k < Primitive::kNodes; ++k) {
            lo = lo.cwiseMin(x[facets_[e][k]]);
            hi = hi.cwiseMax(x[facets_[e][k]]);
        }
        if (dx) {
            for (int k = 0; k < Primitive::kNodes; ++k) {
                const Vec<dim> moved = x[facets_[e][k]] + (*dx)[facets_[e][k]];
                lo = lo.cwiseMin(moved);
                hi = hi.cwiseMax(moved);
            }
        }
        facet_lo_[e] = lo.array() - margin;
        facet_hi_[e] = hi.array() + margin;
        mesh_lo = mesh_lo.cwiseMin(facet_lo_[e]);
        mesh_hi = mesh_hi.cwiseMax(facet_hi_[e]);
    }
    for (std::size_t p = 0; p < X.size(); ++p) {
        Vec<dim> lo = X[p], hi = X[p];
        if (dX) {
            lo = lo.cwiseMin(X[p] + (*dX)[p]);
            hi = hi.cwiseMax(X[p] + (*dX)[p]);
        }
        if ((hi.array() < mesh_lo.array()).any() || (lo.array() > mesh_hi.array()).any()) continue;
        for (std::size_t e = 0; e < nf; ++e) {
            if ((hi.array() < facet_lo_[e].array()).any() || (lo.array() > facet_hi_[e].array()).any()) continue;
            f(static_cast<int>(p), static_cast<int>(e));
        }
    }
}

template <int dim>
std::vector<typename ParticleContact<dim>::Pair> ParticleContact<dim>::active(const std::vector<Vec<dim>>& X,
                                                                              const std::vector<Vec<dim>>& x) const {
    std::vector<Pair> pairs;
    const double s_hat = barrier_.s_hat;
    for_each_candidate(X, nullptr, x, nullptr, dhat_, [&](int p, int e) {
        if (Primitive::distance_sq(X[p], x, facets_[e]) < s_hat) pairs.push_back({p, e});
    });
    return pairs;
}

template <int dim>
double ParticleContact<dim>::value(const std::vector<Vec<dim>>& X, const std::vector<Vec<dim>>& x) const {
    double sum = 0.0;
    for (const Pair& pair : active(X, x))
        sum += barrier_.value(Primitive::distance_sq(X[pair.particle], x, facets_[pair.facet]));
    return kappa_ * sum;
}

template <int dim>
double ParticleContact<dim>::gradient(const std::vector<Vec<dim>>& X, const std::vector<Vec<dim>>& x,
                                      std::vector<Pair>& pairs, std::vector<Gradient>& gradients) const {
    pairs = active(X, x);
    gradients.resize(pairs.size());
    double sum = 0.0;
    for (std::size_t k = 0; k < pairs.size(); ++k) {
        const Vec<dim>& p = X[pairs[k].particle];
        const Facet& f = facets_[pairs[k].facet];
        const auto c = Primitive::classify(p, x, f);
        const double s = Primitive::distance_sq(p, x, f, c);
        sum += barrier_.value(s);
        gradients[k] = (kappa_ * barrier_.first(s)) * Primitive::gradient(p, x, f, c);
    }
    return kappa_ * sum;
}

template <int dim>
void ParticleContact<dim>::hessians(const std::vector<Vec<dim>>& X, const std::vector<Vec<dim>>& x, bool project_psd,
                                    std::vector<Pair>& pairs, std::vector<Hessian>& hessians) const {
    pairs = active(X, x);
    hessians.resize(pairs.size());
    for (std::size_t k = 0; k < pairs.size(); ++k) {
        const Vec<dim>& p = X[pairs[k].particle];
        const Facet& f = facets_[pairs[k].facet];
        const auto c = Primitive::classify(p, x, f);
        const double s = Primitive::distance_sq(p, x, f, c);
        const Gradient ds = Primitive::gradient(p, x, f, c);
        const Hessian H =
            kappa_ * (barrier_.second(s) * ds * ds.transpose() + barrier_.first(s) * Primitive::hessian(p, x, f, c));
        hessians[k] = project_psd ? pnet::project_psd<Primitive::kStacked>(H) : H;
    }
}

template <int dim>
double ParticleContact<dim>::max_step(const std::vector<Vec<dim>>& X, const std::vector<Vec<dim>>& dX,
                                      const std::vector<Vec<dim>>& x, const std::vector<Vec<dim>>& dx) const {
    double t = 1.0;
    for_each_candidate(X, &dX, x, &dx, 0.0, [&](int p, int e) {
        const double toi = Primitive::time_of_impact(X[p], dX[p], x, dx, facets_[e], t);
        if (toi < t) t = toi;
    });
    return t;
}

template <int dim>
std::vector<ParticleFrictionPair<dim>> ParticleContact<dim>::lagged_pairs(const std::vector<Vec<dim>>& X,
                                                                          const std::vector<Vec<dim>>& x) const {
    std::vector<ParticleFrictionPair<dim>> out;
    for (const Pair& pair : active(X, x)) {
        const Vec<dim>& p = X[pair.particle];
        const Facet& f = facets_[pair.facet];
        ParticleFrictionPair<dim> l;
        l.particle = pair.particle;
        l.facet = pair.facet;
        l.weight = Primitive::closest_weights(p, x, f);
        Vec<dim> closest = Vec<dim>::Zero();
        for (int j = 0; j < Primitive::kNodes; ++j) closest += l.weight[j] * x[f[j]];
        const Vec<dim> normal = p - closest;
        const double d = normal.norm();
        if (!(d > 0.0)) continue;  // touching: no direction to slide along (never at a barrier's iterate)
        l.tangent = tangent_basis<dim>(normal / d);
        l.normal_force = -kappa_ * barrier_.first(d * d) * 2.0 * d;
        if (l.normal_force > 0.0) out.push_back(l);
    }
    return out;
}

template <int dim>
double ParticleContact<dim>::min_distance(const std::vector<Vec<dim>>& X, const std::vector<Vec<dim>>& x) const {
    double best = std::numeric_limits<double>::infinity();
    for_each_candidate(X, nullptr, x, nullptr, dhat_,
                       [&](int p, int e) { best = std::min(best, Primitive::distance_sq(X[p], x, facets_[e])); });
    return std::sqrt(best);
}

template <int dim>
std::string ParticleContact<dim>::first_penetration(const std::vector<Vec<dim>>& X,
                                                    const std::vector<Vec<dim>>& x) const {
    std::string found;
    int last = -1;
    for_each_candidate(X, nullptr, x, nullptr, 0.0, [&](int p, int) {
        if (!found.empty() || p == last) return;
        last = p;
        int facet = -1;
        if (!inside_boundary(X[p], x, facets_, &facet)) return;
        found = "particle " + std::to_string(p);
        if (facet < 0) {
            found += " inside the mesh";
            return;
        }
        found += std::string(" on ") + Primitive::kFacetName + " ";
        for (int k = 0; k < Primitive::kNodes; ++k) found += (k ? "-" : "") + std::to_string(facets_[facet][k]);
    });
    return found;
}

template <int dim>
std::size_t ParticleContact<dim>::penetrations(const std::vector<Vec<dim>>& X, const std::vector<Vec<dim>>& x) const {
    std::size_t count = 0;
    int last = -1;
    for_each_candidate(X, nullptr, x, nullptr, 0.0, [&](int p, int) {
        if (p == last) return;  // one test per particle
        last = p;
        int facet = -1;
        count += inside_boundary(X[p], x, facets_, &facet);
    });
    return count;
}

template <int dim>
double ParticleContact<dim>::stable_time_step(const std::vector<Vec<dim>>& X, const std::vector<Vec<dim>>& x,
                                              const std::vector<double>& particle_mass,
                                              const std::vector<double>& node_mass) const {
    double omega2 = 0.0;
    for (const Pair& pair : active(X, x)) {
        const Facet& f = facets_[pair.facet];
        const double s = Primitive::distance_sq(X[pair.particle], x, f);
        double inverse_mass = 1.0 / particle_mass[pair.particle];
        for (int k = 0; k < Primitive::kNodes; ++k)
            if (node_mass[f[k]] > 0.0) inverse_mass += 1.0 / node_mass[f[k]];
        // d^2/dd^2 b(d^2) = 4 s b''(s) + 2 b'(s).
        const double k = kappa_ * std::abs(4.0 * s * barrier_.second(s) + 2.0 * barrier_.first(s));
        omega2 = std::max(omega2, k * inverse_mass);
    }
    return omega2 > 0.0 ? 1.0 / std::sqrt(omega2) : std::numeric_limits<double>::infinity();
}

template class ParticleContact<2>;
template class ParticleContact<3>;

}  // namespace pnet
