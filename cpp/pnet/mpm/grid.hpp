#pragma once
// The MPM background grid: nodes at origin + i dx, i = 0..cells per axis,
// stored in blocks of 4^d nodes so that a step touches only the blocks near
// particles (clearing and updating a dense 257^2 or 65^3 grid would cost more
// than the particles of a sand column).
//
// Race-free, deterministic P2G: a particle with stencil base node b writes
// nodes b..b+2, inside its block (b >> 2) and the next one. Blocks whose
// coordinates have the same parities (2^d colours) are >= 2 blocks apart, so
// they never write the same node: colours run one after the other, the blocks
// of a colour in parallel, and the particles of a block in index order. Every
// node thus sums its contributions in the same order whatever the thread count.
#include <array>
#include <cmath>
#include <cstdint>
#include <vector>

#include "pnet/math/types.hpp"
#include "pnet/mpm/particles.hpp"

namespace pnet {

struct BoundaryConditions {
    bool slip_walls = true;        // remove the wall-ward normal velocity within 3 nodes of a wall
    int sticky_floor_cells = 3;    // the floor layer: the nodes within this many cells of the floor (y = min)
    // < 0: the floor layer is sticky (velocity zeroed). >= 0: it is a Coulomb floor of this friction
    // coefficient: a node moving into the floor (v_y < 0) loses that normal velocity and as much
    // tangential speed as mu |v_y| (all of it when it is less: static friction); a node moving away is
    // free. The sticky floor takes a fraction of a node's momentum every step, so its drag grows as the
    // step shrinks; the Coulomb floor's impulse is mu times the normal one, whatever the step.
    double floor_friction = -1.0;

    bool coulomb_floor() const { return floor_friction >= 0.0; }
    /// Node coordinate y (index along axis 1) in the floor layer.
    bool in_floor(int y) const { return sticky_floor_cells > 0 && y <= sticky_floor_cells; }
};

/// `bc` without the Coulomb floor's projection (its floor layer off; the sticky one kept): the v* an
/// implicit solve starts from, which holds the pressing nodes' normal component itself and has the
/// floor's friction as a form (IncrementalPotential::floor_friction_contacts).
inline BoundaryConditions unprojected_floor(BoundaryConditions bc) {
    if (bc.coulomb_floor()) bc.sticky_floor_cells = 0;
    return bc;
}

/// The Coulomb floor's projection of a velocity v pressing into the floor with normal impulse per unit
/// mass `pressure` (>= 0; v_y itself when it is below 0): v_y = 0 and the tangential part shrunk by
/// mu pressure, to 0 if that is more than its length.
template <int dim>
inline void coulomb_projection(Vec<dim>& v, double pressure, double mu) {
    v[1] = 0.0;
    double tangential = 0.0;
    for (int a = 0; a < dim; ++a)
        if (a != 1) tangential += v[a] * v[a];
    tangential = std::sqrt(tangential);
    const double scale = tangential > mu * pressure ? 1.0 - mu * pressure / tangential : 0.0;
    for (int a = 0; a < dim; ++a)
        if (a != 1) v[a] *= scale;
}

template <int dim>
class Grid {
public:
    static constexpr int kBlockBits = 2;
    static constexpr int kBlock = 1 << kBlockBits;  // nodes per block and axis
    static constexpr int kBlockNodes = dim == 2 ? kBlock * kBlock : kBlock * kBlock * kBlock;
    static constexpr int kColours = 1 << dim;
    static constexpr int kWallNodes = 3;

    /// Node data: mass and momentum during P2G, velocity after update_velocity().
    struct Node {
        double mass;
        Vec<dim> momentum;  // kg m/s; then velocity, m/s
    };

    Grid(const Vec<dim>& origin, double dx, const std::array<int, dim>& cells);

    const Vec<dim>& origin() const { return origin_; }
    double dx() const { return dx_; }
    double inv_dx() const { return inv_dx_; }
    int nodes(int axis) const { return nodes_[axis]; }

