#include "pnet/mpm/mpm_adjoint.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include <Eigen/SparseLU>

#include "pnet/contact/friction.hpp"
#include "pnet/energy/particle_energy.hpp"
#include "pnet/material/return_map_derivative.hpp"
#include "pnet/mpm/transfer.hpp"
#include "pnet/mpm/transfer_adjoint.hpp"
#include "pnet/solver/method_energy.hpp"
#include "pnet/solver/pcg.hpp"
#include "pnet/solver/rollout_checkpoints.hpp"

namespace pnet {

namespace {

/// Grid::apply_boundary's projection of node i's velocity v after the solve (v projected in place) and its
/// Jacobian, its active set held (one-sided where a component is exactly at 0): on a Coulomb floor's layer a
/// node still moving into it (a normal the solve left free) loses its normal velocity and mu |v_y| of its
/// tangential speed (all of it where that is more); then the slip walls zero their wall-ward components.
template <int dim>
Mat<dim> project_after_solve(const Grid<dim>& grid, std::int64_t i, const BoundaryConditions& bc, bool coulomb,
                             Vec<dim>& v) {
    Mat<dim> A = Mat<dim>::Identity();
    int coord[dim];
    grid.coordinates(i, coord);
    if (coulomb && bc.in_floor(coord[1]) && v[1] < 0.0) {
        // v_t' = v_t (1 - mu p / |v_t|) with p = -v_y where |v_t| > mu p, else 0; v_y' = 0.
        const double p = -v[1], mu = bc.floor_friction;
        Vec<dim> t = v;
        t[1] = 0.0;
        const double length = t.norm();
        A.setZero();
        if (length > mu * p) {
            const Vec<dim> n = t / length;
            for (int a = 0; a < dim; ++a) {
                if (a == 1) continue;
                for (int b = 0; b < dim; ++b) {
                    if (b == 1) continue;
                    const double delta = a == b ? 1.0 : 0.0;
                    A(a, b) = delta - mu * p / length * (delta - n[a] * n[b]);
                }
                A(a, 1) = mu * n[a];  // d v_t' / d v_y = mu t / |t|
            }
        }
        coulomb_projection<dim>(v, p, mu);
    }
    if (bc.slip_walls)
        for (int a = 0; a < dim; ++a) {
            const bool low = coord[a] < Grid<dim>::kWallNodes && v[a] < 0.0;
            const bool high = coord[a] >= grid.nodes(a) - Grid<dim>::kWallNodes && v[a] > 0.0;
            if (low || high) {
                v[a] = 0.0;
                A.row(a).setZero();
            }
        }
    return A;
}

/// The potential's Coulomb floor's contacts (FloorFrictionForm::begin_newton's nodes) at the solution v, with
/// the particles' stress P there; contact_of: unknown node -> its contact (-1: none).
template <int dim>
std::vector<FloorContact<dim>> floor_contacts(const IncrementalPotential<dim>& potential, const Particles<dim>& start,
                                              const std::vector<Mat<dim>>& P, const VecX& v, double dt,
                                              std::vector<int>& contact_of) {
    using Contact = FloorContact<dim>;
    const FloorFrictionForm<dim>& form = potential.floor_friction_form();
    std::vector<Contact> contacts;
    contact_of.assign(potential.nodes(), -1);
    for (const auto& c : form.newton_contacts()) {
        contact_of[c.dof] = static_cast<int>(contacts.size());
        contacts.push_back({c.dof, -c.normal_momentum});
    }
    for (std::size_t p = 0; p < start.size(); ++p) {  // the stress term's rows (k, y), in particle order
        const int* dofs = potential.stencil_dofs(p);
        const Vec<dim>* grads = potential.stencil_gradients(p);
        for (int s = 0; s < IncrementalPotential<dim>::kStencil; ++s)
            if (contact_of[dofs[s]] >= 0)
                contacts[contact_of[dofs[s]]].impulse +=
                    start.rest_volume[p] * dt * (P[p] * start.F_elastic[p].transpose() * grads[s])[1];
    }
    const double mu = form.mu(), eps = form.eps_v();
    for (Contact& c : contacts) {
        if (!(c.impulse > 0.0)) continue;
        typename Contact::Tangent u;
        for (int t = 0; t < dim - 1; ++t) u[t] = v[dim * c.dof + (t == 0 ? 0 : 2)];
        const double slip = u.norm(), f1_over_s = friction_f1_over_x(slip, eps);
        c.c = mu * f1_over_s * u;
        // d(f1(s) u / s)/du = f1'(s) u u^T / s^2 + f1(s) / s (I - u u^T / s^2) (f1'(0) = f1(s) / s at 0).
        using TangentMatrix = typename Contact::TangentMatrix;
        const TangentMatrix I = TangentMatrix::Identity();
        const TangentMatrix uu = slip > 0.0 ? TangentMatrix(u * u.transpose() / (slip * slip)) : TangentMatrix::Zero();
        c.dc = mu * c.impulse * (friction_f1_derivative(slip, eps) * uu + f1_over_s * (I - uu));
    }
    return contacts;
}

VecX solve_transposed(const SparseMatrix& transpose, const VecX& rhs, int step, PcgResult& solve) {
    Eigen::SparseLU<SparseMatrix> lu;
    lu.compute(transpose);
    if (lu.info() != Eigen::Success)
        throw std::runtime_error("MpmAdjoint: step " + std::to_string(step) + ": the step's Jacobian is singular (" +
                                 lu.lastErrorMessage() + ")");
    VecX lambda = lu.solve(rhs);
    solve.iterations = 1;
    solve.relative_residual = (transpose * lambda - rhs).norm() / std::max(rhs.norm(), 1e-300);
    solve.converged = solve.relative_residual <= 1e-9;
    return lambda;
}

}  // namespace

template <int dim>
void require_adjoint_materials(const MpmSystem<dim>& system, const std::string& who) {
    for (std::size_t k = 0; k < system.materials.size(); ++k) {
        const MaterialDescription& m = system.materials[k].description();
        const std::string field = who + ": materials[" + std::to_string(k) + "].";
        if (m.plasticity == PlasticityModel::CamClay && m.cam_clay.variant != CamClayVariant::Exact)
            throw std::invalid_argument(field + "plasticity.variant '" + to_string(m.cam_clay.variant) +
                                        "': the adjoint differentiates Cam-Clay's exact variant (J kept)");
        if (m.plasticity == PlasticityModel::VonMises && m.elasticity != ElasticityModel::StvkHencky)
            throw std::invalid_argument(field + "elasticity '" + to_string(m.elasticity) +
                                        "': the adjoint differentiates von Mises with stvk_hencky (its closed-form "
                                        "return mapping)");
    }
}

template void require_adjoint_materials<2>(const MpmSystem<2>&, const std::string&);
template void require_adjoint_materials<3>(const MpmSystem<3>&, const std::string&);

template <int dim>
MpmAdjoint<dim>::MpmAdjoint(const MpmSystem<dim>& system, const ImplicitOptions& options, const MpmOptions& mpm_options,
                            Method method)
    : system_(system), options_(options), mpm_options_(mpm_options), method_(method) {
    if (method != Method::Lagged && method != Method::ReturnMap)
        throw std::invalid_argument(std::string("MpmAdjoint: integrator '") + to_string(method) +
                                    "': the adjoint is of lagged and return_map (plasticitynet converges to "
                                    "return_map's step)");
    require_adjoint_materials<dim>(system, "MpmAdjoint");
    // A Coulomb floor's friction in the one solve's residual (FloorFrictionForm::begin_newton), without the
    // passes a failed one solve falls back to under "auto": the gradient is that of R(v) = 0 with the friction.
    // That solve is return_map's (under its work line search; lagged solves the floor in passes, whose fixed
    // point after a few passes is not R = 0).
    if (system.boundary.coulomb_floor() && system.boundary.sticky_floor_cells > 0) {
        if (method != Method::ReturnMap)
            throw std::invalid_argument(std::string("MpmAdjoint: boundary.floor_friction with integrator '") +
                                        to_string(method) +
                                        "': a Coulomb floor's adjoint is return_map's (its friction within the one "
                                        "solve; lagged solves the floor in passes)");
        mpm_options_.floor_friction_solve = "newton";
    }
    // Each step from v*: the backward pass replays steps from stored particle states (their start), and a
    // start predicted from the step before would make a replayed step differ from the forward one.
    mpm_options_.newton_start = "v_star";
    if (options.time_integrator != "backward_euler")
        throw std::invalid_argument("MpmAdjoint: time_integrator '" + options.time_integrator +
                                    "': backward Euler only");
}

template <int dim>
void MpmAdjoint<dim>::set_parameter_fields(const std::vector<std::string>& fields) {
    fields_ = perturbed_fields<dim>(system_.materials, fields, "MpmAdjoint");
}

template <int dim>
std::unique_ptr<ImplicitIntegrator<dim>> MpmAdjoint<dim>::make_integrator() const {
    return std::make_unique<ImplicitIntegrator<dim>>(system_, method_, options_, mpm_options_,
                                                     model_free_energy<dim>(method_, options_, system_.materials));
}

template <int dim>
Particles<dim> MpmAdjoint<dim>::forward(const Particles<dim>& start, double dt, int steps,
                                        const std::function<void(int, const Particles<dim>&)>& observe,
                                        int checkpoint_every) {
    if (!(dt > 0.0) || steps < 0 || checkpoint_every < 0)
        throw std::invalid_argument("MpmAdjoint::forward: dt > 0, steps >= 0 and checkpoint_every >= 0 are needed");
    const int every = checkpoint_spacing(steps, checkpoint_every);
    checkpoints_.clear();
    unconverged_ = 0;
    const std::unique_ptr<ImplicitIntegrator<dim>> made = make_integrator();
    ImplicitIntegrator<dim>& integrator = *made;
    integrator.reset(start);
    Particles<dim> particles = start;
    checkpoints_[0] = particles;
    if (observe) observe(0, particles);
    for (int k = 0; k < steps; ++k) {
        if (!integrator.step(particles, dt, k).converged) ++unconverged_;
        if ((k + 1) % every == 0 || k + 1 == steps) checkpoints_[k + 1] = particles;
        if (observe) observe(k + 1, particles);
    }
    dt_ = dt;
    steps_ = steps;
    last_size_ = particles.size();
    peak_states_ = checkpoints_.size();
    return particles;
}

template <int dim>
void MpmAdjoint<dim>::replay(int first, int last, std::vector<Particles<dim>>& starts,
                             std::vector<VecX>& solutions) const {
    const std::unique_ptr<ImplicitIntegrator<dim>> made = make_integrator();
    ImplicitIntegrator<dim>& integrator = *made;
    Particles<dim> particles = checkpoints_.at(first);
    integrator.reset(particles);
    starts.clear();
    solutions.clear();
    for (int k = first; k < last; ++k) {
        starts.push_back(particles);
        integrator.step(particles, dt_, k);
        solutions.push_back(integrator.solution());
    }
}

template <int dim>
MpmRolloutGradient<dim> MpmAdjoint<dim>::backward(const std::vector<Vec<dim>>& x_bar,
                                                  const std::vector<Vec<dim>>& v_bar) const {
    if (steps_ < 0) throw std::logic_error("MpmAdjoint::backward: no forward pass");
    std::vector<std::vector<Vec<dim>>> xs(steps_ + 1), vs(steps_ + 1);
    xs.back() = x_bar;
    vs.back() = v_bar;
    return backward(xs, vs);
}

template <int dim>
MpmRolloutGradient<dim> MpmAdjoint<dim>::backward(const std::vector<std::vector<Vec<dim>>>& x_bar,
                                                  const std::vector<std::vector<Vec<dim>>>& v_bar) const {
    if (steps_ < 0) throw std::logic_error("MpmAdjoint::backward: no forward pass");
    const std::size_t states = static_cast<std::size_t>(steps_) + 1, n = last_size_;
    if (x_bar.size() != states || v_bar.size() != states)
        throw std::invalid_argument("MpmAdjoint::backward: one entry per state (" + std::to_string(states) + ")");
    for (std::size_t k = 0; k < states; ++k)
        if ((!x_bar[k].empty() && x_bar[k].size() != n) || (!v_bar[k].empty() && v_bar[k].size() != n))
            throw std::invalid_argument("MpmAdjoint::backward: state " + std::to_string(k) +
                                        ": dL/dx and dL/dv need one entry per particle (" + std::to_string(n) + ")");
    MpmRolloutGradient<dim> g;
    g.fields.assign(fields_.size(), 0.0);
    g.x.assign(n, Vec<dim>::Zero());
    g.v.assign(n, Vec<dim>::Zero());
    g.C.assign(n, Mat<dim>::Zero());
    g.F.assign(n, Mat<dim>::Zero());
    g.hardening.assign(n, 0.0);
    auto add = [&](std::size_t k) {
        for (std::size_t p = 0; p < n; ++p) {
            if (!x_bar[k].empty()) g.x[p] += x_bar[k][p];
            if (!v_bar[k].empty()) g.v[p] += v_bar[k][p];
        }
    };
    add(states - 1);
    // Segment by segment between checkpoints, the last first; each recomputed from its checkpoint.
    std::vector<int> marks;
    for (const auto& [step, state] : checkpoints_) marks.push_back(step);
    std::vector<Particles<dim>> starts;
    std::vector<VecX> solutions;
    for (std::size_t m = marks.size() - 1; m-- > 0;) {
        const int first = marks[m], last = marks[m + 1];
        replay(first, last, starts, solutions);
        peak_states_ = std::max(peak_states_, checkpoints_.size() + starts.size());
        for (int k = last - 1; k >= first; --k) {
            step_adjoint(starts[k - first], solutions[k - first], k, g);
            add(static_cast<std::size_t>(k));
        }
    }
    return g;
}

template <int dim>
MpmStepAdjoint<dim>::MpmStepAdjoint(const MpmSystem<dim>& system, Method method, const Particles<dim>& start,
                                    const VecX& v, double dt, const std::vector<PerturbedMaterials<dim>>* fields)
    : system_(system),
      method_(method),
      start_(start),
      v_(v),
      dt_(dt),
      n_(start.size()),
      grid_(system.origin, system.dx, system.cells),
      energy_(system.materials),
      potential_(energy_),
      fields_(fields ? *fields : no_fields_) {
    // The step's grid and potential, as the integrator set them up (the same deterministic P2G, so the
    // same unknowns as its solution's).
    particles_to_grid<dim>(grid_, start, nullptr);
    storage_ = grid_.storage_size();
    mass_.resize(storage_);
    momentum_.resize(storage_);
    for (std::int64_t i = 0; i < storage_; ++i) {
        mass_[i] = grid_.node(i).mass;
        momentum_[i] = grid_.node(i).momentum;
    }
    BoundaryConditions solve_boundary = system.boundary;
    solve_boundary.slip_walls = false;
    grid_.update_velocity(dt, system.gravity, unprojected_floor(solve_boundary));
    coulomb_ = solve_boundary.coulomb_floor() && solve_boundary.sticky_floor_cells > 0;
    // v* as update_velocity left it: on a Coulomb floor's held normal rows, the velocity the floor stops (the
    // potential's v* is 0 there), which the floor's impulse J_k = (the stress term)_k,y - m_k v*_k,y reads.
    node_v_star_.resize(storage_);
    for (std::int64_t i = 0; i < storage_; ++i) node_v_star_[i] = grid_.node(i).momentum;
    potential_.set_floor_friction_newton(coulomb_);
    potential_.begin_step(grid_, start, dt, solve_boundary);
    potential_.set_reference(start.F_elastic);
    potential_.set_project_psd(false);
    if (v.size() != potential_.size()) throw std::logic_error("MpmAdjoint: the step's unknowns changed on replay");

    // Storage index -> unknown node (-1: a node no particle's stencil reaches).
    dof_.assign(storage_, -1);
    for (std::size_t k = 0; k < potential_.nodes(); ++k) dof_[potential_.dof_node(k)] = static_cast<int>(k);

    // The grid velocity G2P read: the solution projected as Grid::apply_boundary does after the solve, and
    // the projection's Jacobian A_i.
    grid_v_.assign(storage_, Vec<dim>::Zero());
    projection_.assign(storage_, Mat<dim>::Identity());
    for (std::int64_t i = 0; i < storage_; ++i) {
        if (dof_[i] < 0) continue;
        grid_v_[i] = v.template segment<dim>(dim * dof_[i]);
        projection_[i] = project_after_solve<dim>(grid_, i, system.boundary, coulomb_, grid_v_[i]);
    }

    // The stress and its exact (unprojected, undamped) tangent at the solution: the elastic ones for
    // lagged, the return-mapped Ptilde and its consistent tangent with its skew part for return_map.
    // return_map's stress depends on the start's hardening and the plasticity parameters too.
    const std::size_t n = n_;
    F_.resize(n);
    P_.resize(n);
    dP_dfield_.assign(fields_.size(), std::vector<Mat<dim>>(n, Mat<dim>::Zero()));
    dP_dh_.assign(n, Mat<dim>::Zero());
    dP_dparameter_.resize(n);
    T_.resize(n);
    potential_.deformation(v, F_);
    const bool return_map = method == Method::ReturnMap;
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < static_cast<std::ptrdiff_t>(n); ++p) {
        const Material<dim>& material = system.materials[start.object[p]];
        const PolarSVD<dim> svd = clamped_svd<dim>(F_[p]);  // one decomposition for P and its tangent
        dP_dparameter_[p].fill(Mat<dim>::Zero());
        if (return_map) {
            const double h = start.hardening[p];
            P_[p] = material.elastoplastic_stress(svd, h);
            // The exact Jacobian where written (the stencil averages two branches near a boundary), and Ptilde
            // in h and the plasticity parameters.
            T_[p] = return_map_tangent<dim>(material, svd, h);
            if (material.description().plasticity != PlasticityModel::None) {
                const ReturnMapDerivative<dim> d = return_map_derivative<dim>(material, svd, h, false);
                dP_dh_[p] = d.dP_dh;
                dP_dparameter_[p] = d.dP_dparameter;
            }
        } else {
            const Elasticity<dim>& elasticity = material.elasticity();
            P_[p] = svd.compose(elasticity.tau(svd.Sigma).cwiseQuotient(svd.Sigma));
            T_[p] = elasticity.dPdF(svd, false);
        }
        // The solve's stress in each asked field, by central differences of the material.
        for (std::size_t f = 0; f < fields_.size(); ++f) {
            const PerturbedMaterials<dim>& field = fields_[f];
            const int object = start.object[p];
            if (!field.has[object]) continue;
            auto stress = [&](const Material<dim>& m) -> Mat<dim> {
                if (return_map) return m.elastoplastic_stress(svd, start.hardening[p]);
                return svd.compose(m.elasticity().tau(svd.Sigma).cwiseQuotient(svd.Sigma));
            };
            dP_dfield_[f][p] = (stress(field.plus[object]) - stress(field.minus[object])) / (2.0 * field.delta);
        }
    }
    // The Coulomb floor's contacts (the nodes whose normal velocity the solve holds): the friction on node k's
    // tangential velocity u_k is c_k(u_k) J_k(v), c = mu f1(|u|) u / |u|, with J_k the floor's normal impulse,
    // the residual's row (k, y) with v*_k,y as update_velocity left it. So J = dR/dv has J_k dc/du in the slip
    // and c_k (row (k, y) of the stress term's Jacobian) on the tangential rows. J^T lambda = vb is solved with
    // the held normal rows as unknowns too, mu_k = c_k . lambda_k,t: then lambda's row (k, y) carries the
    // impulse's cotangent to v*_k,y, the node's mass and the particles like any row's.
    if (coulomb_) contacts_ = floor_contacts<dim>(potential_, start, P_, v, dt, contact_of_);
}

