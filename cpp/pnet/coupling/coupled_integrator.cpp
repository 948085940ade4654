#include "pnet/coupling/coupled_integrator.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#include "pnet/mpm/grid_to_particles.hpp"
#include "pnet/mpm/transfer.hpp"
#include "pnet/solver/newton.hpp"

namespace pnet {

namespace {

double seconds_since(std::chrono::steady_clock::time_point start) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

CoupledImplicitIntegrator2d::CoupledImplicitIntegrator2d(const MpmSystem<2>& mpm, const FemSystem<2>& fem,
                                                         ImplicitMethod method, const ImplicitOptions& options,
                                                         std::unique_ptr<ParticleEnergy<2>> mpm_energy,
                                                         std::vector<const LearnedReturnMap<2>*> return_maps,
                                                         const ContactPotential<2>* fem_contact,
                                                         const ParticleContact2d& contact)
    : mpm_system_(mpm),
      fem_system_(fem),
      method_(method),
      options_(options),
      mpm_energy_(std::move(mpm_energy)),
      return_maps_(std::move(return_maps)),
      grid_(mpm.origin, mpm.dx, mpm.cells),
      mpm_(*mpm_energy_),
      fem_energy_(fem.materials),
      fem_(fem.mesh, fem.rest, fem_energy_),
      coupled_(mpm_, fem_, contact) {
    if (options_.time_integrator != "backward_euler")
        throw std::invalid_argument("integrator.time_integrator: \"" + options_.time_integrator +
                                    "\" is implemented for MPM and FEM scenes; MPM-FEM coupling steps are backward Euler");
    if (!return_maps_.empty() && return_maps_.size() != mpm.materials.size())
        throw std::invalid_argument("CoupledImplicitIntegrator2d: one return map (or null) per object is needed");
    fem_.set_contact(fem_contact);
}

StepStats CoupledImplicitIntegrator2d::step(Particles<2>& particles, FemState<2>& state, double dt, long step_index) {
    const auto start = std::chrono::steady_clock::now();
    StepStats stats;
    stats.dt = dt;
    const std::string context = "step " + std::to_string(step_index);

    particles_to_grid<2>(grid_, particles, nullptr);
    const auto after_p2g = std::chrono::steady_clock::now();
    BoundaryConditions solve_boundary = mpm_system_.boundary;
    solve_boundary.slip_walls = false;  // slip walls act after the solve, as in ImplicitIntegrator
    grid_.update_velocity(dt, mpm_system_.gravity, solve_boundary);
    mpm_.begin_step(grid_, particles, dt, solve_boundary);

    const std::size_t nodes = fem_system_.mesh.nodes();
    VecX v_star_fem(2 * nodes);
    for (std::size_t i = 0; i < nodes; ++i) v_star_fem.segment<2>(2 * i) = state.v[i] + dt * fem_system_.gravity;
    fem_.begin_step(state.x, v_star_fem, dt, state.plastic_inverse, {});
    fem_.set_material_state(fem_system_.element_object, state.hardening);
    fem_.set_reference({});  // elastic: no reference
    coupled_.begin_step();

    NewtonOptions newton = options_.newton_options();
    newton.residual_mass = coupled_.residual_mass();
    const bool cholesky = options_.coupled_solver == "cholesky";
    coupled_.set_linear_solve(cholesky ? CoupledPotential2d::LinearSolve::Assembled
                                       : CoupledPotential2d::LinearSolve::BlockPreconditioned);
    newton.linear_solver = cholesky ? NewtonOptions::LinearSolver::Cholesky : NewtonOptions::LinearSolver::Pcg;

    // An intersection-free start: v* as far as CCD allows from the start positions (v = 0). The
    // fixed components (the sticky floor, massless nodes) have v* = 0, so the scaling keeps them.
    v_ = coupled_.v_star();
    const double alpha = coupled_.max_step(VecX::Zero(v_.size()), v_);
    if (alpha < 1.0) v_ *= alpha;

    ReferenceSolveOptions solve = options_.reference_solve_options(method_ == ImplicitMethod::PlasticityNet);
    solve.work_line_search = mpm_energy_->tangent_hessian();
    if (!solve.fixed_point) coupled_.set_reference(particles.F_elastic);
    ReferenceSolveStats s;
    try {
        s = solve_with_reference<2>(coupled_, v_, newton, solve, context, work_, [&] {
            stats.hardening_clamped = std::max(stats.hardening_clamped, mpm_energy_->hardening_clamped());
        });
    } catch (const NewtonError& e) {
        throw SimulationError(e.what());
    }
    record_solve(s, stats);
    stats.ccd_queries = coupled_.ccd_queries();
    stats.ccd_limited = coupled_.ccd_limited() + (alpha < 1.0);
    stats.energy_seconds = mpm_.energy_seconds();
    stats.cg_seconds = mpm_.multiply_seconds();  // the grid's Hessian-vector products (PCG)
    const auto after_solve = std::chrono::steady_clock::now();

    // MPM: the grid velocities, slip walls, G2P.
    const Eigen::Index ng = coupled_.grid_size();
    mpm_.write_velocity(v_.head(ng), grid_);
    grid_.project_velocity(mpm_system_.boundary);
    double max_speed = 0.0;
    for (Eigen::Index k = 0; k < v_.size() / 2; ++k) max_speed = std::max(max_speed, v_.segment<2>(2 * k).norm());
    stats.max_grid_speed = max_speed;
    auto return_map = [&](std::ptrdiff_t p, const Vec<2>& Sigma, double hardening) {
        const int object = particles.object[p];
        if (!return_maps_.empty() && return_maps_[object]) return return_maps_[object]->return_map(Sigma, hardening);
        return mpm_system_.materials[object].return_map(Sigma, hardening);
    };
    grid_to_particles(grid_, particles, dt, return_map,
                      [](std::ptrdiff_t, const PolarSVD<2>&, const ReturnResult<2>&) {});
    double extent = 1e300;
    for (int a = 0; a < 2; ++a) extent = std::min(extent, mpm_system_.cells[a] * mpm_system_.dx);
    stats.clamped = clamp_to_grid(particles, grid_, step_index, 0.25 * extent / dt);

    // FEM: positions and the return mapping (identity for elastic bodies).
    for (std::size_t i = 0; i < nodes; ++i) {
        state.v[i] = v_.segment<2>(ng + 2 * i);
        state.x[i] += dt * state.v[i];
        if (!state.x[i].allFinite())
            throw SimulationError(context + ": node " + std::to_string(i) + " has a non-finite position");
    }
    fem_return_mapping(fem_system_, state);

    const auto end = std::chrono::steady_clock::now();
    stats.p2g_seconds = std::chrono::duration<double>(after_p2g - start).count();
    stats.grid_seconds = std::chrono::duration<double>(after_solve - after_p2g).count();
    stats.g2p_seconds = std::chrono::duration<double>(end - after_solve).count();
    stats.wall_seconds = std::chrono::duration<double>(end - start).count();
    return stats;
}

CoupledExplicitIntegrator2d::CoupledExplicitIntegrator2d(const MpmSystem<2>& mpm, const FemSystem<2>& fem,
                                                         const ContactPotential<2>* fem_contact,
                                                         const ParticleContact2d& contact)
    : mpm_system_(mpm), mpm_(mpm), fem_(fem, fem_contact), contact_(contact) {}

double CoupledExplicitIntegrator2d::cfl_time_step(const Particles<2>& particles, double cfl) const {
    return std::min(pnet::cfl_time_step(mpm_system_, particles, cfl), fem_.cfl_time_step(cfl));
}

StepStats CoupledExplicitIntegrator2d::step(Particles<2>& particles, FemState<2>& state, double dt, long step_index) {
    const auto start = std::chrono::steady_clock::now();
    const std::string context = "step " + std::to_string(step_index);
    // The barrier's forces at the start of the step.
    contact_.gradient(particles.x, state.x, pairs_, gradients_);
    const std::size_t nodes = state.x.size();
    node_force_.assign(nodes, Vec<2>::Zero());
    for (std::size_t k = 0; k < pairs_.size(); ++k) {
        const auto& edge = contact_.edges()[pairs_[k].edge];
        node_force_[edge[0]] -= gradients_[k].segment<2>(2);
        node_force_[edge[1]] -= gradients_[k].segment<2>(4);
    }
    x_start_ = state.x;
    fem_.set_external_force(&node_force_);
    const StepStats fem_stats = fem_.step(state, dt, step_index);
    dx_.resize(nodes);
    for (std::size_t i = 0; i < nodes; ++i) dx_[i] = state.x[i] - x_start_[i];

    mpm_.set_grid_hook([&](Grid<2>& grid, double h) {
        // Barrier impulses on the particles' stencil nodes, then their boundary conditions again.
        for (std::size_t k = 0; k < pairs_.size(); ++k) {
            const Vec<2> f = -gradients_[k].head<2>();
            const StencilNodes<2> st(grid, particles.x[pairs_[k].particle]);
            st.for_each([&](std::int64_t node, double w, const Vec<2>&, const Vec<2>&) {
                Grid<2>::Node& n = grid.node(node);
                if (!(n.mass > 0.0)) return;
                n.momentum += (h * w / n.mass) * f;
                int coord[2];
                grid.coordinates(node, coord);
                grid.apply_boundary(coord, n.momentum, mpm_system_.boundary);
            });
        }
        // CCD of this step's motion: the particles near the mesh, moved by their grid velocities.
        double max_speed = 0.0;
        for (std::size_t i = 0; i < nodes; ++i) max_speed = std::max(max_speed, dx_[i].norm());
        Vec<2> lo = Vec<2>::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
        for (std::size_t i = 0; i < nodes; ++i) {
            lo = lo.cwiseMin(x_start_[i]).cwiseMin(state.x[i]);
            hi = hi.cwiseMax(x_start_[i]).cwiseMax(state.x[i]);
        }
        near_X_.clear();
        near_dX_.clear();
        double grid_speed = 0.0;
        for (int block : grid.active_blocks())
            for (int k = 0; k < Grid<2>::kBlockNodes; ++k)
                grid_speed = std::max(
                    grid_speed, grid.node(static_cast<std::int64_t>(block) * Grid<2>::kBlockNodes + k).momentum.norm());
        const double margin = h * grid_speed + contact_.dhat();
        for (std::size_t p = 0; p < particles.size(); ++p) {
            const Vec<2>& X = particles.x[p];
            if ((X.array() < lo.array() - margin).any() || (X.array() > hi.array() + margin).any()) continue;
            Vec<2> v;
            Mat<2> C, G;
            gather_velocity(grid, X, v, C, G);
            near_X_.push_back(X);
            near_dX_.push_back(h * v);
        }
        const double t = contact_.max_step(near_X_, near_dX_, x_start_, dx_);
        if (t < 1.0)
            throw SimulationError(context + ": a particle would cross the FEM mesh (CCD allows " + std::to_string(t) +
                                  " of the step): the explicit step is too large for the barrier");
    });
    StepStats stats = mpm_.step(particles, dt, step_index);
    mpm_.set_grid_hook({});
    stats.substeps = fem_stats.substeps;
    stats.max_grid_speed = std::max(stats.max_grid_speed, fem_stats.max_grid_speed);
    stats.wall_seconds = seconds_since(start);
    return stats;
}

}  // namespace pnet
