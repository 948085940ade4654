#include "pnet/contact/adaptive_stiffness.hpp"

#include <algorithm>
#include <stdexcept>

#include "pnet/contact/barrier.hpp"

namespace pnet {

BarrierStiffness initial_barrier_stiffness(double bbox_diagonal, double dhat, double average_mass, double dt,
                                           const Eigen::VectorXd& g_energy, const Eigen::VectorXd& g_barrier) {
    if (!(bbox_diagonal > 0.0) || !(dhat > 0.0) || !(average_mass > 0.0) || !(dt > 0.0))
        throw std::invalid_argument("initial_barrier_stiffness: diagonal, dhat, mass and dt must be > 0");
    const Barrier barrier{dhat * dhat};
    double d0 = 1e-8 * bbox_diagonal;
    d0 *= d0;
    if (d0 >= dhat * dhat) d0 = 0.5 * dhat * dhat;
    // IPC's bounds (position form), divided by dt^2 for ours.
    const double kappa_min = 1e11 * average_mass / (4.0 * d0 * barrier.second(d0)) / (dt * dt);
    const double kappa_max = 100.0 * kappa_min;
    double kappa = kappa_min;
    if (g_barrier.squaredNorm() > 0.0) kappa = -g_barrier.dot(g_energy) / g_barrier.squaredNorm();
    return {std::clamp(kappa, kappa_min, kappa_max), kappa_max};
}

double update_barrier_stiffness(const BarrierStiffness& stiffness, double previous_min_distance, double min_distance,
                                double bbox_diagonal) {
    const double eps = 1e-9 * bbox_diagonal;
    if (previous_min_distance < eps && min_distance < eps && min_distance < previous_min_distance)
        return std::min(stiffness.kappa_max, 2.0 * stiffness.kappa);
    return stiffness.kappa;
}

}  // namespace pnet
