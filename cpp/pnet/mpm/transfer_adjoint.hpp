#pragma once
// The adjoints (vector-Jacobian products) of the APIC transfers (transfer.hpp, grid_to_particles.hpp), with
// the particles' positions differentiated through the quadratic B-spline weights, their gradients and
// Hessians: the transfer half of the implicit MPM step's adjoint (issue 57; docs/adjoint.md). With
// d_ip = x_i - x_p (so d d_ip / d x_p = -I) and the node arrays indexed by Grid storage index:
//
// P2G:  m_i = sum_p w_ip m_p,   q_i = sum_p w_ip m_p (v_p + C_p d_ip).
//   From the cotangents (mb_i, qb_i):
//     vb_p += m_p sum_i w_ip qb_i,          Cb_p += m_p sum_i w_ip qb_i d_ip^T,
//     xb_p += m_p sum_i [grad w_ip (mb_i + qb_i . (v_p + C_p d_ip)) - w_ip C_p^T qb_i].
//
// G2P:  v_p' = sum_i w_ip v_i,   C_p' = 4/dx^2 sum_i w_ip v_i d_ip^T,   G_p = sum_i v_i grad w_ip^T,
//       F_p' = (I + dt G_p) F_p (the trial F, before the return mapping),   x_p' = x_p + dt v_p'.
//   From (xb', vb', Cb', Fb'), with u_p = vb' + dt xb' and Gb_p = dt Fb' F_p^T:
//     vb_i += w_ip u_p + 4/dx^2 w_ip Cb' d_ip + Gb_p grad w_ip,
//     Fb_p += (I + dt G_p)^T Fb',
//     xb_p += xb' + sum_i [grad w_ip (u_p . v_i + 4/dx^2 v_i . Cb' d_ip) - 4/dx^2 w_ip Cb'^T v_i
//                          + Hess w_ip Gb_p^T v_i].
//
// A particle's stencil is where it starts; the weights are differentiated within it (a particle crossing
// a cell boundary changes its stencil's nodes, where w and grad w are continuous but Hess w is not: the
// derivative there is one-sided). The particles' cotangents are computed in parallel, the nodes' serially in
// particle order, so that the result does not depend on the thread count.
#include <vector>

#include "pnet/mpm/grid.hpp"
#include "pnet/mpm/particles.hpp"
#include "pnet/mpm/transfer.hpp"

namespace pnet {

/// StencilNodes with the weights' Hessians: fn(storage index, w, grad w, Hess w, x_i - x_p) per node.
template <int dim>
struct StencilNodeDerivatives {
    double w[dim][3], dw[dim][3], ddw[dim][3], d[dim][3];
    std::int64_t index[dim][3];

    StencilNodeDerivatives(const Grid<dim>& grid, const Vec<dim>& x) {
        const BSplineStencil<dim> st(x - grid.origin(), grid.inv_dx());
        const double inv_dx2 = grid.inv_dx() * grid.inv_dx();
        for (int a = 0; a < dim; ++a)
            for (int k = 0; k < 3; ++k) {
                w[a][k] = st.w[a][k];
                dw[a][k] = st.dw[a][k];
                ddw[a][k] =
                    (k == 1 ? -2.0 : 1.0) * inv_dx2;  // w'' of (1.5 - f)^2 / 2, 0.75 - (f - 1)^2, (f - 0.5)^2 / 2
                d[a][k] = (k - st.offset[a]) * grid.dx();
                index[a][k] = grid.axis_offset(a, st.base[a] + k);
            }
    }

