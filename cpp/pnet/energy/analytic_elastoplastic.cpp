#include "pnet/energy/analytic_elastoplastic.hpp"

#include <cmath>
#include <stdexcept>

namespace pnet {

template <int dim>
AnalyticElastoplasticEnergy<dim>::AnalyticElastoplasticEnergy(const std::vector<Material<dim>>& materials,
                                                              const std::vector<std::string>& context,
                                                              double regularizer_weight)
    : materials_(materials), w_(regularizer_weight) {
    if (!(regularizer_weight >= 0.0) || !std::isfinite(regularizer_weight))
        throw std::invalid_argument("AnalyticElastoplasticEnergy: the regularizer weight must be a finite number >= 0");
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
void AnalyticElastoplasticEnergy<dim>::set_reference(const std::vector<Mat<dim>>& F0,
                                                     const std::vector<double>& hardening,
                                                     const std::vector<int>& object) {
    object_ = object;
    hardening_ = hardening;
    if (w_ > 0.0) {
        if (F0.size() != object.size())
            throw std::invalid_argument("AnalyticElastoplasticEnergy: a regularized energy needs F0 per particle");
        F0_ = F0;
    }
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
        const double wmu = w_ * mu;
        const Mat<dim> dF = w_ > 0.0 ? Mat<dim>(F[p] - F0_[p]) : Mat<dim>::Zero();
        if (w_ > 0.0) psi[p] += 0.5 * wmu * dF.squaredNorm();
        if (order == Order::Value) continue;
        // tau_i = dpsi/de_i = 2 k tr + 2 mu s ehat_i, s = 1 (elastic) or h / |ehat| (plastic).
        const double s = plastic ? h / norm : 1.0;
        const Vec<dim> tau = (2.0 * k * tr) * Vec<dim>::Ones() + (2.0 * mu * s) * ehat;
        P[p] = svd.compose(tau.cwiseQuotient(svd.Sigma)) + wmu * dF;
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
        // w mu I is PSD: adding it after the projection keeps H PSD.
        if (w_ > 0.0) H[p].diagonal().array() += wmu;
    }
}

template class AnalyticElastoplasticEnergy<2>;
template class AnalyticElastoplasticEnergy<3>;

}  // namespace pnet
