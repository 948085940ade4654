#include "pnet/fem/fem_integrator.hpp"

#include "pnet/math/clock.hpp"
#include "pnet/solver/bdf2.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace pnet {

template <int dim>
void FemSystem<dim>::make_rest() {
    std::vector<double> density(mesh.elements.size());
    for (std::size_t e = 0; e < density.size(); ++e) density[e] = materials.at(element_object[e]).description().density;
    rest = ElementRest<dim>(mesh, density);
    if (fixed_node.empty()) fixed_node.assign(mesh.nodes(), 0);
    if (prescribed_velocity.empty()) prescribed_velocity.assign(mesh.nodes(), Vec<dim>::Zero());
}

template <int dim>
double FemSystem<dim>::free_mass() const {
    double m = 0.0;
    for (std::size_t i = 0; i < mesh.nodes(); ++i)
        if (!fixed_node[i]) m += rest.node_mass[i];
    return m;
}

template <int dim>
FemState<dim> FemState<dim>::at_rest(const FemSystem<dim>& system) {
    FemState s;
    s.x = system.mesh.x;
    s.v.assign(system.mesh.nodes(), Vec<dim>::Zero());
    s.plastic_inverse.assign(system.mesh.elements.size(), Mat<dim>::Identity());
    s.hardening.resize(system.mesh.elements.size());
    for (std::size_t e = 0; e < s.hardening.size(); ++e)
        s.hardening[e] = system.materials[system.element_object[e]].description().initial_hardening;
    return s;
}

template <int dim>
void fem_return_mapping(const FemSystem<dim>& system, FemState<dim>& state) {
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(system.mesh.elements.size());
#pragma omp parallel for schedule(static) if (n >= 256)
    for (std::ptrdiff_t e = 0; e < n; ++e) {
        const int object = system.element_object[e];
        // Elastic bodies (the MPM-FEM coupling's disk) keep F^P = I: no decomposition needed.
        if (system.materials[object].description().plasticity == PlasticityModel::None) continue;
        const Mat<dim> F = deformation_gradient(system.mesh, system.rest, state.x, e);
        const Mat<dim> FE_trial = F * state.plastic_inverse[e];
        const LearnedReturnMap<dim>* learned =
            static_cast<std::size_t>(object) < system.return_maps.size() ? system.return_maps[object] : nullptr;
        const PolarSVD<dim> svd = clamped_svd<dim>(FE_trial);
        const ReturnResult<dim> Z = learned ? learned->return_map(svd.Sigma, state.hardening[e])
                                            : system.materials[object].return_map(svd.Sigma, state.hardening[e]);
        state.plastic_inverse[e] = F.inverse() * svd.compose(Z.Sigma);  // F^P = (F^E)^-1 F
        state.hardening[e] = Z.hardening;
    }
}

template <int dim>
FemImplicitIntegrator<dim>::FemImplicitIntegrator(const FemSystem<dim>& system, FemMethod method,
                                                  const ImplicitOptions& options,
                                                  std::unique_ptr<ParticleEnergy<dim>> energy,
                                                  const ContactPotential<dim>* contact,
                                                  const FemOptions& fem_options)
    : system_(system),
      method_(method),
      options_(options),
      fem_options_(fem_options),
      iterates_reference_(integrator_info(method).references ||
                          (method == FemMethod::Analytic && options.analytic_regularizer > 0.0)),
      energy_(std::move(energy)),
      potential_(system_.mesh, system_.rest, *energy_),
      elastic_energy_(system_.materials),
      predictor_(system_.mesh, system_.rest, elastic_energy_) {
    potential_.set_contact(contact);
    predictor_.set_contact(contact);
    fixed_components_.assign(dim * system.mesh.nodes(), 0);
    for (std::size_t i = 0; i < system.mesh.nodes(); ++i) {
        for (int a = 0; a < dim; ++a) fixed_components_[dim * i + a] = system.fixed_node[i];
        has_kinematic_ = has_kinematic_ || system.fixed_node[i];
    }
}

