#include "pnet/contact/collisions/contact.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>
#include <stdexcept>

#include "pnet/contact/ccd/point_edge.hpp"
#include "pnet/contact/ccd/point_triangle_edge_edge.hpp"
#include "pnet/contact/distance/closest_point.hpp"
#include "pnet/contact/distance/point_edge.hpp"
#include "pnet/contact/distance/point_triangle_edge_edge.hpp"
#include "pnet/math/clock.hpp"
#include "pnet/math/psd.hpp"

namespace pnet {

namespace {

double orient(const Vec<2>& a, const Vec<2>& b, const Vec<2>& c) {
    return (b - a)[0] * (c - a)[1] - (b - a)[1] * (c - a)[0];
}

double orient(const Vec<3>& a, const Vec<3>& b, const Vec<3>& c, const Vec<3>& d) {
    return (b - a).cross(c - a).dot(d - a);
}

/// 2D: segment pq and the edge facet rs (no shared endpoint) cross or touch.
bool segment_crosses_facet(const Vec<2>& p, const Vec<2>& q, const std::vector<Vec<2>>& x,
                           const std::array<int, 2>& facet) {
    const Vec<2>&r = x[facet[0]], &s = x[facet[1]];
    const double d1 = orient(r, s, p), d2 = orient(r, s, q), d3 = orient(p, q, r), d4 = orient(p, q, s);
    if (((d1 > 0 && d2 < 0) || (d1 < 0 && d2 > 0)) && ((d3 > 0 && d4 < 0) || (d3 < 0 && d4 > 0))) return true;
    // Touching or collinear overlap: an endpoint on the other segment.
    return !(point_edge_distance_sq(p, r, s) > 0.0) || !(point_edge_distance_sq(q, r, s) > 0.0) ||
           !(point_edge_distance_sq(r, p, q) > 0.0) || !(point_edge_distance_sq(s, p, q) > 0.0);
}

/// 3D: segment pq and the triangle facet abc (no common node) cross or touch; coplanar contact
/// is left to the distance tests.
bool segment_crosses_facet(const Vec<3>& p, const Vec<3>& q, const std::vector<Vec<3>>& x,
                           const std::array<int, 3>& facet) {
    const Vec<3>&a = x[facet[0]], &b = x[facet[1]], &c = x[facet[2]];
    const double dp = orient(a, b, c, p), dq = orient(a, b, c, q);
    if ((dp > 0.0 && dq > 0.0) || (dp < 0.0 && dq < 0.0) || (dp == 0.0 && dq == 0.0)) return false;
    const double s1 = orient(p, q, a, b), s2 = orient(p, q, b, c), s3 = orient(p, q, c, a);
    return !((s1 > 0.0 || s2 > 0.0 || s3 > 0.0) && (s1 < 0.0 || s2 < 0.0 || s3 < 0.0));
}

/// A normal of a facet (not normalized): the edge turned by +90 degrees, the triangle's cross product.
Vec<2> facet_normal(const std::vector<Vec<2>>& x, const std::array<int, 2>& f) {
    const Vec<2> e = x[f[1]] - x[f[0]];
    return Vec<2>(-e[1], e[0]);
}

Vec<3> facet_normal(const std::vector<Vec<3>>& x, const std::array<int, 3>& f) {
    return (x[f[1]] - x[f[0]]).cross(x[f[2]] - x[f[0]]);
}

template <typename Array>
std::string join(const Array& nodes) {
    std::string out;
    for (std::size_t k = 0; k < nodes.size(); ++k) out += (k ? "-" : "") + std::to_string(nodes[k]);
    return out;
}

}  // namespace

template <int dim>
Contact<dim>::Contact(const std::vector<Facet>& facets, const std::vector<Vec<dim>>& rest, double dhat, double kappa,
                      ContactPoints points)
    : facets_(facets), points_(points), dhat_(dhat), kappa_(kappa), barrier_{dhat * dhat} {
    if (!(dhat > 0.0) || !(kappa > 0.0)) throw std::invalid_argument("Contact: dhat and kappa must be > 0");
    if (dim == 3 && rest.empty() && !facets.empty() && !points.only)
        throw std::invalid_argument("Contact: 3D contact needs the rest positions (the edge-edge mollifier)");
    constexpr int n = PointFacet<dim>::kNodes;
    for (const Facet& f : facets_) {
        for (int k = 0; k < n; ++k) {
            const int a = f[k], b = f[(k + 1) % n];
            if (a < 0 || b < 0 || (!rest.empty() && std::max(a, b) >= static_cast<int>(rest.size())))
                throw std::invalid_argument("Contact: a boundary facet's node is out of range");
            if (dim == 3 || k == 0) edges_.push_back({std::min(a, b), std::max(a, b)});
            nodes_.push_back(a);
        }
    }
    std::sort(edges_.begin(), edges_.end());
    edges_.erase(std::unique(edges_.begin(), edges_.end()), edges_.end());
    std::sort(nodes_.begin(), nodes_.end());
    nodes_.erase(std::unique(nodes_.begin(), nodes_.end()), nodes_.end());
    if (dim == 3 && !rest.empty())
        for (const auto& e : edges_) edge_rest_sq_.push_back((rest[e[1]] - rest[e[0]]).squaredNorm());
    if (points_.first >= 0 && !nodes_.empty() && nodes_.back() >= points_.first)
        throw std::invalid_argument("Contact: the stand-alone points start at " + std::to_string(points_.first) +
                                    ", before the last boundary node " + std::to_string(nodes_.back()));
    if (points_.only && points_.first < 0)
        throw std::invalid_argument("Contact: only the stand-alone points' pairs, but no points");
}

template <int dim>
template <typename F>
void Contact<dim>::for_each_query_vertex(const std::vector<Vec<dim>>& x, F&& f) const {
    if (!points_.only)
        for (int node : nodes_) f(node, false);
    if (points_.first >= 0)
        for (int p = points_.first; p < static_cast<int>(x.size()); ++p) f(p, true);
}

template <int dim>
template <typename F>
void Contact<dim>::for_each_moving_vertex(const std::vector<Vec<dim>>& x, F&& f) const {
    for (int node : nodes_) f(node);
    if (points_.first >= 0)
        for (int p = points_.first; p < static_cast<int>(x.size()); ++p) f(p);
}

template <int dim>
template <typename F>
void Contact<dim>::for_each_candidate(const std::vector<Vec<dim>>& x, const std::vector<Vec<dim>>* dx, double margin,
                                      F&& f) const {
    // The broad phase gathers the candidate pairs (timed), then f visits them (not timed: the
    // narrow phase is the caller's).
    const Clock::time_point start = Clock::now();
    auto box = [&](const int* node, int count, Vec<dim>& lo, Vec<dim>& hi) {
        lo = hi = x[node[0]];
        for (int k = 0; k < count; ++k) {
            lo = lo.cwiseMin(x[node[k]]);
            hi = hi.cwiseMax(x[node[k]]);
            if (dx) {
                lo = lo.cwiseMin(x[node[k]] + (*dx)[node[k]]);
                hi = hi.cwiseMax(x[node[k]] + (*dx)[node[k]]);
            }
        }
    };
    const std::size_t nf = facets_.size();
    lo_.resize(nf);
    hi_.resize(nf);
    for (std::size_t t = 0; t < nf; ++t) {
        box(facets_[t].data(), PointFacet<dim>::kNodes, lo_[t], hi_[t]);
        lo_[t].array() -= margin;
        hi_[t].array() += margin;
    }
    // Cells about a box wide: a box then covers a few cells whatever the margin.
    facet_grid_.build(lo_, hi_, HashGrid<dim>::suggested_cell(lo_, hi_, 1e-9));
    candidates_.clear();
    std::vector<int>& found = found_;
    for_each_query_vertex(x, [&](int node, bool point) {
        Vec<dim> lo = x[node], hi = x[node];
        if (dx) {
            lo = lo.cwiseMin(x[node] + (*dx)[node]);
            hi = hi.cwiseMax(x[node] + (*dx)[node]);
        }
        facet_grid_.query(lo, hi, found);
        for (int t : found) {
            const Facet& facet = facets_[t];
            if (!point && std::find(facet.begin(), facet.end(), node) != facet.end()) continue;
            candidates_.push_back(Pair{Kind::PointFacet, node, t});
        }
        if (point) return;
        for (std::size_t h = 0; h < half_spaces_.size(); ++h)
            candidates_.push_back(Pair{Kind::PointPlane, node, static_cast<int>(h)});
    });
    if constexpr (dim == 3)
        if (!points_.only) {
            const std::size_t ne = edges_.size();
            edge_lo_.resize(ne);
            edge_hi_.resize(ne);
            grown_lo_.resize(ne);
            grown_hi_.resize(ne);
            for (std::size_t e = 0; e < ne; ++e) {
                box(edges_[e].data(), 2, edge_lo_[e], edge_hi_[e]);
                grown_lo_[e] = edge_lo_[e].array() - margin;
                grown_hi_[e] = edge_hi_[e].array() + margin;
            }
            edge_grid_.build(grown_lo_, grown_hi_, HashGrid<dim>::suggested_cell(grown_lo_, grown_hi_, 1e-9));
            for (std::size_t e = 0; e < ne; ++e) {
                edge_grid_.query(edge_lo_[e], edge_hi_[e], found);
                const auto& ea = edges_[e];
                for (int other : found) {
                    if (other <= static_cast<int>(e)) continue;
                    const auto& eb = edges_[other];
                    if (ea[0] == eb[0] || ea[0] == eb[1] || ea[1] == eb[0] || ea[1] == eb[1]) continue;
                    candidates_.push_back(Pair{Kind::EdgeEdge, static_cast<int>(e), other});
                }
            }
        }
    this->timing_.broad_phase_seconds += seconds_since(start);
    for (const Pair& pair : candidates_) f(pair);
}

template <int dim>
typename Contact<dim>::Terms Contact<dim>::terms(const Pair& pair, const std::vector<Vec<dim>>& x, int order,
                                                 bool project_psd) const {
    using PF = PointFacet<dim>;
    Terms t;
    switch (pair.kind) {
        case Kind::PointFacet: {
            const Facet& facet = facets_[pair.b];
            t.node[0] = pair.a;
            for (int k = 0; k < PF::kNodes; ++k) t.node[k + 1] = facet[k];
            t.count = PF::kNodes + 1;
            const Vec<dim>& p = x[pair.a];
            const typename PF::Case c = PF::classify(p, x, facet);
            t.s = PF::distance_sq(p, x, facet, c);
            t.value = barrier_.value(t.s);
            if (order >= 1) t.gradient = barrier_.first(t.s) * PF::gradient(p, x, facet, c);
            if (order >= 2) {
                const typename PF::Gradient ds = PF::gradient(p, x, facet, c);
                t.hessian =
                    barrier_.second(t.s) * ds * ds.transpose() + barrier_.first(t.s) * PF::hessian(p, x, facet, c);
            }
            break;
        }
        case Kind::EdgeEdge: {
            if constexpr (dim == 3) {
                const auto &ea = edges_[pair.a], &eb = edges_[pair.b];
                t.node = {ea[0], ea[1], eb[0], eb[1]};
                t.count = 4;
                const Vec<3>&a0 = x[ea[0]], &a1 = x[ea[1]], &b0 = x[eb[0]], &b1 = x[eb[1]];
                const EdgeEdgeCase k = edge_edge_case(a0, a1, b0, b1);
                t.s = edge_edge_distance_sq(a0, a1, b0, b1, k);
                const double eps = 1e-3 * edge_rest_sq_[pair.a] * edge_rest_sq_[pair.b];
                const double m = edge_edge_mollifier(a0, a1, b0, b1, eps), b = barrier_.value(t.s);
                t.value = m * b;
                if (order >= 1) {
                    const Vec12 ds = edge_edge_distance_sq_gradient(a0, a1, b0, b1, k);
                    const Vec12 dm = edge_edge_mollifier_gradient(a0, a1, b0, b1, eps);
                    const double b1s = barrier_.first(t.s);
                    t.gradient = b * dm + m * b1s * ds;
                    if (order >= 2)
                        t.hessian = b * edge_edge_mollifier_hessian(a0, a1, b0, b1, eps) +
                                    b1s * (dm * ds.transpose() + ds * dm.transpose()) +
                                    m * (barrier_.second(t.s) * ds * ds.transpose() +
                                         b1s * edge_edge_distance_sq_hessian(a0, a1, b0, b1, k));
                }
            }
            break;
        }
        case Kind::PointPlane: {
            const HalfSpace<dim>& h = half_spaces_[pair.b];
            t.node[0] = pair.a;
            t.count = 1;
            const double d = h.normal.dot(x[pair.a] - h.origin);
            t.s = d > 0.0 ? d * d : 0.0;  // on or below the plane: intersecting
            t.value = barrier_.value(t.s);
            if (order >= 1) {
                t.gradient.setZero();
                t.gradient.template head<dim>() = barrier_.first(d * d) * 2.0 * d * h.normal;
            }
            if (order >= 2) {
                // d2b/dx2 = (4 s b'' + 2 b') n n^T.
                t.hessian.setZero();
                t.hessian.template topLeftCorner<dim, dim>() =
                    (4.0 * d * d * barrier_.second(d * d) + 2.0 * barrier_.first(d * d)) * h.normal *
                    h.normal.transpose();
            }
            break;
        }
    }
    if (order >= 2 && project_psd) {
        if (t.count == dim + 1) {
            t.hessian = pnet::project_psd<kStacked>(t.hessian);
        } else {
            const Mat<dim> H = t.hessian.template topLeftCorner<dim, dim>();
            t.hessian.template topLeftCorner<dim, dim>() = pnet::project_psd<dim>(H);
        }
    }
    return t;
}

template <int dim>
double Contact<dim>::displacement_since_list(const std::vector<Vec<dim>>& x) const {
    if (!list_valid_ || list_x_.size() != x.size()) return std::numeric_limits<double>::infinity();
    double worst = 0.0;
    for_each_moving_vertex(x, [&](int node) { worst = std::max(worst, (x[node] - list_x_[node]).squaredNorm()); });
    return std::sqrt(worst);
}

template <int dim>
void Contact<dim>::rebuild_list(const std::vector<Vec<dim>>& x) const {
    list_.clear();
    for_each_candidate(x, nullptr, kListMargin * dhat_, [&](const Pair& pair) { list_.push_back(pair); });
    list_x_ = x;
    list_valid_ = true;
}

template <int dim>
const std::vector<typename Contact<dim>::Pair>& Contact<dim>::active(const std::vector<Vec<dim>>& x) const {
    // Newton asks for the value, gradient and Hessian at the same x in turn: one broad phase.
    if (active_valid_ && active_x_.size() == x.size() &&
        std::memcmp(active_x_.data(), x.data(), x.size() * sizeof(Vec<dim>)) == 0)
        return active_pairs_;
    std::vector<Pair>& pairs = active_pairs_;
    pairs.clear();
    const double s_hat = dhat_ * dhat_;
    // A pair closer than dhat at x was closer than dhat + 2 delta when the list was built, delta
    // the largest node displacement since: the list (margin kListMargin dhat) holds it while
    // delta <= (kListMargin - 1) dhat / 2.
    if (!(displacement_since_list(x) <= 0.5 * (kListMargin - 1.0) * dhat_)) rebuild_list(x);
    const Clock::time_point start = Clock::now();
    for (const Pair& pair : list_) {
        double s = 0.0;
        switch (pair.kind) {
            case Kind::PointFacet:
                s = PointFacet<dim>::distance_sq(x[pair.a], x, facets_[pair.b]);
                break;
            case Kind::EdgeEdge:
                if constexpr (dim == 3) {
                    const auto &ea = edges_[pair.a], &eb = edges_[pair.b];
                    s = edge_edge_distance_sq(x[ea[0]], x[ea[1]], x[eb[0]], x[eb[1]]);
                }
                break;
            case Kind::PointPlane: {
                const double d = half_spaces_[pair.b].normal.dot(x[pair.a] - half_spaces_[pair.b].origin);
                s = d < dhat_ ? 0.0 : s_hat;
                break;
            }
        }
        if (s < s_hat) pairs.push_back(pair);
    }
    this->timing_.broad_phase_seconds += seconds_since(start);
    active_x_ = x;
    active_valid_ = true;
    return pairs;
}

template <int dim>
double Contact<dim>::energy(const std::vector<Vec<dim>>& x, double scale, Eigen::VectorXd* g) const {
    double sum = 0.0;
    for (const Pair& pair : active(x)) {
        const Terms t = terms(pair, x, g ? 1 : 0);
        sum += t.value;
        if (!g) continue;
        for (int k = 0; k < t.count; ++k)
            g->template segment<dim>(dim * t.node[k]) += scale * kappa_ * t.gradient.template segment<dim>(dim * k);
    }
    return kappa_ * sum;
}

template <int dim>
double Contact<dim>::value(const std::vector<Vec<dim>>& x) const {
    return energy(x, 0.0, nullptr);
}

template <int dim>
double Contact<dim>::add_gradient(const std::vector<Vec<dim>>& x, double scale, Eigen::VectorXd& g) const {
    return energy(x, scale, &g);
}

template <int dim>
void Contact<dim>::add_hessian(const std::vector<Vec<dim>>& x, double scale,
                               std::vector<Eigen::Triplet<double>>& triplets, bool project_psd) const {
    for (const Pair& pair : active(x)) {
        const Terms t = terms(pair, x, 2, project_psd);
        const int n = dim * t.count;
        const double c = scale * kappa_;
        for (int r = 0; r < n; ++r)
            for (int q = 0; q < n; ++q)
                triplets.emplace_back(dim * t.node[r / dim] + r % dim, dim * t.node[q / dim] + q % dim,
                                      c * t.hessian(r, q));
    }
}

template <int dim>
void Contact<dim>::pair_terms(const std::vector<Vec<dim>>& x, int order, bool project_psd,
                              std::vector<Terms>& out) const {
    const std::vector<Pair>& pairs = active(x);
    out.resize(pairs.size());
    for (std::size_t k = 0; k < pairs.size(); ++k) out[k] = terms(pairs[k], x, order, project_psd);
}

template <int dim>
double Contact<dim>::max_step(const std::vector<Vec<dim>>& x, const std::vector<Vec<dim>>& dx) const {
    double t = 1.0;
    long queries = 0;
    Clock::time_point start;
    bool started = false;
    auto toi = [&](const Pair& pair) {
        if (!started) start = Clock::now(), started = true;
        ++queries;
        switch (pair.kind) {
            case Kind::PointFacet:
                t = std::min(t, PointFacet<dim>::time_of_impact(x[pair.a], dx[pair.a], x, dx, facets_[pair.b], t));
                break;
            case Kind::EdgeEdge:
                if constexpr (dim == 3) {
                    const auto &ea = edges_[pair.a], &eb = edges_[pair.b];
                    t = std::min(t, edge_edge_time_of_impact(x[ea[0]], x[ea[1]], x[eb[0]], x[eb[1]], dx[ea[0]],
                                                             dx[ea[1]], dx[eb[0]], dx[eb[1]], 0.0, t));
                }
                break;
            case Kind::PointPlane: {
                const HalfSpace<dim>& h = half_spaces_[pair.b];
                t = std::min(t, point_plane_time_of_impact(x[pair.a], dx[pair.a], h.origin, h.normal, t));
                break;
            }
        }
    };
    // A pair that touches along x -> x + dx was within 2 D of itself when the list was built (D:
    // the largest displacement since, plus the largest of dx): the list holds every such pair
    // while 2 D <= kListMargin dhat. Of those, exactly the pairs whose swept boxes overlap (the
    // broad phase's own test) are checked, so the result does not depend on the list's age.
    double step = 0.0;
    for_each_moving_vertex(x, [&](int node) { step = std::max(step, dx[node].squaredNorm()); });
    const double reach = displacement_since_list(x) + std::sqrt(step);
    if (2.0 * reach <= kListMargin * dhat_) {
        const Clock::time_point broad = Clock::now();
        std::vector<Pair>& swept = candidates_;
        swept.clear();
        auto sweep = [&](const int* node, int count, Vec<dim>& lo, Vec<dim>& hi) {
            lo = hi = x[node[0]];
            for (int k = 0; k < count; ++k) {
                const Vec<dim> a = x[node[k]], b = x[node[k]] + dx[node[k]];
                lo = lo.cwiseMin(a).cwiseMin(b);
                hi = hi.cwiseMax(a).cwiseMax(b);
            }
        };
        for (const Pair& pair : list_) {
            if (pair.kind == Kind::PointPlane) {
                swept.push_back(pair);
                continue;
            }
            Vec<dim> lo_a, hi_a, lo_b, hi_b;
            if (pair.kind == Kind::PointFacet) {
                sweep(&pair.a, 1, lo_a, hi_a);
                sweep(facets_[pair.b].data(), PointFacet<dim>::kNodes, lo_b, hi_b);
            } else {
                sweep(edges_[pair.a].data(), 2, lo_a, hi_a);
                sweep(edges_[pair.b].data(), 2, lo_b, hi_b);
            }
            if ((hi_a.array() < lo_b.array()).any() || (lo_a.array() > hi_b.array()).any()) continue;
            swept.push_back(pair);
        }
        this->timing_.broad_phase_seconds += seconds_since(broad);
        for (const Pair& pair : swept) toi(pair);
    } else {
        for_each_candidate(x, &dx, 0.0, toi);
    }
    if (started) this->timing_.ccd_seconds += seconds_since(start);
    this->timing_.ccd_pairs += queries;
    return t;
}

template <int dim>
double Contact<dim>::stable_time_step(const std::vector<Vec<dim>>& x, const std::vector<double>& free_mass) const {
    double omega2 = 0.0;
    for (const Pair& pair : active(x)) {
        const Terms t = terms(pair, x, 0);
        double inverse_mass = 0.0;
        for (int k = 0; k < t.count; ++k)
            if (free_mass[t.node[k]] > 0.0) inverse_mass += 1.0 / free_mass[t.node[k]];
        // d^2/dd^2 b(d^2) = 4 s b''(s) + 2 b'(s).
        const double k = kappa_ * std::abs(4.0 * t.s * barrier_.second(t.s) + 2.0 * barrier_.first(t.s));
        omega2 = std::max(omega2, k * inverse_mass);
    }
    return omega2 > 0.0 ? 1.0 / std::sqrt(omega2) : std::numeric_limits<double>::infinity();
}

template <int dim>
std::vector<FrictionPair<dim>> Contact<dim>::lagged_pairs(const std::vector<Vec<dim>>& x) const {
    std::vector<FrictionPair<dim>> out;
    for (const Pair& pair : active(x)) {
        const Terms t = terms(pair, x, 0);
        FrictionPair<dim> l;
        l.count = t.count;
        for (int k = 0; k < t.count; ++k) l.node[k] = t.node[k];
        Vec<dim> normal = Vec<dim>::Zero();
        double m = 1.0;
        switch (pair.kind) {
            case Kind::PointFacet: {
                const Facet& facet = facets_[pair.b];
                const Vec<dim>& p = x[pair.a];
                const auto w = PointFacet<dim>::closest_weights(p, x, facet);
                Vec<dim> closest = Vec<dim>::Zero();
                l.weight[0] = 1.0;
                for (int k = 0; k < PointFacet<dim>::kNodes; ++k) {
                    l.weight[k + 1] = -w[k];
                    closest += w[k] * x[facet[k]];
                }
                normal = p - closest;
                if (!(normal.norm() > 0.0)) normal = facet_normal(x, facet);
                break;
            }
            case Kind::EdgeEdge: {
                if constexpr (dim == 3) {
                    const Vec<3>&a0 = x[t.node[0]], &a1 = x[t.node[1]], &b0 = x[t.node[2]], &b1 = x[t.node[3]];
                    const auto [s, u] = closest_on_segments(a0, a1, b0, b1);
                    l.weight = {1.0 - s, s, -(1.0 - u), -u};
                    normal = (a0 + s * (a1 - a0)) - (b0 + u * (b1 - b0));
                    if (!(normal.norm() > 0.0)) normal = (a1 - a0).cross(b1 - b0);
                    m = t.s > 0.0 && barrier_.value(t.s) != 0.0 ? t.value / barrier_.value(t.s) : 1.0;
                }
                break;
            }
            case Kind::PointPlane:
                l.weight[0] = 1.0;
                normal = half_spaces_[pair.b].normal;
                break;
        }
        if (!(normal.norm() > 0.0)) continue;  // degenerate: no direction to slide along
        l.tangent = tangent_basis<dim>(normal.normalized());
        l.normal_force = -kappa_ * m * barrier_.first(t.s) * 2.0 * std::sqrt(t.s);
        out.push_back(l);
    }
    return out;
}

template <int dim>
double Contact<dim>::min_distance(const std::vector<Vec<dim>>& x) const {
    Vec<dim> lo = x[nodes_.empty() ? 0 : nodes_[0]], hi = lo;
    for_each_moving_vertex(x, [&](int node) {
        lo = lo.cwiseMin(x[node]);
        hi = hi.cwiseMax(x[node]);
    });
    const double extent = std::max((hi - lo).norm(), dhat_);
    double d = kNoImpact;
    for (double margin = dhat_;; margin *= 10.0) {
        for_each_candidate(x, nullptr, margin, [&](const Pair& pair) {
            if (pair.kind == Kind::PointPlane)
                d = std::min(d, half_spaces_[pair.b].normal.dot(x[pair.a] - half_spaces_[pair.b].origin));
            else
                d = std::min(d, std::sqrt(terms(pair, x, 0).s));
        });
        if (d <= margin || margin > extent) return d;
    }
}

template <int dim>
std::size_t Contact<dim>::active_pairs(const std::vector<Vec<dim>>& x) const {
    return active(x).size();
}

template <int dim>
std::string Contact<dim>::first_intersection(const std::vector<Vec<dim>>& x) const {
    if (!points_.only)
        for (int node : nodes_)
            for (std::size_t h = 0; h < half_spaces_.size(); ++h)
                if (!(half_spaces_[h].normal.dot(x[node] - half_spaces_[h].origin) > 0.0))
                    return "node " + std::to_string(node) + " and half-space " + std::to_string(h);
    std::string found;
    for_each_candidate(x, nullptr, 0.0, [&](const Pair& pair) {
        if (!found.empty() || pair.kind == Kind::PointPlane) return;
        if (pair.kind == Kind::PointFacet) {
            const bool point = points_.first >= 0 && pair.a >= points_.first;
            if (!(PointFacet<dim>::distance_sq(x[pair.a], x, facets_[pair.b]) > 0.0))
                found = (point ? "point " + std::to_string(pair.a - points_.first) : "node " + std::to_string(pair.a)) +
                        " and " + PointFacet<dim>::kFacetName + " " + join(facets_[pair.b]);
        } else if (!(terms(pair, x, 0).s > 0.0)) {
            found = "edge " + join(edges_[pair.a]) + " and edge " + join(edges_[pair.b]);
        }
    });
    if (!found.empty()) return found;
    // Boundary edges through facets: the facets' boxes (the broad phase above) against each edge's.
    if (points_.only) return "";
    std::vector<int> near;
    for (const auto& edge : edges_) {
        facet_grid_.query(x[edge[0]].cwiseMin(x[edge[1]]), x[edge[0]].cwiseMax(x[edge[1]]), near);
        for (int t : near) {
            const Facet& facet = facets_[t];
            if (std::find(facet.begin(), facet.end(), edge[0]) != facet.end() ||
                std::find(facet.begin(), facet.end(), edge[1]) != facet.end())
                continue;
            if (segment_crosses_facet(x[edge[0]], x[edge[1]], x, facet))
                return "edge " + join(edge) + " and " + PointFacet<dim>::kFacetName + " " + join(facet);
        }
    }
    return "";
}

template class Contact<2>;
template class Contact<3>;

}  // namespace pnet
