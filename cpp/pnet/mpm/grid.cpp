#include "pnet/mpm/grid.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace pnet {

template <int dim>
Grid<dim>::Grid(const Vec<dim>& origin, double dx, const std::array<int, dim>& cells)
    : origin_(origin), dx_(dx), inv_dx_(1.0 / dx) {
    if (!(dx > 0.0)) throw std::invalid_argument("grid: dx must be positive");
    std::int64_t total_blocks = 1;
    for (int a = 0; a < dim; ++a) {
        if (cells[a] < 4) throw std::invalid_argument("grid: at least 4 cells per axis");
        nodes_[a] = cells[a] + 1;
        blocks_[a] = (nodes_[a] + kBlock - 1) / kBlock;
        total_blocks *= blocks_[a];
    }
    std::int64_t block_stride = kBlockNodes, local_stride = 1;
    for (int a = dim - 1; a >= 0; --a) {
        block_stride_[a] = block_stride;
        local_stride_[a] = local_stride;
        block_stride *= blocks_[a];
        local_stride *= kBlock;
    }
    storage_.assign(total_blocks * kBlockNodes, Node{0.0, Vec<dim>::Zero()});
    block_count_.assign(total_blocks, 0);
    block_start_.assign(total_blocks + 1, 0);
    block_active_.assign(total_blocks, 0);
}

template <int dim>
void Grid<dim>::coordinates(std::int64_t index, int* node) const {
    std::int64_t block = index / kBlockNodes, local = index % kBlockNodes;
    for (int a = dim - 1; a >= 0; --a) {
        node[a] = static_cast<int>((block % blocks_[a]) * kBlock + local % kBlock);
        block /= blocks_[a];
        local /= kBlock;
    }
}

template <int dim>
void Grid<dim>::bin_and_clear(const std::vector<Vec<dim>>& x) {
    const std::size_t n = x.size();
    particle_block_.resize(n);
    std::fill(block_count_.begin(), block_count_.end(), 0);
    for (int block : active_blocks_) block_active_[block] = 0;
    active_blocks_.clear();
    for (int c = 0; c < kColours; ++c) colour_blocks_[c].clear();

    // The blocks in parallel, the counts serially (a stable counting sort).
    const std::ptrdiff_t count = static_cast<std::ptrdiff_t>(n);
    bool outside = false;
#pragma omp parallel for schedule(static) reduction(|| : outside)
    for (std::ptrdiff_t p = 0; p < count; ++p) {
        int block = 0;
        for (int a = 0; a < dim; ++a) {
            const int base = static_cast<int>(std::floor((x[p][a] - origin_[a]) * inv_dx_ - 0.5));
            if (base < 0 || base + 2 >= nodes_[a]) {
                outside = true;
                block = 0;
                break;
            }
            block = block * blocks_[a] + (base >> kBlockBits);
        }
        particle_block_[p] = block;
    }
    if (outside) throw std::logic_error("grid: a particle's stencil leaves the grid (positions must be clamped)");
    for (std::size_t p = 0; p < n; ++p) ++block_count_[particle_block_[p]];
    block_start_[0] = 0;
    for (std::size_t b = 0; b < block_count_.size(); ++b) block_start_[b + 1] = block_start_[b] + block_count_[b];
    order_.resize(n);
    {
        // Stable scatter: particles of a block keep their index order.
        std::vector<int>& cursor = block_count_;
        for (std::size_t b = 0; b < cursor.size(); ++b) cursor[b] = block_start_[b];
        for (std::size_t p = 0; p < n; ++p) order_[cursor[particle_block_[p]]++] = static_cast<int>(p);
    }

    // Blocks with particles, by colour, and the blocks they write (the block
    // and its successors along each axis).
    const int total_blocks = static_cast<int>(block_start_.size()) - 1;
    for (int b = 0; b < total_blocks; ++b) {
        if (block_start_[b + 1] == block_start_[b]) continue;
        int coord[dim], rest = b, colour = 0;
        for (int a = dim - 1; a >= 0; --a) {
            coord[a] = rest % blocks_[a];
            rest /= blocks_[a];
        }
        for (int a = 0; a < dim; ++a) colour = colour * 2 + (coord[a] & 1);
        colour_blocks_[colour].push_back(b);
        for (int corner = 0; corner < kColours; ++corner) {
            int neighbour = 0;
            bool inside = true;
            for (int a = 0; a < dim; ++a) {
                const int c = coord[a] + ((corner >> (dim - 1 - a)) & 1);
                inside = inside && c < blocks_[a];
                neighbour = neighbour * blocks_[a] + c;
            }
            if (inside && !block_active_[neighbour]) {
                block_active_[neighbour] = 1;
                active_blocks_.push_back(neighbour);
            }
        }
    }
    std::sort(active_blocks_.begin(), active_blocks_.end());
    const std::ptrdiff_t active = static_cast<std::ptrdiff_t>(active_blocks_.size());
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t i = 0; i < active; ++i) {
        Node* nodes = &storage_[static_cast<std::int64_t>(active_blocks_[i]) * kBlockNodes];
        for (int k = 0; k < kBlockNodes; ++k) nodes[k] = Node{0.0, Vec<dim>::Zero()};
    }
}