template <int dim>
void FemImplicitIntegrator<dim>::set_friction(Friction<dim>* friction, const ContactPotential<dim>* contact) {
    friction_ = friction;
    friction_contact_ = contact;
    potential_.set_friction(friction);
    predictor_.set_friction(friction);
}

// The fixed point's tolerance in the solves that only lead kinematic nodes to their targets.
constexpr double kStageTolerance = 1e-4;

template <int dim>
FemStepStats FemImplicitIntegrator<dim>::step(FemState<dim>& state, double dt, long step_index) {
    const auto start = std::chrono::steady_clock::now();
    if (friction_) friction_->lag(*friction_contact_, state.x);  // normal forces and tangents of the start
    FemStepStats stats;
    stats.dt = dt;
    const long network_before = energy_->network_evaluations(), points_before = energy_->network_points();
    const std::size_t n = system_.mesh.nodes();
    // The potential is over v with x(v) = x^ + h v (fem_integrator.hpp): backward Euler x^ = x^n, h = dt;
    // BDF2, once the state has history, x^ = ((1 + w)^2 x^n - w^2 x^{n-1}) / (1 + 2 w), h = beta dt with
    // w = dt / dt_prev and beta = (1 + w) / (1 + 2 w): (4 x^n - x^{n-1}) / 3 and 2/3 dt at constant steps.
    const bool bdf2 = options_.time_integrator == "bdf2" && state.x_previous.size() == n;
    const Bdf2Weights w = bdf2_weights(bdf2 && state.dt_previous > 0.0 ? dt / state.dt_previous : 1.0);
    const double h = bdf2 ? w.beta * dt : dt;
    std::vector<Vec<dim>> x_hat = state.x;
    VecX at_start(dim * n), v_star(dim * n);  // at_start: the v that leaves x at x^n (0 for backward Euler)
    for (std::size_t i = 0; i < n; ++i) {
        Vec<dim> v_hat = state.v[i];
        if (bdf2) {
            x_hat[i] = w.current * state.x[i] - w.previous * state.x_previous[i];
            v_hat = w.current * state.v[i] - w.previous * state.v_previous[i];
        }
        const Vec<dim> rest = bdf2 ? Vec<dim>((state.x[i] - x_hat[i]) / h) : Vec<dim>::Zero();
        at_start.template segment<dim>(dim * i) = rest;
        // A kinematic node's v puts it on its target x^n + dt v_prescribed.
        v_star.template segment<dim>(dim * i) = system_.fixed_node[i]
                                                    ? Vec<dim>(rest + (dt / h) * system_.prescribed_velocity[i])
                                                    : Vec<dim>(v_hat + h * system_.gravity);
    }
    potential_.begin_step(x_hat, v_star, h, state.plastic_inverse, fixed_components_);
    potential_.set_material_state(system_.element_object, state.hardening);

    NewtonOptions newton = options_.newton_options(dt, method_);
    newton.residual_mass = potential_.residual_mass();
    newton.linear_solver = NewtonOptions::LinearSolver::Cholesky;

    // An intersection-free start: v* as far as CCD allows from x^n (v = 0). The
    // kinematic nodes (fixed components, held where they start) then reach
    // their targets in stages below. (Starting instead from the last step's
    // velocities with the plate on its target skips the stages, 2.7x faster, but
    // lands the crushed frame in another minimum: metal_nh_frame_2d at 1e-2 ended
    // 2.36% of the diagonal from the ground truth instead of 0.52%.)
    VecX v = v_star;
    double alpha = potential_.max_step(at_start, v_star - at_start);
    if (alpha < 1.0 && has_kinematic_ && fem_options_.kinematic_start == "last_velocity") {
        // CCD usually holds v* back because gravity's increment pushes the nodes resting on the
        // ground into it, and the uniform scaling then holds the plate back too. The free nodes at
        // their last velocities (the ones under the plate already move with it) with the kinematic
        // nodes on their targets is often intersection-free: then no kinematic stage is needed.
        VecX last(v.size());
        for (std::size_t i = 0; i < n; ++i)
            last.template segment<dim>(dim * i) = system_.fixed_node[i] ? system_.prescribed_velocity[i] : state.v[i];
        last = at_start + (dt / h) * last;  // the unknowns that move x^n by dt times those velocities
        if (potential_.max_step(at_start, last - at_start) >= 1.0) {
            v = last;
            alpha = 1.0;
        }
    }
    if (alpha < 1.0) v = at_start + alpha * (v_star - at_start);

    // The elastic predictor keeps the paper's fixed point's first F0 near the solution; the Newton
    // outer iteration evaluates the energy only within a step of its reference and needs none
    // (FemOptions::fem_predictor).
    const bool predictor = iterates_reference_ && (options_.resolved_outer_iteration() == "fixed_point" || fem_options_.fem_predictor);
    if (predictor) {
        predictor_.begin_step(x_hat, v_star, h, state.plastic_inverse, fixed_components_);
        predictor_.set_material_state(system_.element_object, state.hardening);
        predictor_.set_reference({});
        try {
            const NewtonStats p =
                minimize(predictor_, v, newton, "step " + std::to_string(step_index) + ", predictor", &work_.newton);
            stats.newton_iterations += p.iterations;
            stats.predictor_iterations += p.iterations;
            stats.line_search_steps += p.line_search_steps;
        } catch (const NewtonError& e) {
            throw SimulationError(e.what());
        }
    }
    // FEM keeps exact solves from a fresh Hessian (its direct solver refactors either way).
    ReferenceSolveOptions solve = options_.reference_solve_options(iterates_reference_);
    solve.keep_hessian = false;
    solve.work_line_search = energy_->tangent_hessian();
    solve.inexact_forcing = 0.0;
    if (!solve.fixed_point) potential_.set_reference({});  // the elastic and analytic energies need no F0
    // When CCD held the kinematic nodes back, this first solve only starts the
    // stages below: its fixed point stops at their tolerance (kStageTolerance).
    ReferenceSolveOptions first_solve = solve;
    if (has_kinematic_ && alpha < 1.0) first_solve.tolerance = std::max(solve.tolerance, kStageTolerance);
    ReferenceSolveStats s;
    try {
        s = solve_with_reference<dim>(
            potential_, v, newton, first_solve, "step " + std::to_string(step_index), work_,
            [&] { stats.hardening_clamped = std::max(stats.hardening_clamped, energy_->hardening_clamped()); });
    } catch (const NewtonError& e) {
        throw SimulationError(e.what());
    }
    // Kinematic targets not reached (CCD held the start back): as IPC does, make
    // the kinematic nodes unknowns pulled to their targets by a stiff weight,
    // so that they move together with what they push (every iterate stays
    // intersection-free), stiffening it tenfold until they are within 1e-9 m
    // of their targets; then put them on the targets exactly (if CCD allows)
    // and solve once more with them fixed.
    stats.kinematic_reached = true;
    auto deviation = [&] {
        double worst = 0.0;
        for (Eigen::Index k = 0; k < v.size(); ++k)
            if (fixed_components_[k]) worst = std::max(worst, std::abs(v[k] - v_star[k]));
        return worst * h;  // m
    };
    if (has_kinematic_ && deviation() > 0.0) {
        try {
            // Measured on metal_frame_2d (plasticitynet, fixed point to 1e-6 with Anderson(5),
            // 3 frames, nodal distance to analytic at the last): a first weight of 1e5 x the
            // plate's mass needs 4-5 stages per step instead of 7 from 1e3 (2.36 against 3.71 s,
            // both 0.0002% of the diagonal from analytic; 1e7: 3 stages, no faster).
            double weight = 1e5;
            // The intermediate stages only lead the plate to its target: their fixed point on F0
            // stops at 1e-4 (at most the step's tolerance). Measured as above: 25 solves per
            // step instead of 90 with the full tolerance at every stage, 0.0003% from analytic
            // against 0.0001%; at 1e-3 the result moved to 0.025% (one solve per stage, the
            // fixed point only at the end: 0.090%, 5 frames).
            ReferenceSolveOptions stage_solve = solve;
            stage_solve.tolerance = std::max(solve.tolerance, kStageTolerance);
            for (int stage = 0; stage < fem_options_.max_kinematic_stages && deviation() > 1e-9; ++stage, weight *= 10.0) {
                potential_.soften_fixed(weight);
                NewtonOptions soft = newton;
                soft.residual_mass = potential_.residual_mass();
                s.append(solve_with_reference<dim>(
                    potential_, v, soft, stage_solve,
                    "step " + std::to_string(step_index) + ", kinematic stage " + std::to_string(stage + 1), work_));
                ++stats.kinematic_stages;
            }
            potential_.harden_fixed();
            VecX d = VecX::Zero(v.size());
            for (Eigen::Index k = 0; k < d.size(); ++k)
                if (fixed_components_[k]) d[k] = v_star[k] - v[k];
            const double t = potential_.max_step(v, d);
            v += t * d;
            stats.kinematic_reached = t >= 1.0;
            s.append(solve_with_reference<dim>(potential_, v, newton, solve,
                                               "step " + std::to_string(step_index) + ", kinematic targets", work_));
        } catch (const NewtonError& e) {
            throw SimulationError(e.what());
        }
    }
    record_solve(s, stats);
    stats.ccd_queries = potential_.ccd_queries() + predictor_.ccd_queries();
    stats.ccd_limited = potential_.ccd_limited() + predictor_.ccd_limited();
    const auto after_solve = std::chrono::steady_clock::now();

    double max_speed = 0.0;
    state.x_previous = state.x;  // the history of the next step (BDF2)
    state.v_previous = state.v;
    state.dt_previous = dt;
    for (std::size_t i = 0; i < n; ++i) {
        state.v[i] = v.template segment<dim>(dim * i);
        state.x[i] = x_hat[i] + h * state.v[i];
        if (!state.x[i].allFinite())
            throw SimulationError("step " + std::to_string(step_index) + ": node " + std::to_string(i) +
                                  " has a non-finite position");
        max_speed = std::max(max_speed, state.v[i].norm());
    }
    stats.max_grid_speed = max_speed;
    stats.network_evaluations = energy_->network_evaluations() - network_before;
    stats.network_points = energy_->network_points() - points_before;
    fem_return_mapping(system_, state);
    stats.grid_seconds = std::chrono::duration<double>(after_solve - start).count();
    stats.g2p_seconds = seconds_since(after_solve);
    stats.wall_seconds = seconds_since(start);
    return stats;
}

