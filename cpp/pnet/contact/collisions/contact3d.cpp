#include "pnet/contact/collisions/contact3d.hpp"

#include "pnet/math/clock.hpp"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <cmath>
#include <limits>
#include <map>
#include <stdexcept>

#include "pnet/contact/ccd/point_edge.hpp"
#include "pnet/contact/ccd/point_triangle_edge_edge.hpp"
#include "pnet/contact/distance/closest_point.hpp"
#include "pnet/contact/distance/point_triangle_edge_edge.hpp"
#include "pnet/math/psd.hpp"

namespace pnet {

namespace {


double orient3d(const Vec<3>& a, const Vec<3>& b, const Vec<3>& c, const Vec<3>& d) {
    return (b - a).cross(c - a).dot(d - a);
}

/// Segment pq and triangle abc (no common node) cross or touch; coplanar contact is left to
/// the distance tests.
bool segment_crosses_triangle(const Vec<3>& p, const Vec<3>& q, const Vec<3>& a, const Vec<3>& b, const Vec<3>& c) {
    const double dp = orient3d(a, b, c, p), dq = orient3d(a, b, c, q);
    if ((dp > 0.0 && dq > 0.0) || (dp < 0.0 && dq < 0.0) || (dp == 0.0 && dq == 0.0)) return false;
    const double s1 = orient3d(p, q, a, b), s2 = orient3d(p, q, b, c), s3 = orient3d(p, q, c, a);
    return !((s1 > 0.0 || s2 > 0.0 || s3 > 0.0) && (s1 < 0.0 || s2 < 0.0 || s3 < 0.0));
}

template <typename Array>
std::string join(const Array& nodes, int count) {
    std::string out;
    for (int k = 0; k < count; ++k) out += (k ? "-" : "") + std::to_string(nodes[k]);
    return out;
}

}  // namespace

Contact3d::Contact3d(const std::vector<std::array<int, 3>>& boundary_triangles, const std::vector<Vec<3>>& rest,
                     double dhat, double kappa)
    : triangles_(boundary_triangles), dhat_(dhat), kappa_(kappa), barrier_{dhat * dhat} {
    if (!(dhat > 0.0) || !(kappa > 0.0)) throw std::invalid_argument("Contact3d: dhat and kappa must be > 0");
    for (const auto& t : triangles_) {
        for (int k = 0; k < 3; ++k) {
            const int a = t[k], b = t[(k + 1) % 3];
            if (a < 0 || b < 0 || a >= static_cast<int>(rest.size()) || b >= static_cast<int>(rest.size()))
                throw std::invalid_argument("Contact3d: a boundary triangle's node is out of range");
            edges_.push_back({std::min(a, b), std::max(a, b)});
            nodes_.push_back(a);
        }
    }
    std::sort(edges_.begin(), edges_.end());
    edges_.erase(std::unique(edges_.begin(), edges_.end()), edges_.end());
    std::sort(nodes_.begin(), nodes_.end());
    nodes_.erase(std::unique(nodes_.begin(), nodes_.end()), nodes_.end());
    for (const auto& e : edges_) edge_rest_sq_.push_back((rest[e[1]] - rest[e[0]]).squaredNorm());
}

template <typename F>
void Contact3d::for_each_candidate(const std::vector<Vec<3>>& x, const std::vector<Vec<3>>* dx, double margin,
                                   F&& f) const {
    // The broad phase gathers the candidate pairs (timed), then f visits them (not timed: the
    // narrow phase is the caller's).
    const Clock::time_point start = Clock::now();
    auto box = [&](const int* node, int count, Vec<3>& lo, Vec<3>& hi) {
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
    const std::size_t nt = triangles_.size(), ne = edges_.size();
    lo_.resize(nt);
    hi_.resize(nt);
    for (std::size_t t = 0; t < nt; ++t) {
        box(triangles_[t].data(), 3, lo_[t], hi_[t]);
        lo_[t].array() -= margin;
        hi_[t].array() += margin;
    }
    // Cells about a box wide: a box then covers a few cells whatever the margin.
    const double cell = HashGrid<3>::suggested_cell(lo_, hi_, 1e-9);
    triangle_grid_.build(lo_, hi_, cell);
    candidates_.clear();
    std::vector<int>& found = found_;
    for (int node : nodes_) {
        Vec<3> lo = x[node], hi = x[node];
        if (dx) {
            lo = lo.cwiseMin(x[node] + (*dx)[node]);
            hi = hi.cwiseMax(x[node] + (*dx)[node]);
        }
        triangle_grid_.query(lo, hi, found);
        for (int t : found) {
            const auto& tri = triangles_[t];
            if (tri[0] == node || tri[1] == node || tri[2] == node) continue;
            candidates_.push_back(Pair{Kind::PointTriangle, node, t});
        }
        for (std::size_t h = 0; h < half_spaces_.size(); ++h)
            candidates_.push_back(Pair{Kind::PointPlane, node, static_cast<int>(h)});
    }
    edge_lo_.resize(ne);
    edge_hi_.resize(ne);
    grown_lo_.resize(ne);
    grown_hi_.resize(ne);
    for (std::size_t e = 0; e < ne; ++e) {
        box(edges_[e].data(), 2, edge_lo_[e], edge_hi_[e]);
        grown_lo_[e] = edge_lo_[e].array() - margin;
        grown_hi_[e] = edge_hi_[e].array() + margin;
    }
    edge_grid_.build(grown_lo_, grown_hi_, HashGrid<3>::suggested_cell(grown_lo_, grown_hi_, 1e-9));
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
    timing_.broad_phase_seconds += seconds_since(start);
    // f may call back into the broad phase (min_distance does not; first_intersection queries
    // the triangle grid after): iterate over a copy-free view that f cannot invalidate.
    for (const Pair& pair : candidates_) f(pair);
}

Contact3d::Terms Contact3d::terms(const Pair& pair, const std::vector<Vec<3>>& x, int order) const {
    Terms t;
    switch (pair.kind) {
        case Kind::PointTriangle: {
            const auto& tri = triangles_[pair.b];
            t.node = {pair.a, tri[0], tri[1], tri[2]};
            t.count = 4;
            const Vec<3>&p = x[pair.a], &a = x[tri[0]], &b = x[tri[1]], &c = x[tri[2]];
            const PointTriangleCase k = point_triangle_case(p, a, b, c);
            t.s = point_triangle_distance_sq(p, a, b, c, k);
            t.value = barrier_.value(t.s);
            if (order >= 1) t.gradient = barrier_.first(t.s) * point_triangle_distance_sq_gradient(p, a, b, c, k);
            if (order >= 2) {
                const Vec12 ds = point_triangle_distance_sq_gradient(p, a, b, c, k);
                t.hessian = barrier_.second(t.s) * ds * ds.transpose() +
                            barrier_.first(t.s) * point_triangle_distance_sq_hessian(p, a, b, c, k);
            }
            break;
        }
        case Kind::EdgeEdge: {
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
            break;
        }
        case Kind::PointPlane: {
            const HalfSpace<3>& h = half_spaces_[pair.b];
            t.node = {pair.a, 0, 0, 0};
            t.count = 1;
            const double d = h.normal.dot(x[pair.a] - h.origin);
            t.s = d > 0.0 ? d * d : 0.0;  // on or below the plane: intersecting
            t.value = barrier_.value(t.s);
            if (order >= 1) {
                t.gradient.setZero();
                t.gradient.head<3>() = barrier_.first(d * d) * 2.0 * d * h.normal;
            }
            if (order >= 2) {
                // d2b/dx2 = (4 s b'' + 2 b') n n^T.
                t.hessian.setZero();
                t.hessian.topLeftCorner<3, 3>() =
                    (4.0 * d * d * barrier_.second(d * d) + 2.0 * barrier_.first(d * d)) * h.normal * h.normal.transpose();
            }
            break;
        }
    }
    return t;
}

double Contact3d::displacement_since_list(const std::vector<Vec<3>>& x) const {
    if (!list_valid_ || list_x_.size() != x.size()) return std::numeric_limits<double>::infinity();
    double worst = 0.0;
    for (int node : nodes_) worst = std::max(worst, (x[node] - list_x_[node]).squaredNorm());
    return std::sqrt(worst);
}

void Contact3d::rebuild_list(const std::vector<Vec<3>>& x) const {
    list_.clear();
    for_each_candidate(x, nullptr, kListMargin * dhat_, [&](const Pair& pair) { list_.push_back(pair); });
    list_x_ = x;
    list_valid_ = true;
}

const std::vector<Contact3d::Pair>& Contact3d::active(const std::vector<Vec<3>>& x) const {
    // Newton asks for the value, gradient and Hessian at the same x in turn: one broad phase.
    if (active_valid_ && active_x_.size() == x.size() &&
        std::memcmp(active_x_.data(), x.data(), x.size() * sizeof(Vec<3>)) == 0)
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
            case Kind::PointTriangle: {
                const auto& t = triangles_[pair.b];
                s = point_triangle_distance_sq(x[pair.a], x[t[0]], x[t[1]], x[t[2]]);
                break;
            }
            case Kind::EdgeEdge: {
                const auto &ea = edges_[pair.a], &eb = edges_[pair.b];
                s = edge_edge_distance_sq(x[ea[0]], x[ea[1]], x[eb[0]], x[eb[1]]);
                break;
            }
            case Kind::PointPlane: {
                const double d = half_spaces_[pair.b].normal.dot(x[pair.a] - half_spaces_[pair.b].origin);
                s = d < dhat_ ? 0.0 : s_hat;
                break;
            }
        }
        if (s < s_hat) pairs.push_back(pair);
    }
    timing_.broad_phase_seconds += seconds_since(start);
    active_x_ = x;
    active_valid_ = true;
    return pairs;
}

