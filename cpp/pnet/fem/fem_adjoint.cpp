#include "pnet/fem/fem_adjoint.hpp"

#include <stdexcept>
#include <string>

#include <Eigen/SparseCholesky>

#include "pnet/energy/particle_energy.hpp"

namespace pnet {

template <int dim>
FemAdjoint<dim>::FemAdjoint(const FemSystem<dim>& system, const ContactPotential<dim>* contact,
                            const ImplicitOptions& options)
    : system_(system), contact_(contact), options_(options) {
    if (system.materials.size() != 1)
        throw std::invalid_argument("FemAdjoint: materials: the adjoint takes one material (the scene has " +
                                    std::to_string(system.materials.size()) + ")");
    if (system.materials[0].description().plasticity != PlasticityModel::None)
        throw std::invalid_argument(
            "FemAdjoint: materials[0].plasticity: the adjoint is of elastic bodies (its "
            "return mapping's derivatives are not written yet)");
    for (char fixed : system.fixed_node)
        if (fixed) throw std::invalid_argument("FemAdjoint: fixed_node: kinematic nodes are not supported");
    if (options.time_integrator != "backward_euler")
        throw std::invalid_argument("FemAdjoint: time_integrator \"" + options.time_integrator +
                                    "\": the adjoint is of backward Euler");
}

template <int dim>
FemState<dim> FemAdjoint<dim>::forward(const FemState<dim>& start, double dt, int steps) {
    if (!(dt > 0.0) || steps < 0) throw std::invalid_argument("FemAdjoint::forward: dt > 0 and steps >= 0 are needed");
    FemImplicitIntegrator<dim> integrator(system_, FemMethod::Lagged, options_,
                                          std::make_unique<ElasticParticleEnergy<dim>>(system_.materials), contact_);
    dt_ = dt;
    tape_.assign(1, start);
    tape_.back().x_previous.clear();  // backward Euler: no history
    tape_.back().v_previous.clear();
    FemState<dim> state = tape_.back();
    for (int n = 0; n < steps; ++n) {
        integrator.step(state, dt, n);
        tape_.push_back(state);
    }
    return state;
}

template <int dim>
FemRolloutGradient<dim> FemAdjoint<dim>::backward(const std::vector<Vec<dim>>& dL_dx,
                                                  const std::vector<Vec<dim>>& dL_dv) const {
    if (tape_.empty()) throw std::logic_error("FemAdjoint::backward: forward() first");
    std::vector<std::vector<Vec<dim>>> xs(tape_.size()), vs(tape_.size());
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
    if (tape_.empty()) throw std::logic_error("FemAdjoint::backward: forward() first");
    if (dL_dx.size() != tape_.size() || dL_dv.size() != tape_.size())
        throw std::invalid_argument("FemAdjoint::backward: one dL/dx and one dL/dv per kept state (" +
                                    std::to_string(tape_.size()) + ", the start and every step's end)");
    for (std::size_t k = 0; k < tape_.size(); ++k)
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
    add_state(tape_.size() - 1);
    const double E = system_.materials[0].description().elastic.E;
    ElasticParticleEnergy<dim> energy(system_.materials);
    FemPotential<dim> potential(system_.mesh, system_.rest, energy);  // the step's R and H
    FemPotential<dim> elastic(system_.mesh, system_.rest, energy);    // its elastic part alone (dR/dE)
    potential.set_contact(contact_);
    potential.set_project_psd(false);
    FemRolloutGradient<dim> out;
    Eigen::SimplicialLDLT<SparseMatrix> ldlt;
    VecX v(n), v_star(n), gradient(n);
    for (std::size_t k = tape_.size() - 1; k-- > 0;) {
        const FemState<dim>& start = tape_[k];
        for (std::size_t i = 0; i < nodes; ++i) {
            v.template segment<dim>(dim * i) = tape_[k + 1].v[i];
            v_star.template segment<dim>(dim * i) = start.v[i] + dt_ * system_.gravity;
        }
        for (FemPotential<dim>* p : {&potential, &elastic}) {
            p->begin_step(start.x, v_star, dt_, start.plastic_inverse, {});
            p->set_material_state(system_.element_object, start.hardening);
            p->set_reference({});
        }
        potential.prepare_hessian(v);
        ldlt.compute(*potential.hessian_matrix());
        if (ldlt.info() != Eigen::Success)
            throw std::runtime_error("FemAdjoint::backward: step " + std::to_string(k) +
                                     ": the step's Hessian could not be factorized");
        const VecX rhs = vb + dt_ * xb;
        const VecX lambda = ldlt.solve(rhs);
        const VecX m_lambda = mass.cwiseProduct(lambda);
        // dR/dE = g_el / E, g_el the elastic form's gradient in v: the elastic potential's gradient
        // less its inertia M (v - v*).
        elastic.value_gradient(v, gradient);
        gradient -= mass.cwiseProduct(v - v_star);
        out.youngs_modulus -= lambda.dot(gradient) / E;
        xb -= (rhs - m_lambda) / dt_;
        vb = m_lambda;
        add_state(k);
    }
    out.x.resize(nodes);
    out.v.resize(nodes);
    for (std::size_t i = 0; i < nodes; ++i) {
        out.x[i] = xb.template segment<dim>(dim * i);
        out.v[i] = vb.template segment<dim>(dim * i);
    }
    return out;
}

template class FemAdjoint<2>;
template class FemAdjoint<3>;

}  // namespace pnet