constexpr int kMaxSubsteps = 100000;
constexpr double kLookAhead = 5.0;  // explicit substeps: CCD on this multiple of the motion
// The element bound 2 c / height underestimates the highest frequency of lumped linear
// elements (and of crushed, stiffened ones): substeps are at most this fraction of 1 / omega_e.
constexpr double kElementSafety = 0.5;

template <int dim>
FemStepStats FemExplicitIntegrator<dim>::step(FemState<dim>& state, double dt, long step_index) {
    const auto start = std::chrono::steady_clock::now();
    FemStepStats stats;
    stats.dt = dt;
    stats.substeps = 0;
    if (free_mass_.empty()) {
        free_mass_ = system_.rest.node_mass;
        inverse_mass_.assign(free_mass_.size(), 0.0);
        for (std::size_t i = 0; i < free_mass_.size(); ++i) {
            if (system_.fixed_node[i]) free_mass_[i] = 0.0;
            if (free_mass_[i] > 0.0) inverse_mass_[i] = 1.0 / free_mass_[i];
        }
    }
    // Each substep is at most 1 / sqrt(omega_e^2 + omega_c^2): the elements' highest frequency
    // in their current shape (once per step) with the stiffest contact pair's (per substep).
    // At rest and out of contact this is the CFL step at cfl 0.5 (1.7e-5 s on metal_frame_2d).
    const double omega_e = element_frequency(state.x) / kElementSafety;
    if (!std::isfinite(omega_e))
        throw SimulationError("step " + std::to_string(step_index) + ": an element is inverted");
    double remaining = dt;
    while (remaining > 1e-12 * dt) {
        double omega2 = omega_e * omega_e;
        if (contact_) {
            const double h_c = contact_->stable_time_step(state.x, free_mass_);
            if (std::isfinite(h_c)) omega2 += 1.0 / (h_c * h_c);
        }
        const double h = omega2 > 0.0 ? std::min(remaining, 1.0 / std::sqrt(omega2)) : remaining;
        remaining -= substep(state, h, step_index, stats);
        // A barrier too soft for the impact lets a gap close towards 0 (the stable substep
        // shrinks with it): stop instead of crawling.
        if (++stats.substeps > kMaxSubsteps)
            throw SimulationError("step " + std::to_string(step_index) + ": contact needed more than " +
                                  std::to_string(kMaxSubsteps) +
                                  " explicit substeps (a gap is closing to 0: "
                                  "the barrier stiffness kappa is too low for this impact)");
    }
    stats.wall_seconds = seconds_since(start);
    return stats;
}

