#include "pnet/coupling/coupled_adjoint.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include <Eigen/SparseCholesky>
#include <Eigen/SparseLU>

#include "pnet/contact/friction.hpp"
#include "pnet/solver/method_energy.hpp"
#include "pnet/solver/rollout_checkpoints.hpp"

namespace pnet {

template <int dim>
struct CoupledAdjoint<dim>::Stepper {
    std::unique_ptr<CoupledImplicitIntegrator<dim>> integrator;
};

template <int dim>
struct CoupledAdjoint<dim>::Factor {
    Eigen::SimplicialLDLT<SparseMatrix> ldlt;
    SparseMatrix pattern;  // the last analyzed J's (its values unused)
};

template <int dim>
CoupledAdjoint<dim>::~CoupledAdjoint() = default;
template <int dim>
CoupledAdjoint<dim>::CoupledAdjoint(CoupledAdjoint&&) noexcept = default;

template <int dim>
void CoupledAdjoint<dim>::set_friction(double mu, double eps_v) {
    if (!(mu >= 0.0) || !(eps_v > 0.0))
        throw std::invalid_argument("CoupledAdjoint::set_friction: mu >= 0 and eps_v > 0 are needed");
    mu_ = mu;
    eps_v_ = eps_v;
}

template <int dim>
CoupledAdjoint<dim>::CoupledAdjoint(const MpmSystem<dim>& mpm, const FemSystem<dim>& fem,
                                    const ContactPotential<dim>* mesh_contact, const ContactPotential<dim>& contact,
                                    const ImplicitOptions& options, const MpmOptions& mpm_options,
                                    const CouplingOptions& coupling_options, Method method)
    : mpm_(mpm),
      fem_(fem),
      mesh_contact_(mesh_contact),
      contact_(contact),
      options_(options),
      mpm_options_(mpm_options),
      coupling_options_(coupling_options),
      method_(method),
      factor_(std::make_unique<Factor>()) {
    const std::string who = "CoupledAdjoint";
    if (method != Method::Lagged && method != Method::ReturnMap)
        throw std::invalid_argument(who + ": integrator '" + to_string(method) +
                                    "': the adjoint is of lagged and return_map (plasticitynet converges to "
                                    "return_map's step)");
    require_adjoint_materials<dim>(mpm, who);
    // Each step from v* (as MpmAdjoint's): the backward pass replays steps from stored states.
    mpm_options_.newton_start = "v_star";
    if (mpm.boundary.coulomb_floor() && mpm.boundary.sticky_floor_cells > 0)
        throw std::invalid_argument(who +
                                    ": boundary.floor_friction: a Coulomb floor beside meshes is not "
                                    "differentiated (its adjoint is MPM's alone)");
    if (fem.materials.size() != 1)
        throw std::invalid_argument(who + ": meshes: one mesh material is differentiated, got " +
                                    std::to_string(fem.materials.size()));
    if (fem.materials[0].description().plasticity != PlasticityModel::None)
        throw std::invalid_argument(who + ": meshes[0].material.plasticity '" +
                                    to_string(fem.materials[0].description().plasticity) +
                                    "': a coupled step's mesh is elastic");
    if (std::any_of(fem.fixed_node.begin(), fem.fixed_node.end(), [](char fixed) { return fixed != 0; }))
        throw std::invalid_argument(who + ": meshes: kinematic nodes are not supported beside particles");
    if (options.time_integrator != "backward_euler")
        throw std::invalid_argument(who + ": time_integrator '" + options.time_integrator +
                                    "': a coupled step is backward Euler");
}

template <int dim>
void CoupledAdjoint<dim>::set_parameter_fields(const std::vector<std::string>& fields) {
    fields_ = perturbed_fields<dim>(mpm_.materials, fields, "CoupledAdjoint");
}

template <int dim>
std::unique_ptr<typename CoupledAdjoint<dim>::Stepper> CoupledAdjoint<dim>::make_stepper() const {
    auto stepper = std::make_unique<Stepper>();
    stepper->integrator = std::make_unique<CoupledImplicitIntegrator<dim>>(
        mpm_, fem_, method_, options_, mpm_options_, coupling_options_,
        model_free_energy<dim>(method_, options_, mpm_.materials), std::vector<const LearnedReturnMap<dim>*>{},
        mesh_contact_, contact_, CouplingFriction{mu_, eps_v_});
    return stepper;
}

template <int dim>
CoupledState<dim> CoupledAdjoint<dim>::forward(const CoupledState<dim>& start, double dt, int steps,
                                               const std::function<void(int, const CoupledState<dim>&)>& observe,
                                               int checkpoint_every) {
    if (!(dt > 0.0) || steps < 0 || checkpoint_every < 0)
        throw std::invalid_argument("CoupledAdjoint::forward: dt > 0, steps >= 0 and checkpoint_every >= 0 are needed");
    if (start.mesh.x.size() != fem_.mesh.nodes())
        throw std::invalid_argument("CoupledAdjoint::forward: the mesh state has " +
                                    std::to_string(start.mesh.x.size()) + " nodes, the mesh " +
                                    std::to_string(fem_.mesh.nodes()));
    const int every = checkpoint_spacing(steps, checkpoint_every);
    checkpoints_.clear();
    unconverged_ = 0;
    const std::unique_ptr<Stepper> stepper = make_stepper();
    CoupledState<dim> state = start;
    checkpoints_[0] = state;
    if (observe) observe(0, state);
    for (int k = 0; k < steps; ++k) {
        if (!stepper->integrator->step(state.particles, state.mesh, dt, k).converged) ++unconverged_;
        if ((k + 1) % every == 0 || k + 1 == steps) checkpoints_[k + 1] = state;
        if (observe) observe(k + 1, state);
    }
    dt_ = dt;
    steps_ = steps;
    particles_ = state.particles.size();
    peak_states_ = checkpoints_.size();
    return state;
}

template <int dim>
CoupledRolloutGradient<dim> CoupledAdjoint<dim>::backward(const std::vector<std::vector<Vec<dim>>>& particle_x_bar,
                                                          const std::vector<std::vector<Vec<dim>>>& particle_v_bar,
                                                          const std::vector<std::vector<Vec<dim>>>& node_x_bar,
                                                          const std::vector<std::vector<Vec<dim>>>& node_v_bar) const {
    if (steps_ < 0) throw std::logic_error("CoupledAdjoint::backward: no forward pass");
    const std::size_t states = static_cast<std::size_t>(steps_) + 1, n = particles_, nodes = fem_.mesh.nodes();
    for (const auto* bars : {&particle_x_bar, &particle_v_bar, &node_x_bar, &node_v_bar})
        if (bars->size() != states)
            throw std::invalid_argument("CoupledAdjoint::backward: one entry per state (" + std::to_string(states) +
                                        ")");
    for (std::size_t k = 0; k < states; ++k) {
        if ((!particle_x_bar[k].empty() && particle_x_bar[k].size() != n) ||
            (!particle_v_bar[k].empty() && particle_v_bar[k].size() != n))
            throw std::invalid_argument("CoupledAdjoint::backward: state " + std::to_string(k) +
                                        ": the particles' dL/dx and dL/dv need one entry per particle (" +
                                        std::to_string(n) + ")");
        if ((!node_x_bar[k].empty() && node_x_bar[k].size() != nodes) ||
            (!node_v_bar[k].empty() && node_v_bar[k].size() != nodes))
            throw std::invalid_argument("CoupledAdjoint::backward: state " + std::to_string(k) +
                                        ": the nodes' dL/dx and dL/dv need one entry per mesh node (" +
                                        std::to_string(nodes) + ")");
    }
    CoupledRolloutGradient<dim> g;
    MpmRolloutGradient<dim>& gp = g.particles;
    gp.fields.assign(fields_.size(), 0.0);
    gp.x.assign(n, Vec<dim>::Zero());
    gp.v.assign(n, Vec<dim>::Zero());
    gp.C.assign(n, Mat<dim>::Zero());
    gp.F.assign(n, Mat<dim>::Zero());
    gp.hardening.assign(n, 0.0);
    VecX xb = VecX::Zero(dim * nodes), vb = VecX::Zero(dim * nodes);
    auto add = [&](std::size_t k) {
        for (std::size_t p = 0; p < n; ++p) {
            if (!particle_x_bar[k].empty()) gp.x[p] += particle_x_bar[k][p];
            if (!particle_v_bar[k].empty()) gp.v[p] += particle_v_bar[k][p];
        }
        for (std::size_t a = 0; a < nodes; ++a) {
            if (!node_x_bar[k].empty()) xb.template segment<dim>(dim * a) += node_x_bar[k][a];
            if (!node_v_bar[k].empty()) vb.template segment<dim>(dim * a) += node_v_bar[k][a];
        }
    };
    add(states - 1);
    std::vector<int> marks;
    for (const auto& [step, state] : checkpoints_) marks.push_back(step);
    for (std::size_t m = marks.size() - 1; m-- > 0;) {
        const int first = marks[m], last = marks[m + 1];
        // The segment's start states and solutions, recomputed from its checkpoint (the same to the last bit).
        std::vector<CoupledState<dim>> starts;
        std::vector<VecX> solutions;
        {
            const std::unique_ptr<Stepper> stepper = make_stepper();
            CoupledState<dim> state = checkpoints_.at(first);
            for (int k = first; k < last; ++k) {
                starts.push_back(state);
                stepper->integrator->step(state.particles, state.mesh, dt_, k);
                solutions.push_back(stepper->integrator->solution());
            }
        }
        peak_states_ = std::max(peak_states_, checkpoints_.size() + starts.size());
        for (int k = last - 1; k >= first; --k) {
            step_adjoint(starts[k - first], solutions[k - first], k, g, xb, vb);
            add(static_cast<std::size_t>(k));
        }
    }
    g.node_x.resize(nodes);
    g.node_v.resize(nodes);
    for (std::size_t a = 0; a < nodes; ++a) {
        g.node_x[a] = xb.template segment<dim>(dim * a);
        g.node_v[a] = vb.template segment<dim>(dim * a);
    }
    return g;
}

template <int dim>
void CoupledAdjoint<dim>::step_adjoint(const CoupledState<dim>& start, const VecX& solution, int step,
                                       CoupledRolloutGradient<dim>& g, VecX& xb, VecX& vb) const {
    const double dt = dt_;
    const std::size_t nodes = fem_.mesh.nodes(), n = start.particles.size();
    constexpr int kStencil = IncrementalPotential<dim>::kStencil;

    // The MPM part of the step, rebuilt from its start and the solution's grid velocities.
    MpmStepAdjoint<dim> mpm(mpm_, method_, start.particles, solution.head(solution.size() - dim * nodes), dt, &fields_);
    IncrementalPotential<dim>& grid_potential = mpm.potential();
    const Eigen::Index ng = grid_potential.size(), nf = static_cast<Eigen::Index>(dim * nodes);
    if (solution.size() != ng + nf) throw std::logic_error("CoupledAdjoint: the step's unknowns changed on replay");
    const VecX vg = solution.head(ng), vf = solution.tail(nf);

    // The mesh's potential as the coupled integrator sets it up (its elasticity and its own contact), exact
    // (unprojected), and the same without contact (its elasticity's gradient is dR/dE times E).
    VecX v_star(nf);
    for (std::size_t a = 0; a < nodes; ++a) v_star.template segment<dim>(dim * a) = start.mesh.v[a] + dt * fem_.gravity;
    // With friction, the meshes' own lagged friction is in the solve's Hessian, and held: their x^n term takes the
    // Hessian without it (frictionless).
    ElasticParticleEnergy<dim> fem_energy(fem_.materials);
    FemPotential<dim> fem(fem_.mesh, fem_.rest, fem_energy), elastic(fem_.mesh, fem_.rest, fem_energy),
        frictionless(fem_.mesh, fem_.rest, fem_energy);
    fem.set_contact(mesh_contact_);
    frictionless.set_contact(mesh_contact_);
    Friction<dim> mesh_friction(mu_, eps_v_);
    const bool friction = mu_ > 0.0;
    if (friction && mesh_contact_) {
        mesh_friction.lag(*mesh_contact_, start.mesh.x);
        fem.set_friction(&mesh_friction);
    }
    const bool held_friction = friction && mesh_contact_;  // the meshes' own lagged friction, held below
    for (FemPotential<dim>* p : {&fem, &elastic, &frictionless}) {
        if (p == &frictionless && !held_friction) continue;
        p->begin_step(start.mesh.x, v_star, dt, start.mesh.plastic_inverse, {});
        p->set_material_state(fem_.element_object, start.mesh.hardening);
        p->set_reference({});
        p->set_project_psd(false);
    }
    fem.prepare_hessian(vf);
    const VecX& node_mass = fem.residual_mass();

    // The barrier at the solution: the vertices' positions y(v), B's gradient and Hessian in them.
    CoupledVertices<dim> vertices(grid_potential, fem);
    std::vector<Vec<dim>> y;
    vertices.positions(solution, y);
    const Eigen::Index vertex_size = static_cast<Eigen::Index>(dim * y.size());
    VecX barrier_gradient = VecX::Zero(vertex_size);
    contact_.add_gradient(y, 1.0, barrier_gradient);
    std::vector<Eigen::Triplet<double>> vertex_triplets;
    contact_.add_hessian(y, 1.0, vertex_triplets, false);
    SparseMatrix barrier_hessian(vertex_size, vertex_size);
    barrier_hessian.setFromTriplets(vertex_triplets.begin(), vertex_triplets.end());

    // J^T = blockdiag(J_mpm^T, H_fem) + dt^2 W^T H_B W (symmetric), on the free components.
    std::vector<Eigen::Triplet<double>> triplets;
    mpm.jacobian_transpose(triplets, 0);
    fem.add_hessian_triplets(triplets, ng);
    // A vertex-space matrix A (dim per vertex: the mesh's nodes, then the particles) as W^T A W on the free
    // components, times `scale`.
    const VecX& grid_free = grid_potential.free_components();
    auto add_vertex_block = [&](const SparseMatrix& A, double scale) {
        Eigen::Index row_index[ContactVertices<dim>::kMaxUnknowns], column_index[ContactVertices<dim>::kMaxUnknowns];
        double row_weight[ContactVertices<dim>::kMaxUnknowns], column_weight[ContactVertices<dim>::kMaxUnknowns];
        auto free = [&](Eigen::Index i) { return i >= ng || grid_free[i] > 0.0; };
        for (int k = 0; k < A.outerSize(); ++k)
            for (SparseMatrix::InnerIterator it(A, k); it; ++it) {
                const int a = static_cast<int>(it.row() / dim), i = static_cast<int>(it.row() % dim);
                const int b = static_cast<int>(it.col() / dim), j = static_cast<int>(it.col() % dim);
                const int rows = vertices.unknowns(a, row_index, row_weight);
                const int columns = vertices.unknowns(b, column_index, column_weight);
                for (int r = 0; r < rows; ++r)
                    for (int c = 0; c < columns; ++c) {
                        const Eigen::Index row = row_index[r] + i, column = column_index[c] + j;
                        if (free(row) && free(column))
                            triplets.emplace_back(row, column, scale * row_weight[r] * column_weight[c] * it.value());
                    }
            }
    };
    add_vertex_block(barrier_hessian, dt * dt);  // y = x^n + dt W v
    // The particle-mesh friction's Hessian in the vertices' velocities, dt mu lambda_k (c c^T) (x) T H(s) T^T per
    // lagged pair (its pairs at the step's start), through the vertices' weights on the unknowns; and its gradient
    // G_j = dt sum_k c_kj mu lambda_k f1(|s|) / |s| T s in vertex j's velocity.
    std::vector<FrictionPair<dim>> pairs;
    VecX friction_gradient = VecX::Zero(vertex_size);
    std::vector<Eigen::Triplet<double>> friction_triplets;
    if (friction) {
        std::vector<Vec<dim>> y_start;
        CoupledVertices<dim>::join(start.mesh.x, start.particles.x, y_start);
        pairs = contact_.lagged_pairs(y_start);
        for (const FrictionPair<dim>& fp : pairs) {
            Vec<dim> relative = Vec<dim>::Zero();
            for (int j = 0; j < fp.count; ++j) relative += fp.weight[j] * vertices.velocity(fp.node[j], solution);
            const Eigen::Matrix<double, dim - 1, 1> s = fp.tangent.transpose() * relative;
            const double scale = dt * mu_ * fp.normal_force;
            const Vec<dim> f = scale * friction_f1_over_x(s.norm(), eps_v_) * (fp.tangent * s);
            const Mat<dim> H = scale * fp.tangent * friction_slip_hessian<dim - 1>(s, eps_v_) * fp.tangent.transpose();
            for (int i = 0; i < fp.count; ++i) {
                friction_gradient.template segment<dim>(dim * fp.node[i]) += fp.weight[i] * f;
                for (int j = 0; j < fp.count; ++j)
                    for (int a = 0; a < dim; ++a)
                        for (int b = 0; b < dim; ++b)
                            friction_triplets.emplace_back(dim * fp.node[i] + a, dim * fp.node[j] + b,
                                                           fp.weight[i] * fp.weight[j] * H(a, b));
            }
        }
    }
    SparseMatrix friction_hessian(vertex_size, vertex_size);
    friction_hessian.setFromTriplets(friction_triplets.begin(), friction_triplets.end());
    add_vertex_block(friction_hessian, 1.0);
    SparseMatrix transpose(ng + nf, ng + nf);
    transpose.setFromTriplets(triplets.begin(), triplets.end());

    // The right-hand side: G2P's adjoint on the grid, vb + dt xb on the nodes (x' = x^n + dt v, v' = v).
    VecX rhs(ng + nf);
    rhs.head(ng) = mpm.output_adjoint(g.particles);
    rhs.tail(nf) = vb + dt * xb;
    // Symmetric where the MPM part is (the elastic stress of lagged; the barrier, the meshes and the friction are
    // potentials): LDL^T, else sparse LU.
    VecX lambda;
    if (mpm.symmetric()) {
        // The ordering and symbolic analysis are kept while the pattern is the last step's (the same active grid
        // and contact pairs: most consecutive steps).
        transpose.makeCompressed();
        const bool same_pattern =
            transpose.rows() == factor_->pattern.rows() && transpose.nonZeros() == factor_->pattern.nonZeros() &&
            std::equal(transpose.outerIndexPtr(), transpose.outerIndexPtr() + transpose.outerSize() + 1,
                       factor_->pattern.outerIndexPtr()) &&
            std::equal(transpose.innerIndexPtr(), transpose.innerIndexPtr() + transpose.nonZeros(),
                       factor_->pattern.innerIndexPtr());
        Eigen::SimplicialLDLT<SparseMatrix>& ldlt = factor_->ldlt;
        if (!same_pattern) {
            ldlt.analyzePattern(transpose);
            factor_->pattern = transpose;
        }
        ldlt.factorize(transpose);
        if (ldlt.info() != Eigen::Success)
            throw std::runtime_error("CoupledAdjoint: step " + std::to_string(step) +
                                     ": the step's Jacobian could not be factorized");
        lambda = ldlt.solve(rhs);
    } else {
        Eigen::SparseLU<SparseMatrix> lu;
        lu.compute(transpose);
        if (lu.info() != Eigen::Success)
            throw std::runtime_error("CoupledAdjoint: step " + std::to_string(step) +
                                     ": the step's Jacobian is singular (" + lu.lastErrorMessage() + ")");
        lambda = lu.solve(rhs);
    }
    const double residual = (transpose * lambda - rhs).norm() / std::max(rhs.norm(), 1e-300);
    if (!(residual <= 1e-9))
        throw std::runtime_error("CoupledAdjoint: step " + std::to_string(step) +
                                 ": the adjoint solve left a relative residual of " + std::to_string(residual));
    const VecX lambda_g = lambda.head(ng), lambda_f = lambda.tail(nf);

    // The particles' start, through the MPM part of the residual (MpmAdjoint's).
    mpm.input_adjoint(lambda_g, g.particles);

    // The mesh's start: v* = v^n + dt g, the elastic (and its own contact's) term's x^n = x(v) - dt v.
    const VecX m_lambda = node_mass.cwiseProduct(lambda_f);
    VecX h_lambda = VecX::Zero(nf);
    {
        FemPotential<dim>& held = held_friction ? frictionless : fem;
        if (held_friction) frictionless.prepare_hessian(vf);
        std::vector<Eigen::Triplet<double>> fem_triplets;
        held.add_hessian_triplets(fem_triplets, 0);
        SparseMatrix H(nf, nf);
        H.setFromTriplets(fem_triplets.begin(), fem_triplets.end());
        h_lambda = H * lambda_f;
    }
    VecX elastic_gradient;
    elastic.value_gradient(vf, elastic_gradient);
    elastic_gradient -= node_mass.cwiseProduct(vf - v_star);
    g.mesh_youngs_modulus -= lambda_f.dot(elastic_gradient) / fem_.materials[0].elasticity().params().E;
    xb -= (h_lambda - m_lambda) / dt;
    vb = m_lambda;

    // The barrier's dependence on the start's positions: mu = W dt lambda, the vertices' motion along lambda.
    std::vector<Vec<dim>> mu;
    vertices.motion(lambda, mu);
    VecX mu_flat(vertex_size);
    for (std::size_t k = 0; k < mu.size(); ++k) mu_flat.template segment<dim>(dim * k) = mu[k];
    const VecX h_mu = barrier_hessian * mu_flat;
    for (std::size_t a = 0; a < nodes; ++a) xb.template segment<dim>(dim * a) -= h_mu.template segment<dim>(dim * a);
    // The friction's, through a particle's velocity u_p = sum_i w_ip v_i: nu = W lambda, Hess D nu.
    VecX h_nu = VecX::Zero(vertex_size);
    if (friction) {
        VecX nu(vertex_size);
        for (std::size_t k = 0; k < y.size(); ++k)
            nu.template segment<dim>(dim * k) = vertices.velocity(static_cast<int>(k), lambda);
        h_nu = friction_hessian * nu;
    }
    for (std::size_t p = 0; p < n; ++p) {
        const Eigen::Index vertex = static_cast<Eigen::Index>(dim * (nodes + p));
        const Vec<dim> hp = h_mu.template segment<dim>(vertex), gb = barrier_gradient.template segment<dim>(vertex);
        const Vec<dim> hf = h_nu.template segment<dim>(vertex), gf = friction_gradient.template segment<dim>(vertex);
        if (hp.isZero(0.0) && gb.isZero(0.0) && hf.isZero(0.0) && gf.isZero(0.0)) continue;  // in no active pair
        const int* dofs = grid_potential.stencil_dofs(p);
        const Vec<dim>* grads = grid_potential.stencil_gradients(p);
        Vec<dim> xb_p = hp;
        for (int s = 0; s < kStencil; ++s) {
            const Vec<dim> vi = vg.template segment<dim>(dim * dofs[s]);
            const Vec<dim> li = lambda_g.template segment<dim>(dim * dofs[s]);
            xb_p += (dt * (vi.dot(hp) + li.dot(gb)) + li.dot(gf) + vi.dot(hf)) * grads[s];
        }
        g.particles.x[p] -= xb_p;
    }
}

template class CoupledAdjoint<2>;
template class CoupledAdjoint<3>;

}  // namespace pnet