double Contact3d::energy(const std::vector<Vec<3>>& x, double scale, Eigen::VectorXd* g) const {
    double sum = 0.0;
    for (const Pair& pair : active(x)) {
        const Terms t = terms(pair, x, g ? 1 : 0);
        sum += t.value;
        if (!g) continue;
        for (int k = 0; k < t.count; ++k) g->segment<3>(3 * t.node[k]) += scale * kappa_ * t.gradient.segment<3>(3 * k);
    }
    return kappa_ * sum;
}

double Contact3d::value(const std::vector<Vec<3>>& x) const { return energy(x, 0.0, nullptr); }

double Contact3d::add_gradient(const std::vector<Vec<3>>& x, double scale, Eigen::VectorXd& g) const {
    return energy(x, scale, &g);
}

void Contact3d::add_hessian(const std::vector<Vec<3>>& x, double scale, std::vector<Eigen::Triplet<double>>& triplets,
                            bool project_psd) const {
    for (const Pair& pair : active(x)) {
        Terms t = terms(pair, x, 2);
        const int n = 3 * t.count;
        if (t.count == 4) {
            if (project_psd) t.hessian = pnet::project_psd<12>(t.hessian);
        } else {
            Mat<3> H = t.hessian.topLeftCorner<3, 3>();
            if (project_psd) H = pnet::project_psd<3>(H);
            t.hessian.topLeftCorner<3, 3>() = H;
        }
        const double c = scale * kappa_;
        for (int r = 0; r < n; ++r)
            for (int q = 0; q < n; ++q)
                triplets.emplace_back(3 * t.node[r / 3] + r % 3, 3 * t.node[q / 3] + q % 3, c * t.hessian(r, q));
    }
}

