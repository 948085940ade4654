#include "pnet/coupling/particle_contact.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

#include "pnet/contact/ccd.hpp"
#include "pnet/math/psd.hpp"

namespace pnet {

ParticleContact2d::ParticleContact2d(const std::vector<std::array<int, 2>>& edges, double dhat, double kappa)
    : edges_(edges), dhat_(dhat), kappa_(kappa) {
    if (!(dhat > 0.0) || !std::isfinite(dhat)) throw std::invalid_argument("ParticleContact2d: dhat must be > 0");
    if (!(kappa > 0.0) || !std::isfinite(kappa)) throw std::invalid_argument("ParticleContact2d: kappa must be > 0");
    barrier_.s_hat = dhat * dhat;
}

template <typename F>
void ParticleContact2d::for_each_candidate(const std::vector<Vec<2>>& X, const std::vector<Vec<2>>* dX,
                                           const std::vector<Vec<2>>& x, const std::vector<Vec<2>>* dx, double margin,
                                           F&& f) const {
    const std::size_t ne = edges_.size();
    edge_lo_.resize(ne);
    edge_hi_.resize(ne);
    Vec<2> mesh_lo = Vec<2>::Constant(std::numeric_limits<double>::infinity()), mesh_hi = -mesh_lo;
    for (std::size_t e = 0; e < ne; ++e) {
        Vec<2> lo = x[edges_[e][0]].cwiseMin(x[edges_[e][1]]), hi = x[edges_[e][0]].cwiseMax(x[edges_[e][1]]);
        if (dx) {
            for (int k = 0; k < 2; ++k) {
                const Vec<2> moved = x[edges_[e][k]] + (*dx)[edges_[e][k]];
                lo = lo.cwiseMin(moved);
                hi = hi.cwiseMax(moved);
            }
        }
        edge_lo_[e] = lo.array() - margin;
        edge_hi_[e] = hi.array() + margin;
        mesh_lo = mesh_lo.cwiseMin(edge_lo_[e]);
        mesh_hi = mesh_hi.cwiseMax(edge_hi_[e]);
    }
    for (std::size_t p = 0; p < X.size(); ++p) {
        Vec<2> lo = X[p], hi = X[p];
        if (dX) {
            lo = lo.cwiseMin(X[p] + (*dX)[p]);
            hi = hi.cwiseMax(X[p] + (*dX)[p]);
        }
        if ((hi.array() < mesh_lo.array()).any() || (lo.array() > mesh_hi.array()).any()) continue;
        for (std::size_t e = 0; e < ne; ++e) {
            if ((hi.array() < edge_lo_[e].array()).any() || (lo.array() > edge_hi_[e].array()).any()) continue;
            f(static_cast<int>(p), static_cast<int>(e));
        }
    }
}

std::vector<ParticleContact2d::Pair> ParticleContact2d::active(const std::vector<Vec<2>>& X,
                                                               const std::vector<Vec<2>>& x) const {
    std::vector<Pair> pairs;
    const double s_hat = barrier_.s_hat;
    for_each_candidate(X, nullptr, x, nullptr, dhat_, [&](int p, int e) {
        if (point_edge_distance_sq(X[p], x[edges_[e][0]], x[edges_[e][1]]) < s_hat) pairs.push_back({p, e});
    });
    return pairs;
}

double ParticleContact2d::value(const std::vector<Vec<2>>& X, const std::vector<Vec<2>>& x) const {
    double sum = 0.0;
    for (const Pair& pair : active(X, x))
        sum +=
            barrier_.value(point_edge_distance_sq(X[pair.particle], x[edges_[pair.edge][0]], x[edges_[pair.edge][1]]));
    return kappa_ * sum;
}

double ParticleContact2d::gradient(const std::vector<Vec<2>>& X, const std::vector<Vec<2>>& x, std::vector<Pair>& pairs,
                                   std::vector<Vec6>& gradients) const {
    pairs = active(X, x);
    gradients.resize(pairs.size());
    double sum = 0.0;
    for (std::size_t k = 0; k < pairs.size(); ++k) {
        const Vec<2>& p = X[pairs[k].particle];
        const Vec<2>& a = x[edges_[pairs[k].edge][0]];
        const Vec<2>& b = x[edges_[pairs[k].edge][1]];
        const PointEdgeCase c = point_edge_case(p, a, b);
        const double s = point_edge_distance_sq(p, a, b, c);
        sum += barrier_.value(s);
        gradients[k] = (kappa_ * barrier_.first(s)) * point_edge_distance_sq_gradient(p, a, b, c);
    }
    return kappa_ * sum;
}

void ParticleContact2d::hessians(const std::vector<Vec<2>>& X, const std::vector<Vec<2>>& x, bool project_psd,
                                 std::vector<Pair>& pairs, std::vector<Mat6>& hessians) const {
    pairs = active(X, x);
    hessians.resize(pairs.size());
    for (std::size_t k = 0; k < pairs.size(); ++k) {
        const Vec<2>& p = X[pairs[k].particle];
        const Vec<2>& a = x[edges_[pairs[k].edge][0]];
        const Vec<2>& b = x[edges_[pairs[k].edge][1]];
        const PointEdgeCase c = point_edge_case(p, a, b);
        const double s = point_edge_distance_sq(p, a, b, c);
        const Vec6 ds = point_edge_distance_sq_gradient(p, a, b, c);
        const Mat6 H = kappa_ * (barrier_.second(s) * ds * ds.transpose() +
                                 barrier_.first(s) * point_edge_distance_sq_hessian(p, a, b, c));
        hessians[k] = project_psd ? pnet::project_psd<6>(H) : H;
    }
}

double ParticleContact2d::max_step(const std::vector<Vec<2>>& X, const std::vector<Vec<2>>& dX,
                                   const std::vector<Vec<2>>& x, const std::vector<Vec<2>>& dx) const {
    double t = 1.0;
    for_each_candidate(X, &dX, x, &dx, 0.0, [&](int p, int e) {
        const int a = edges_[e][0], b = edges_[e][1];
        const double toi = point_edge_time_of_impact(X[p], x[a], x[b], dX[p], dx[a], dx[b], 0.0, t);
        if (toi < t) t = toi;
    });
    return t;
}

double ParticleContact2d::min_distance(const std::vector<Vec<2>>& X, const std::vector<Vec<2>>& x) const {
    double best = std::numeric_limits<double>::infinity();
    for_each_candidate(X, nullptr, x, nullptr, dhat_, [&](int p, int e) {
        best = std::min(best, point_edge_distance_sq(X[p], x[edges_[e][0]], x[edges_[e][1]]));
    });
    return std::sqrt(best);
}

bool ParticleContact2d::inside(const Vec<2>& p, const std::vector<Vec<2>>& x, int* edge_on) const {
    // Crossing number of the ray from p along +x with the closed boundary; a point on an edge counts as inside.
    bool in = false;
    for (std::size_t e = 0; e < edges_.size(); ++e) {
        const Vec<2>& a = x[edges_[e][0]];
        const Vec<2>& b = x[edges_[e][1]];
        const double cross = (b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0]);
        if (cross == 0.0 && (p - a).dot(p - b) <= 0.0) {
            *edge_on = static_cast<int>(e);
            return true;
        }
        if ((a[1] > p[1]) != (b[1] > p[1])) {
            const double xc = a[0] + (p[1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1]);
            if (p[0] < xc) in = !in;
        }
    }
    *edge_on = -1;
    return in;
}

