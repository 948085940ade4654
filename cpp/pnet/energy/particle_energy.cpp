#include "pnet/energy/particle_energy.hpp"

#include <cmath>
#include <stdexcept>

namespace pnet {

template <int dim>
void ElasticParticleEnergy<dim>::set_reference(const std::vector<Mat<dim>>&, const std::vector<double>&,
                                               const std::vector<int>& object) {
    object_ = object;
}

template <int dim>
void ElasticParticleEnergy<dim>::evaluate(const std::vector<Mat<dim>>& F, typename ParticleEnergy<dim>::Order order,
                                          double* psi, Mat<dim>* P, Tensor4<dim>* H, bool project_psd) {
    using Order = typename ParticleEnergy<dim>::Order;
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(F.size());
#pragma omp parallel for schedule(static) if (n >= 256)
    for (std::ptrdiff_t p = 0; p < n; ++p) {
        const Elasticity<dim>& elasticity = materials_[object_[p]].elasticity();
        const PolarSVD<dim> svd = clamped_svd<dim>(F[p]);
        psi[p] = elasticity.psi(svd.Sigma);
        if (order == Order::Value) continue;
        const Vec<dim> tau = elasticity.tau(svd.Sigma);
        P[p] = svd.compose(tau.cwiseQuotient(svd.Sigma));
        if (order == Order::Hessian) H[p] = elasticity.dPdF(svd, project_psd);
    }
}

template <int dim>
NeuralParticleEnergy<dim>::NeuralParticleEnergy(const std::vector<std::shared_ptr<const ModelFile>>& models,
                                                const std::vector<Material<dim>>& materials,
                                                const std::vector<std::string>& context, double regularizer_weight,
                                                typename NeuralElastoplasticEnergy<dim>::Options::Hessian hessian,
                                                double tangent_damping)
    : NeuralParticleEnergy(models, materials, context, std::vector<double>(materials.size(), regularizer_weight),
                           hessian, tangent_damping) {}

template <int dim>
NeuralParticleEnergy<dim>::NeuralParticleEnergy(const std::vector<std::shared_ptr<const ModelFile>>& models,
                                                const std::vector<Material<dim>>& materials,
                                                const std::vector<std::string>& context,
                                                const std::vector<double>& regularizer_weights,
                                                typename NeuralElastoplasticEnergy<dim>::Options::Hessian hessian,
                                                double tangent_damping, FusedMlp::Precision hessian_precision,
                                                double network_reuse) {
    if (models.size() != materials.size() || context.size() != materials.size() ||
        regularizer_weights.size() != materials.size())
        throw std::invalid_argument("NeuralParticleEnergy: one model, context and weight per object are needed");
    for (std::size_t k = 0; k < materials.size(); ++k) {
        if (!models[k])
            throw std::invalid_argument(context[k] + ": the plasticitynet integrator needs an energy model for "
                                                     "every object (none given)");
        const ModelFile& model = *models[k];
        // The model checks the object's material (material_for_object): the same constitutive model,
        // and for a parametric model its parameters within their trained ranges.
        const MaterialDescription& scene = materials[k].description();
        Group group;
        try {
            // The forms that sum these energies (MPM particles, FEM elements) take non-symmetric
            // Hessians, so the tangent of non-associative flow keeps its skew part.
            group.energy = std::make_unique<NeuralElastoplasticEnergy<dim>>(
                model, typename NeuralElastoplasticEnergy<dim>::Options{scene.elastic.E, regularizer_weights[k],
                                                                        /*relative_to_reference=*/true, hessian,
                                                                        scene, tangent_damping,
                                                                        /*nonsymmetric_tangent=*/true,
                                                                        hessian_precision, network_reuse});
        } catch (const std::invalid_argument& e) {
            throw std::invalid_argument(context[k] + ": " + e.what());
        }
        objects_.push_back(std::move(group));
    }
}

template <int dim>
void NeuralParticleEnergy<dim>::set_reference(const std::vector<Mat<dim>>& F0, const std::vector<double>& hardening,
                                              const std::vector<int>& object) {
    if (objects_.size() == 1) {  // one object: evaluate() needs no gathering
        objects_[0].energy->set_reference(F0.data(), hardening.data(), F0.size());
        hardening_clamped_ = objects_[0].energy->hardening_clamped();
        return;
    }
    hardening_clamped_ = 0;
    for (Group& g : objects_) g.particles.clear();
    for (std::size_t p = 0; p < object.size(); ++p) objects_.at(object[p]).particles.push_back(static_cast<int>(p));
    std::vector<Mat<dim>> F0_group;
    std::vector<double> h_group;
    for (Group& g : objects_) {
        const std::size_t n = g.particles.size();
        F0_group.resize(n);
        h_group.resize(n);
        for (std::size_t q = 0; q < n; ++q) {
            F0_group[q] = F0[g.particles[q]];
            h_group[q] = hardening[g.particles[q]];
        }
        g.F.resize(n);
        g.P.resize(n);
        g.psi.resize(n);
        g.H.resize(n);
        g.energy->set_reference(F0_group.data(), h_group.data(), n);
        hardening_clamped_ += g.energy->hardening_clamped();
    }
}

template <int dim>
void NeuralParticleEnergy<dim>::evaluate(const std::vector<Mat<dim>>& F, typename ParticleEnergy<dim>::Order order,
                                         double* psi, Mat<dim>* P, Tensor4<dim>* H, bool project_psd) {
    using Order = typename ParticleEnergy<dim>::Order;
    auto run = [order, project_psd](const NeuralElastoplasticEnergy<dim>& energy, const Mat<dim>* F, double* psi, Mat<dim>* P,
                       Tensor4<dim>* H) {
        if (order == Order::Value)
            energy.value(F, psi);
        else if (order == Order::Gradient)
            energy.value_gradient(F, psi, P);
        else
            energy.value_gradient_hessian(F, psi, P, H, project_psd);
    };
    if (objects_.size() == 1) {  // one object: no gathering
        run(*objects_[0].energy, F.data(), psi, P, H);
        return;
    }
    for (Group& g : objects_) {
        const std::size_t n = g.particles.size();
        if (n == 0) continue;
        for (std::size_t q = 0; q < n; ++q) g.F[q] = F[g.particles[q]];
        run(*g.energy, g.F.data(), g.psi.data(), g.P.data(), g.H.data());
        for (std::size_t q = 0; q < n; ++q) {
            const int p = g.particles[q];
            psi[p] = g.psi[q];
            if (order != Order::Value) P[p] = g.P[q];
            if (order == Order::Hessian) H[p] = g.H[q];
        }
    }
}

template class ElasticParticleEnergy<2>;
template class ElasticParticleEnergy<3>;
template class NeuralParticleEnergy<2>;
template class NeuralParticleEnergy<3>;

}  // namespace pnet
