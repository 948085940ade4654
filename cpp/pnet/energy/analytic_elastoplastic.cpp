#include "pnet/energy/analytic_elastoplastic.hpp"

#include <cmath>
#include <stdexcept>

namespace pnet {

template <int dim>
AnalyticElastoplasticEnergy<dim>::AnalyticElastoplasticEnergy(const std::vector<Material<dim>>& materials,
                                                              const std::vector<std::string>& context)
    : materials_(materials) {
    if (context.size() != materials.size())
        throw std::invalid_argument("AnalyticElastoplasticEnergy: one context per material is needed");
    for (std::size_t k = 0; k < materials.size(); ++k) {
        const MaterialDescription& m = materials[k].description();
        if (m.elasticity != ElasticityModel::StvkHencky || m.plasticity != PlasticityModel::VonMises)
            throw std::invalid_argument(context[k] + ": the analytic integrator needs StVK-Hencky elasticity with von "
                                        "Mises plasticity (the ECI closed-form energy), not " +
                                        to_string(m.elasticity) + " with " + to_string(m.plasticity));
    }
}

template <int dim>
void AnalyticElastoplasticEnergy<dim>::set_reference(const std::vector<Mat<dim>>&, const std::vector<double>& hardening,
                                                     const std::vector<int>& object) {
    object_ = object;
    hardening_ = hardening;
}

template <int dim>
void AnalyticElastoplasticEnergy<dim>::evaluate(const std::vector<Mat<dim>>& F,
                                                typename ParticleEnergy<dim>::Order order, double* psi, Mat<dim>* P,
                                                Tensor4<dim>* H, bool project_psd) {
    using Order = typename ParticleEnergy<dim>::Order;
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(F.size());
#pragma omp parallel for schedule(static) if (n >= 256)
    for (std::ptrdiff_t p = 0; p < n; ++p) {
        const Elasticity<dim>& elasticity = materials_[object_[p]].elasticity();
        const double mu = elasticity.mu(), k = 0.5 * elasticity.lambda() + mu / dim;
        const double h = hardening_[p];
        const PolarSVD<dim> svd = clamped_svd<dim>(F[p]);
        const Vec<dim> e = svd.Sigma.array().log().matrix();
        const double tr = e.sum();
        const Vec<dim> ehat = e.array() - tr / dim;
        const double norm = ehat.norm();
        const bool plastic = norm > h;
        psi[p] = k * tr * tr + (plastic ? 2.0 * mu * h * norm - mu * h * h : mu * norm * norm);
        if (order == Order::Value) continue;
        // tau_i = dpsi/de_i = 2 k tr + 2 mu s ehat_i, s = 1 (elastic) or h / |ehat| (plastic).
        const double s = plastic ? h / norm : 1.0;
        const Vec<dim> tau = (2.0 * k * tr) * Vec<dim>::Ones() + (2.0 * mu * s) * ehat;
        P[p] = svd.compose(tau.cwiseQuotient(svd.Sigma));
        if (order != Order::Hessian) continue;
        // dtau_i/de_j = 2 k + 2 mu s (delta_ij - 1/d) [- 2 mu h ehat_i ehat_j / |ehat|^3 when plastic].
        Mat<dim> dtau = Mat<dim>::Constant(2.0 * k - 2.0 * mu * s / dim);
        dtau.diagonal().array() += 2.0 * mu * s;
        if (plastic) dtau -= (2.0 * mu * h / (norm * norm * norm)) * (ehat * ehat.transpose());
        // (tau_i - tau_j) / (Sigma_i - Sigma_j) = 2 mu s (e_i - e_j) / (Sigma_i - Sigma_j).
        const Vec<dim> S = svd.Sigma;
        H[p] = isotropic_dPdF<dim>(svd, tau, dtau,
                                   [&](int i, int j) { return 2.0 * mu * s * log_difference_quotient(S[i], S[j]); },
                                   project_psd);
    }
}

template class AnalyticElastoplasticEnergy<2>;
template class AnalyticElastoplasticEnergy<3>;

}  // namespace pnet
