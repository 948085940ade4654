#include "pnet/mpm/explicit_integrator.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>

#include "pnet/math/svd.hpp"
#include "pnet/mpm/grid_to_particles.hpp"
#include "pnet/mpm/transfer.hpp"

namespace pnet {

template <int dim>
double MpmSystem<dim>::max_wave_speed() const {
    double c = 0.0;
    for (std::size_t k = 0; k < materials.size(); ++k) {
        const ElasticParams& e = materials[k].description().elastic;
        c = std::max(c, std::sqrt((e.lambda() + 2.0 * e.mu()) / density[k]));
    }
    return c;
}

template <int dim>
ExplicitIntegrator<dim>::ExplicitIntegrator(const MpmSystem<dim>& system)
    : system_(system), grid_(system.origin, system.dx, system.cells) {}

template <int dim>
double cfl_time_step(const MpmSystem<dim>& system, const Particles<dim>& particles, double cfl) {
    double v_max = 0.0;
    for (const Vec<dim>& v : particles.v) v_max = std::max(v_max, v.norm());
    return cfl * system.dx / (system.max_wave_speed() + v_max);
}

template <int dim>
void ExplicitIntegrator<dim>::compute_stress(const Particles<dim>& particles) {
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(particles.size());
    scaled_stress_.resize(n);
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < n; ++p) {
        const Material<dim>& material = system_.materials[particles.object[p]];
        const PolarSVD<dim> svd = clamped_svd<dim>(particles.F_elastic[p]);
        const Vec<dim> tau = material.elasticity().tau(svd.Sigma);
        scaled_stress_[p] = particles.rest_volume[p] * (svd.U * tau.asDiagonal() * svd.U.transpose());
    }
    stress_valid_ = true;
}

template <int dim>
std::size_t clamp_to_grid(Particles<dim>& particles, const Grid<dim>& grid, long step_index, double speed_limit) {
    std::size_t clamped = 0;
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(particles.size());
    std::ptrdiff_t bad = -1;
#pragma omp parallel for schedule(static) reduction(+ : clamped)
    for (std::ptrdiff_t p = 0; p < n; ++p) {
        Vec<dim>& x = particles.x[p];
        if (!x.allFinite() || !particles.v[p].allFinite() || particles.v[p].norm() > speed_limit) {
#pragma omp critical
            bad = bad < 0 ? p : std::min(bad, p);
            continue;
        }
        bool moved = false;
        for (int a = 0; a < dim; ++a) {
            const double lo = grid.lower_limit(a), hi = grid.upper_limit(a);
            if (x[a] < lo) {
                x[a] = lo;
                moved = true;
            } else if (x[a] > hi) {
                x[a] = hi;
                moved = true;
            }
        }
        clamped += moved;
    }
    if (bad >= 0)
        throw SimulationError("step " + std::to_string(step_index) + ": particle " + std::to_string(bad) +
                              " has a non-finite position or velocity, or a speed above " + std::to_string(speed_limit) +
                              " m/s (the simulation blew up; try a smaller dt)");
    return clamped;
}

template <int dim>
std::size_t clamp_implicit_step(Particles<dim>& particles, const MpmSystem<dim>& system, const Grid<dim>& grid,
                                long step_index, double dt, double advection_cfl) {
    double extent = 1e300;
    for (int a = 0; a < dim; ++a) extent = std::min(extent, system.cells[a] * system.dx);
    try {
        return clamp_to_grid(particles, grid, step_index, 0.25 * extent / dt);
    } catch (const SimulationError& e) {
        if (advection_cfl > 0.0) throw;
        throw SimulationError(std::string(e.what()) +
                              "; an implicit step whose particles cross a cell or more also stops converging, "
                              "and this run has the advection limit off: the default, --advection-cfl 0.2 "
                              "(integrator.advection_cfl), cuts the steps so that no particle crosses more than "
                              "0.2 cells (docs/solver.md, \"The advection limit\")");
    }
}

template <int dim>
MpmStepStats ExplicitIntegrator<dim>::step(Particles<dim>& particles, double dt, long step_index) {
    const auto start = std::chrono::steady_clock::now();
    MpmStepStats stats;
    stats.dt = dt;
    if (!stress_valid_ || scaled_stress_.size() != particles.size()) compute_stress(particles);
    force_matrix_.resize(particles.size());
    const double alpha = flip_fraction(dt, system_.flip_relaxation_time);
    if (alpha > 0.0) {  // AFLIP: the residual from a force-free P2G first
        particles_to_grid<dim>(grid_, particles, nullptr);
        velocity_residual(grid_, particles, residual_);
    }

    // P2G (race-free by block colouring, see grid.hpp) with the stress force.
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(particles.size());
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < n; ++p) force_matrix_[p] = -dt * scaled_stress_[p];
    particles_to_grid(grid_, particles, &force_matrix_);
    const auto after_p2g = std::chrono::steady_clock::now();

    stats.max_grid_speed = grid_.update_velocity(dt, system_.gravity, system_.boundary);
    if (grid_hook_) grid_hook_(grid_, dt);
    const auto after_grid = std::chrono::steady_clock::now();

    // G2P, return mapping, advection; the projection's SVD gives the next step's stress.
    grid_to_particles(grid_, particles, dt, MaterialReturnMap<dim>{system_, particles},
                      [&](std::ptrdiff_t p, const PolarSVD<dim>& svd, const ReturnResult<dim>& Z) {
                          const Material<dim>& material = system_.materials[particles.object[p]];
                          const Vec<dim> tau = material.elasticity().tau_of_strain(Z.hencky_strain());
                          scaled_stress_[p] = particles.rest_volume[p] * (svd.U * tau.asDiagonal() * svd.U.transpose());
                      });
    if (alpha > 0.0) add_velocity_residual(particles, residual_, alpha);
    stats.clamped = clamp_to_grid(particles, grid_, step_index, system_.dx / dt);
    const auto end = std::chrono::steady_clock::now();
    record_phases(stats, start, after_p2g, after_grid, end);
    return stats;
}

template struct MpmSystem<2>;
template struct MpmSystem<3>;
template class ExplicitIntegrator<2>;
template class ExplicitIntegrator<3>;
template <int dim>
double advection_time_step(const MpmSystem<dim>& system, const Particles<dim>& particles, double dt, double cfl) {
    if (!(cfl > 0.0)) return dt;
    double v_max = 0.0;
    for (const Vec<dim>& v : particles.v) v_max = std::max(v_max, v.norm());
    return v_max > 0.0 ? std::min(dt, cfl * system.dx / v_max) : dt;
}

template double advection_time_step<2>(const MpmSystem<2>&, const Particles<2>&, double, double);
template double advection_time_step<3>(const MpmSystem<3>&, const Particles<3>&, double, double);
template double cfl_time_step<2>(const MpmSystem<2>&, const Particles<2>&, double);
template double cfl_time_step<3>(const MpmSystem<3>&, const Particles<3>&, double);
template std::size_t clamp_to_grid<2>(Particles<2>&, const Grid<2>&, long, double);
template std::size_t clamp_to_grid<3>(Particles<3>&, const Grid<3>&, long, double);
template std::size_t clamp_implicit_step<2>(Particles<2>&, const MpmSystem<2>&, const Grid<2>&, long, double, double);
template std::size_t clamp_implicit_step<3>(Particles<3>&, const MpmSystem<3>&, const Grid<3>&, long, double, double);

}  // namespace pnet
