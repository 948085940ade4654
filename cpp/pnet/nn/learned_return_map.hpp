#pragma once
// The learned volume-preserving return mapping of paper eq. 12 (von Mises with
// the metal neo-Hookean elasticity, which has no closed-form projection), the
// C++ twin of python/plasticitynet/training/return_map_net.py:
//
//   Sigma_c = max(Sigma, 1e-4), eps = log Sigma_c, L = ||dev eps||, n = dev eps / L,
//   dgamma = min(N(Sigma_c, h), L),
//   Z = exp(eps - dgamma n), h_new = h + xi dgamma   where y(Sigma_c, h) > 0 and L > 0,
//   Z = Sigma_c, h_new = h                            elsewhere.
//
// The network's input is dimensionless (Sigma and h = tau_Y / (2 mu)), so the
// mapping does not depend on the scene's Young's modulus.
#include <cstddef>

#include "pnet/material/material.hpp"
#include "pnet/nn/fused_mlp.hpp"
#include "pnet/nn/model_file.hpp"

namespace pnet {

template <int dim>
class LearnedReturnMap {
public:
    /// Throws std::invalid_argument (naming the file) unless `model` is a
    /// return map of this dimension with von Mises plasticity.
    explicit LearnedReturnMap(const ModelFile& model);

    /// Z_theta(Sigma, h); branch Yield where the mapping projects.
    ReturnResult<dim> return_map(const Vec<dim>& Sigma, double hardening) const;
    /// The same for n states at once (one network evaluation for all).
    void return_map(const Vec<dim>* Sigma, const double* hardening, std::size_t n, ReturnResult<dim>* out) const;

    /// Ptilde(F, h) = U diag(tau(Z) / Sigma) V^T at the training Young's
    /// modulus (dimensionless: multiply by E).
    Mat<dim> elastoplastic_stress(const Mat<dim>& F, double hardening) const;
    /// The same for n states at once (one network evaluation), P[p] = Ptilde(F[p], hardening[p]).
    void elastoplastic_stress(const Mat<dim>* F, const double* hardening, std::size_t n, Mat<dim>* P) const;

    /// The material at the training E (its yield function decides who yields).
    const Material<dim>& material() const { return material_; }

private:
    Material<dim> material_;
    FusedMlp net_;
    double xi_;
    ModelMetadata metadata_;  // the network's hardening input range
};

}  // namespace pnet
