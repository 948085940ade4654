#include "pnet/mpm/implicit_integrator.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#include "pnet/mpm/explicit_integrator.hpp"  // clamp_implicit_step
#include "pnet/mpm/floor_friction_passes.hpp"
#include "pnet/mpm/grid_to_particles.hpp"
#include "pnet/mpm/transfer.hpp"
#include "pnet/solver/newton.hpp"

namespace pnet {

template <int dim>
ImplicitIntegrator<dim>::ImplicitIntegrator(const MpmSystem<dim>& system, ImplicitMethod method,
                                            const ImplicitOptions& options, const MpmOptions& mpm_options,
                                            std::unique_ptr<ParticleEnergy<dim>> energy,
                                            std::vector<const LearnedReturnMap<dim>*> return_maps)
    : system_(system),
      method_(method),
      options_(options),
      mpm_options_(mpm_options),
      energy_(std::move(energy)),
      return_maps_(std::move(return_maps)),
      grid_(system.origin, system.dx, system.cells),
      potential_(*energy_),
      history_grid_(system.origin, system.dx, system.cells) {
    if (!return_maps_.empty() && return_maps_.size() != system.materials.size())
        throw std::invalid_argument("ImplicitIntegrator: one return map (or null) per object is needed");
}

template <int dim>
void ImplicitIntegrator<dim>::reset(const Particles<dim>&) {
    previous_v_.clear();
    rate_.clear();
    previous_C_.clear();
    rate_C_.clear();
    history_dt_ = 0.0;
    predictor_.clear();
}

template <int dim>
std::vector<Mat<dim>> ImplicitIntegrator<dim>::checkpoint_state() const {
    const std::size_t n = rate_.size();
    std::vector<Mat<dim>> state;
    if (n == 0) return state;
    state.reserve(3 * n + 1);
    state.insert(state.end(), previous_C_.begin(), previous_C_.end());
    state.insert(state.end(), rate_C_.begin(), rate_C_.end());
    for (std::size_t p = 0; p < n; ++p) {
        Mat<dim> m = Mat<dim>::Zero();
        m.col(0) = previous_v_[p];
        m.col(1) = rate_[p];
        state.push_back(m);
    }
    Mat<dim> step = Mat<dim>::Zero();
    step(0, 0) = history_dt_;
    state.push_back(step);
    return state;
}

template <int dim>
void ImplicitIntegrator<dim>::restore_checkpoint_state(std::vector<Mat<dim>> state) {
    reset({});
    if (state.empty()) return;
    // 3 n + 1 matrices; 3 n from before the last step's dt was kept (taken as the next step's then).
    if (state.size() % 3 == 1) {
        history_dt_ = state.back()(0, 0);
        state.pop_back();
        if (!(history_dt_ > 0.0) || !std::isfinite(history_dt_))
            throw std::invalid_argument("implicit integrator state: the last step's dt is " +
                                        std::to_string(history_dt_) + ", expected a number > 0 (BDF2 history)");
    }
    if (state.size() % 3 != 0)
        throw std::invalid_argument("implicit integrator state: expected 3 n + 1 matrices (BDF2 history)");
    const std::size_t n = state.size() / 3;
    previous_C_.assign(state.begin(), state.begin() + n);
    rate_C_.assign(state.begin() + n, state.begin() + 2 * n);
    for (std::size_t p = 0; p < n; ++p) {
        previous_v_.push_back(state[2 * n + p].col(0));
        rate_.push_back(state[2 * n + p].col(1));
    }
}

template <int dim>
void ImplicitIntegrator<dim>::restore_checkpoint_prediction(const std::vector<Mat<dim>>& state) {
    predictor_.restore(state, grid_.storage_size(), "implicit integrator state");
}

template <int dim>
void ImplicitIntegrator<dim>::solve_grid(const Particles<dim>& particles, double dt, long step_index,
                                         const BoundaryConditions& solve_boundary, bool predicted,
                                         MpmStepStats& stats) {
    potential_.set_floor_friction_newton(floor_friction_in_one_solve(mpm_options_, dim, energy_->tangent_hessian()));
    potential_.begin_step(grid_, particles, dt, solve_boundary);
    const bool bdf2 = options_.time_integrator == "bdf2";
    if (bdf2 && rate_.size() == particles.size()) {  // BDF2 once there is history
        field_to_grid<dim>(history_grid_, particles, rate_, rate_C_, nullptr);
        potential_.grid_field(history_grid_, history_u_);
        field_to_grid<dim>(history_grid_, particles, previous_v_, previous_C_, nullptr);
        potential_.grid_field(history_grid_, history_v_);
        // Variable steps (the advection limit, a frame's clipped last step) use BDF2's variable-step
        // coefficients; a history restored without its step takes this one's.
        const double omega = history_dt_ > 0.0 ? dt / history_dt_ : 1.0;
        potential_.use_bdf2(history_u_, history_v_, system_.gravity, omega);
    }

    const bool floor_passes = system_.boundary.coulomb_floor() && !potential_.floor_friction_newton();
    if (floor_passes) {  // its friction, lagged to the start-of-step stress
        potential_.set_reference(particles.F_elastic);
        potential_.floor_friction_contacts();
    }

    NewtonOptions newton = options_.newton_options(dt, method_);
    newton.residual_mass = potential_.residual_mass();  // mass-weighted velocity residual, m/s
    newton.block_preconditioner = options_.preconditioner == "block_jacobi";
    newton.incomplete_cholesky = options_.preconditioner == "ichol";
    if (mpm_options_.linear_solver == "cholesky") newton.linear_solver = NewtonOptions::LinearSolver::Cholesky;
    const bool multigrid = options_.preconditioner == "multigrid";
    potential_.set_multigrid(multigrid, options_.multigrid_rebuild == "hessian");
    potential_.set_assemble(mpm_options_.linear_solver == "cholesky" || newton.incomplete_cholesky);

    v_ = potential_.v_star();
    if (predicted) predictor_.predict(potential_, dt, v_);
    ReferenceSolveOptions solve = options_.reference_solve_options(integrator_info(method_).references);
    solve.work_line_search = energy_->tangent_hessian();
    // The elastic energy has no reference state: lagged passes the particles' F^E.
    if (!solve.fixed_point) potential_.set_reference(particles.F_elastic);
    // On a Coulomb floor in passes, the first pass has the contacts of the start-of-step stress (above).
    // Under "auto" a one solve that fails is solved again by the passes, from v* and the floor's
    // contacts of the start-of-step stress.
    const bool one_solve = system_.boundary.coulomb_floor() && potential_.floor_friction_newton();
    std::function<void(VecX&)> retry;
    if (one_solve)
        retry = [&](VecX& v) {
            potential_.floor_friction_to_passes();
            potential_.set_reference(particles.F_elastic);
            potential_.floor_friction_contacts();
            v = potential_.v_star();
        };
    stats.floor_friction_retried = solve_on_coulomb_floor<dim>(
        potential_, v_, newton, solve, mpm_options_, "step " + std::to_string(step_index), work_, !floor_passes,
        [&](const VecX& v) { potential_.floor_friction_contacts(&v); }, retry,
        [&] { stats.hardening_clamped = std::max(stats.hardening_clamped, energy_->hardening_clamped()); }, stats);
}

template <int dim>
MpmStepStats ImplicitIntegrator<dim>::step(Particles<dim>& particles, double dt, long step_index) {
    const auto start = std::chrono::steady_clock::now();
    MpmStepStats stats;
    stats.dt = dt;

    particles_to_grid<dim>(grid_, particles, nullptr);
    const double alpha = flip_fraction(dt, system_.flip_relaxation_time);
    if (alpha > 0.0) velocity_residual(grid_, particles, residual_);  // AFLIP (transfer.hpp)
    const auto after_p2g = std::chrono::steady_clock::now();
    // v* with the sticky floor applied; slip walls act after the solve (see the header).
    BoundaryConditions solve_boundary = system_.boundary;
    solve_boundary.slip_walls = false;
    grid_.update_velocity(dt, system_.gravity, unprojected_floor(solve_boundary));
    const long network_before = energy_->network_evaluations(), points_before = energy_->network_points();
    predictor_.solve(predicts_newton_start(mpm_options_.newton_start, method_), options_.newton_tolerance_at(dt),
                     potential_, v_, dt, stats, [&](bool from_prediction, MpmStepStats& into) {
                         solve_grid(particles, dt, step_index, solve_boundary, from_prediction, into);
                     });
    const bool bdf2 = options_.time_integrator == "bdf2";
    // G2P moves the particles and their F by the displacement rate (v itself for backward Euler).
    potential_.write_velocity(potential_.displacement_rate(v_), grid_);
    grid_.project_velocity(system_.boundary);  // slip walls, as explicit MPM
    double max_speed = 0.0;
    for (Eigen::Index k = 0; k < v_.size() / dim; ++k) max_speed = std::max(max_speed, v_.segment<dim>(dim * k).norm());
    stats.max_grid_speed = max_speed;
    stats.network_evaluations = energy_->network_evaluations() - network_before;
    stats.network_points = energy_->network_points() - points_before;
    stats.energy_seconds = potential_.energy_seconds();
    stats.cg_seconds = potential_.multiply_seconds();
    const auto after_solve = std::chrono::steady_clock::now();

    auto return_map = [&](std::ptrdiff_t p, const Vec<dim>& Sigma, double hardening) {
        const int object = particles.object[p];
        if (!return_maps_.empty() && return_maps_[object]) return return_maps_[object]->return_map(Sigma, hardening);
        return system_.materials[object].return_map(Sigma, hardening);
    };
    if (bdf2) {  // the next step's history
        history_dt_ = dt;
        previous_v_ = particles.v;
        previous_C_ = particles.C;
        start_x_ = particles.x;
    }
    grid_to_particles(grid_, particles, dt, return_map,
                      [](std::ptrdiff_t, const PolarSVD<dim>&, const ReturnResult<dim>&) {});
    if (bdf2) {
        // What G2P gathered is the displacement rate; the velocity comes from v at the start positions.
        rate_ = particles.v;
        rate_C_ = particles.C;
        potential_.write_velocity(v_, grid_);
        grid_.project_velocity(system_.boundary);
        const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(particles.size());
#pragma omp parallel for schedule(static)
        for (std::ptrdiff_t p = 0; p < n; ++p) {
            Mat<dim> grad_v;
            gather_velocity(grid_, start_x_[p], particles.v[p], particles.C[p], grad_v);
        }
    }
    if (alpha > 0.0) add_velocity_residual(particles, residual_, alpha);
    stats.clamped = clamp_implicit_step(particles, system_, grid_, step_index, dt, mpm_options_.advection_cfl);

    const auto end = std::chrono::steady_clock::now();
    record_phases(stats, start, after_p2g, after_solve, end);
    return stats;
}

template class ImplicitIntegrator<2>;
template class ImplicitIntegrator<3>;

}  // namespace pnet