template <int dim>
double FemExplicitIntegrator<dim>::substep(FemState<dim>& state, double h, long step_index, FemStepStats& stats) {
    const Mesh<dim>& mesh = system_.mesh;
    const std::size_t n = mesh.nodes();
    // The elements' stresses in parallel (an SVD each), gathered onto the nodes in element
    // order (the same sums for any thread count).
    const std::ptrdiff_t elements = static_cast<std::ptrdiff_t>(mesh.elements.size());
    stress_.resize(mesh.elements.size());
#pragma omp parallel for schedule(static) if (elements >= 256)
    for (std::ptrdiff_t e = 0; e < elements; ++e) {
        const Mat<dim> FE = deformation_gradient(mesh, system_.rest, state.x, e) * state.plastic_inverse[e];
        const Mat<dim> P = system_.materials[system_.element_object[e]].elasticity().P(FE);
        stress_[e] = system_.rest.volume[e] * P * state.plastic_inverse[e].transpose();
    }
    VecX force = VecX::Zero(dim * n);
    for (std::size_t e = 0; e < mesh.elements.size(); ++e)
        for (int a = 0; a <= dim; ++a)
            force.template segment<dim>(dim * mesh.elements[e][a]) -= stress_[e] * system_.rest.grad[e][a];
    if (contact_) {
        VecX barrier = VecX::Zero(dim * n);
        contact_->add_gradient(state.x, 1.0, barrier);
        force -= barrier;
    }
    if (external_force_)
        for (std::size_t i = 0; i < n; ++i) force.template segment<dim>(dim * i) += (*external_force_)[i];
    if (friction_) friction_->lag(*friction_contact_, state.x);  // normal forces and tangents of the start
    std::vector<Vec<dim>> v(n), dx(n), ahead(n);
    // The step is shortened until it closes no gap by more than about a fifth (CCD on 5 times
    // the motion): the barrier's stiffness, ~1/d^2, then grows at most 1.5-fold before the
    // next substep's stability bound sees it, keeping omega h below 1.25 (symplectic Euler
    // is stable to 2). Closing half the gap let omega h reach 2 and pumped energy into the
    // contact: metal_nh_frame_2d at 2e-5 s had a node driven at 3.6 m/s to within 1e-15 m of
    // the plate (round-off) by frame 8.
    for (int attempt = 0;; ++attempt) {
        double max_speed = 0.0;
        for (std::size_t i = 0; i < n; ++i) {
            v[i] = system_.fixed_node[i]
                       ? system_.prescribed_velocity[i]
                       : Vec<dim>(state.v[i] + h * (force.template segment<dim>(dim * i) / system_.rest.node_mass[i] +
                                                    system_.gravity));
            if (!v[i].allFinite())
                throw SimulationError("step " + std::to_string(step_index) + ": node " + std::to_string(i) +
                                      " has a non-finite velocity (the simulation blew up; try a smaller dt)");
        }
        if (friction_) {
            VecX flat(dim * n);
            for (std::size_t i = 0; i < n; ++i) flat.template segment<dim>(dim * i) = v[i];
            friction_->apply_impulses(flat, h, inverse_mass_);
            for (std::size_t i = 0; i < n; ++i) v[i] = flat.template segment<dim>(dim * i);
        }
        for (std::size_t i = 0; i < n; ++i) {
            dx[i] = h * v[i];
            ahead[i] = kLookAhead * dx[i];
            max_speed = std::max(max_speed, v[i].norm());
        }
        stats.max_grid_speed = std::max(stats.max_grid_speed, max_speed);
        if (!contact_) break;
        const double t = contact_->max_step(state.x, ahead);
        ++stats.ccd_queries;
        if (t >= 1.0) break;
        ++stats.ccd_limited;
        if (attempt == 60 || !(h > 0.0))
            throw SimulationError("step " + std::to_string(step_index) +
                                  ": the explicit step cannot avoid "
                                  "intersecting the mesh (CCD allows " +
                                  std::to_string(t) + " of it)");
        h *= std::min(0.5, t);
    }
    for (std::size_t i = 0; i < n; ++i) {
        state.v[i] = v[i];
        state.x[i] += dx[i];
    }
    fem_return_mapping(system_, state);
    return h;
}

