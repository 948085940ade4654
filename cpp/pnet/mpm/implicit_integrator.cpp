#include "pnet/mpm/implicit_integrator.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#include "pnet/mpm/explicit_integrator.hpp"  // clamp_to_grid
#include "pnet/mpm/grid_to_particles.hpp"
#include "pnet/mpm/transfer.hpp"
#include "pnet/solver/newton.hpp"

namespace pnet {

namespace {

template <typename T>
T read_option(const nlohmann::json& block, const char* key, T value, const std::string& context, T lowest,
              const char* expected) {
    const auto it = block.find(key);
    if (it == block.end()) return value;
    const bool ok = std::is_integral_v<T> ? it->is_number_integer() : it->is_number();
    if (ok) {
        const T v = it->get<T>();
        if (std::isfinite(static_cast<double>(v)) && v >= lowest) return v;
    }
    throw std::invalid_argument(context + ": integrator." + key + ": expected " + expected + ", got " + it->dump());
}

}  // namespace

ImplicitOptions ImplicitOptions::from_json(const nlohmann::json& block, const std::string& context) {
    ImplicitOptions o;
    if (!block.is_object()) return o;
    o.newton_tolerance =
        read_option(block, "newton_tolerance", o.newton_tolerance, context, 1e-300, "a positive number (m/s)");
    o.max_newton_iterations =
        read_option(block, "max_newton_iterations", o.max_newton_iterations, context, 1, "an integer >= 1");
    o.max_cg_iterations = read_option(block, "max_cg_iterations", o.max_cg_iterations, context, 1, "an integer >= 1");
    o.cg_tolerance = read_option(block, "cg_tolerance", o.cg_tolerance, context, 1e-300, "a positive number");
    if (o.cg_tolerance >= 1.0)
        throw std::invalid_argument(context + ": integrator.cg_tolerance: expected a number in (0, 1), got " +
                                    std::to_string(o.cg_tolerance));
    o.fixed_point_tolerance =
        read_option(block, "fixed_point_tolerance", o.fixed_point_tolerance, context, 0.0, "a number >= 0");
    o.max_fixed_point_iterations =
        read_option(block, "max_fixed_point_iterations", o.max_fixed_point_iterations, context, 1, "an integer >= 1");
    o.fixed_point_anderson =
        read_option(block, "fixed_point_anderson", o.fixed_point_anderson, context, 0, "an integer >= 0");
    o.fixed_point_inexact =
        read_option(block, "fixed_point_inexact", o.fixed_point_inexact, context, 0.0, "a number in [0, 1)");
    if (o.fixed_point_inexact >= 1.0)
        throw std::invalid_argument(context + ": integrator.fixed_point_inexact: expected a number in [0, 1), got " +
                                    nlohmann::json(o.fixed_point_inexact).dump());
    o.regularizer_weight =
        read_option(block, "regularizer_weight", o.regularizer_weight, context, 0.0, "a number >= 0");
    o.analytic_regularizer =
        read_option(block, "analytic_regularizer", o.analytic_regularizer, context, 0.0, "a number >= 0");
    o.lazy_hessian = read_option(block, "lazy_hessian", o.lazy_hessian, context, 0.0, "a number in [0, 1)");
    if (o.lazy_hessian >= 1.0)
        throw std::invalid_argument(context + ": integrator.lazy_hessian: expected a number in [0, 1), got " +
                                    nlohmann::json(o.lazy_hessian).dump());
    o.max_kinematic_stages =
        read_option(block, "max_kinematic_stages", o.max_kinematic_stages, context, 0, "an integer >= 0");
    if (const auto it = block.find("fail_on_unconverged"); it != block.end()) {
        if (!it->is_boolean())
            throw std::invalid_argument(context + ": integrator.fail_on_unconverged: expected true or false, got " +
                                        it->dump());
        o.fail_on_unconverged = it->get<bool>();
    }
    if (const auto it = block.find("fixed_point_keep_hessian"); it != block.end()) {
        if (!it->is_boolean())
            throw std::invalid_argument(
                context + ": integrator.fixed_point_keep_hessian: expected true or false, got " + it->dump());
        o.fixed_point_keep_hessian = it->get<bool>();
    }
    if (const auto it = block.find("fem_predictor"); it != block.end()) {
        if (!it->is_boolean())
            throw std::invalid_argument(context + ": integrator.fem_predictor: expected true or false, got " +
                                        it->dump());
        o.fem_predictor = it->get<bool>();
    }
    if (const auto it = block.find("learned_return_map"); it != block.end()) {
        if (!it->is_boolean())
            throw std::invalid_argument(context + ": integrator.learned_return_map: expected true or false, got " +
                                        it->dump());
        o.learned_return_map = it->get<bool>();
    }
    if (const auto it = block.find("linear_solver"); it != block.end()) {
        if (!it->is_string() || (*it != "pcg" && *it != "cholesky"))
            throw std::invalid_argument(context + ": integrator.linear_solver: expected \"pcg\" or \"cholesky\", got " +
                                        it->dump());
        o.linear_solver = it->get<std::string>();
    }
    if (const auto it = block.find("coupled_solver"); it != block.end()) {
        if (!it->is_string() || (*it != "block" && *it != "cholesky"))
            throw std::invalid_argument(
                context + ": integrator.coupled_solver: expected \"block\" or \"cholesky\", got " + it->dump());
        o.coupled_solver = it->get<std::string>();
    }
    if (const auto it = block.find("kinematic_start"); it != block.end()) {
        if (!it->is_string() || (*it != "scaled" && *it != "last_velocity"))
            throw std::invalid_argument(context + ": integrator.kinematic_start: expected \"scaled\" or "
                                        "\"last_velocity\", got " + it->dump());
        o.kinematic_start = it->get<std::string>();
    }
    if (const auto it = block.find("hessian"); it != block.end()) {
        if (!it->is_string() || (*it != "auto" && *it != "network" && *it != "tangent"))
            throw std::invalid_argument(
                context + ": integrator.hessian: expected \"auto\", \"network\" or \"tangent\", got " + it->dump());
        o.hessian = it->get<std::string>();
    }
    if (const auto it = block.find("outer_iteration"); it != block.end()) {
        if (!it->is_string() || (*it != "newton" && *it != "fixed_point"))
            throw std::invalid_argument(
                context + ": integrator.outer_iteration: expected \"newton\" or \"fixed_point\", got " + it->dump());
        o.outer_iteration = it->get<std::string>();
    }
    if (const auto it = block.find("time_integrator"); it != block.end()) {
        if (!it->is_string() || (*it != "backward_euler" && *it != "bdf2"))
            throw std::invalid_argument(context + ": integrator.time_integrator: expected \"backward_euler\" or "
                                        "\"bdf2\", got " + it->dump());
        o.time_integrator = it->get<std::string>();
    }
    if (const auto it = block.find("preconditioner"); it != block.end()) {
        if (!it->is_string() || (*it != "jacobi" && *it != "block_jacobi" && *it != "ichol"))
            throw std::invalid_argument(
                context + ": integrator.preconditioner: expected \"jacobi\", \"block_jacobi\" or \"ichol\", got " +
                it->dump());
        o.preconditioner = it->get<std::string>();
    }
    return o;
}

NewtonOptions ImplicitOptions::newton_options() const {
    NewtonOptions newton;
    newton.tolerance = newton_tolerance;
    newton.max_iterations = max_newton_iterations;
    newton.max_cg_iterations = max_cg_iterations;
    newton.cg_tolerance = cg_tolerance;
    newton.lazy_hessian = lazy_hessian;
    return newton;
}

ReferenceSolveOptions ImplicitOptions::reference_solve_options(bool fixed_point) const {
    ReferenceSolveOptions solve;
    solve.fixed_point = fixed_point;
    solve.outer = outer_iteration == "fixed_point" ? OuterIteration::FixedPoint : OuterIteration::Newton;
    solve.max_solves = max_fixed_point_iterations;
    solve.tolerance = fixed_point_tolerance;
    solve.anderson_depth = fixed_point_anderson;
    solve.keep_hessian = fixed_point_keep_hessian;
    solve.inexact_forcing = fixed_point_inexact;
    solve.fail_on_unconverged = fail_on_unconverged;
    return solve;
}

nlohmann::json ImplicitOptions::to_json() const {
    return {{"newton_tolerance", newton_tolerance},
            {"max_newton_iterations", max_newton_iterations},
            {"max_cg_iterations", max_cg_iterations},
            {"cg_tolerance", cg_tolerance},
            {"outer_iteration", outer_iteration},
            {"time_integrator", time_integrator},
            {"fixed_point_tolerance", fixed_point_tolerance},
            {"max_fixed_point_iterations", max_fixed_point_iterations},
            {"fixed_point_anderson", fixed_point_anderson},
            {"fixed_point_keep_hessian", fixed_point_keep_hessian},
            {"fixed_point_inexact", fixed_point_inexact},
            {"regularizer_weight", regularizer_weight},
            {"analytic_regularizer", analytic_regularizer},
            {"hessian", hessian},
            {"preconditioner", preconditioner},
            {"linear_solver", linear_solver},
            {"coupled_solver", coupled_solver},
            {"lazy_hessian", lazy_hessian},
            {"fail_on_unconverged", fail_on_unconverged},
            {"max_kinematic_stages", max_kinematic_stages},
            {"kinematic_start", kinematic_start},
            {"fem_predictor", fem_predictor},
            {"learned_return_map", learned_return_map}};
}

template <int dim>
ImplicitIntegrator<dim>::ImplicitIntegrator(const MpmSystem<dim>& system, ImplicitMethod method,
                                            const ImplicitOptions& options, std::unique_ptr<ParticleEnergy<dim>> energy,
                                            std::vector<const LearnedReturnMap<dim>*> return_maps)
    : system_(system),
      method_(method),
      options_(options),
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
}

