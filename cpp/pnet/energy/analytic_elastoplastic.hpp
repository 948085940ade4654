#pragma once
// The closed-form elastoplastic energy of StVK-Hencky elasticity with von
// Mises plasticity (ECI: Li, Li, Jiang 2022; docs/methods.md), the `analytic`
// reference integrator of the metal scenes. With e = log Sigma, ehat = dev e,
// k = lambda/2 + mu/d and h = tau_Y / (2 mu) the element's hardening state:
//   psi = k tr(e)^2 + mu |ehat|^2               if |ehat| <= h (elastic),
//   psi = k tr(e)^2 + 2 mu h |ehat| - mu h^2    otherwise,
// which is C1 in F and whose gradient is exactly the elastoplastic stress
// Ptilde(F, h) = tau(Z(F, h)) F^-T of the von Mises return mapping: an implicit
// run with it isolates the time discretization from the learning error.
//
// With a regularizer weight w > 0 it becomes a stand-in for the learned energy whose local
// approximation is exact: psi(F) + w mu/2 ||F - F0||^2 about the reference F0, the same proximal
// term as paper eq. 11. Its gradient at F = F0 is Ptilde(F0, h) and its fixed point on F0 is the
// analytic step for any w, so the outer iteration's rate can be measured without learning error
// (docs/solver.md).
#include <vector>

#include "pnet/energy/particle_energy.hpp"
#include "pnet/material/material.hpp"

namespace pnet {

template <int dim>
class AnalyticElastoplasticEnergy final : public ParticleEnergy<dim> {
public:
    /// Throws std::invalid_argument naming context[k] unless every material is
    /// StVK-Hencky with von Mises plasticity.
    AnalyticElastoplasticEnergy(const std::vector<Material<dim>>& materials, const std::vector<std::string>& context,
                                double regularizer_weight = 0.0);

    /// Records each particle's object and hardening state h (and F0 when regularized).
    void set_reference(const std::vector<Mat<dim>>& F0, const std::vector<double>& hardening,
                       const std::vector<int>& object) override;
    void evaluate(const std::vector<Mat<dim>>& F, typename ParticleEnergy<dim>::Order order, double* psi, Mat<dim>* P,
                  Tensor4<dim>* H, bool project_psd = true) override;

private:
    const std::vector<Material<dim>>& materials_;
    std::vector<int> object_;
    std::vector<double> hardening_;
    std::vector<Mat<dim>> F0_;
    double w_;  // regularizer weight (0: the plain energy)
};

}  // namespace pnet
