#include "pnet/metrics/iou.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <sstream>
#include <stdexcept>
#include <string>

namespace pnet {
namespace {

// Quadratic B-spline weights along one axis for a position s in grid units (s = (x - origin) / dx),
// moved into [1, nodes - 2] first so that the three nodes base..base + 2 lie on the grid.
struct AxisStencil {
    int base;
    double w[3];
};

inline AxisStencil axis_stencil(double s, int nodes, bool& clamped) {
    const double s_max = nodes - 2;
    if (s < 1.0) {
        s = 1.0;
        clamped = true;
    } else if (s > s_max) {
        s = s_max;
        clamped = true;
    }
    AxisStencil a;
    a.base = static_cast<int>(std::floor(s - 0.5));  // in [0, nodes - 3]
    const double f = s - a.base;                     // in [0.5, 1.5)
    a.w[0] = 0.5 * (1.5 - f) * (1.5 - f);
    a.w[1] = 0.75 - (f - 1.0) * (f - 1.0);
    a.w[2] = 0.5 * (f - 0.5) * (f - 0.5);
    return a;
}

std::string grid_description(const GridField& f) {
    std::ostringstream s;
    s << f.dim << "D, " << f.nodes[0];
    for (int d = 1; d < f.dim; ++d) s << "x" << f.nodes[d];
    s << " nodes, dx " << f.dx << ", origin (" << f.origin[0];
    for (int d = 1; d < f.dim; ++d) s << ", " << f.origin[d];
    s << ")";
    return s.str();
}

GridField make_grid(int dim, const double* domain_min, const double* domain_max, double dx) {
    if (!(dx > 0.0) || !std::isfinite(dx))
        throw std::invalid_argument("rasterize_mass: dx must be positive and finite, got " + std::to_string(dx));
    GridField grid;
    grid.dim = dim;
    grid.dx = dx;
    for (int d = 0; d < dim; ++d) {
        const double extent = domain_max[d] - domain_min[d];
        if (!std::isfinite(domain_min[d]) || !std::isfinite(extent) || !(extent > 0.0))
            throw std::invalid_argument("rasterize_mass: empty or non-finite domain on axis " + std::to_string(d) +
                                        ": [" + std::to_string(domain_min[d]) + ", " + std::to_string(domain_max[d]) +
                                        "]");
        // cells = ceil(extent / dx), forgiving the rounding of an extent that is a whole number of cells.
        const double r = extent / dx;
        const double cells = std::ceil(r - 1e-9 * r);
        if (cells < 2.0 || cells > (1 << 20))
            throw std::invalid_argument("rasterize_mass: the domain spans " + std::to_string(r) + " cells on axis " +
                                        std::to_string(d) + "; need between 2 and 2^20");
        grid.nodes[d] = static_cast<int>(cells) + 1;
        grid.origin[d] = domain_min[d];
    }
    if (grid.size() > (std::size_t(1) << 31))
        throw std::invalid_argument("rasterize_mass: a grid of " + std::to_string(grid.size()) + " nodes is too large");
    grid.value.assign(grid.size(), 0.0);
    return grid;
}

// Slab-parallel P2G of the mass. Particles are binned (stably) by the base node b of their stencil on the
// last axis L, so a particle of bin b touches only the slabs b, b + 1, b + 2 (the nodes with that index on
// L). The order in which a node adds its contributions is fixed by the bins and the particle indices,
// independent of the thread count.
template <int dim>
std::size_t splat_mass(const std::vector<double>& position, const std::vector<double>& mass, GridField& grid) {
    constexpr int L = dim - 1;
    const std::int64_t n = static_cast<std::int64_t>(mass.size());
    const int slabs = grid.nodes[L];
    const double inv_dx = 1.0 / grid.dx;
    const std::size_t slab_size = grid.size() / static_cast<std::size_t>(slabs);

    auto stencil = [&](const double* x, AxisStencil(&a)[dim]) {
        bool clamped = false;
        for (int d = 0; d < dim; ++d) a[d] = axis_stencil((x[d] - grid.origin[d]) * inv_dx, grid.nodes[d], clamped);
        return clamped;
    };

    // Pass 1, over fixed chunks of particles: validate, find each particle's bin, count the clamped ones
    // and the particles of each bin in each chunk.
    constexpr std::int64_t chunk = 1 << 15;
    const std::int64_t chunks = (n + chunk - 1) / chunk;
    const auto chunk_end = [&](std::int64_t c) { return std::min(n, (c + 1) * chunk); };
    std::vector<int> bin(static_cast<std::size_t>(n));
    std::vector<std::int64_t> offset(static_cast<std::size_t>(chunks * slabs), 0);  // [chunk][bin]
    std::int64_t clamped = 0;
    std::int64_t first_bad = n;
#pragma omp parallel for schedule(static) reduction(+ : clamped) reduction(min : first_bad) if (chunks > 1)
    for (std::int64_t c = 0; c < chunks; ++c) {
        std::int64_t* count = &offset[c * slabs];
        for (std::int64_t p = c * chunk; p < chunk_end(c); ++p) {
            bool finite = std::isfinite(mass[p]) && mass[p] >= 0.0;
            for (int d = 0; d < dim; ++d) finite = finite && std::isfinite(position[p * dim + d]);
            if (!finite) {
                first_bad = std::min(first_bad, p);
                bin[p] = 0;
                continue;
            }
            AxisStencil a[dim];
            clamped += stencil(&position[p * dim], a) ? 1 : 0;
            bin[p] = a[L].base;
            ++count[bin[p]];
        }
    }
    if (first_bad < n) {
        std::ostringstream s;
        s << "rasterize_mass: particle " << first_bad << " has mass " << mass[first_bad] << " and position (";
        for (int d = 0; d < dim; ++d) s << (d ? ", " : "") << position[first_bad * dim + d];
        s << "); need a finite position and a finite mass >= 0";
        throw std::invalid_argument(s.str());
    }

    // Stable counting sort by bin (bins 0..slabs - 3): bin b starts at start[b], and within it chunk c's
    // particles at offset[c][b]. The order (bin, particle index) is unique, whatever the chunking. Position
    // and mass are copied in that order so that pass 2 streams through memory.
    std::vector<std::int64_t> start(static_cast<std::size_t>(slabs) + 1, 0);
    for (int b = 0; b < slabs; ++b) {
        std::int64_t next = start[b];
        for (std::int64_t c = 0; c < chunks; ++c) {
            const std::int64_t count = offset[c * slabs + b];
            offset[c * slabs + b] = next;
            next += count;
        }
        start[b + 1] = next;
    }
    std::vector<double> sorted_position(position.size()), sorted_mass(mass.size());
#pragma omp parallel for schedule(static) if (chunks > 1)
    for (std::int64_t c = 0; c < chunks; ++c) {
        std::int64_t* next = &offset[c * slabs];
        for (std::int64_t p = c * chunk; p < chunk_end(c); ++p) {
            const std::int64_t q = next[bin[p]]++;
            for (int d = 0; d < dim; ++d) sorted_position[q * dim + d] = position[p * dim + d];
            sorted_mass[q] = mass[p];
        }
    }

    // Pass 2: bin b adds to slabs b..b + 2, so bins of one colour (b mod 3) write disjoint slabs and run in
    // parallel; the colours run in turn. A node thus adds its bins in colour order, each in particle order.
    for (int colour = 0; colour < 3; ++colour) {
#pragma omp parallel for schedule(dynamic, 1) if (chunks > 1)
        for (int b = colour; b < slabs - 2; b += 3) {
            double* slab = grid.value.data() + static_cast<std::size_t>(b) * slab_size;
            for (std::int64_t q = start[b]; q < start[b + 1]; ++q) {
                AxisStencil a[dim];
                stencil(&sorted_position[q * dim], a);
                const double m = sorted_mass[q];
                if constexpr (dim == 2) {
                    for (int j = 0; j < 3; ++j) {
                        double* row = slab + static_cast<std::size_t>(grid.nodes[0]) * j + a[0].base;
                        const double mj = m * a[1].w[j];
                        for (int i = 0; i < 3; ++i) row[i] += mj * a[0].w[i];
                    }
                } else {
                    for (int k = 0; k < 3; ++k) {
                        for (int j = 0; j < 3; ++j) {
                            double* row = slab + static_cast<std::size_t>(k) * slab_size +
                                          static_cast<std::size_t>(grid.nodes[0]) * (a[1].base + j) + a[0].base;
                            const double mjk = m * a[1].w[j] * a[2].w[k];
                            for (int i = 0; i < 3; ++i) row[i] += mjk * a[0].w[i];
                        }
                    }
                }
            }
        }
    }
    return static_cast<std::size_t>(clamped);
}

void check_field(const GridField& f, const char* name) {
    bool ok = (f.dim == 2 || f.dim == 3) && (f.dim == 3 || f.nodes[2] == 1);
    for (int d = 0; d < 3; ++d) ok = ok && f.nodes[d] > 0;
    if (!ok || f.value.size() != f.size())
        throw std::invalid_argument(std::string("iou: field ") + name + " is malformed (" + grid_description(f) + ", " +
                                    std::to_string(f.value.size()) + " values)");
}

bool same_grid(const GridField& a, const GridField& b) {
    if (a.dim != b.dim || a.nodes != b.nodes) return false;
    // Fields rasterized on the same domain with the same dx agree exactly; allow for a domain given with
    // rounding differences.
    if (std::abs(a.dx - b.dx) > 1e-12 * std::max(a.dx, b.dx)) return false;
    for (int d = 0; d < a.dim; ++d)
        if (std::abs(a.origin[d] - b.origin[d]) > 1e-9 * a.dx) return false;
    return true;
}

// max of the field; throws if a value is negative or not finite, or if all are zero.
double field_max(const GridField& f, const char* name) {
    const std::int64_t n = static_cast<std::int64_t>(f.value.size());
    double max = 0.0;
    std::int64_t first_bad = n;
#pragma omp parallel for schedule(static) reduction(max : max) reduction(min : first_bad) if (n > 65536)
    for (std::int64_t i = 0; i < n; ++i) {
        const double v = f.value[i];
        if (!(v >= 0.0) || !std::isfinite(v)) first_bad = std::min(first_bad, i);
        max = std::max(max, v);
    }
    if (first_bad < n)
        throw std::invalid_argument(std::string("iou: field ") + name + " has value " +
                                    std::to_string(f.value[first_bad]) + " at node " + std::to_string(first_bad) +
                                    "; a mass field must be finite and >= 0");
    if (!(max > 0.0))
        throw std::invalid_argument(std::string("iou: field ") + name +
                                    " is all zero; IoU normalizes each field by its maximum and needs some mass");
    return max;
}

}  // namespace

GridField rasterize_mass(int dim, const std::vector<double>& position, const std::vector<double>& mass,
                         const double* domain_min, const double* domain_max, double dx, std::size_t* clamped) {
    if (dim != 2 && dim != 3)
        throw std::invalid_argument("rasterize_mass: dim is " + std::to_string(dim) + ", not 2 or 3");
    if (position.size() != mass.size() * static_cast<std::size_t>(dim))
        throw std::invalid_argument("rasterize_mass: " + std::to_string(position.size()) + " coordinates for " +
                                    std::to_string(mass.size()) + " masses in " + std::to_string(dim) +
                                    "D; need dim per particle");
    GridField grid = make_grid(dim, domain_min, domain_max, dx);
    const std::size_t count = dim == 2 ? splat_mass<2>(position, mass, grid) : splat_mass<3>(position, mass, grid);
    if (clamped) *clamped = count;
    return grid;
}

IouResult iou(const GridField& a, const GridField& b) {
    check_field(a, "a");
    check_field(b, "b");
    if (!same_grid(a, b))
        throw std::invalid_argument("iou: the fields are on different grids: a is " + grid_description(a) + ", b is " +
                                    grid_description(b));
    const double max_a = field_max(a, "a");
    const double max_b = field_max(b, "b");
    const double occupied_a = 1e-3 * max_a;
    const double occupied_b = 1e-3 * max_b;

    // Fixed blocks of nodes, summed in block order: the result does not depend on the thread count.
    constexpr std::int64_t block = 1 << 14;
    const std::int64_t n = static_cast<std::int64_t>(a.value.size());
    const std::int64_t blocks = (n + block - 1) / block;
    std::vector<double> intersection(blocks), union_(blocks), minimum(blocks), maximum(blocks);
    std::int64_t both = 0, either = 0;  // occupied node counts: integers, exact in any order
#pragma omp parallel for schedule(static) reduction(+ : both, either) if (blocks > 4)
    for (std::int64_t k = 0; k < blocks; ++k) {
        double I = 0.0, U = 0.0, lo = 0.0, hi = 0.0;
        for (std::int64_t i = k * block; i < std::min(n, (k + 1) * block); ++i) {
            const double A = a.value[i], B = b.value[i];
            lo += std::min(A, B);
            hi += std::max(A, B);
            const double ai = A / max_a, bi = B / max_b;
            const double ab = ai * bi;
            I += ab;
            U += (ai + bi) - ab;  // a + b - ab, written symmetric in (a, b)
            const bool in_a = A > occupied_a, in_b = B > occupied_b;
            both += (in_a && in_b) ? 1 : 0;
            either += (in_a || in_b) ? 1 : 0;
        }
        intersection[k] = I;
        union_[k] = U;
        minimum[k] = lo;
        maximum[k] = hi;
    }
    double I = 0.0, U = 0.0, lo = 0.0, hi = 0.0;
    for (std::int64_t k = 0; k < blocks; ++k) {
        I += intersection[k];
        U += union_[k];
        lo += minimum[k];
        hi += maximum[k];
    }
    // hi >= max A > 0, U >= max(sum a, sum b) >= 1 (the maximum node has a = 1) and
    // either >= 1, so every ratio is defined.
    return {lo / hi, static_cast<double>(both) / static_cast<double>(either), I / U};
}

}  // namespace pnet
