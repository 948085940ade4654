#include "pnet/contact/collisions/contact2d.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

#include "pnet/contact/ccd/point_edge.hpp"
#include "pnet/contact/distance/point_edge.hpp"
#include "pnet/math/psd.hpp"

namespace pnet {

Contact2d::Contact2d(const std::vector<std::array<int, 2>>& boundary_edges, double dhat, double kappa)
    : edges_(boundary_edges), dhat_(dhat), kappa_(kappa), barrier_{dhat * dhat} {
    if (!(dhat > 0.0) || !(kappa > 0.0)) throw std::invalid_argument("Contact2d: dhat and kappa must be > 0");
    for (const auto& e : edges_) nodes_.insert(nodes_.end(), e.begin(), e.end());
    std::sort(nodes_.begin(), nodes_.end());
    nodes_.erase(std::unique(nodes_.begin(), nodes_.end()), nodes_.end());
}

template <typename F>
void Contact2d::for_each_candidate(const std::vector<Vec<2>>& x, const std::vector<Vec<2>>* dx, double margin,
                                   F&& f) const {
    // Sort and sweep along x: the edges' boxes (swept over dx, grown by margin) sorted by their
    // lower x; a node's candidates are the edges whose lower x lies in [node lo - widest box,
    // node hi]; those whose boxes overlap the node's are visited in ascending edge order, as
    // the all-pairs loop did, so that sums over pairs keep their order (and their bits).
    const std::size_t m = edges_.size();
    box_lo_.resize(m);
    box_hi_.resize(m);
    double widest = 0.0;
    for (std::size_t k = 0; k < m; ++k) {
        const auto& e = edges_[k];
        Vec<2> lo = x[e[0]].cwiseMin(x[e[1]]), hi = x[e[0]].cwiseMax(x[e[1]]);
        if (dx) {
            const Vec<2> a1 = x[e[0]] + (*dx)[e[0]], b1 = x[e[1]] + (*dx)[e[1]];
            lo = lo.cwiseMin(a1).cwiseMin(b1);
            hi = hi.cwiseMax(a1).cwiseMax(b1);
        }
        box_lo_[k] = lo.array() - margin;
        box_hi_[k] = hi.array() + margin;
        widest = std::max(widest, box_hi_[k][0] - box_lo_[k][0]);
    }
    order_.resize(m);
    for (std::size_t k = 0; k < m; ++k) order_[k] = static_cast<int>(k);
    std::sort(order_.begin(), order_.end(), [&](int a, int b) { return box_lo_[a][0] < box_lo_[b][0]; });
    sorted_lo_.resize(m);
    for (std::size_t k = 0; k < m; ++k) sorted_lo_[k] = box_lo_[order_[k]][0];
    std::vector<int>& found = found_;
    for (int node : nodes_) {
        const Vec<2>& p = x[node];
        Vec<2> lo = p, hi = p;
        if (dx) {
            lo = lo.cwiseMin(p + (*dx)[node]);
            hi = hi.cwiseMax(p + (*dx)[node]);
        }
        const auto first = std::lower_bound(sorted_lo_.begin(), sorted_lo_.end(), lo[0] - widest);
        const auto last = std::upper_bound(first, sorted_lo_.end(), hi[0]);
        found.clear();
        for (auto it = first; it != last; ++it) {
            const int k = order_[it - sorted_lo_.begin()];
            const auto& e = edges_[k];
            if (e[0] == node || e[1] == node) continue;
            if ((hi.array() < box_lo_[k].array()).any() || (lo.array() > box_hi_[k].array()).any()) continue;
            found.push_back(k);
        }
        std::sort(found.begin(), found.end());
        f(node, found);
    }
}

std::vector<Contact2d::Pair> Contact2d::active(const std::vector<Vec<2>>& x) const {
    std::vector<Pair> pairs;
    const double s_hat = dhat_ * dhat_;
    for_each_candidate(x, nullptr, dhat_, [&](int node, const std::vector<int>& edges) {
        const Vec<2>& p = x[node];
        for (int k : edges)
            if (point_edge_distance_sq(p, x[edges_[k][0]], x[edges_[k][1]]) < s_hat) pairs.push_back({node, k});
        for (std::size_t h = 0; h < half_spaces_.size(); ++h) {
            const double d = half_spaces_[h].normal.dot(p - half_spaces_[h].origin);
            if (d < dhat_) pairs.push_back({node, -static_cast<int>(h) - 1});
        }
    });
    return pairs;
}

double Contact2d::energy(const std::vector<Vec<2>>& x, double scale, Eigen::VectorXd* g) const {
    double sum = 0.0;
    for (const Pair& pair : active(x)) {
        const Vec<2>& p = x[pair.node];
        if (pair.edge >= 0) {
            const int a = edges_[pair.edge][0], b = edges_[pair.edge][1];
            const PointEdgeCase c = point_edge_case(p, x[a], x[b]);
            const double s = point_edge_distance_sq(p, x[a], x[b], c);
            sum += barrier_.value(s);
            if (!g) continue;
            const Vec6 ds = point_edge_distance_sq_gradient(p, x[a], x[b], c);
            const double f = scale * kappa_ * barrier_.first(s);
            const int slot[3] = {pair.node, a, b};
            for (int k = 0; k < 3; ++k) g->segment<2>(2 * slot[k]) += f * ds.segment<2>(2 * k);
        } else {
            const HalfSpace2d& h = half_spaces_[-pair.edge - 1];
            const double d = h.normal.dot(p - h.origin);
            sum += barrier_.value(d > 0.0 ? d * d : 0.0);  // on or below the plane: intersecting
            if (g) g->segment<2>(2 * pair.node) += scale * kappa_ * barrier_.first(d * d) * 2.0 * d * h.normal;
        }
    }
    return kappa_ * sum;
}

double Contact2d::stable_time_step(const std::vector<Vec<2>>& x, const std::vector<double>& free_mass) const {
    double omega2 = 0.0;
    for (const Pair& pair : active(x)) {
        double s = 0.0, inverse_mass = 0.0;
        auto add = [&](int node) {
            if (free_mass[node] > 0.0) inverse_mass += 1.0 / free_mass[node];
        };
        add(pair.node);
        if (pair.edge >= 0) {
            const int a = edges_[pair.edge][0], b = edges_[pair.edge][1];
            s = point_edge_distance_sq(x[pair.node], x[a], x[b]);
            add(a);
            add(b);
        } else {
            const HalfSpace2d& h = half_spaces_[-pair.edge - 1];
            const double d = h.normal.dot(x[pair.node] - h.origin);
            s = d * d;
        }
        // d^2/dd^2 b(d^2) = 4 s b''(s) + 2 b'(s).
        const double k = kappa_ * std::abs(4.0 * s * barrier_.second(s) + 2.0 * barrier_.first(s));
        omega2 = std::max(omega2, k * inverse_mass);
    }
    return omega2 > 0.0 ? 1.0 / std::sqrt(omega2) : std::numeric_limits<double>::infinity();
}

double Contact2d::value(const std::vector<Vec<2>>& x) const { return energy(x, 0.0, nullptr); }

double Contact2d::add_gradient(const std::vector<Vec<2>>& x, double scale, Eigen::VectorXd& g) const {
    return energy(x, scale, &g);
}

void Contact2d::add_hessian(const std::vector<Vec<2>>& x, double scale,
                            std::vector<Eigen::Triplet<double>>& triplets, bool project_psd) const {
    for (const Pair& pair : active(x)) {
        const Vec<2>& p = x[pair.node];
        if (pair.edge >= 0) {
            const int a = edges_[pair.edge][0], b = edges_[pair.edge][1];
            const PointEdgeCase c = point_edge_case(p, x[a], x[b]);
            const double s = point_edge_distance_sq(p, x[a], x[b], c);
            const Vec6 ds = point_edge_distance_sq_gradient(p, x[a], x[b], c);
            Mat6 H = barrier_.second(s) * ds * ds.transpose() +
                     barrier_.first(s) * point_edge_distance_sq_hessian(p, x[a], x[b], c);
            if (project_psd) H = pnet::project_psd<6>(H);
            H *= scale * kappa_;
            const int slot[3] = {pair.node, a, b};
            for (int r = 0; r < 6; ++r)
                for (int q = 0; q < 6; ++q)
                    triplets.emplace_back(2 * slot[r / 2] + r % 2, 2 * slot[q / 2] + q % 2, H(r, q));
        } else {
            const HalfSpace2d& h = half_spaces_[-pair.edge - 1];
            const double d = h.normal.dot(p - h.origin), s = d * d;
            // d2b/dx2 = b'' (2 d n)(2 d n)^T + b' 2 n n^T: PSD whenever b'' >= 0 > b' ... project anyway.
            const double coefficient = barrier_.second(s) * 4.0 * s + barrier_.first(s) * 2.0;
            const double k = scale * kappa_ * (project_psd ? std::max(coefficient, 0.0) : coefficient);
            const Eigen::Matrix2d H = k * h.normal * h.normal.transpose();
            for (int r = 0; r < 2; ++r)
                for (int q = 0; q < 2; ++q) triplets.emplace_back(2 * pair.node + r, 2 * pair.node + q, H(r, q));
        }
    }
}

std::vector<FrictionPair<2>> Contact2d::lagged_pairs(const std::vector<Vec<2>>& x) const {
    std::vector<FrictionPair<2>> out;
    const Eigen::Matrix2d R = (Eigen::Matrix2d() << 0.0, -1.0, 1.0, 0.0).finished();  // +90 degrees
    for (const Pair& pair : active(x)) {
        FrictionPair<2> l;
        const Vec<2>& p = x[pair.node];
        double s = 0.0;
        if (pair.edge >= 0) {
            const int a = edges_[pair.edge][0], b = edges_[pair.edge][1];
            const PointEdgeCase c = point_edge_case(p, x[a], x[b]);
            s = point_edge_distance_sq(p, x[a], x[b], c);
            l.count = 3;
            l.node = {pair.node, a, b, 0};
            if (c == PointEdgeCase::Interior) {
                const Vec<2> e = x[b] - x[a];
                const double alpha = (p - x[a]).dot(e) / e.squaredNorm();
                l.weight = {1.0, -(1.0 - alpha), -alpha, 0.0};
                l.tangent = e.normalized();
            } else {
                const int end = c == PointEdgeCase::EndpointA ? a : b;
                l.weight = {1.0, end == a ? -1.0 : 0.0, end == b ? -1.0 : 0.0, 0.0};
                l.tangent = (R * (p - x[end])).normalized();
            }
        } else {
            const HalfSpace2d& h = half_spaces_[-pair.edge - 1];
            const double d = h.normal.dot(p - h.origin);
            s = d * d;
            l.count = 1;
            l.node = {pair.node, 0, 0, 0};
            l.weight = {1.0, 0.0, 0.0, 0.0};
            l.tangent = R * h.normal;
        }
        l.normal_force = -kappa_ * barrier_.first(s) * 2.0 * std::sqrt(s);
        out.push_back(l);
    }
    return out;
}

double Contact2d::max_step(const std::vector<Vec<2>>& x, const std::vector<Vec<2>>& dx) const {
    double t = 1.0;
    for_each_candidate(x, &dx, 0.0, [&](int node, const std::vector<int>& edges) {
        const Vec<2>& p = x[node];
        for (int k : edges) {
            const auto& e = edges_[k];
            t = std::min(t, point_edge_time_of_impact(p, x[e[0]], x[e[1]], dx[node], dx[e[0]], dx[e[1]], 0.0, t));
        }
        for (const HalfSpace2d& h : half_spaces_)
            t = std::min(t, point_plane_time_of_impact(p, dx[node], h.origin, h.normal, t));
    });
    return t;
}

double Contact2d::min_distance(const std::vector<Vec<2>>& x) const {
    // The pairs within dhat first (the broad phase); only when none is that close, all pairs.
    double d = kNoImpact;
    for_each_candidate(x, nullptr, dhat_, [&](int node, const std::vector<int>& edges) {
        for (int k : edges) d = std::min(d, std::sqrt(point_edge_distance_sq(x[node], x[edges_[k][0]], x[edges_[k][1]])));
        for (const HalfSpace2d& h : half_spaces_) d = std::min(d, h.normal.dot(x[node] - h.origin));
    });
    if (d < dhat_) return d;
    for (int node : nodes_) {
        for (const auto& e : edges_)
            if (e[0] != node && e[1] != node)
                d = std::min(d, std::sqrt(point_edge_distance_sq(x[node], x[e[0]], x[e[1]])));
        for (const HalfSpace2d& h : half_spaces_) d = std::min(d, h.normal.dot(x[node] - h.origin));
    }
    return d;
}

std::size_t Contact2d::active_pairs(const std::vector<Vec<2>>& x) const { return active(x).size(); }

namespace {

double orient(const Vec<2>& a, const Vec<2>& b, const Vec<2>& c) {
    return (b - a)[0] * (c - a)[1] - (b - a)[1] * (c - a)[0];
}

/// Segments pq and rs (no shared endpoint) cross or touch.
bool segments_intersect(const Vec<2>& p, const Vec<2>& q, const Vec<2>& r, const Vec<2>& s) {
    const double d1 = orient(r, s, p), d2 = orient(r, s, q), d3 = orient(p, q, r), d4 = orient(p, q, s);
    if (((d1 > 0 && d2 < 0) || (d1 < 0 && d2 > 0)) && ((d3 > 0 && d4 < 0) || (d3 < 0 && d4 > 0))) return true;
    // Touching or collinear overlap: an endpoint on the other segment.
    return !(point_edge_distance_sq(p, r, s) > 0.0) || !(point_edge_distance_sq(q, r, s) > 0.0) ||
           !(point_edge_distance_sq(r, p, q) > 0.0) || !(point_edge_distance_sq(s, p, q) > 0.0);
}

}  // namespace

std::string Contact2d::first_intersection(const std::vector<Vec<2>>& x) const {
    for (int node : nodes_) {
        for (const auto& e : edges_)
            if (e[0] != node && e[1] != node && !(point_edge_distance_sq(x[node], x[e[0]], x[e[1]]) > 0.0))
                return "node " + std::to_string(node) + " and edge " + std::to_string(e[0]) + "-" + std::to_string(e[1]);
        for (std::size_t h = 0; h < half_spaces_.size(); ++h)
            if (!(half_spaces_[h].normal.dot(x[node] - half_spaces_[h].origin) > 0.0))
                return "node " + std::to_string(node) + " and half-space " + std::to_string(h);
    }
    for (std::size_t i = 0; i < edges_.size(); ++i) {
        const auto& a = edges_[i];
        for (std::size_t j = i + 1; j < edges_.size(); ++j) {
            const auto& b = edges_[j];
            if (a[0] == b[0] || a[0] == b[1] || a[1] == b[0] || a[1] == b[1]) continue;
            if (segments_intersect(x[a[0]], x[a[1]], x[b[0]], x[b[1]]))
                return "edge " + std::to_string(a[0]) + "-" + std::to_string(a[1]) + " and edge " +
                       std::to_string(b[0]) + "-" + std::to_string(b[1]);
        }
    }
    return "";
}

}  // namespace pnet