template <int dim>
bool MpmStepAdjoint<dim>::symmetric() const {
    // Symmetric where the solve's stress is elastic (lagged, or no plasticity) and no floor's friction is in
    // it.
    return !coulomb_ && (method_ != Method::ReturnMap ||
                         std::all_of(system_.materials.begin(), system_.materials.end(), [](const Material<dim>& m) {
                             return m.description().plasticity == PlasticityModel::None;
                         }));
}

template <int dim>
VecX MpmStepAdjoint<dim>::output_adjoint(const MpmRolloutGradient<dim>& g) {
    const double dt = dt_;
    const std::size_t n = n_;
    const Particles<dim>& start = start_;
    // G2P: the cotangents of the output (x, v, C, F: g) to the grid velocities and the start's x, F.
    std::vector<Vec<dim>> grid_v_bar(storage_, Vec<dim>::Zero());
    x_bar_.assign(n, Vec<dim>::Zero());
    F_bar_.assign(n, Mat<dim>::Zero());
    // G2P's return mapping F^E' = Z(F_trial, h), h' = h'(F_trial, h): the trial F's cotangent dF^E/dF_trial^T Fb'
    // + dh'/dF_trial hb', the start hardening's dF^E/dh : Fb' + dh'/dh hb', and each plasticity parameter's
    // through dF^E/dparameter and dh'/dparameter (F_trial from the projected velocities G2P read).
    std::vector<Mat<dim>> F_trial_bar = g.F;
    h_bar_ = g.hardening;
    std::vector<Parameters> mapped_parameter_bar(n, Parameters{});
    field_bar_.assign(fields_.size(), std::vector<double>(n, 0.0));
    // AFLIP: v_p' = (G2P's v_p) + alpha r_p, r_p = v_p - sum_i w_ip u_i with u_i = q_i / m_i of P2G's grid
    // (transfer.hpp): r_p's cotangent alpha vb_p', taken before G2P's adjoint reads vb'.
    alpha_ = flip_fraction(dt, system_.flip_relaxation_time);
    residual_bar_.clear();
    if (alpha_ > 0.0) {
        residual_bar_.resize(n);
        for (std::size_t p = 0; p < n; ++p) residual_bar_[p] = alpha_ * g.v[p];
    }
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < static_cast<std::ptrdiff_t>(n); ++p) {
        const Material<dim>& material = system_.materials[start.object[p]];
        if (material.description().plasticity == PlasticityModel::None) continue;
        const StencilNodes<dim> st(grid_, start.x[p]);
        Mat<dim> G = Mat<dim>::Zero();
        st.for_each([&](std::int64_t node, double, const Vec<dim>& grad, const Vec<dim>&) {
            G += grid_v_[node] * grad.transpose();
        });
        const Mat<dim> F_trial = (Mat<dim>::Identity() + dt * G) * start.F_elastic[p];
        const ReturnMapDerivative<dim> d =
            return_map_derivative<dim>(material, clamped_svd<dim>(F_trial), start.hardening[p]);
        F_trial_bar[p] = unflatten<dim>(d.dFE_dF.transpose() * flatten<dim>(g.F[p])) + g.hardening[p] * d.dh_dF;
        h_bar_[p] = g.F[p].cwiseProduct(d.dFE_dh).sum() + d.dh_dh * g.hardening[p];
        for (int q = 0; q < kPlasticityParameters; ++q)
            mapped_parameter_bar[p][q] =
                g.F[p].cwiseProduct(d.dFE_dparameter[q]).sum() + d.dh_dparameter[q] * g.hardening[p];
        // The asked fields' share, by central differences of the return mapping (F^E = U diag(Z) V^T, h').
        const PolarSVD<dim> svd = clamped_svd<dim>(F_trial);
        for (std::size_t f = 0; f < fields_.size(); ++f) {
            const PerturbedMaterials<dim>& field = fields_[f];
            if (!field.has[start.object[p]]) continue;
            const ReturnResult<dim> plus = field.plus[start.object[p]].return_map(svd.Sigma, start.hardening[p]);
            const ReturnResult<dim> minus = field.minus[start.object[p]].return_map(svd.Sigma, start.hardening[p]);
            const Mat<dim> dFE = svd.compose((plus.Sigma - minus.Sigma) / (2.0 * field.delta));
            const double dh = (plus.hardening - minus.hardening) / (2.0 * field.delta);
            field_bar_[f][p] = g.F[p].cwiseProduct(dFE).sum() + dh * g.hardening[p];
        }
    }
    parameter_bar_ = Parameters{};
    for (const Parameters& a : mapped_parameter_bar)
        for (int q = 0; q < kPlasticityParameters; ++q) parameter_bar_[q] += a[q];
    grid_to_particles_adjoint<dim>(grid_, start, grid_v_, dt, g.x, g.v, g.C, F_trial_bar, grid_v_bar, x_bar_, F_bar_);

    // The solve's right-hand side: A^T vb on the unknowns (the projection's adjoint). The components the solve
    // holds (the sticky floor's nodes, a Coulomb floor's pressing normals: free 0) are constants: lambda is 0
    // there (but a Coulomb contact's normal row, jacobian_transpose).
    const VecX& free = potential_.free_components();
    VecX rhs = VecX::Zero(potential_.size());
    for (std::int64_t i = 0; i < storage_; ++i)
        if (dof_[i] >= 0) {
            const Vec<dim> unprojected_bar = projection_[i].transpose() * grid_v_bar[i];
            for (int a = 0; a < dim; ++a) rhs[dim * dof_[i] + a] = free[dim * dof_[i] + a] * unprojected_bar[a];
        }
    return rhs;
}