template <int dim>
double FemExplicitIntegrator<dim>::element_frequency(const std::vector<Vec<dim>>& x) const {
    // The highest element frequency 2 c / height of the deformed elements, with c the material's
    // dilatational wave speed raised by sqrt(V0 / V) under compression (the neo-Hookean
    // lambda log J term stiffens as 1/J), height = d V / (longest edge)^(d-1). Elements of
    // kinematic nodes only (the plate) move rigidly and do not count.
    const Mesh<dim>& mesh = system_.mesh;
    const std::ptrdiff_t elements = static_cast<std::ptrdiff_t>(mesh.elements.size());
    double omega = 0.0;
#pragma omp parallel for schedule(static) reduction(max : omega) if (elements >= 256)
    for (std::ptrdiff_t e = 0; e < elements; ++e) {
        const auto& el = mesh.elements[e];
        bool rigid = true;
        for (int a = 0; a <= dim; ++a) rigid = rigid && system_.fixed_node[el[a]];
        if (rigid) continue;
        const MaterialDescription& m = system_.materials[system_.element_object[e]].description();
        const double c = std::sqrt((m.elastic.lambda() + 2.0 * m.elastic.mu()) / m.density);
        double longest = 0.0;
        for (int a = 0; a <= dim; ++a)
            for (int b = 0; b < a; ++b) longest = std::max(longest, (x[el[a]] - x[el[b]]).norm());
        const double volume = mesh.signed_volume(x, e);
        if (!(volume > 0.0)) {  // inverted: no stable step
            omega = std::numeric_limits<double>::infinity();
            continue;
        }
        const double height = dim * volume / std::pow(longest, dim - 1);
        const double stiffening = std::sqrt(std::max(1.0, system_.rest.volume[e] / volume));
        omega = std::max(omega, 2.0 * c * stiffening / height);
    }
    return omega;
}

template <int dim>
double FemExplicitIntegrator<dim>::cfl_time_step(double cfl) const {
    // cfl h / c of the rest shape: cfl 2 / omega.
    return cfl * 2.0 / element_frequency(system_.mesh.x);
}

template struct FemSystem<2>;
template struct FemSystem<3>;
template struct FemState<2>;
template struct FemState<3>;
template class FemImplicitIntegrator<2>;
template class FemImplicitIntegrator<3>;
template class FemExplicitIntegrator<2>;
template class FemExplicitIntegrator<3>;
template void fem_return_mapping<2>(const FemSystem<2>&, FemState<2>&);
template void fem_return_mapping<3>(const FemSystem<3>&, FemState<3>&);

}  // namespace pnet