template <int dim>
std::vector<Mat<dim>> ImplicitIntegrator<dim>::checkpoint_state() const {
    const std::size_t n = rate_.size();
    std::vector<Mat<dim>> state;
    if (n == 0) return state;
    state.reserve(3 * n);
    state.insert(state.end(), previous_C_.begin(), previous_C_.end());
    state.insert(state.end(), rate_C_.begin(), rate_C_.end());
    for (std::size_t p = 0; p < n; ++p) {
        Mat<dim> m = Mat<dim>::Zero();
        m.col(0) = previous_v_[p];
        m.col(1) = rate_[p];
        state.push_back(m);
    }
    return state;
}

template <int dim>
void ImplicitIntegrator<dim>::restore_checkpoint_state(std::vector<Mat<dim>> state) {
    reset({});
    if (state.empty()) return;
    if (state.size() % 3 != 0) throw std::invalid_argument("implicit integrator state: expected 3 n matrices (BDF2 history)");
    const std::size_t n = state.size() / 3;
    previous_C_.assign(state.begin(), state.begin() + n);
    rate_C_.assign(state.begin() + n, state.begin() + 2 * n);
    for (std::size_t p = 0; p < n; ++p) {
        previous_v_.push_back(state[2 * n + p].col(0));
        rate_.push_back(state[2 * n + p].col(1));
    }
}