template <int dim>
void MpmStepAdjoint<dim>::jacobian_transpose(std::vector<Eigen::Triplet<double>>& triplets, Eigen::Index offset) {
    constexpr int kStencil = IncrementalPotential<dim>::kStencil;
    const double dt = dt_;
    const Particles<dim>& start = start_;
    const VecX& free = potential_.free_components();
    if (method_ == Method::Lagged && symmetric()) {
        // J = J^T = M + the elastic term, whose node-pair blocks the potential sums from the tangents at v (far fewer
        // entries than a particle's 9 x 9 blocks each); the held components' rows and columns the identity's.
        potential_.set_particle_hessians(v_, T_);
        const VecX& node_mass = potential_.residual_mass();
        for (Eigen::Index i = 0; i < potential_.size(); ++i)
            triplets.emplace_back(offset + i, offset + i, free[i] > 0.0 ? node_mass[i] : 1.0);
        potential_.add_particle_hessian_triplets(triplets, offset);
        return;
    }
    auto contact_normal = [&](Eigen::Index i) {  // a held normal row of a contact
        return coulomb_ && i % dim == 1 && contact_of_[i / dim] >= 0;
    };
    // J^T = M + sum_p V dt^2 B_p^T T_p^T B_p, on the free components; the held ones' rows and columns are the
    // identity's, but a contact's normal row: mu_k - c_k . lambda_k,t = 0, with its column (k, y) of the stress
    // term on the free rows.
    const Eigen::Index size = potential_.size();
    triplets.reserve(triplets.size() + static_cast<std::size_t>(size) + n_ * kStencil * kStencil * dim * dim);
    const VecX& node_mass = potential_.residual_mass();
    for (Eigen::Index i = 0; i < size; ++i)
        triplets.emplace_back(offset + i, offset + i, free[i] > 0.0 ? node_mass[i] : 1.0);
    for (const FloorContact<dim>& c : contacts_)
        for (int t = 0; t < dim - 1; ++t) {
            const Eigen::Index it = dim * c.dof + (t == 0 ? 0 : 2);
            if (free[it] == 0.0) continue;
            triplets.emplace_back(offset + dim * c.dof + 1, offset + it, -c.c[t]);
            for (int r = 0; r < dim - 1; ++r) {  // J_k dc/du, transposed
                const Eigen::Index ir = dim * c.dof + (r == 0 ? 0 : 2);
                if (free[ir] > 0.0) triplets.emplace_back(offset + ir, offset + it, c.dc(t, r));
            }
        }
    for (std::size_t p = 0; p < n_; ++p) {
        const int* dofs = potential_.stencil_dofs(p);
        const Vec<dim>* grads = potential_.stencil_gradients(p);
        const double scale = start.rest_volume[p] * dt * dt;
        Vec<dim> g_of[kStencil];
        for (int q = 0; q < kStencil; ++q) g_of[q] = start.F_elastic[p].transpose() * grads[q];
        for (int q = 0; q < kStencil; ++q)
            for (int r = 0; r < kStencil; ++r)
                for (int a = 0; a < dim; ++a)
                    for (int b = 0; b < dim; ++b) {
                        if (free[dim * dofs[r] + b] == 0.0) continue;  // J^T's row: a free column of J
                        if (free[dim * dofs[q] + a] == 0.0 && !contact_normal(dim * dofs[q] + a)) continue;
                        double value = 0.0;  // J((q, a), (r, b)) = V dt^2 g_q . T[(a, .), (b, .)] g_r
                        for (int j = 0; j < dim; ++j)
                            for (int l = 0; l < dim; ++l)
                                value += g_of[q][j] * T_[p](a * dim + j, b * dim + l) * g_of[r][l];
                        triplets.emplace_back(offset + dim * dofs[r] + b, offset + dim * dofs[q] + a,
                                              scale * value);  // J^T
                    }
    }
}

