#pragma once
// APIC transfers between particles and grid (Jiang et al. 2015), shared by
// every integrator. With quadratic B-splines D_p = dx^2/4 I, so C_p = 4/dx^2 B_p.
#include <vector>

#include "pnet/mpm/bspline.hpp"
#include "pnet/mpm/grid.hpp"
#include "pnet/mpm/particles.hpp"

namespace pnet {

/// P2G: bins the particles, then m_i = sum w_ip m_p and
/// momentum_i = sum w_ip m_p (v_p + C_p (x_i - x_p)) + sum K_p grad w_ip,
/// with K_p = force_matrix[p] (for explicit MPM -dt V0_p tau_p; null: none).
template <int dim>
void particles_to_grid(Grid<dim>& grid, const Particles<dim>& particles, const std::vector<Mat<dim>>* force_matrix) {
    grid.bin_and_clear(particles.x);
    const double dx = grid.dx(), inv_dx = grid.inv_dx();
    const Vec<dim> origin = grid.origin();
    grid.for_each_particle_coloured([&](int p) {
        const BSplineStencil<dim> st(particles.x[p] - origin, inv_dx);
        const double m = particles.mass[p];
        const Vec<dim> mv = m * particles.v[p];
        const Mat<dim> mC = m * particles.C[p];
        const Mat<dim> K = force_matrix ? (*force_matrix)[p] : Mat<dim>::Zero();
        st.for_each_node(dx, [&](const int* node, double w, const Vec<dim>& grad, const Vec<dim>& dpos) {
            typename Grid<dim>::Node& n = grid.node(grid.index(node));
            n.mass += w * m;
            n.momentum += w * (mv + mC * dpos) + K * grad;
        });
    });
}

/// G2P gather of particle p from grid velocities (Node::momentum after
/// update_velocity()): v_p = sum w v_i, C_p = 4/dx^2 sum w v_i (x_i - x_p)^T,
/// grad v_p = sum v_i grad w_ip^T.
template <int dim>
inline void gather_velocity(const Grid<dim>& grid, const Vec<dim>& x, Vec<dim>& v, Mat<dim>& C, Mat<dim>& grad_v) {
    const double dx = grid.dx(), inv_dx = grid.inv_dx();
    const BSplineStencil<dim> st(x - grid.origin(), inv_dx);
    v.setZero();
    Mat<dim> B = Mat<dim>::Zero();
    grad_v.setZero();
    st.for_each_node(dx, [&](const int* node, double w, const Vec<dim>& grad, const Vec<dim>& dpos) {
        const Vec<dim>& vi = grid.node(grid.index(node)).momentum;
        v += w * vi;
        B += (w * vi) * dpos.transpose();
        grad_v += vi * grad.transpose();
    });
    C = (4.0 * inv_dx * inv_dx) * B;
}

}  // namespace pnet