template <int dim>
StepStats ImplicitIntegrator<dim>::step(Particles<dim>& particles, double dt, long step_index) {
    const auto start = std::chrono::steady_clock::now();
    StepStats stats;
    stats.dt = dt;

    particles_to_grid<dim>(grid_, particles, nullptr);
    const auto after_p2g = std::chrono::steady_clock::now();
    // v* with the sticky floor applied; slip walls act after the solve (see the header).
    BoundaryConditions solve_boundary = system_.boundary;
    solve_boundary.slip_walls = false;
    grid_.update_velocity(dt, system_.gravity, solve_boundary);
    potential_.begin_step(grid_, particles, dt, solve_boundary);
    const bool bdf2 = options_.time_integrator == "bdf2";
    if (bdf2 && rate_.size() == particles.size()) {  // BDF2 once there is history
        field_to_grid<dim>(history_grid_, particles, rate_, rate_C_, nullptr);
        potential_.grid_field(history_grid_, history_u_);
        field_to_grid<dim>(history_grid_, particles, previous_v_, previous_C_, nullptr);
        potential_.grid_field(history_grid_, history_v_);
        potential_.use_bdf2(history_u_, history_v_, system_.gravity);
    }

    NewtonOptions newton = options_.newton_options();
    newton.residual_mass = potential_.residual_mass();  // mass-weighted velocity residual, m/s
    newton.block_preconditioner = options_.preconditioner == "block_jacobi";
    newton.incomplete_cholesky = options_.preconditioner == "ichol";
    if (options_.linear_solver == "cholesky") newton.linear_solver = NewtonOptions::LinearSolver::Cholesky;
    potential_.set_assemble(options_.linear_solver == "cholesky" || newton.incomplete_cholesky);

    v_ = potential_.v_star();
    ReferenceSolveOptions solve = options_.reference_solve_options(method_ == ImplicitMethod::PlasticityNet);
    solve.work_line_search = energy_->tangent_hessian();
    // The elastic energy has no reference state: lagged passes the particles' F^E.
    if (!solve.fixed_point) potential_.set_reference(particles.F_elastic);
    ReferenceSolveStats s;
    try {
        s = solve_with_reference<dim>(potential_, v_, newton, solve, "step " + std::to_string(step_index), work_, [&] {
            stats.hardening_clamped = std::max(stats.hardening_clamped, energy_->hardening_clamped());
        });
    } catch (const NewtonError& e) {
        throw SimulationError(e.what());
    }
    record_solve(s, stats);
    // G2P moves the particles and their F by the displacement rate (v itself for backward Euler).
    potential_.write_velocity(potential_.displacement_rate(v_), grid_);
    grid_.project_velocity(system_.boundary);  // slip walls, as explicit MPM
    double max_speed = 0.0;
    for (Eigen::Index k = 0; k < v_.size() / dim; ++k) max_speed = std::max(max_speed, v_.segment<dim>(dim * k).norm());
    stats.max_grid_speed = max_speed;
    stats.energy_seconds = potential_.energy_seconds();
    stats.cg_seconds = potential_.multiply_seconds();
    const auto after_solve = std::chrono::steady_clock::now();

    auto return_map = [&](std::ptrdiff_t p, const Vec<dim>& Sigma, double hardening) {
        const int object = particles.object[p];
        if (!return_maps_.empty() && return_maps_[object]) return return_maps_[object]->return_map(Sigma, hardening);
        return system_.materials[object].return_map(Sigma, hardening);
    };
    if (bdf2) {  // the next step's history
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
    // Large steps legitimately move particles several cells; a quarter of the
    // domain in one step only happens after a blow-up.
    double extent = 1e300;
    for (int a = 0; a < dim; ++a) extent = std::min(extent, system_.cells[a] * system_.dx);
    stats.clamped = clamp_to_grid(particles, grid_, step_index, 0.25 * extent / dt);

    const auto end = std::chrono::steady_clock::now();
    stats.p2g_seconds = std::chrono::duration<double>(after_p2g - start).count();
    stats.grid_seconds = std::chrono::duration<double>(after_solve - after_p2g).count();
    stats.g2p_seconds = std::chrono::duration<double>(end - after_solve).count();
    stats.wall_seconds = std::chrono::duration<double>(end - start).count();
    return stats;
}

template class ImplicitIntegrator<2>;
template class ImplicitIntegrator<3>;

}  // namespace pnet
