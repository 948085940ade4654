#pragma once
// IPC's adaptive barrier stiffness kappa (Li et al. 2020, sec. 4.3;
// docs/methods.md), for our velocity-form incremental potential. IPC's potential is
// 1/2 (x - x~)^T M (x - x~) + h^2 Psi(x) + kappa_IPC B(x); ours is that divided
// by dt^2, so kappa = kappa_IPC / dt^2.
//
// Initial value: kappa_IPC = clamp(-g_B . g_E / |g_B|^2, kappa_min, 100 kappa_min)
// with g_E the gradient of the rest of the potential, g_B that of sum b, and
//   kappa_min = 1e11 m_avg / (4 d0 b''(d0)),  d0 = (1e-8 diag)^2
// (m_avg the average nodal mass, diag the bounding-box diagonal). Update: the
// stiffness doubles (up to the maximum) while the smallest distance stays
// below 1e-9 diag and keeps shrinking.
#include <Eigen/Core>

namespace pnet {

struct BarrierStiffness {
    double kappa = 0.0;      // for the velocity form (kappa_IPC / dt^2)
    double kappa_max = 0.0;  // likewise
};

/// g_energy, g_barrier: gradients in the positions of our potential without
/// contact (dE/dv / dt) and of sum_k b(s_k) (kappa = 1), at the same state; the
/// balancing kappa -g_B . g_E / |g_B|^2 is then already in our form.
BarrierStiffness initial_barrier_stiffness(double bbox_diagonal, double dhat, double average_mass, double dt,
                                           const Eigen::VectorXd& g_energy, const Eigen::VectorXd& g_barrier);

/// Doubles kappa (up to kappa_max) when both distances are below 1e-9 diag and the new one is smaller.
double update_barrier_stiffness(const BarrierStiffness& stiffness, double previous_min_distance,
                                double min_distance, double bbox_diagonal);

}  // namespace pnet
