#include "pnet/mpm/mpm_adjoint.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "pnet/energy/particle_energy.hpp"
#include "pnet/mpm/transfer.hpp"
#include "pnet/mpm/transfer_adjoint.hpp"
#include "pnet/solver/pcg.hpp"

namespace pnet {

template <int dim>
MpmAdjoint<dim>::MpmAdjoint(const MpmSystem<dim>& system, const ImplicitOptions& options, const MpmOptions& mpm_options)
    : system_(system), options_(options), mpm_options_(mpm_options) {
    for (std::size_t k = 0; k < system.materials.size(); ++k)
        if (system.materials[k].description().plasticity != PlasticityModel::None)
            throw std::invalid_argument("MpmAdjoint: materials[" + std::to_string(k) + "].plasticity '" +
                                        to_string(system.materials[k].description().plasticity) +
                                        "': the MPM adjoint covers elastic materials so far");
    if (system.flip_relaxation_time > 0.0)
        throw std::invalid_argument(
            "MpmAdjoint: transfer.flip_relaxation_time: AFLIP transfers are not covered "
            "(APIC is)");
    if (system.boundary.sticky_floor_cells > 0)
        throw std::invalid_argument(std::string("MpmAdjoint: boundary: a ") +
                                    (system.boundary.coulomb_floor() ? "Coulomb" : "sticky") +
                                    " floor is not covered (slip walls are)");
    if (options.time_integrator != "backward_euler")
        throw std::invalid_argument("MpmAdjoint: time_integrator '" + options.time_integrator +
                                    "': backward Euler only");
}

template <int dim>
Particles<dim> MpmAdjoint<dim>::forward(const Particles<dim>& start, double dt, int steps,
                                        const std::function<void(int, const Particles<dim>&)>& observe,
                                        int checkpoint_every) {
    if (!(dt > 0.0) || steps < 0 || checkpoint_every < 0)
        throw std::invalid_argument("MpmAdjoint::forward: dt > 0, steps >= 0 and checkpoint_every >= 0 are needed");
    const int every =
        checkpoint_every > 0 ? checkpoint_every : std::max(1, static_cast<int>(std::ceil(std::sqrt(steps))));
    checkpoints_.clear();
    ImplicitIntegrator<dim> integrator(system_, Method::Lagged, options_, mpm_options_,
                                       std::make_unique<ElasticParticleEnergy<dim>>(system_.materials));
    integrator.reset(start);
    Particles<dim> particles = start;
    checkpoints_[0] = particles;
    if (observe) observe(0, particles);
    for (int k = 0; k < steps; ++k) {
        integrator.step(particles, dt, k);
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
    ImplicitIntegrator<dim> integrator(system_, Method::Lagged, options_, mpm_options_,
                                       std::make_unique<ElasticParticleEnergy<dim>>(system_.materials));
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
    g.x.assign(n, Vec<dim>::Zero());
    g.v.assign(n, Vec<dim>::Zero());
    g.C.assign(n, Mat<dim>::Zero());
    g.F.assign(n, Mat<dim>::Zero());
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
void MpmAdjoint<dim>::step_adjoint(const Particles<dim>& start, const VecX& v, int k, MpmRolloutGradient<dim>& g) const {
    const double dt = dt_;
    const std::size_t n = start.size();
    constexpr int kStencil = IncrementalPotential<dim>::kStencil;

    // The step's grid and potential, as the integrator set them up (the same deterministic P2G, so the
    // same unknowns as its solution's).
    Grid<dim> grid(system_.origin, system_.dx, system_.cells);
    particles_to_grid<dim>(grid, start, nullptr);
    const std::int64_t storage = grid.storage_size();
    std::vector<double> mass(storage);
    std::vector<Vec<dim>> momentum(storage);
    for (std::int64_t i = 0; i < storage; ++i) {
        mass[i] = grid.node(i).mass;
        momentum[i] = grid.node(i).momentum;
    }
    BoundaryConditions solve_boundary = system_.boundary;
    solve_boundary.slip_walls = false;
    grid.update_velocity(dt, system_.gravity, solve_boundary);
    ElasticParticleEnergy<dim> energy(system_.materials);
    IncrementalPotential<dim> potential(energy);
    potential.begin_step(grid, start, dt, solve_boundary);
    potential.set_reference(start.F_elastic);
    potential.set_project_psd(false);
    if (v.size() != potential.size()) throw std::logic_error("MpmAdjoint: the step's unknowns changed on replay");
    const VecX& v_star = potential.v_star();

    // Storage index <-> unknown, from the stencils.
    std::vector<int> dof(storage, -1);
    std::vector<std::int64_t> node_of(static_cast<std::size_t>(potential.size() / dim), -1);
    for (std::size_t p = 0; p < n; ++p) {
        const StencilNodeDerivatives<dim> st(grid, start.x[p]);
        int s = 0;
        st.for_each([&](std::int64_t node, double, const Vec<dim>&, const Mat<dim>&, const Vec<dim>&) {
            const int d = potential.stencil_dofs(p)[s++];
            dof[node] = d;
            node_of[d] = node;
        });
    }

    // The grid velocity G2P read: the solution with the slip walls' projection; the components it set
    // to 0 are held.
    std::vector<Vec<dim>> grid_v(storage, Vec<dim>::Zero());
    std::vector<std::array<bool, dim>> held(storage);
    for (std::int64_t i = 0; i < storage; ++i) {
        held[i].fill(false);
        if (dof[i] < 0) continue;
        Vec<dim> vi = v.template segment<dim>(dim * dof[i]);
        if (system_.boundary.slip_walls) {
            int coord[dim];
            grid.coordinates(i, coord);
            for (int a = 0; a < dim; ++a) {
                const bool low = coord[a] < Grid<dim>::kWallNodes && vi[a] < 0.0;
                const bool high = coord[a] >= grid.nodes(a) - Grid<dim>::kWallNodes && vi[a] > 0.0;
                if (low || high) {
                    vi[a] = 0.0;
                    held[i][a] = true;
                }
            }
        }
        grid_v[i] = vi;
    }

    // G2P: the cotangents of the output (x, v, C, F: g) to the grid velocities and the start's x, F.
    std::vector<Vec<dim>> grid_v_bar(storage, Vec<dim>::Zero()), x_bar(n, Vec<dim>::Zero());
    std::vector<Mat<dim>> F_bar(n, Mat<dim>::Zero());
    grid_to_particles_adjoint<dim>(grid, start, grid_v, dt, g.x, g.v, g.C, g.F, grid_v_bar, x_bar, F_bar);

    // The solve: lambda = H^-1 vb on the unknowns (the projected components' cotangent dropped).
    VecX rhs = VecX::Zero(potential.size());
    for (std::int64_t i = 0; i < storage; ++i)
        if (dof[i] >= 0)
            for (int a = 0; a < dim; ++a)
                if (!held[i][a]) rhs[dim * dof[i] + a] = grid_v_bar[i][a];
    VecX residual;
    potential.value_gradient_hessian(v, residual);
    VecX diagonal;
    potential.hessian_diagonal(diagonal);
    VecX lambda;
    const PcgResult solve = solve_pcg(potential, rhs, Preconditioner::jacobi(diagonal), lambda, 1e-10, 100000);
    if (!solve.converged)
        throw std::runtime_error(
            "MpmAdjoint: step " + std::to_string(k) + ": the adjoint solve did not converge (" +
            std::to_string(solve.relative_residual) + " after " + std::to_string(solve.iterations) + " iterations" +
            (solve.negative_curvature ? ", negative curvature: H is not positive definite" : "") + ")");

    // Through the solve: v* and the node masses, the particles' F^n and x (the stress term), E.
    std::vector<double> mass_bar(storage, 0.0);
    std::vector<Vec<dim>> v_star_bar(storage, Vec<dim>::Zero());
    for (std::int64_t i = 0; i < storage; ++i) {
        if (dof[i] < 0) continue;
        const Vec<dim> li = lambda.template segment<dim>(dim * dof[i]);
        v_star_bar[i] = mass[i] * li;
        mass_bar[i] = -li.dot(v.template segment<dim>(dim * dof[i]) - v_star.template segment<dim>(dim * dof[i]));
    }
    std::vector<Mat<dim>> F(n);
    potential.deformation(v, F);
    std::vector<double> youngs_bar(n);  // summed in particle order after the parallel loop
#pragma omp parallel for schedule(static)
    for (std::ptrdiff_t p = 0; p < static_cast<std::ptrdiff_t>(n); ++p) {
        const Elasticity<dim>& elasticity = system_.materials[start.object[p]].elasticity();
        const Mat<dim>& Fn = start.F_elastic[p];
        const PolarSVD<dim> svd = clamped_svd<dim>(F[p]);  // one decomposition for P and dP/dF
        const Mat<dim> P = svd.compose(elasticity.tau(svd.Sigma).cwiseQuotient(svd.Sigma));
        const Tensor4<dim> dPdF = elasticity.dPdF(svd, false);
        Mat<dim> Lambda = Mat<dim>::Zero(), G = Mat<dim>::Zero();
        const int* dofs = potential.stencil_dofs(p);
        const Vec<dim>* grads = potential.stencil_gradients(p);
        for (int s = 0; s < kStencil; ++s) {
            Lambda += lambda.template segment<dim>(dim * dofs[s]) * grads[s].transpose();
            G += v.template segment<dim>(dim * dofs[s]) * grads[s].transpose();
        }
        const double V = start.rest_volume[p];
        const Mat<dim> LF = Lambda * Fn;
        const Mat<dim> Q = unflatten<dim>(dPdF * flatten<dim>(LF));
        const Mat<dim> A = Mat<dim>::Identity() + dt * G;
        F_bar[p] -= V * dt * (A.transpose() * Q + Lambda.transpose() * P);
        youngs_bar[p] = -V * dt * P.cwiseProduct(LF).sum() / elasticity.params().E;
        const StencilNodeDerivatives<dim> st(grid, start.x[p]);
        int s = 0;
        Vec<dim> xb = Vec<dim>::Zero();
        st.for_each([&](std::int64_t, double, const Vec<dim>&, const Mat<dim>& hess, const Vec<dim>&) {
            const Vec<dim> li = lambda.template segment<dim>(dim * dofs[s]);
            const Vec<dim> vi = v.template segment<dim>(dim * dofs[s]);
            xb += hess * (Fn * (P.transpose() * li + dt * Q.transpose() * vi));
            ++s;
        });
        x_bar[p] -= V * dt * xb;
    }
    for (double e : youngs_bar) g.youngs_modulus += e;

    // P2G: v* = q / m + dt g on the nodes with mass.
    std::vector<Vec<dim>> momentum_bar(storage, Vec<dim>::Zero());
    for (std::int64_t i = 0; i < storage; ++i) {
        if (dof[i] < 0 || !(mass[i] > 0.0)) continue;
        momentum_bar[i] = v_star_bar[i] / mass[i];
        mass_bar[i] -= v_star_bar[i].dot(momentum[i]) / (mass[i] * mass[i]);
    }
    std::vector<Vec<dim>> v_bar(n, Vec<dim>::Zero());
    std::vector<Mat<dim>> C_bar(n, Mat<dim>::Zero());
    particles_to_grid_adjoint<dim>(grid, start, mass_bar, momentum_bar, x_bar, v_bar, C_bar);
    g.x = std::move(x_bar);
    g.v = std::move(v_bar);
    g.C = std::move(C_bar);
    g.F = std::move(F_bar);
}

template class MpmAdjoint<2>;
template class MpmAdjoint<3>;

}  // namespace pnet