template <int dim>
VecX MpmStepAdjoint<dim>::solve(const VecX& rhs, int step) {
    // Symmetric: the potential's own exact Hessian by PCG; else J^T (the consistent tangent's skew part
    // transposed, the friction's) by sparse LU.
    VecX lambda;
    PcgResult solve;
    if (symmetric()) {
        VecX residual, diagonal;
        if (method_ == Method::Lagged)
            potential_.set_particle_hessians(v_, T_);  // the elastic dP/dF at the solution: the energy's own Hessian
        else
            potential_.value_gradient_hessian(v_, residual);
        potential_.hessian_diagonal(diagonal);
        solve = solve_pcg(potential_, rhs, Preconditioner::jacobi(diagonal), lambda, 1e-11, 100000);
    } else {
        // J^T assembled and factorized by sparse LU: the unprojected consistent tangent of perfect plasticity
        // can make J indefinite, where BiCGSTAB with Jacobi stalled (the sand column: 0.057 of the right-hand
        // side left after 6168 products).
        std::vector<Eigen::Triplet<double>> triplets;
        jacobian_transpose(triplets);
        SparseMatrix transpose(potential_.size(), potential_.size());
        transpose.setFromTriplets(triplets.begin(), triplets.end());
        lambda = solve_transposed(transpose, rhs, step, solve);
    }
    if (!solve.converged)
        throw std::runtime_error("MpmAdjoint: step " + std::to_string(step) + ": the adjoint solve did not converge (" +
                                 std::to_string(solve.relative_residual) + " after " +
                                 std::to_string(solve.iterations) + " products)");
    return lambda;
}

