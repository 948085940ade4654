#pragma once
// Grid-mass IoU of two MPM results at the same time (docs/metrics.md, PlasticineLab style):
// rasterize each particle set's mass to the same grid with the quadratic B-spline, then
// compare the two nodal mass fields.
#include <array>
#include <cstddef>
#include <vector>

namespace pnet {

/// A scalar field on the nodes of a regular grid: node (i, j, k) sits at origin + (i, j, k) dx and
/// its value is value[index(i, j, k)] = value[i + nodes[0] (j + nodes[1] k)] (x fastest, then y, then z).
/// In 2D nodes[2] = 1, k = 0 and origin[2] = 0.
struct GridField {
    int dim = 2;
    std::array<int, 3> nodes = {0, 0, 1};            // nodes per axis (cells + 1)
    double dx = 0.0;                                 // node spacing, m
    std::array<double, 3> origin = {0.0, 0.0, 0.0};  // position of node (0, 0, 0), m
    std::vector<double> value;                       // nodes[0] nodes[1] nodes[2] entries

    std::size_t size() const {
        return static_cast<std::size_t>(nodes[0]) * static_cast<std::size_t>(nodes[1]) *
               static_cast<std::size_t>(nodes[2]);
    }
    std::size_t index(int i, int j, int k = 0) const {
        return static_cast<std::size_t>(i) +
               static_cast<std::size_t>(nodes[0]) *
                   (static_cast<std::size_t>(j) + static_cast<std::size_t>(nodes[1]) * static_cast<std::size_t>(k));
    }
};

/// Nodal mass m_i = sum_p w_ip m_p with the quadratic B-spline of the MPM transfers: per axis, with
/// s = (x_p - domain_min) / dx, base = floor(s - 0.5) and f = s - base,
///   w0 = (1.5 - f)^2 / 2,  w1 = 0.75 - (f - 1)^2,  w2 = (f - 0.5)^2 / 2  on nodes base, base + 1, base + 2,
/// and w_ip the tensor product. The grid has nodes at domain_min + i dx, i = 0..cells per axis, with
/// cells = ceil((domain_max - domain_min) / dx) (>= 2). Since the weights sum to 1, sum_i m_i = sum_p m_p.
///
/// A particle whose stencil would leave the grid (s < 1 or s > cells - 1 on some axis, e.g. outside the
/// domain) is splatted as if at the nearest admissible position, so no mass is lost; the number of such
/// particles is written to *clamped when clamped is not null.
///
/// position holds n dim coordinates (particle-major: x0 y0 [z0] x1 ...), mass n values >= 0 (kg);
/// domain_min / domain_max point to dim values (m). Throws std::invalid_argument on inconsistent sizes,
/// dim not 2 or 3, dx <= 0, an empty or degenerate domain, or a non-finite position or mass.
///
/// Parallel with OpenMP: particles are sorted (stably) into slabs of the last axis by their stencil's base
/// node, and every third slab is splatted at once. Each node adds its contributions in an order fixed by the
/// slabs and the particle indices, so the result is bitwise the same for any thread count.
GridField rasterize_mass(int dim, const std::vector<double>& position, const std::vector<double>& mass,
                         const double* domain_min, const double* domain_max, double dx, std::size_t* clamped = nullptr);

struct IouResult {
    double soft;           // sum_i min(A_i, B_i) / sum_i max(A_i, B_i)
    double binary;         // |occ(A) ∩ occ(B)| / |occ(A) ∪ occ(B)|, occ(A) = {i : A_i > 1e-3 max A}
    double plasticinelab;  // sum(a b) / sum(a + b - a b) with a = A / max A, b = B / max B
};

/// IoU of two nodal mass fields A, B (docs/metrics.md, with the project's choice
/// of soft IoU):
///   soft = sum_i min(A_i, B_i) / sum_i max(A_i, B_i)   (fuzzy-set Jaccard index
///     of the mass fields: intersection = min, union = max). It is 1 exactly when
///     A = B, drops as mass moves away, and needs no normalization: both runs
///     carry the same total mass, so the raw fields are compared.
///   binary = IoU of the occupied nodes (value > 1e-3 x the field's maximum).
///   plasticinelab = the formula docs/metrics.md prints (PlasticineLab's iou_kernel):
///     normalize each field by its maximum to a, b in [0, 1], sum a b / sum (a + b - a b).
///     Kept for reference only: its self-IoU sum a^2 / sum (2a - a^2) is below 1
///     wherever a node is partly filled (the B-spline rim of a body, a thin
///     deposit), e.g. 0.13 for a flat sand deposit against itself, so it cannot
///     judge accuracy.
/// All three are in [0, 1], symmetric, and 0 for fields without common support.
/// Throws std::invalid_argument if the fields are on different grids (dim, nodes, dx, origin), a field's
/// value size does not match its nodes, a value is negative or not finite, or a field is all zero.
IouResult iou(const GridField& a, const GridField& b);

}  // namespace pnet
