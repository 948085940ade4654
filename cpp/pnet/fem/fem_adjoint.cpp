#include "pnet/fem/fem_adjoint.hpp"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include <Eigen/SparseCholesky>

#include "pnet/energy/particle_energy.hpp"
#include "pnet/material/return_map_derivative.hpp"
#include "pnet/solver/bdf2.hpp"
#include "pnet/solver/method_energy.hpp"
#include "pnet/solver/rollout_checkpoints.hpp"

namespace pnet {

template <int dim>
FemAdjoint<dim>::FemAdjoint(const FemSystem<dim>& system, const ContactPotential<dim>* contact,
                            const ImplicitOptions& options, FemMethod method)
    : system_(system), contact_(contact), options_(options), method_(method) {
    if (method != FemMethod::Lagged && method != FemMethod::ReturnMap)
        throw std::invalid_argument(std::string("FemAdjoint: integrator \"") + integrator_info(method).name +
                                    "\": the adjoint is of lagged and return_map (plasticitynet converges to "
                                    "return_map's step: differentiate that)");
    if (system.materials.size() != 1)
        throw std::invalid_argument("FemAdjoint: materials: the adjoint takes one material (the scene has " +
                                    std::to_string(system.materials.size()) + ")");
    const MaterialDescription& m = system.materials[0].description();
    if (m.plasticity != PlasticityModel::None &&
        !(m.plasticity == PlasticityModel::VonMises && m.elasticity == ElasticityModel::StvkHencky))
        throw std::invalid_argument(
            "FemAdjoint: materials[0].plasticity: the adjoint is of elastic bodies and of "
            "von Mises with StVK-Hencky (the other return mappings' derivatives are not "
            "written yet)");
    for (std::size_t i = 0; i < system.fixed_node.size(); ++i)
        if (system.fixed_node[i] && !system.prescribed_velocity[i].isZero())
            throw std::invalid_argument("FemAdjoint: fixed_node " + std::to_string(i) +
                                        ": moving kinematic nodes are not supported (clamps, at rest, are)");
}

template <int dim>
void FemAdjoint<dim>::set_friction(double mu, double eps_v) {
    if (!(mu >= 0.0) || !(eps_v > 0.0))
        throw std::invalid_argument("FemAdjoint: contact.friction >= 0 and contact.friction_eps_v > 0 are needed");
    if (!contact_ && mu > 0.0) throw std::invalid_argument("FemAdjoint: contact.friction without contact");
    mu_ = mu;
    eps_v_ = eps_v;
}

template <int dim>
typename FemAdjoint<dim>::Stepper FemAdjoint<dim>::make_stepper() const {
    Stepper s;
    s.integrator = std::make_unique<FemImplicitIntegrator<dim>>(system_, method_, options_, make_energy(), contact_);
    if (mu_ > 0.0) {
        s.friction = std::make_unique<Friction<dim>>(mu_, eps_v_);
        s.integrator->set_friction(s.friction.get(), contact_);
    }
    return s;
}

template <int dim>
void FemAdjoint<dim>::set_parameter_fields(const std::vector<std::string>& fields) {
    fields_ = perturbed_fields<dim>(system_.materials, fields, "FemAdjoint");
}

template <int dim>
std::unique_ptr<ParticleEnergy<dim>> FemAdjoint<dim>::make_energy() const {
    return model_free_energy<dim>(method_, options_, system_.materials);
}

template <int dim>
FemState<dim> FemAdjoint<dim>::forward(const FemState<dim>& start, double dt, int steps, int checkpoint_every,
                                       const std::function<void(int, const FemState<dim>&)>& observe) {
    if (!(dt > 0.0) || steps < 0 || checkpoint_every < 0)
        throw std::invalid_argument("FemAdjoint::forward: dt > 0, steps >= 0 and checkpoint_every >= 0 are needed");
    const int every = checkpoint_spacing(steps, checkpoint_every);
    const Stepper stepper = make_stepper();
    dt_ = dt;
    steps_ = steps;
    checkpoints_.clear();
    FemState<dim> state = start;
    state.x_previous.clear();  // backward Euler: no history
    state.v_previous.clear();
    for (int n = 0;; ++n) {
        if (n % every == 0 || n == steps) checkpoints_[n] = state;
        if (observe) observe(n, state);
        if (n == steps) break;
        stepper.integrator->step(state, dt, n);
    }
    peak_states_ = checkpoints_.size();
    return state;
}

template <int dim>
std::vector<FemState<dim>> FemAdjoint<dim>::segment(int first, int last) const {
    if (last - first == 1) return {checkpoints_.at(first), checkpoints_.at(last)};  // both kept
    // A fresh integrator: a step depends on its start state only (the contact's broad phase gives the
    // same bits whatever its cache, contact.hpp), so the recomputed states are the forward pass's.
    const Stepper stepper = make_stepper();
    std::vector<FemState<dim>> states{checkpoints_.at(first)};
    for (int n = first; n < last; ++n) {
        FemState<dim> next = states.back();
        stepper.integrator->step(next, dt_, n);
        states.push_back(std::move(next));
    }
    return states;
}

template <int dim>
FemRolloutGradient<dim> FemAdjoint<dim>::backward(const std::vector<Vec<dim>>& dL_dx,
                                                  const std::vector<Vec<dim>>& dL_dv) const {
    if (steps_ < 0) throw std::logic_error("FemAdjoint::backward: forward() first");
    std::vector<std::vector<Vec<dim>>> xs(steps_ + 1), vs(steps_ + 1);
    xs.back() = dL_dx;
    vs.back() = dL_dv;
    if (dL_dx.empty() || dL_dv.empty())
        throw std::invalid_argument("FemAdjoint::backward: dL/dx and dL/dv need one entry per node (" +
                                    std::to_string(system_.mesh.nodes()) + ")");
    return backward(xs, vs);
}

template <int dim>
FemRolloutGradient<dim> FemAdjoint<dim>::backward(const std::vector<std::vector<Vec<dim>>>& dL_dx,
                                                  const std::vector<std::vector<Vec<dim>>>& dL_dv) const {
    const std::size_t nodes = system_.mesh.nodes();
    if (steps_ < 0) throw std::logic_error("FemAdjoint::backward: forward() first");
    const std::size_t states = static_cast<std::size_t>(steps_) + 1;
    if (dL_dx.size() != states || dL_dv.size() != states)
        throw std::invalid_argument("FemAdjoint::backward: one dL/dx and one dL/dv per state (" +
                                    std::to_string(states) + ", the start and every step's end)");
    for (std::size_t k = 0; k < states; ++k)
        if ((!dL_dx[k].empty() && dL_dx[k].size() != nodes) || (!dL_dv[k].empty() && dL_dv[k].size() != nodes))
            throw std::invalid_argument("FemAdjoint::backward: state " + std::to_string(k) +
                                        ": dL/dx and dL/dv need one entry per node (" + std::to_string(nodes) +
                                        ") or none");
    const Eigen::Index n = static_cast<Eigen::Index>(dim * nodes);
    VecX xb = VecX::Zero(n), vb = VecX::Zero(n), mass(n);
    for (std::size_t i = 0; i < nodes; ++i) mass.template segment<dim>(dim * i).setConstant(system_.rest.node_mass[i]);
    // Adds state k's own cotangents to those flowing back into it.
    auto add_state = [&](std::size_t k) {
        for (std::size_t i = 0; i < nodes; ++i) {
            if (!dL_dx[k].empty()) xb.template segment<dim>(dim * i) += dL_dx[k][i];
            if (!dL_dv[k].empty()) vb.template segment<dim>(dim * i) += dL_dv[k][i];
        }
    };
    add_state(states - 1);
    const double E = system_.materials[0].description().elastic.E;
    const std::unique_ptr<ParticleEnergy<dim>> energy = make_energy();
    FemPotential<dim> potential(system_.mesh, system_.rest, *energy);      // the step's R and H
    FemPotential<dim> material_only(system_.mesh, system_.rest, *energy);  // without contact (dR/dE)
    // Each asked field's elastic force at p -+ delta (dR/dp by central differences): the energies and potentials of
    // the perturbed materials, set up as material_only.
    std::vector<std::unique_ptr<ParticleEnergy<dim>>> field_energies;
    std::vector<std::unique_ptr<FemPotential<dim>>> field_potentials;  // [2 f]: minus, [2 f + 1]: plus
    for (const PerturbedMaterials<dim>& field : fields_)
        for (const std::vector<Material<dim>>* materials : {&field.minus, &field.plus}) {
            field_energies.push_back(model_free_energy<dim>(method_, options_, *materials));
            field_potentials.push_back(
                std::make_unique<FemPotential<dim>>(system_.mesh, system_.rest, *field_energies.back()));
            field_potentials.back()->set_project_psd(false);
        }
    std::vector<double> field_bar(fields_.size(), 0.0);
    const bool return_mapped = method_ == FemMethod::ReturnMap;
    std::vector<Mat<dim>> FE;
    potential.set_contact(contact_);
    potential.set_project_psd(false);
    // Lagged friction: its pairs lagged at each step's start, as the forward step's; held, so the x^n
    // term of the adjoint takes the Hessian without it (frictionless).
    Friction<dim> friction(mu_, eps_v_);
    FemPotential<dim> frictionless(system_.mesh, system_.rest, *energy);
    const bool frictional = mu_ > 0.0;
    std::vector<FemPotential<dim>*> potentials{&potential, &material_only};
    for (const auto& p : field_potentials) potentials.push_back(p.get());
    if (frictional) {
        potentials.push_back(&frictionless);
        potential.set_friction(&friction);
        frictionless.set_contact(contact_);
        frictionless.set_project_psd(false);
    }
    FemRolloutGradient<dim> out;
    const Material<dim>& material = system_.materials[0];
    const bool plastic = material.description().plasticity != PlasticityModel::None;
    const std::size_t elements = system_.mesh.elements.size();
    std::vector<Mat<dim>> pb(elements, Mat<dim>::Zero());  // dL/d(F^P)^-1 of the state being reached back to
    std::vector<double> hb(elements, 0.0);                 // dL/dh likewise
    // Per element, at the step's end: F = F(x^{n+1}), the SVD of F (F^P)^-1 and the return mapping's
    // derivatives there (the state update and the residual's terms both need them).
    std::vector<Mat<dim>> F_end(plastic ? elements : 0);
    std::vector<PolarSVD<dim>> svd_end(F_end.size());
    std::vector<ReturnMapDerivative<dim>> d_end(F_end.size());
    // Clamps (fixed nodes at rest) are no unknowns: their v* is 0 and their lambda is 0 (the masked
    // Hessian keeps only their mass, so the free nodes' lambda does not see them).
    std::vector<char> fixed_components(dim * nodes, 0);
    for (std::size_t i = 0; i < system_.fixed_node.size(); ++i)
        for (int a = 0; a < dim; ++a) fixed_components[dim * i + a] = system_.fixed_node[i];
    Eigen::SimplicialLDLT<SparseMatrix> ldlt;
    std::vector<Vec<dim>> x_hat(nodes);
    VecX xpb = VecX::Zero(n), vpb = VecX::Zero(n);  // the cotangents of a state's history (x^{n-1}, v^{n-1})
    VecX v(n), v_star(n), gradient(n);
    // Segment by segment between checkpoints, the last first; each recomputed from its checkpoint.
    std::vector<int> marks;
    for (const auto& [step, state] : checkpoints_) marks.push_back(step);
    for (std::size_t j = marks.size() - 1; j-- > 0;) {
        const std::vector<FemState<dim>> kept = segment(marks[j], marks[j + 1]);
        peak_states_ = std::max(peak_states_, checkpoints_.size() + kept.size());
        for (int k = marks[j + 1] - 1; k >= marks[j]; --k) {
            const FemState<dim>& start = kept[k - marks[j]];
            const FemState<dim>& next = kept[k - marks[j] + 1];
            if (plastic) {
                // The return mapping after the solve: (F^P)^-1' = F^-1 F^E(F (F^P)^-1, h), h' = h'(...), with
                // F = F(x^{n+1}): back into x^{n+1} (xb), (F^P)^-1 and h of the step's start.
                for (std::size_t e = 0; e < elements; ++e) {
                    const Mat<dim>& F = F_end[e] = deformation_gradient(system_.mesh, system_.rest, next.x, e);
                    const Mat<dim>& Pn = start.plastic_inverse[e];
                    svd_end[e] = clamped_svd<dim>(Mat<dim>(F * Pn));
                    const ReturnMapDerivative<dim>& d = d_end[e] =
                        return_map_derivative<dim>(material, svd_end[e], start.hardening[e]);
                    const Mat<dim> F_inv_T = F.inverse().transpose();
                    const Mat<dim> FE_bar = F_inv_T * pb[e];
                    Mat<dim> F_bar = -F_inv_T * pb[e] * next.plastic_inverse[e].transpose();
                    // The asked fields' share through the return mapping, by central differences in p.
                    for (std::size_t f = 0; f < fields_.size(); ++f) {
                        const PerturbedMaterials<dim>& field = fields_[f];
                        const int object = system_.element_object[e];
                        if (!field.has[object]) continue;
                        const ReturnResult<dim> up =
                            field.plus[object].return_map(svd_end[e].Sigma, start.hardening[e]);
                        const ReturnResult<dim> down =
                            field.minus[object].return_map(svd_end[e].Sigma, start.hardening[e]);
                        const Mat<dim> dFE = svd_end[e].compose((up.Sigma - down.Sigma) / (2.0 * field.delta));
                        field_bar[f] += FE_bar.cwiseProduct(dFE).sum() +
                                        hb[e] * (up.hardening - down.hardening) / (2.0 * field.delta);
                    }
                    const Mat<dim> Ft_bar =
                        unflatten<dim>(d.dFE_dF.transpose() * flatten<dim>(FE_bar)) + hb[e] * d.dh_dF;
                    hb[e] = d.dFE_dh.cwiseProduct(FE_bar).sum() + d.dh_dh * hb[e];
                    F_bar += Ft_bar * Pn.transpose();
                    pb[e] = F.transpose() * Ft_bar;
                    for (int a = 0; a <= dim; ++a)
                        xb.template segment<dim>(dim * system_.mesh.elements[e][a]) += F_bar * system_.rest.grad[e][a];
                }
            }
            // BDF2 (once the state has history): the potential about x^ = c x^n - p x^{n-1} with the step
            // h = beta dt (fem_integrator.hpp); backward Euler: c = 1, p = 0, h = dt.
            const bool bdf2 = options_.time_integrator == "bdf2" && start.x_previous.size() == nodes;
            const Bdf2Weights w = bdf2 ? bdf2_weights(start.dt_previous > 0.0 ? dt_ / start.dt_previous : 1.0)
                                       : Bdf2Weights{1.0, 0.0, 1.0};
            const double h = w.beta * dt_;
            for (std::size_t i = 0; i < nodes; ++i) {
                v.template segment<dim>(dim * i) = next.v[i];
                x_hat[i] = bdf2 ? Vec<dim>(w.current * start.x[i] - w.previous * start.x_previous[i]) : start.x[i];
                const Vec<dim> v_hat =
                    bdf2 ? Vec<dim>(w.current * start.v[i] - w.previous * start.v_previous[i]) : start.v[i];
                v_star.template segment<dim>(dim * i) =
                    fixed_components[dim * i] ? Vec<dim>::Zero() : Vec<dim>(v_hat + h * system_.gravity);
            }
            if (frictional) friction.lag(*contact_, start.x);
            for (FemPotential<dim>* p : potentials) {
                p->begin_step(x_hat, v_star, h, start.plastic_inverse, fixed_components);
                p->set_material_state(system_.element_object, start.hardening);
                p->set_reference({});
            }
            if (return_mapped) {  // the return-mapped stress is evaluated at its reference: the iterate
                potential.deformation(v, FE);
                for (FemPotential<dim>* p : potentials) p->set_reference(FE);
            }
            potential.prepare_hessian(v);
            ldlt.compute(*potential.hessian_matrix());
            if (ldlt.info() != Eigen::Success)
                throw std::runtime_error("FemAdjoint::backward: step " + std::to_string(k) +
                                         ": the step's Hessian could not be factorized");
            const VecX rhs = vb + h * xb;
            VecX lambda = ldlt.solve(rhs);
            for (Eigen::Index c = 0; c < n; ++c)
                if (fixed_components[c]) lambda[c] = 0.0;
            const VecX m_lambda = mass.cwiseProduct(lambda);
            // dR/dE = g_el / E, g_el the elastic form's gradient in v: the elastic potential's gradient
            // less its inertia M (v - v*).
            material_only.value_gradient(v, gradient);
            gradient -= mass.cwiseProduct(v - v_star);
            out.youngs_modulus -= lambda.dot(gradient) / E;
            for (std::size_t f = 0; f < fields_.size(); ++f) {  // dR/dp = (g(p + delta) - g(p - delta)) / (2 delta)
                VecX minus, plus;
                field_potentials[2 * f]->value_gradient(v, minus);
                field_potentials[2 * f + 1]->value_gradient(v, plus);
                field_bar[f] -= lambda.dot(plus - minus) / (2.0 * fields_[f].delta);
            }
            if (plastic) {
                // The residual's dependence on the start's (F^P)^-1: -lambda . dR/d(F^P)^-1 with
                // lambda . g_el = dt V P(F (F^P)^-1) : (G (F^P)^-1), G = sum_a lambda_a g_a^T.
                for (std::size_t e = 0; e < elements; ++e) {
                    const Mat<dim>& F = F_end[e];
                    const Mat<dim>& Pn = start.plastic_inverse[e];
                    const PolarSVD<dim>& svd = svd_end[e];
                    Mat<dim> G = Mat<dim>::Zero();
                    for (int a = 0; a <= dim; ++a)
                        G += lambda.template segment<dim>(dim * system_.mesh.elements[e][a]) *
                             system_.rest.grad[e][a].transpose();
                    const Mat<dim> GP = G * Pn;
                    const double scale = h * system_.rest.volume[e];
                    if (return_mapped) {
                        // Ptilde(A, h) and its consistent tangent T = dPtilde/dA (not symmetric in general: T^T).
                        const Mat<dim> P = material.elastoplastic_stress(svd, start.hardening[e]);
                        const Tensor4<dim> T = material.elastoplastic_tangent(svd, start.hardening[e], false, true);
                        const Mat<dim> TGP = unflatten<dim>(T.transpose() * flatten<dim>(GP));
                        pb[e] -= scale * (F.transpose() * TGP + G.transpose() * P);
                        hb[e] -= scale * d_end[e].dP_dh.cwiseProduct(GP).sum();
                    } else {
                        const Elasticity<dim>& elasticity = material.elasticity();
                        const Mat<dim> P = svd.compose(elasticity.tau(svd.Sigma).cwiseQuotient(svd.Sigma));
                        const Mat<dim> CGP = unflatten<dim>(elasticity.dPdF(svd, false) * flatten<dim>(GP));
                        pb[e] -= scale * (F.transpose() * CGP + G.transpose() * P);
                    }
                }
            }
            // x^'s cotangent: xb - (H_nf - M) lambda / h (the friction's lagged pairs held; H_nf = H
            // without friction, and H lambda = rhs); v^'s: M lambda. Then x^n and v^n take c times them
            // and what flows back through the next state's history (x_prev = x^n, v_prev = v^n); the
            // history of this state, -p times them.
            VecX x_hat_bar = xb;
            if (frictional) {
                frictionless.prepare_hessian(v);
                x_hat_bar -= (*frictionless.hessian_matrix() * lambda - m_lambda) / h;
            } else {
                x_hat_bar -= (rhs - m_lambda) / h;
            }
            xb = w.current * x_hat_bar + xpb;
            vb = w.current * m_lambda + vpb;
            xpb = -w.previous * x_hat_bar;
            vpb = -w.previous * m_lambda;
            // A clamp's velocity is prescribed (0), whatever the start's: nothing flows back through it.
            for (std::size_t i = 0; i < system_.fixed_node.size(); ++i)
                if (system_.fixed_node[i]) {
                    vb.template segment<dim>(dim * i).setZero();
                    vpb.template segment<dim>(dim * i).setZero();
                }
            add_state(static_cast<std::size_t>(k));
        }
    }
    out.hardening = hb;
    out.plastic_inverse = pb;
    out.fields = field_bar;
    out.x.resize(nodes);
    out.v.resize(nodes);
    for (std::size_t i = 0; i < nodes; ++i) {
        // A clamp's start position: its pull on the free nodes is not in the masked Hessian, so its
        // gradient is not computed (0).
        const bool clamp = i < system_.fixed_node.size() && system_.fixed_node[i];
        out.x[i] = clamp ? Vec<dim>::Zero() : Vec<dim>(xb.template segment<dim>(dim * i));
        out.v[i] = clamp ? Vec<dim>::Zero() : Vec<dim>(vb.template segment<dim>(dim * i));
    }
    return out;
}

template class FemAdjoint<2>;
template class FemAdjoint<3>;

}  // namespace pnet