template <int dim>
void Grid<dim>::apply_boundary(const int* node, Vec<dim>& v, const BoundaryConditions& bc) const {
    if (bc.in_floor(node[1])) {
        if (!bc.coulomb_floor()) {
            v.setZero();
            return;
        }
        if (v[1] < 0.0) coulomb_projection<dim>(v, -v[1], bc.floor_friction);
    }
    if (!bc.slip_walls) return;
    for (int a = 0; a < dim; ++a) {
        if (node[a] < kWallNodes && v[a] < 0.0) v[a] = 0.0;
        if (node[a] >= nodes_[a] - kWallNodes && v[a] > 0.0) v[a] = 0.0;
    }
}

template <int dim>
void Grid<dim>::project_velocity(const BoundaryConditions& bc) {
    const std::ptrdiff_t active = static_cast<std::ptrdiff_t>(active_blocks_.size());
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t i = 0; i < active; ++i) {
        const std::int64_t first = static_cast<std::int64_t>(active_blocks_[i]) * kBlockNodes;
        for (int k = 0; k < kBlockNodes; ++k) {
            int coord[dim];
            coordinates(first + k, coord);
            apply_boundary(coord, storage_[first + k].momentum, bc);
        }
    }
}

template <int dim>
void Grid<dim>::constrained_components(const int* node, bool* fixed, const BoundaryConditions& bc) const {
    const bool floor = bc.in_floor(node[1]);
    for (int a = 0; a < dim; ++a)
        fixed[a] = (floor && (!bc.coulomb_floor() || a == 1)) ||
                   (bc.slip_walls && (node[a] < kWallNodes || node[a] >= nodes_[a] - kWallNodes));
}

template <int dim>
double Grid<dim>::update_velocity(double dt, const Vec<dim>& gravity, const BoundaryConditions& bc) {
    const std::ptrdiff_t active = static_cast<std::ptrdiff_t>(active_blocks_.size());
    double max_speed = 0.0;
#pragma omp parallel for schedule(static) reduction(max : max_speed)
    for (std::ptrdiff_t i = 0; i < active; ++i) {
        const std::int64_t first = static_cast<std::int64_t>(active_blocks_[i]) * kBlockNodes;
        for (int k = 0; k < kBlockNodes; ++k) {
            Node& n = storage_[first + k];
            if (n.mass <= 0.0) {
                n.momentum.setZero();
                continue;
            }
            Vec<dim> v = n.momentum / n.mass + dt * gravity;
            int coord[dim];
            coordinates(first + k, coord);
            apply_boundary(coord, v, bc);
            n.momentum = v;
            max_speed = std::max(max_speed, v.norm());
        }
    }
    return max_speed;
}

template class Grid<2>;
template class Grid<3>;

}  // namespace pnet