    /// Storage index of node (i, j[, k]): the sum over the axes of
    /// axis_offset(axis, coordinate), so that a stencil computes 3 offsets per
    /// axis instead of a full index per node.
    std::int64_t axis_offset(int axis, int c) const {
        return (c >> kBlockBits) * block_stride_[axis] + (c & (kBlock - 1)) * local_stride_[axis];
    }
    std::int64_t index(const int* node) const {
        std::int64_t i = 0;
        for (int a = 0; a < dim; ++a) i += axis_offset(a, node[a]);
        return i;
    }
    Node& node(std::int64_t index) { return storage_[index]; }
    const Node& node(std::int64_t index) const { return storage_[index]; }
    /// Number of storage slots (every node of every block; indices are below it).
    std::int64_t storage_size() const { return static_cast<std::int64_t>(storage_.size()); }
    /// storage_size() of a grid of `cells` (without making one).
    static std::int64_t storage_size(const std::array<int, dim>& cells) {
        std::int64_t blocks = 1;
        for (int a = 0; a < dim; ++a) blocks *= (cells[a] + 1 + kBlock - 1) / kBlock;
        return blocks * kBlockNodes;
    }

    /// Bins the particles by the block of their stencil base node (counting
    /// sort, stable), marks the blocks they write as active and zeroes them.
    /// Particles must lie at least one cell inside the domain (see clamp).
    void bin_and_clear(const std::vector<Vec<dim>>& x);

    /// Calls fn(p) for every particle, colour after colour, blocks of a colour
    /// in parallel (OpenMP), particles of a block in index order. One parallel
    /// region for all colours (a barrier between them, not a fork and join):
    /// the implicit solver calls this in every Hessian-vector product.
    template <typename Fn>
    void for_each_particle_coloured(Fn&& fn) const {
#pragma omp parallel
        for (int colour = 0; colour < kColours; ++colour) {
            const std::vector<int>& blocks = colour_blocks_[colour];
            const std::ptrdiff_t count = static_cast<std::ptrdiff_t>(blocks.size());
#pragma omp for schedule(dynamic, 2)
            for (std::ptrdiff_t b = 0; b < count; ++b) {
                const int block = blocks[b];
                for (int q = block_start_[block]; q < block_start_[block + 1]; ++q) fn(order_[q]);
            }
        }
    }

    /// v_i = momentum_i / m_i + dt g on every active node with mass (0 on the
    /// others), then the boundary conditions. Returns the largest |v_i|.
    double update_velocity(double dt, const Vec<dim>& gravity, const BoundaryConditions& bc);

    /// Applies the boundary conditions to a velocity v of node `node`.
    void apply_boundary(const int* node, Vec<dim>& v, const BoundaryConditions& bc) const;

    /// apply_boundary() on the velocity (Node::momentum after
    /// update_velocity() or an implicit solve) of every active node.
    void project_velocity(const BoundaryConditions& bc);

    /// The velocity components of node `node` that the boundary conditions
    /// constrain (fixed[a] for axis a): all of them on the sticky floor, the
    /// normal one on the Coulomb floor (its tangential ones are free during a
    /// solve, with the floor's friction a form of the potential), the
    /// wall-normal one within kWallNodes of a slip wall. An implicit solve
    /// holds these at their apply_boundary() value (the integrators pass
    /// conditions without slip walls: those act after the solve, see
    /// implicit_integrator.hpp).
    void constrained_components(const int* node, bool* fixed, const BoundaryConditions& bc) const;

    /// The active blocks (valid after bin_and_clear), sorted; block b holds the
    /// storage indices [b kBlockNodes, (b + 1) kBlockNodes).
    const std::vector<int>& active_blocks() const { return active_blocks_; }
    /// Node coordinates of storage index `index`.
    void coordinates(std::int64_t index, int* node) const;

    /// The lowest and highest particle position whose stencil stays on the grid.
    double lower_limit(int axis) const { return origin_[axis] + dx_; }
    double upper_limit(int axis) const { return origin_[axis] + (nodes_[axis] - 2) * dx_; }

private:
    Vec<dim> origin_;
    double dx_, inv_dx_;
    std::array<int, dim> nodes_, blocks_;
    std::array<std::int64_t, dim> block_stride_, local_stride_;
    std::vector<Node> storage_;
    // Binning, rebuilt every step without reallocation once sizes settle.
    std::vector<int> particle_block_, block_count_, block_start_, order_, active_blocks_;
    std::vector<std::uint8_t> block_active_;
    std::vector<int> colour_blocks_[kColours];
};

}  // namespace pnet