    template <typename Fn>
    void for_each(Fn&& fn) const {
        int k[dim];
        const int count = dim == 2 ? 9 : 27;
        for (int s = 0; s < count; ++s) {
            int rest = s;
            for (int a = dim - 1; a >= 0; --a) {  // the last axis fastest, as StencilNodes
                k[a] = rest % 3;
                rest /= 3;
            }
            std::int64_t node = 0;
            double weight = 1.0;
            Vec<dim> grad, offset;
            Mat<dim> hess;
            for (int a = 0; a < dim; ++a) {
                node += index[a][k[a]];
                weight *= w[a][k[a]];
                offset[a] = d[a][k[a]];
            }
            for (int a = 0; a < dim; ++a)
                for (int b = 0; b < dim; ++b) {
                    double value = 1.0;
                    for (int c = 0; c < dim; ++c) {
                        const bool da = c == a, db = c == b;
                        value *= da && db ? ddw[c][k[c]] : (da || db) ? dw[c][k[c]] : w[c][k[c]];
                    }
                    hess(a, b) = value;
                }
            for (int a = 0; a < dim; ++a) {
                double value = dw[a][k[a]];
                for (int c = 0; c < dim; ++c)
                    if (c != a) value *= w[c][k[c]];
                grad[a] = value;
            }
            fn(node, weight, grad, hess, offset);
        }
    }
};

/// The adjoint of P2G (field_to_grid of the particles' v_p, C_p without a force matrix): accumulates into
/// x_bar, v_bar, C_bar (sized as the particles) from the node cotangents mass_bar, momentum_bar (sized
/// grid.storage_size()).
template <int dim>
void particles_to_grid_adjoint(const Grid<dim>& grid, const Particles<dim>& particles,
                               const std::vector<double>& mass_bar, const std::vector<Vec<dim>>& momentum_bar,
                               std::vector<Vec<dim>>& x_bar, std::vector<Vec<dim>>& v_bar,
                               std::vector<Mat<dim>>& C_bar) {
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(particles.size());
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < n; ++p) {  // each particle's own entries: no write conflicts
        const StencilNodeDerivatives<dim> st(grid, particles.x[p]);
        const double m = particles.mass[p];
        const Vec<dim>& v = particles.v[p];
        const Mat<dim>& C = particles.C[p];
        st.for_each([&](std::int64_t node, double w, const Vec<dim>& grad, const Mat<dim>&, const Vec<dim>& d) {
            const Vec<dim>& qb = momentum_bar[node];
            v_bar[p] += m * w * qb;
            C_bar[p] += m * w * qb * d.transpose();
            x_bar[p] += m * (grad * (mass_bar[node] + qb.dot(v + C * d)) - w * C.transpose() * qb);
        });
    }
}

/// The adjoint of G2P's velocity, affine matrix, trial F and advection from the node velocities grid_v
/// (storage-indexed) and the step's start state `start` (x_p, F_p): from the cotangents of x_p', v_p', C_p'
/// and the trial F_p', accumulates into grid_v_bar (storage-indexed), x_bar and F_bar (the start's).
template <int dim>
void grid_to_particles_adjoint(const Grid<dim>& grid, const Particles<dim>& start, const std::vector<Vec<dim>>& grid_v,
                               double dt, const std::vector<Vec<dim>>& x_out_bar,
                               const std::vector<Vec<dim>>& v_out_bar, const std::vector<Mat<dim>>& C_out_bar,
                               const std::vector<Mat<dim>>& F_trial_bar, std::vector<Vec<dim>>& grid_v_bar,
                               std::vector<Vec<dim>>& x_bar, std::vector<Mat<dim>>& F_bar) {
    const double c = 4.0 * grid.inv_dx() * grid.inv_dx();
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(start.size());
    // The particles' own cotangents in parallel; the nodes' (a scatter) after, serially, in particle order.
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < n; ++p) {
        const StencilNodeDerivatives<dim> st(grid, start.x[p]);
        Mat<dim> G = Mat<dim>::Zero();
        st.for_each([&](std::int64_t node, double, const Vec<dim>& grad, const Mat<dim>&, const Vec<dim>&) {
            G += grid_v[node] * grad.transpose();
        });
        const Vec<dim> u = v_out_bar[p] + dt * x_out_bar[p];
        const Mat<dim>& Cb = C_out_bar[p];
        const Mat<dim> Gb = dt * F_trial_bar[p] * start.F_elastic[p].transpose();
        F_bar[p] += (Mat<dim>::Identity() + dt * G).transpose() * F_trial_bar[p];
        Vec<dim> xb = x_out_bar[p];
        st.for_each([&](std::int64_t node, double w, const Vec<dim>& grad, const Mat<dim>& hess, const Vec<dim>& d) {
            const Vec<dim>& vi = grid_v[node];
            xb += grad * (u.dot(vi) + c * vi.dot(Cb * d)) - c * w * Cb.transpose() * vi + hess * (Gb.transpose() * vi);
        });
        x_bar[p] += xb;
    }
    for (std::ptrdiff_t p = 0; p < n; ++p) {
        const StencilNodes<dim> st(grid, start.x[p]);
        const Vec<dim> u = v_out_bar[p] + dt * x_out_bar[p];
        const Mat<dim>& Cb = C_out_bar[p];
        const Mat<dim> Gb = dt * F_trial_bar[p] * start.F_elastic[p].transpose();
        st.for_each([&](std::int64_t node, double w, const Vec<dim>& grad, const Vec<dim>& d) {
            grid_v_bar[node] += w * u + c * w * Cb * d + Gb * grad;
        });
    }
}

}  // namespace pnet
