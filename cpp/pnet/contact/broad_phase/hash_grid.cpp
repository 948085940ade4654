#include "pnet/contact/broad_phase/hash_grid.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace pnet {

namespace {
constexpr double kMaxCells = 8388608.0;  // 2^23
}

template <int dim>
typename HashGrid<dim>::Index HashGrid<dim>::cell_of(const Vec<dim>& p) const {
    Index c;
    for (int a = 0; a < dim; ++a) {
        const double t = std::floor((p[a] - origin_[a]) / cell_);
        c[a] = static_cast<long>(std::clamp(t, 0.0, static_cast<double>(size_[a] - 1)));
    }
    return c;
}

template <int dim>
long HashGrid<dim>::linear(const Index& c) const {
    long k = 0;
    for (int a = dim - 1; a >= 0; --a) k = k * size_[a] + c[a];
    return k;
}

template <int dim>
double HashGrid<dim>::suggested_cell(const std::vector<Vec<dim>>& lo, const std::vector<Vec<dim>>& hi, double floor) {
    double sum = 0.0;
    for (std::size_t k = 0; k < lo.size(); ++k) sum += (hi[k] - lo[k]).maxCoeff();
    return std::max(lo.empty() ? floor : sum / lo.size(), floor);
}

template <int dim>
void HashGrid<dim>::build(const std::vector<Vec<dim>>& lo, const std::vector<Vec<dim>>& hi, double cell) {
    if (!(cell > 0.0) || !std::isfinite(cell)) throw std::invalid_argument("HashGrid: the cell side must be > 0");
    lo_ = lo;
    hi_ = hi;
    Vec<dim> top = Vec<dim>::Zero();
    origin_ = Vec<dim>::Zero();
    if (!lo.empty()) {
        origin_ = lo[0];
        top = hi[0];
        for (std::size_t k = 0; k < lo.size(); ++k) {
            origin_ = origin_.cwiseMin(lo[k]);
            top = top.cwiseMax(hi[k]);
        }
    }
    for (cell_ = cell;; cell_ *= 1.5) {
        double cells = 1.0;
        for (int a = 0; a < dim; ++a) cells *= std::floor((top[a] - origin_[a]) / cell_) + 1.0;
        if (cells <= kMaxCells) break;
    }
    for (int a = 0; a < dim; ++a) size_[a] = static_cast<long>(std::floor((top[a] - origin_[a]) / cell_)) + 1;
    long cells = 1;
    for (int a = 0; a < dim; ++a) cells *= size_[a];
    start_.assign(static_cast<std::size_t>(cells) + 1, 0);
    // Visits every cell of box k: f(linear cell index).
    auto for_cells = [&](std::size_t k, auto&& f) {
        const Index a = cell_of(lo[k]), b = cell_of(hi[k]);
        Index c = a;
        while (true) {  // odometer order
            f(linear(c));
            int axis = 0;
            while (axis < dim && c[axis] == b[axis]) c[axis] = a[axis], ++axis;
            if (axis == dim) break;
            ++c[axis];
        }
    };
    for (std::size_t k = 0; k < lo.size(); ++k) for_cells(k, [&](long c) { ++start_[c + 1]; });
    for (long c = 0; c < cells; ++c) start_[c + 1] += start_[c];
    entries_.resize(static_cast<std::size_t>(start_[cells]));
    std::vector<int> fill(start_.begin(), start_.end() - 1);
    for (std::size_t k = 0; k < lo.size(); ++k)
        for_cells(k, [&](long c) { entries_[fill[c]++] = static_cast<int>(k); });
}

template <int dim>
void HashGrid<dim>::query(const Vec<dim>& lo, const Vec<dim>& hi, std::vector<int>& out) const {
    out.clear();
    if (lo_.empty()) return;
    for (int a = 0; a < dim; ++a)  // wholly outside the grid: nothing (cell_of would clamp onto a border cell)
        if (hi[a] < origin_[a] || lo[a] > origin_[a] + size_[a] * cell_) return;
    const Index a = cell_of(lo), b = cell_of(hi);
    Index c = a;
    int visited = 0;
    while (true) {
        const long k = linear(c);
        for (int e = start_[k]; e < start_[k + 1]; ++e) {
            const int box = entries_[e];
            if ((hi.array() < lo_[box].array()).any() || (lo.array() > hi_[box].array()).any()) continue;
            out.push_back(box);
        }
        ++visited;
        int axis = 0;
        while (axis < dim && c[axis] == b[axis]) c[axis] = a[axis], ++axis;
        if (axis == dim) break;
        ++c[axis];
    }
    if (visited > 1) {  // a box in several of the cells appears once per cell
        std::sort(out.begin(), out.end());
        out.erase(std::unique(out.begin(), out.end()), out.end());
    }
}

template class HashGrid<2>;
template class HashGrid<3>;

}  // namespace pnet
