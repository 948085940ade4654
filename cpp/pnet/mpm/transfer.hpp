#pragma once
// APIC transfers between particles and grid (Jiang et al. 2015), shared by
// every integrator. With quadratic B-splines D_p = dx^2/4 I, so C_p = 4/dx^2 B_p.
#include <cmath>
#include <vector>

#include "pnet/mpm/bspline.hpp"
#include "pnet/mpm/grid.hpp"
#include "pnet/mpm/particles.hpp"

namespace pnet {

/// The 3^d stencil nodes of a particle at x on `grid`, per axis a and stencil
/// position k: weight factor w, its derivative dw (1/m), the node's offset
/// x_i - x_p (m) and its storage-index term (Grid::axis_offset). Node
/// (i, j[, k]) has weight w[0][i] w[1][j] (w[2][k]) and storage index
/// index[0][i] + index[1][j] (+ index[2][k]).
template <int dim>
struct StencilNodes {
    double w[dim][3], dw[dim][3], d[dim][3];
    std::int64_t index[dim][3];

    StencilNodes(const Grid<dim>& grid, const Vec<dim>& x) {
        const BSplineStencil<dim> st(x - grid.origin(), grid.inv_dx());
        for (int a = 0; a < dim; ++a)
            for (int k = 0; k < 3; ++k) {
                w[a][k] = st.w[a][k];
                dw[a][k] = st.dw[a][k];
                d[a][k] = (k - st.offset[a]) * grid.dx();
                index[a][k] = grid.axis_offset(a, st.base[a] + k);
            }
    }

    /// fn(storage index, w, grad w, x_i - x_p) for the 3^d nodes, with the
    /// products formed once per axis pair (the loops the transfers inline).
    template <typename Fn>
    void for_each(Fn&& fn) const {
        if constexpr (dim == 2) {
            for (int i = 0; i < 3; ++i)
                for (int j = 0; j < 3; ++j)
                    fn(index[0][i] + index[1][j], w[0][i] * w[1][j], Vec<2>(dw[0][i] * w[1][j], w[0][i] * dw[1][j]),
                       Vec<2>(d[0][i], d[1][j]));
        } else {
            for (int i = 0; i < 3; ++i)
                for (int j = 0; j < 3; ++j) {
                    const double wij = w[0][i] * w[1][j], gi = dw[0][i] * w[1][j], gj = w[0][i] * dw[1][j];
                    const std::int64_t ij = index[0][i] + index[1][j];
                    for (int k = 0; k < 3; ++k)
                        fn(ij + index[2][k], wij * w[2][k], Vec<3>(gi * w[2][k], gj * w[2][k], wij * dw[2][k]),
                           Vec<3>(d[0][i], d[1][j], d[2][k]));
                }
        }
    }
};

/// P2G of any velocity-like field u_p with its APIC affine part A_p (the particles' own v_p, C_p, or
/// BDF2's history): bins the particles, m_i = sum w_ip m_p, momentum_i = sum w_ip m_p (u_p + A_p (x_i -
/// x_p)) + sum K_p grad w_ip.
template <int dim>
void field_to_grid(Grid<dim>& grid, const Particles<dim>& particles, const std::vector<Vec<dim>>& u,
                   const std::vector<Mat<dim>>& A, const std::vector<Mat<dim>>* force_matrix) {
    grid.bin_and_clear(particles.x);
    grid.for_each_particle_coloured([&](int p) {
        const StencilNodes<dim> st(grid, particles.x[p]);
        const double m = particles.mass[p];
        const Vec<dim> mv = m * u[p];
        const Mat<dim> mC = m * A[p];
        const Mat<dim> K = force_matrix ? (*force_matrix)[p] : Mat<dim>::Zero();
        st.for_each([&](std::int64_t node, double w, const Vec<dim>& grad, const Vec<dim>& dpos) {
            typename Grid<dim>::Node& n = grid.node(node);
            n.mass += w * m;
            n.momentum += w * (mv + mC * dpos) + K * grad;
        });
    });
}

/// P2G: bins the particles, then m_i = sum w_ip m_p and
/// momentum_i = sum w_ip m_p (v_p + C_p (x_i - x_p)) + sum K_p grad w_ip,
/// with K_p = force_matrix[p] (for explicit MPM -dt V0_p tau_p; null: none).
template <int dim>
void particles_to_grid(Grid<dim>& grid, const Particles<dim>& particles, const std::vector<Mat<dim>>* force_matrix) {
    field_to_grid(grid, particles, particles.v, particles.C, force_matrix);
}

/// G2P gather of particle p from grid velocities (Node::momentum after
/// update_velocity()): v_p = sum w v_i, C_p = 4/dx^2 sum w v_i (x_i - x_p)^T,
/// grad v_p = sum v_i grad w_ip^T.
template <int dim>
inline void gather_velocity(const Grid<dim>& grid, const Vec<dim>& x, Vec<dim>& v, Mat<dim>& C, Mat<dim>& grad_v) {
    const StencilNodes<dim> st(grid, x);
    Vec<dim> sum_v = Vec<dim>::Zero();
    Mat<dim> B = Mat<dim>::Zero(), G = Mat<dim>::Zero();
    st.for_each([&](std::int64_t node, double w, const Vec<dim>& grad, const Vec<dim>& dpos) {
        const Vec<dim> vi = grid.node(node).momentum;
        const Vec<dim> wv = w * vi;
        sum_v += wv;
        for (int b = 0; b < dim; ++b) {
            B.col(b) += dpos[b] * wv;
            G.col(b) += grad[b] * vi;
        }
    });
    v = sum_v;
    C = (4.0 * grid.inv_dx() * grid.inv_dx()) * B;
    grad_v = G;
}

/// AFLIP (Fei et al. 2021): the part of each particle's velocity that the grid does not carry,
/// r_p = v_p - sum w_ip v_i, with v_i = momentum_i / m_i of a force-free P2G of the particles (call
/// right after particles_to_grid(grid, particles, nullptr)). APIC's G2P drops r_p every step; keeping
/// alpha r_p (flip_fraction()) makes that loss a rate in time instead of a fraction per step.
template <int dim>
void velocity_residual(const Grid<dim>& grid, const Particles<dim>& particles, std::vector<Vec<dim>>& r) {
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(particles.size());
    r.resize(n);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < n; ++p) {
        const StencilNodes<dim> st(grid, particles.x[p]);
        Vec<dim> sum = Vec<dim>::Zero();
        st.for_each([&](std::int64_t node, double w, const Vec<dim>&, const Vec<dim>&) {
            const typename Grid<dim>::Node& nd = grid.node(node);
            if (nd.mass > 0.0) sum += (w / nd.mass) * nd.momentum;
        });
        r[p] = particles.v[p] - sum;
    }
}

/// The fraction of r_p a step of dt keeps: exp(-dt / relaxation_time); 0 (APIC) for a time <= 0.
inline double flip_fraction(double dt, double relaxation_time) {
    return relaxation_time > 0.0 ? std::exp(-dt / relaxation_time) : 0.0;
}

/// v_p += alpha r_p after G2P (AFLIP; positions moved with the grid velocity, as G2P did).
template <int dim>
void add_velocity_residual(Particles<dim>& particles, const std::vector<Vec<dim>>& r, double alpha) {
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(particles.size());
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < n; ++p) particles.v[p] += alpha * r[p];
}

}  // namespace pnet
