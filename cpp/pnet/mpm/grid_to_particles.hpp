#pragma once
// G2P, return mapping and advection: the end of every MPM step, shared by the
// explicit and the implicit integrators (docs/methods.md). From the grid
// velocities (Grid::Node::momentum after the update or solve):
//   v_p = sum w_ip v_i,  C_p = 4/dx^2 sum w_ip v_i (x_i - x_p)^T,  grad v_p = sum v_i grad w_ip^T,
//   F^E_p <- Z((I + dt grad v_p) F^E_p, h_p),  h_p updated,  x_p += dt v_p.
// For the implicit integrators (I + dt grad v_p) F^E_p is exactly F_p(v) of
// the incremental potential at the solution.
#include <cmath>
#include <cstddef>

#include "pnet/math/svd.hpp"
#include "pnet/mpm/mpm_system.hpp"
#include "pnet/mpm/transfer.hpp"

namespace pnet {

/// `return_map(p, Sigma, h)` gives particle p's ReturnResult for the clamped
/// singular values of its trial F; `after(p, svd, Z)` sees the decomposition
/// and the projection (explicit MPM computes the next step's stress from them).
/// A non-finite trial F sets x_p to NaN, which clamp_to_grid() reports.
template <int dim, typename ReturnMapFn, typename AfterFn>
void grid_to_particles(const Grid<dim>& grid, Particles<dim>& particles, double dt, ReturnMapFn&& return_map,
                       AfterFn&& after) {
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(particles.size());
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < n; ++p) {
        Vec<dim> v;
        Mat<dim> C, grad_v;
        gather_velocity(grid, particles.x[p], v, C, grad_v);
        particles.v[p] = v;
        particles.C[p] = C;
        const Mat<dim> F_trial = (Mat<dim>::Identity() + dt * grad_v) * particles.F_elastic[p];
        if (!F_trial.allFinite()) {
            particles.x[p].setConstant(std::nan(""));
            continue;
        }
        const PolarSVD<dim> svd = clamped_svd<dim>(F_trial);
        const ReturnResult<dim> Z = return_map(p, svd.Sigma, particles.hardening[p]);
        particles.F_elastic[p] = svd.compose(Z.Sigma);
        particles.hardening[p] = Z.hardening;
        after(p, svd, Z);
        particles.x[p] += dt * v;
    }
}

/// The analytic return mapping of each particle's material.
template <int dim>
struct MaterialReturnMap {
    const MpmSystem<dim>& system;
    const Particles<dim>& particles;
    ReturnResult<dim> operator()(std::ptrdiff_t p, const Vec<dim>& Sigma, double hardening) const {
        return system.materials[particles.object[p]].return_map(Sigma, hardening);
    }
};

}  // namespace pnet
