#include "pnet/energy/return_mapping_energy.hpp"

namespace pnet {

template <int dim>
ReturnMappingEnergy<dim>::ReturnMappingEnergy(const std::vector<Material<dim>>& materials, double tangent_damping)
    : materials_(materials), tangent_damping_(tangent_damping) {
    for (const Material<dim>& m : materials) {
        const PlasticityModel plasticity = m.description().plasticity;
        const bool associative = plasticity == PlasticityModel::VonMises || plasticity == PlasticityModel::None;
        keep_skew_.push_back(!associative);
        symmetric_ = symmetric_ && associative;
    }
}

template <int dim>
void ReturnMappingEnergy<dim>::set_reference(const std::vector<Mat<dim>>& F0, const std::vector<double>& hardening,
                                             const std::vector<int>& object) {
    F0_ = F0;
    hardening_ = hardening;
    object_ = object;
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(F0.size());
    // The last reference's SVDs (the same particles, the last Newton iterate's) start this one's:
    // polar_svd's warm start. A step's first reference starts cold (begin_step).
    const bool warm = static_cast<std::ptrdiff_t>(svd0_.size()) == n;
    svd0_.resize(n);
    stress0_.resize(n);
#pragma omp parallel for schedule(static) if (n >= 64)
    for (std::ptrdiff_t p = 0; p < n; ++p) {
        svd0_[p] = warm ? clamped_svd<dim>(F0[p], svd0_[p].V) : clamped_svd<dim>(F0[p]);
        stress0_[p] = materials_[object[p]].elastoplastic_stress(svd0_[p], hardening[p]);
    }
}

template <int dim>
void ReturnMappingEnergy<dim>::evaluate(const std::vector<Mat<dim>>& F, typename ParticleEnergy<dim>::Order order,
                                        double* psi, Mat<dim>* P, Tensor4<dim>* H, bool project_psd) {
    using Order = typename ParticleEnergy<dim>::Order;
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(F.size());
#pragma omp parallel for schedule(static) if (n >= 64)
    for (std::ptrdiff_t p = 0; p < n; ++p) {
        const Material<dim>& material = materials_[object_[p]];
        const double mu = material.elasticity().mu();
        const Mat<dim> dF = F[p] - F0_[p];
        const bool at_reference = (dF.array() == 0.0).all();
        const PolarSVD<dim> svd = at_reference ? svd0_[p] : clamped_svd<dim>(F[p]);
        const Mat<dim> stress = at_reference ? stress0_[p] : material.elastoplastic_stress(svd, hardening_[p]);
        psi[p] = 0.5 * (stress0_[p] + stress).cwiseProduct(dF).sum() + 0.5 * damping_ * mu * dF.squaredNorm();
        if (order == Order::Value) continue;
        P[p] = stress + damping_ * mu * dF;
        if (order != Order::Hessian) continue;
        const bool non_associative = keep_skew_[object_[p]];
        H[p] = material.elastoplastic_tangent(svd, hardening_[p], project_psd, non_associative);
        H[p].diagonal().array() += ((non_associative ? tangent_damping_ : 0.0) + damping_) * mu;
    }
}

template class ReturnMappingEnergy<2>;
template class ReturnMappingEnergy<3>;

}  // namespace pnet
