#include "pnet/metrics/deposit_shape.hpp"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <stdexcept>

namespace pnet {

DepositShape deposit_shape(int dim, const std::vector<double>& position, const std::vector<double>& mass) {
    if (dim != 2 && dim != 3) throw std::invalid_argument("deposit_shape: dim must be 2 or 3");
    const std::size_t n = mass.size();
    if (position.size() != n * static_cast<std::size_t>(dim))
        throw std::invalid_argument("deposit_shape: position must hold dim numbers per particle");
    double total = 0.0, centre[3] = {0.0, 0.0, 0.0};
    for (std::size_t p = 0; p < n; ++p) {
        total += mass[p];
        for (int a = 0; a < dim; ++a) centre[a] += mass[p] * position[p * dim + a];
    }
    if (!(total > 0.0)) throw std::invalid_argument("deposit_shape: no mass");
    for (int a = 0; a < dim; ++a) centre[a] /= total;
    double sum = 0.0;
    for (std::size_t p = 0; p < n; ++p)
        for (int a = 0; a < dim; ++a) {
            if (a == 1) continue;  // y is up
            const double d = position[p * dim + a] - centre[a];
            sum += mass[p] * d * d;
        }
    DepositShape s;
    s.spread = std::sqrt(sum / total);
    // Height: the smallest y with at least 90% of the mass at or below it.
    std::vector<std::size_t> order(n);
    std::iota(order.begin(), order.end(), 0);
    std::sort(order.begin(), order.end(),
              [&](std::size_t a, std::size_t b) { return position[a * dim + 1] < position[b * dim + 1]; });
    double below = 0.0;
    for (std::size_t p : order) {
        below += mass[p];
        s.height = position[p * dim + 1];
        if (below >= 0.9 * total) break;
    }
    return s;
}

}  // namespace pnet
