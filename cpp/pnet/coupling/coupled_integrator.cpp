#include "pnet/coupling/coupled_integrator.hpp"

#include "pnet/math/clock.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>

#include "pnet/mpm/floor_friction_passes.hpp"
#include "pnet/mpm/grid_to_particles.hpp"
#include "pnet/mpm/transfer.hpp"
#include "pnet/solver/newton.hpp"

namespace pnet {

template <int dim>
CoupledImplicitIntegrator<dim>::CoupledImplicitIntegrator(
    const MpmSystem<dim>& mpm, const FemSystem<dim>& fem, ImplicitMethod method, const ImplicitOptions& options,
    const MpmOptions& mpm_options, const CouplingOptions& coupling_options,
    std::unique_ptr<ParticleEnergy<dim>> mpm_energy, std::vector<const LearnedReturnMap<dim>*> return_maps,
    const ContactPotential<dim>* fem_contact, const ContactPotential<dim>& contact, CouplingFriction friction)
    : mpm_system_(mpm),
      fem_system_(fem),
      method_(method),
      options_(options),
      mpm_options_(mpm_options),
      coupling_options_(coupling_options),
      mpm_energy_(std::move(mpm_energy)),
      return_maps_(std::move(return_maps)),
      fem_contact_(fem_contact),
      contact_(contact),
      friction_(friction),
      mesh_friction_(friction.mu, friction.eps_v),
      grid_(mpm.origin, mpm.dx, mpm.cells),
      mpm_(*mpm_energy_),
      fem_energy_(fem.materials),
      fem_(fem.mesh, fem.rest, fem_energy_),
      coupled_(mpm_, fem_, contact) {
    if (options_.time_integrator != "backward_euler")
        throw std::invalid_argument(
            "integrator.time_integrator: \"" + options_.time_integrator +
            "\" is implemented for MPM and FEM scenes; MPM-FEM coupling steps are backward Euler");
    if (!return_maps_.empty() && return_maps_.size() != mpm.materials.size())
        throw std::invalid_argument("CoupledImplicitIntegrator: one return map (or null) per object is needed");
    fem_.set_contact(fem_contact);
    if (friction_.mu > 0.0 && fem_contact) fem_.set_friction(&mesh_friction_);
}

template <int dim>
void CoupledImplicitIntegrator<dim>::solve_step(const Particles<dim>& particles, const FemState<dim>& state, double dt,
                                                const std::string& context, const BoundaryConditions& solve_boundary,
                                                bool predicted, CoupledStepStats& stats) {
    mpm_.set_floor_friction_newton(floor_friction_in_one_solve(mpm_options_, dim, mpm_energy_->tangent_hessian()));
    mpm_.begin_step(grid_, particles, dt, solve_boundary);
    const bool floor_passes = mpm_system_.boundary.coulomb_floor() && !mpm_.floor_friction_newton();
    if (floor_passes) {  // its friction, as in ImplicitIntegrator
        mpm_.set_reference(particles.F_elastic);
        mpm_.floor_friction_contacts();
    }

    const std::size_t nodes = fem_system_.mesh.nodes();
    VecX v_star_fem(dim * nodes);
    for (std::size_t i = 0; i < nodes; ++i)
        v_star_fem.template segment<dim>(dim * i) = state.v[i] + dt * fem_system_.gravity;
    fem_.begin_step(state.x, v_star_fem, dt, state.plastic_inverse, {});
    fem_.set_material_state(fem_system_.element_object, state.hardening);
    fem_.set_reference({});  // elastic: no reference
    coupled_.begin_step();
    if (friction_.mu > 0.0) {  // lagged at the start of the step
        CoupledVertices<dim>::join(state.x, particles.x, contact_x_);
        coupled_.set_friction(contact_.lagged_pairs(contact_x_), friction_.mu, friction_.eps_v);
        if (fem_contact_) mesh_friction_.lag(*fem_contact_, state.x);
    }

    NewtonOptions newton = options_.newton_options(dt, method_);
    newton.residual_mass = coupled_.residual_mass();
    const bool cholesky = coupling_options_.coupled_solver == "cholesky";
    coupled_.set_linear_solve(cholesky ? CoupledPotential<dim>::LinearSolve::Assembled
                                       : CoupledPotential<dim>::LinearSolve::BlockPreconditioned);
    newton.linear_solver = cholesky ? NewtonOptions::LinearSolver::Cholesky : NewtonOptions::LinearSolver::Pcg;

    // An intersection-free start: v* as far as CCD allows from the start positions (v = 0). The
    // fixed components (the sticky floor, massless nodes) have v* = 0, so the scaling keeps them.
    v_ = coupled_.v_star();
    if (predicted) predictor_.predict(mpm_, dt, v_);  // the grid's unknowns lead v_
    const double alpha = coupled_.max_step(VecX::Zero(v_.size()), v_);
    if (alpha < 1.0) v_ *= alpha;
    stats.ccd_limited += alpha < 1.0;

    ReferenceSolveOptions solve = options_.reference_solve_options(integrator_info(method_).references);
    solve.work_line_search = mpm_energy_->tangent_hessian();
    if (!solve.fixed_point) coupled_.set_reference(particles.F_elastic);
    // Under "auto" a failed one solve on the floor is solved again by the passes (ImplicitIntegrator).
    const bool one_solve = mpm_system_.boundary.coulomb_floor() && mpm_.floor_friction_newton();
    std::function<void(VecX&)> retry;
    if (one_solve) {
        const VecX v_start = v_;
        retry = [&, v_start](VecX& v) {
            mpm_.floor_friction_to_passes();
            mpm_.set_reference(particles.F_elastic);
            mpm_.floor_friction_contacts();
            v = v_start;
        };
    }
    stats.floor_friction_retried = solve_on_coulomb_floor<dim>(
        coupled_, v_, newton, solve, mpm_options_, context, work_, !floor_passes,
        [&](const VecX& v) {
            const VecX grid_v = v.head(coupled_.grid_size());
            mpm_.floor_friction_contacts(&grid_v);
        },
        retry, [&] { stats.hardening_clamped = std::max(stats.hardening_clamped, mpm_energy_->hardening_clamped()); },
        stats);
}

template <int dim>
CoupledStepStats CoupledImplicitIntegrator<dim>::step(Particles<dim>& particles, FemState<dim>& state, double dt,
                                                      long step_index) {
    const auto start = std::chrono::steady_clock::now();
    CoupledStepStats stats;
    stats.dt = dt;
    const std::string context = "step " + std::to_string(step_index);

    particles_to_grid<dim>(grid_, particles, nullptr);
    const double flip_alpha = flip_fraction(dt, mpm_system_.flip_relaxation_time);
    if (flip_alpha > 0.0) velocity_residual(grid_, particles, residual_);  // AFLIP (transfer.hpp)
    const auto after_p2g = std::chrono::steady_clock::now();
    BoundaryConditions solve_boundary = mpm_system_.boundary;
    solve_boundary.slip_walls = false;  // slip walls act after the solve, as in ImplicitIntegrator
    grid_.update_velocity(dt, mpm_system_.gravity, unprojected_floor(solve_boundary));
    const long network_before = mpm_energy_->network_evaluations(), points_before = mpm_energy_->network_points();
    predictor_.solve(predicts_newton_start(mpm_options_.newton_start, method_), options_.newton_tolerance_at(dt), mpm_,
                     v_, dt, stats, [&](bool from_prediction, CoupledStepStats& into) {
                         solve_step(particles, state, dt, context, solve_boundary, from_prediction, into);
                     });
    stats.network_evaluations = mpm_energy_->network_evaluations() - network_before;
    stats.network_points = mpm_energy_->network_points() - points_before;
    stats.ccd_queries = coupled_.ccd_queries();
    stats.ccd_limited += coupled_.ccd_limited();
    stats.energy_seconds = mpm_.energy_seconds();
    stats.cg_seconds = mpm_.multiply_seconds();  // the grid's Hessian-vector products (PCG)
    const auto after_solve = std::chrono::steady_clock::now();

    // MPM: the grid velocities, slip walls, G2P.
    const Eigen::Index ng = coupled_.grid_size();
    mpm_.write_velocity(v_.head(ng), grid_);
    grid_.project_velocity(mpm_system_.boundary);
    double max_speed = 0.0;
    for (Eigen::Index k = 0; k < v_.size() / dim; ++k)
        max_speed = std::max(max_speed, v_.template segment<dim>(dim * k).norm());
    stats.max_grid_speed = max_speed;
    auto return_map = [&](std::ptrdiff_t p, const Vec<dim>& Sigma, double hardening) {
        const int object = particles.object[p];
        if (!return_maps_.empty() && return_maps_[object]) return return_maps_[object]->return_map(Sigma, hardening);
        return mpm_system_.materials[object].return_map(Sigma, hardening);
    };
    grid_to_particles(grid_, particles, dt, return_map,
                      [](std::ptrdiff_t, const PolarSVD<dim>&, const ReturnResult<dim>&) {});
    if (flip_alpha > 0.0) add_velocity_residual(particles, residual_, flip_alpha);
    stats.clamped = clamp_implicit_step(particles, mpm_system_, grid_, step_index, dt, mpm_options_.advection_cfl);

    // FEM: positions and the return mapping (identity for elastic bodies).
    for (std::size_t i = 0; i < fem_system_.mesh.nodes(); ++i) {
        state.v[i] = v_.template segment<dim>(ng + dim * i);
        state.x[i] += dt * state.v[i];
        if (!state.x[i].allFinite())
            throw SimulationError(context + ": node " + std::to_string(i) + " has a non-finite position");
    }
    fem_return_mapping(fem_system_, state);

    const auto end = std::chrono::steady_clock::now();
    record_phases(stats, start, after_p2g, after_solve, end);
    return stats;
}

template <int dim>
CoupledExplicitIntegrator<dim>::CoupledExplicitIntegrator(const MpmSystem<dim>& mpm, const FemSystem<dim>& fem,
                                                          const ContactPotential<dim>* fem_contact,
                                                          const ContactPotential<dim>& contact,
                                                          CouplingFriction friction)
    : mpm_system_(mpm),
      fem_system_(fem),
      mpm_(mpm),
      fem_(fem, fem_contact),
      contact_(contact),
      friction_(friction),
      mesh_friction_(friction.mu, friction.eps_v) {
    if (friction_.mu > 0.0 && fem_contact) fem_.set_friction(&mesh_friction_, fem_contact);
}

template <int dim>
double CoupledExplicitIntegrator<dim>::cfl_time_step(const Particles<dim>& particles, double cfl) const {
    return std::min(pnet::cfl_time_step(mpm_system_, particles, cfl), fem_.cfl_time_step(cfl));
}

template <int dim>
void CoupledExplicitIntegrator<dim>::apply_friction(Grid<dim>& grid, const Particles<dim>& particles,
                                                    FemState<dim>& state, double h) const {
    const std::vector<double>& node_mass = fem_system_.rest.node_mass;
    const int nodes = static_cast<int>(state.x.size());
    for (const FrictionPair<dim>& f : friction_pairs_) {
        // The particle's velocity from its stencil and 1 / m_eff, then the facet point's (the pair's
        // other vertices, weighted -c_j).
        const StencilNodes<dim> st(grid, particles.x[f.node[0] - nodes]);
        Vec<dim> relative = Vec<dim>::Zero();
        double inverse_mass = 0.0;
        st.for_each([&](std::int64_t node, double w, const Vec<dim>&, const Vec<dim>&) {
            const typename Grid<dim>::Node& n = grid.node(node);
            if (!(n.mass > 0.0)) return;
            relative += w * n.momentum;
            inverse_mass += w * w / n.mass;
        });
        for (int j = 1; j < f.count; ++j) {
            relative += f.weight[j] * state.v[f.node[j]];
            if (node_mass[f.node[j]] > 0.0) inverse_mass += f.weight[j] * f.weight[j] / node_mass[f.node[j]];
        }
        const Eigen::Matrix<double, dim - 1, 1> u = f.tangent.transpose() * relative;
        const double speed = u.norm();
        if (speed == 0.0 || !(inverse_mass > 0.0)) continue;
        const double impulse = std::min(friction_.mu * f.normal_force * h, speed / inverse_mass);
        const Vec<dim> J = -impulse * (f.tangent * (u / speed));  // on the particle; -J on the facet
        st.for_each([&](std::int64_t node, double w, const Vec<dim>&, const Vec<dim>&) {
            typename Grid<dim>::Node& n = grid.node(node);
            if (!(n.mass > 0.0)) return;
            n.momentum += (w / n.mass) * J;
            int coord[dim];
            grid.coordinates(node, coord);
            grid.apply_boundary(coord, n.momentum, mpm_system_.boundary);
        });
        for (int j = 1; j < f.count; ++j)
            if (node_mass[f.node[j]] > 0.0) state.v[f.node[j]] += (f.weight[j] / node_mass[f.node[j]]) * J;
    }
}

template <int dim>
CoupledStepStats CoupledExplicitIntegrator<dim>::step(Particles<dim>& particles, FemState<dim>& state, double dt,
                                                      long step_index) {
    const auto start = std::chrono::steady_clock::now();
    const std::string context = "step " + std::to_string(step_index);
    // The barrier's forces at the start of the step: -kappa dB/dx of each pair's vertices (the
    // particle first, then the facet's nodes).
    const std::size_t nodes = state.x.size();
    CoupledVertices<dim>::join(state.x, particles.x, contact_x_);
    contact_.pair_terms(contact_x_, 1, false, pairs_);
    if (friction_.mu > 0.0) friction_pairs_ = contact_.lagged_pairs(contact_x_);
    const double kappa = contact_.kappa();
    node_force_.assign(nodes, Vec<dim>::Zero());
    for (const ContactPairTerms<dim>& t : pairs_)
        for (int j = 1; j < t.count; ++j) node_force_[t.node[j]] -= kappa * t.gradient.template segment<dim>(dim * j);
    x_start_ = state.x;
    fem_.set_external_force(&node_force_);
    const FemStepStats fem_stats = fem_.step(state, dt, step_index);
    dx_.resize(nodes);
    for (std::size_t i = 0; i < nodes; ++i) dx_[i] = state.x[i] - x_start_[i];

    mpm_.set_grid_hook([&](Grid<dim>& grid, double h) {
        // Barrier impulses on the particles' stencil nodes, then their boundary conditions again.
        for (const ContactPairTerms<dim>& t : pairs_) {
            const Vec<dim> f = -kappa * t.gradient.template head<dim>();
            const StencilNodes<dim> st(grid, particles.x[t.node[0] - nodes]);
            st.for_each([&](std::int64_t node, double w, const Vec<dim>&, const Vec<dim>&) {
                typename Grid<dim>::Node& n = grid.node(node);
                if (!(n.mass > 0.0)) return;
                n.momentum += (h * w / n.mass) * f;
                int coord[dim];
                grid.coordinates(node, coord);
                grid.apply_boundary(coord, n.momentum, mpm_system_.boundary);
            });
        }
        if (!friction_pairs_.empty()) apply_friction(grid, particles, state, h);
        // CCD of this step's motion: the particles near the mesh, moved by their grid velocities.
        double max_speed = 0.0;
        for (std::size_t i = 0; i < nodes; ++i) max_speed = std::max(max_speed, dx_[i].norm());
        Vec<dim> lo = Vec<dim>::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
        for (std::size_t i = 0; i < nodes; ++i) {
            lo = lo.cwiseMin(x_start_[i]).cwiseMin(state.x[i]);
            hi = hi.cwiseMax(x_start_[i]).cwiseMax(state.x[i]);
        }
        // The contact's positions: the mesh's nodes, then the particles near it.
        contact_x_.assign(x_start_.begin(), x_start_.end());
        contact_dx_.assign(dx_.begin(), dx_.end());
        double grid_speed = 0.0;
        for (int block : grid.active_blocks())
            for (int k = 0; k < Grid<dim>::kBlockNodes; ++k)
                grid_speed =
                    std::max(grid_speed,
                             grid.node(static_cast<std::int64_t>(block) * Grid<dim>::kBlockNodes + k).momentum.norm());
        const double margin = h * grid_speed + contact_.dhat();
        for (std::size_t p = 0; p < particles.size(); ++p) {
            const Vec<dim>& X = particles.x[p];
            if ((X.array() < lo.array() - margin).any() || (X.array() > hi.array() + margin).any()) continue;
            Vec<dim> v;
            Mat<dim> C, G;
            gather_velocity(grid, X, v, C, G);
            contact_x_.push_back(X);
            contact_dx_.push_back(h * v);
        }
        const double t = contact_.max_step(contact_x_, contact_dx_);
        if (t < 1.0)
            throw SimulationError(context + ": a particle would cross the FEM mesh (CCD allows " + std::to_string(t) +
                                  " of the step): the explicit step is too large for the barrier");
    });
    CoupledStepStats stats = mpm_.step(particles, dt, step_index);
    mpm_.set_grid_hook({});
    stats.substeps = fem_stats.substeps;
    stats.max_grid_speed = std::max(stats.max_grid_speed, fem_stats.max_grid_speed);
    stats.wall_seconds = seconds_since(start);
    return stats;
}

template class CoupledImplicitIntegrator<2>;
template class CoupledImplicitIntegrator<3>;
template class CoupledExplicitIntegrator<2>;
template class CoupledExplicitIntegrator<3>;

}  // namespace pnet