std::string ParticleContact2d::first_penetration(const std::vector<Vec<2>>& X, const std::vector<Vec<2>>& x) const {
    std::string found;
    for_each_candidate(X, nullptr, x, nullptr, 0.0, [&](int p, int) {
        if (!found.empty()) return;
        int edge = -1;
        if (!inside(X[p], x, &edge)) return;
        found = "particle " + std::to_string(p) +
                (edge >= 0 ? " on edge " + std::to_string(edges_[edge][0]) + "-" + std::to_string(edges_[edge][1])
                           : " inside the mesh");
    });
    return found;
}

std::size_t ParticleContact2d::penetrations(const std::vector<Vec<2>>& X, const std::vector<Vec<2>>& x) const {
    std::size_t count = 0;
    int last = -1;
    for_each_candidate(X, nullptr, x, nullptr, 0.0, [&](int p, int) {
        if (p == last) return;  // one test per particle
        last = p;
        int edge = -1;
        count += inside(X[p], x, &edge);
    });
    return count;
}

double ParticleContact2d::stable_time_step(const std::vector<Vec<2>>& X, const std::vector<Vec<2>>& x,
                                           const std::vector<double>& particle_mass,
                                           const std::vector<double>& node_mass) const {
    double omega2 = 0.0;
    for (const Pair& pair : active(X, x)) {
        const int a = edges_[pair.edge][0], b = edges_[pair.edge][1];
        const double s = point_edge_distance_sq(X[pair.particle], x[a], x[b]);
        double inverse_mass = 1.0 / particle_mass[pair.particle];
        if (node_mass[a] > 0.0) inverse_mass += 1.0 / node_mass[a];
        if (node_mass[b] > 0.0) inverse_mass += 1.0 / node_mass[b];
        // d^2/dd^2 b(d^2) = 4 s b''(s) + 2 b'(s).
        const double k = kappa_ * std::abs(4.0 * s * barrier_.second(s) + 2.0 * barrier_.first(s));
        omega2 = std::max(omega2, k * inverse_mass);
    }
    return omega2 > 0.0 ? 1.0 / std::sqrt(omega2) : std::numeric_limits<double>::infinity();
}

}  // namespace pnet