double Contact3d::max_step(const std::vector<Vec<3>>& x, const std::vector<Vec<3>>& dx) const {
    double t = 1.0;
    long queries = 0;
    Clock::time_point start;
    bool started = false;
    auto toi = [&](const Pair& pair) {
        if (!started) start = Clock::now(), started = true;
        ++queries;
        switch (pair.kind) {
            case Kind::PointTriangle: {
                const auto& tri = triangles_[pair.b];
                t = std::min(t, point_triangle_time_of_impact(x[pair.a], x[tri[0]], x[tri[1]], x[tri[2]], dx[pair.a],
                                                              dx[tri[0]], dx[tri[1]], dx[tri[2]], 0.0, t));
                break;
            }
            case Kind::EdgeEdge: {
                const auto &ea = edges_[pair.a], &eb = edges_[pair.b];
                t = std::min(t, edge_edge_time_of_impact(x[ea[0]], x[ea[1]], x[eb[0]], x[eb[1]], dx[ea[0]], dx[ea[1]],
                                                         dx[eb[0]], dx[eb[1]], 0.0, t));
                break;
            }
            case Kind::PointPlane: {
                const HalfSpace<3>& h = half_spaces_[pair.b];
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
    for (int node : nodes_) step = std::max(step, dx[node].squaredNorm());
    const double reach = displacement_since_list(x) + std::sqrt(step);
    if (2.0 * reach <= kListMargin * dhat_) {
        const Clock::time_point broad = Clock::now();
        std::vector<Pair>& swept = candidates_;
        swept.clear();
        auto sweep = [&](const int* node, int count, Vec<3>& lo, Vec<3>& hi) {
            lo = hi = x[node[0]];
            for (int k = 0; k < count; ++k) {
                const Vec<3> a = x[node[k]], b = x[node[k]] + dx[node[k]];
                lo = lo.cwiseMin(a).cwiseMin(b);
                hi = hi.cwiseMax(a).cwiseMax(b);
            }
        };
        for (const Pair& pair : list_) {
            if (pair.kind == Kind::PointPlane) {
                swept.push_back(pair);
                continue;
            }
            Vec<3> lo_a, hi_a, lo_b, hi_b;
            if (pair.kind == Kind::PointTriangle) {
                sweep(&pair.a, 1, lo_a, hi_a);
                sweep(triangles_[pair.b].data(), 3, lo_b, hi_b);
            } else {
                sweep(edges_[pair.a].data(), 2, lo_a, hi_a);
                sweep(edges_[pair.b].data(), 2, lo_b, hi_b);
            }
            if ((hi_a.array() < lo_b.array()).any() || (lo_a.array() > hi_b.array()).any()) continue;
            swept.push_back(pair);
        }
        timing_.broad_phase_seconds += seconds_since(broad);
        for (const Pair& pair : swept) toi(pair);
    } else {
        for_each_candidate(x, &dx, 0.0, toi);
    }
    if (started) timing_.ccd_seconds += seconds_since(start);
    timing_.ccd_pairs += queries;
    return t;
}

double Contact3d::stable_time_step(const std::vector<Vec<3>>& x, const std::vector<double>& free_mass) const {
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

std::vector<FrictionPair<3>> Contact3d::lagged_pairs(const std::vector<Vec<3>>& x) const {
    std::vector<FrictionPair<3>> out;
    for (const Pair& pair : active(x)) {
        const Terms t = terms(pair, x, 0);
        FrictionPair<3> l;
        l.count = t.count;
        l.node = t.node;
        Vec<3> normal;
        double m = 1.0;
        switch (pair.kind) {
            case Kind::PointTriangle: {
                const Vec<3>&p = x[t.node[0]], &a = x[t.node[1]], &b = x[t.node[2]], &c = x[t.node[3]];
                const Vec<3> w = closest_on_triangle(p, a, b, c);
                l.weight = {1.0, -w[0], -w[1], -w[2]};
                normal = p - (w[0] * a + w[1] * b + w[2] * c);
                if (!(normal.norm() > 0.0)) normal = (b - a).cross(c - a);
                break;
            }
            case Kind::EdgeEdge: {
                const Vec<3>&a0 = x[t.node[0]], &a1 = x[t.node[1]], &b0 = x[t.node[2]], &b1 = x[t.node[3]];
                const auto [s, u] = closest_on_segments(a0, a1, b0, b1);
                l.weight = {1.0 - s, s, -(1.0 - u), -u};
                normal = (a0 + s * (a1 - a0)) - (b0 + u * (b1 - b0));
                if (!(normal.norm() > 0.0)) normal = (a1 - a0).cross(b1 - b0);
                m = t.s > 0.0 && barrier_.value(t.s) != 0.0 ? t.value / barrier_.value(t.s) : 1.0;
                break;
            }
            case Kind::PointPlane:
                l.weight = {1.0, 0.0, 0.0, 0.0};
                normal = half_spaces_[pair.b].normal;
                break;
        }
        if (!(normal.norm() > 0.0)) continue;  // degenerate: no direction to slide along
        l.tangent = tangent_basis(normal.normalized());
        l.normal_force = -kappa_ * m * barrier_.first(t.s) * 2.0 * std::sqrt(t.s);
        out.push_back(l);
    }
    return out;
}

double Contact3d::min_distance(const std::vector<Vec<3>>& x) const {
    auto [lo, hi] = std::pair<Vec<3>, Vec<3>>(x[nodes_.empty() ? 0 : nodes_[0]], x[nodes_.empty() ? 0 : nodes_[0]]);
    for (int node : nodes_) {
        lo = lo.cwiseMin(x[node]);
        hi = hi.cwiseMax(x[node]);
    }
    const double extent = std::max((hi - lo).norm(), dhat_);
    double d = kNoImpact;
    for (double margin = dhat_;; margin *= 10.0) {
        for_each_candidate(x, nullptr, margin, [&](const Pair& pair) {
            const Terms t = terms(pair, x, 0);
            if (pair.kind == Kind::PointPlane) {
                d = std::min(d, half_spaces_[pair.b].normal.dot(x[pair.a] - half_spaces_[pair.b].origin));
            } else {
                d = std::min(d, std::sqrt(t.s));
            }
        });
        if (d <= margin || margin > extent) return d;
    }
}

std::size_t Contact3d::active_pairs(const std::vector<Vec<3>>& x) const { return active(x).size(); }

std::string Contact3d::first_intersection(const std::vector<Vec<3>>& x) const {
    for (int node : nodes_)
        for (std::size_t h = 0; h < half_spaces_.size(); ++h)
            if (!(half_spaces_[h].normal.dot(x[node] - half_spaces_[h].origin) > 0.0))
                return "node " + std::to_string(node) + " and half-space " + std::to_string(h);
    std::string found;
    for_each_candidate(x, nullptr, 0.0, [&](const Pair& pair) {
        if (!found.empty()) return;
        if (pair.kind == Kind::PointTriangle) {
            const auto& t = triangles_[pair.b];
            if (!(point_triangle_distance_sq(x[pair.a], x[t[0]], x[t[1]], x[t[2]]) > 0.0))
                found = "node " + std::to_string(pair.a) + " and triangle " + join(t, 3);
        } else if (pair.kind == Kind::EdgeEdge) {
            const auto &ea = edges_[pair.a], &eb = edges_[pair.b];
            if (!(edge_edge_distance_sq(x[ea[0]], x[ea[1]], x[eb[0]], x[eb[1]]) > 0.0))
                found = "edge " + join(ea, 2) + " and edge " + join(eb, 2);
        }
    });
    if (!found.empty()) return found;
    // Edges through triangles: the triangles' boxes against each edge's.
    std::vector<int> near;
    for (std::size_t e = 0; e < edges_.size(); ++e) {
        const auto& edge = edges_[e];
        triangle_grid_.query(x[edge[0]].cwiseMin(x[edge[1]]), x[edge[0]].cwiseMax(x[edge[1]]), near);
        for (int t : near) {
            const auto& tri = triangles_[t];
            if (std::find(tri.begin(), tri.end(), edge[0]) != tri.end() ||
                std::find(tri.begin(), tri.end(), edge[1]) != tri.end())
                continue;
            if (segment_crosses_triangle(x[edge[0]], x[edge[1]], x[tri[0]], x[tri[1]], x[tri[2]]))
                return "edge " + join(edge, 2) + " and triangle " + join(tri, 3);
        }
    }
    return "";
}

}  // namespace pnet