template <int dim>
void MpmStepAdjoint<dim>::input_adjoint(const VecX& lambda, MpmRolloutGradient<dim>& g) {
    const double dt = dt_;
    const std::size_t n = n_;
    const Particles<dim>& start = start_;
    const VecX& v = v_;
    constexpr int kStencil = IncrementalPotential<dim>::kStencil;
    // Through the solve: v* and the node masses, the particles' F^n and x (the stress term), E, phi.
    std::vector<double> mass_bar(storage_, 0.0);
    std::vector<Vec<dim>> v_star_bar(storage_, Vec<dim>::Zero());
    for (std::int64_t i = 0; i < storage_; ++i) {
        if (dof_[i] < 0) continue;
        const Vec<dim> li = lambda.template segment<dim>(dim * dof_[i]);
        v_star_bar[i] = mass_[i] * li;
        mass_bar[i] = -li.dot(v.template segment<dim>(dim * dof_[i]) - node_v_star_[i]);
    }
    std::vector<double> youngs_bar(n, 0.0);  // summed in particle order after the loop
    std::vector<Parameters> solve_parameter_bar(n, Parameters{});
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < static_cast<std::ptrdiff_t>(n); ++p) {
        const Material<dim>& material = system_.materials[start.object[p]];
        const Mat<dim>& Fn = start.F_elastic[p];
        Mat<dim> Lambda = Mat<dim>::Zero(), G = Mat<dim>::Zero();
        const int* dofs = potential_.stencil_dofs(p);
        const Vec<dim>* grads = potential_.stencil_gradients(p);
        for (int s = 0; s < kStencil; ++s) {
            Lambda += lambda.template segment<dim>(dim * dofs[s]) * grads[s].transpose();
            G += v.template segment<dim>(dim * dofs[s]) * grads[s].transpose();
        }
        const double V = start.rest_volume[p];
        const Mat<dim> LF = Lambda * Fn;
        const Mat<dim> Q = unflatten<dim>(T_[p].transpose() * flatten<dim>(LF));  // d(P : LF)/dF
        const Mat<dim> A = Mat<dim>::Identity() + dt * G;
        F_bar_[p] -= V * dt * (A.transpose() * Q + Lambda.transpose() * P_[p]);
        youngs_bar[p] = -V * dt * P_[p].cwiseProduct(LF).sum() / material.elasticity().params().E;
        // 0 unless return_map's plasticity
        h_bar_[p] -= V * dt * dP_dh_[p].cwiseProduct(LF).sum();
        for (int q = 0; q < kPlasticityParameters; ++q)
            solve_parameter_bar[p][q] = -V * dt * dP_dparameter_[p][q].cwiseProduct(LF).sum();
        for (std::size_t f = 0; f < fields_.size(); ++f)
            field_bar_[f][p] -= V * dt * dP_dfield_[f][p].cwiseProduct(LF).sum();
        const StencilNodeDerivatives<dim> st(grid_, start.x[p]);
        int s = 0;
        Vec<dim> xb = Vec<dim>::Zero();
        st.for_each([&](std::int64_t, double, const Vec<dim>&, const Mat<dim>& hess, const Vec<dim>&) {
            const Vec<dim> li = lambda.template segment<dim>(dim * dofs[s]);
            const Vec<dim> vi = v.template segment<dim>(dim * dofs[s]);
            xb += hess * (Fn * (P_[p].transpose() * li + dt * Q.transpose() * vi));
            ++s;
        });
        x_bar_[p] -= V * dt * xb;
    }
    Parameters parameter_bar = parameter_bar_;
    for (std::size_t p = 0; p < n; ++p) {
        g.youngs_modulus += youngs_bar[p];
        for (int q = 0; q < kPlasticityParameters; ++q) parameter_bar[q] += solve_parameter_bar[p][q];
    }
    g.fields.resize(fields_.size(), 0.0);
    for (std::size_t f = 0; f < fields_.size(); ++f)
        for (std::size_t p = 0; p < n; ++p) g.fields[f] += field_bar_[f][p];  // in particle order
    g.friction_angle += parameter_bar[static_cast<int>(PlasticityParameter::FrictionAngle)];
    g.xi += parameter_bar[static_cast<int>(PlasticityParameter::Xi)];
    g.beta += parameter_bar[static_cast<int>(PlasticityParameter::Beta)];

    // AFLIP's residual: its cotangent rb_p to v_p (after P2G's adjoint, below), to x_p through the weights
    // (-sum_i (rb_p . u_i) grad w_ip), and to u_i = q_i / m_i, which is v*_i - dt g: -sum_p w_ip rb_p joins
    // v*'s cotangent (serially, in particle order: the sum does not depend on the thread count).
    if (alpha_ > 0.0) {
        for (std::size_t p = 0; p < n; ++p) {
            const StencilNodes<dim> st(grid_, start.x[p]);
            st.for_each([&](std::int64_t node, double w, const Vec<dim>& grad, const Vec<dim>&) {
                if (!(mass_[node] > 0.0)) return;  // as velocity_residual: a node without mass has no u_i
                const Vec<dim> u = momentum_[node] / mass_[node];
                x_bar_[p] -= residual_bar_[p].dot(u) * grad;
                v_star_bar[node] -= w * residual_bar_[p];
            });
        }
    }

    // P2G: v* = q / m + dt g on the nodes with mass.
    std::vector<Vec<dim>> momentum_bar(storage_, Vec<dim>::Zero());
    for (std::int64_t i = 0; i < storage_; ++i) {
        if (dof_[i] < 0 || !(mass_[i] > 0.0)) continue;
        momentum_bar[i] = v_star_bar[i] / mass_[i];
        mass_bar[i] -= v_star_bar[i].dot(momentum_[i]) / (mass_[i] * mass_[i]);
    }
    std::vector<Vec<dim>> v_bar(n, Vec<dim>::Zero());
    std::vector<Mat<dim>> C_bar(n, Mat<dim>::Zero());
    particles_to_grid_adjoint<dim>(grid_, start, mass_bar, momentum_bar, x_bar_, v_bar, C_bar);
    if (alpha_ > 0.0)
        for (std::size_t p = 0; p < n; ++p) v_bar[p] += residual_bar_[p];
    g.x = std::move(x_bar_);
    g.v = std::move(v_bar);
    g.C = std::move(C_bar);
    g.F = std::move(F_bar_);
    g.hardening = std::move(h_bar_);
}

template <int dim>
void MpmAdjoint<dim>::step_adjoint(const Particles<dim>& start, const VecX& v, int k,
                                   MpmRolloutGradient<dim>& g) const {
    MpmStepAdjoint<dim> step(system_, method_, start, v, dt_, &fields_);
    const VecX rhs = step.output_adjoint(g);
    step.input_adjoint(step.solve(rhs, k), g);
}

template class MpmStepAdjoint<2>;
template class MpmStepAdjoint<3>;
template class MpmAdjoint<2>;
template class MpmAdjoint<3>;

}  // namespace pnet
