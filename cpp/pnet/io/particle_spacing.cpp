#include "pnet/io/particle_spacing.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <unordered_map>

namespace pnet {

double particle_spacing(const std::vector<double>& position, int dim) {
    const std::size_t n = position.size() / std::size_t(dim);
    if (n < 2) return 0.0;
    double lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0};
    for (int k = 0; k < dim; ++k) lo[k] = hi[k] = position[std::size_t(k)];
    for (std::size_t i = 0; i < n; ++i)
        for (int k = 0; k < dim; ++k) {
            const double x = position[i * std::size_t(dim) + std::size_t(k)];
            if (!std::isfinite(x)) continue;
            lo[k] = std::min(lo[k], x);
            hi[k] = std::max(hi[k], x);
        }
    // Axes along which all particles lie flat (a sheet or a line) do not count towards the volume.
    const double largest = std::max({hi[0] - lo[0], hi[1] - lo[1], dim == 3 ? hi[2] - lo[2] : 0.0});
    if (!(largest > 0)) return 0.0;
    double volume = 1.0;
    int spread_axes = 0;
    for (int k = 0; k < dim; ++k) {
        if (hi[k] - lo[k] > 1e-9 * largest) {
            volume *= hi[k] - lo[k];
            ++spread_axes;
        }
    }
    const double h0 = std::pow(volume / double(n), 1.0 / spread_axes);
    const double cell = 2.0 * h0;  // the hash cell and the search radius

    // Cell coordinates packed 21 bits per axis; wrapping can only add candidates from far cells,
    // whose true distances are then computed, so the nearest neighbour found is still right.
    constexpr std::uint64_t kMask = (1u << 21) - 1;
    auto cell_of = [&](std::size_t i, int k) {
        return std::int64_t(std::floor((position[i * std::size_t(dim) + std::size_t(k)] - lo[k]) / cell));
    };
    auto key_of = [&](const std::int64_t c[3]) {
        std::uint64_t key = 0;
        for (int k = 0; k < dim; ++k) key = (key << 21) | (std::uint64_t(c[k]) & kMask);
        return key;
    };
    std::vector<std::pair<std::uint64_t, std::uint32_t>> cells;
    cells.reserve(n);
    for (std::size_t i = 0; i < n; ++i) {
        std::int64_t c[3] = {0, 0, 0};
        bool finite = true;
        for (int k = 0; k < dim; ++k) {
            finite = finite && std::isfinite(position[i * std::size_t(dim) + std::size_t(k)]);
            if (finite) c[k] = cell_of(i, k);
        }
        if (finite) cells.emplace_back(key_of(c), std::uint32_t(i));
    }
    std::sort(cells.begin(), cells.end());

    const std::size_t stride = std::max<std::size_t>(1, cells.size() / 4096);
    std::vector<double> nearest;
    for (std::size_t s = 0; s < cells.size(); s += stride) {
        const std::size_t i = cells[s].second;
        std::int64_t c[3] = {0, 0, 0};
        for (int k = 0; k < dim; ++k) c[k] = cell_of(i, k);
        double best2 = cell * cell;
        bool found = false;
        const int neighbours = dim == 3 ? 27 : 9;
        for (int m = 0; m < neighbours; ++m) {
            const std::int64_t nc[3] = {c[0] + m % 3 - 1, c[1] + (m / 3) % 3 - 1, dim == 3 ? c[2] + m / 9 - 1 : 0};
            const std::uint64_t key = key_of(nc);
            auto it = std::lower_bound(cells.begin(), cells.end(), std::make_pair(key, std::uint32_t(0)));
            for (; it != cells.end() && it->first == key; ++it) {
                const std::size_t j = it->second;
                double d2 = 0;
                for (int k = 0; k < dim; ++k) {
                    const double e = position[i * std::size_t(dim) + std::size_t(k)] -
                                     position[j * std::size_t(dim) + std::size_t(k)];
                    d2 += e * e;
                }
                if (j != i && d2 > 0 && d2 <= best2) {
                    best2 = d2;
                    found = true;
                }
            }
        }
        if (found) nearest.push_back(std::sqrt(best2));
    }
    if (nearest.empty()) return h0;
    std::nth_element(nearest.begin(), nearest.begin() + std::ptrdiff_t(nearest.size() / 2), nearest.end());
    return nearest[nearest.size() / 2];
}

}  // namespace pnet
