#pragma once
// Isotropic hyperelastic models in diagonal (principal) space.
//
// With F = U diag(Sigma) V^T (polar SVD) and eps = log(Sigma) (Hencky strain),
// each model gives an energy density psi(Sigma), the Kirchhoff stress
// tau_i = d psi / d eps_i (so tau = U diag(tau) U^T) and the first Piola stress
// P = tau F^{-T} = U diag(tau_i / Sigma_i) V^T. Formulas: docs/physics.md and the
// paper's eqs. 14 (StVK-Hencky), 17 (neo-Hookean, snow), 24 (neo-Hookean, metal).
#include <functional>
#include <string>

#include "pnet/math/svd.hpp"
#include "pnet/math/types.hpp"

namespace pnet {

enum class ElasticityModel { StvkHencky, NeoHookeanSnow, NeoHookeanMetal };

/// "stvk_hencky", "neo_hookean_snow", "neo_hookean_metal".
std::string to_string(ElasticityModel model);
/// Inverse of to_string(); throws std::invalid_argument naming the bad value.
ElasticityModel elasticity_model_from_string(const std::string& name);

/// Young's modulus and Poisson ratio, with the derived moduli.
struct ElasticParams {
    double E = 1.0;   // Young's modulus, Pa
    double nu = 0.3;  // Poisson ratio, -1 < nu < 0.5

    double mu() const { return E / (2.0 * (1.0 + nu)); }
    double lambda() const { return E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)); }
    /// Bulk modulus E / (3 (1 - 2 nu)), used in 2D and 3D alike (as the paper).
    double K() const { return E / (3.0 * (1.0 - 2.0 * nu)); }

    /// Throws std::invalid_argument unless E > 0 and -1 < nu < 0.5, both finite.
    void validate() const;
};

/// A hyperelastic model evaluated in diagonal space. All Sigma arguments are
/// clamped singular values (>= kSigmaMin, see clamp_singular_values()).
template <int dim>
class Elasticity {
public:
    Elasticity(ElasticityModel model, const ElasticParams& params);

    ElasticityModel model() const { return model_; }
    const ElasticParams& params() const { return params_; }
    double mu() const { return mu_; }
    double lambda() const { return lambda_; }
    double K() const { return K_; }

    /// Energy density psi(Sigma), J/m^3 (zero at Sigma = 1).
    double psi(const Vec<dim>& Sigma) const;
    /// Kirchhoff stress in diagonal space, tau_i = d psi / d eps_i.
    Vec<dim> tau(const Vec<dim>& Sigma) const;
    /// The same stress from the Hencky strain eps = log(Sigma).
    Vec<dim> tau_of_strain(const Vec<dim>& eps) const;
    /// d tau_i / d eps_j.
    Mat<dim> dtau_deps(const Vec<dim>& Sigma) const;
    /// (tau_i - tau_j) / (Sigma_i - Sigma_j) for i != j, evaluated in closed
    /// form so that it stays exact as Sigma_i -> Sigma_j.
    double tau_difference_quotient(const Vec<dim>& Sigma, int i, int j) const;

    /// F-space quantities (polar SVD + clamp inside).
    double psi_F(const Mat<dim>& F) const;
    Mat<dim> P(const Mat<dim>& F) const;
    /// dP/dF in the row-major vec() basis. With project_psd the eigenvalues of
    /// the diagonal block and of each 2x2 twist/flip block are clamped at zero,
    /// which makes the whole tensor positive semi-definite.
    Tensor4<dim> dPdF(const Mat<dim>& F, bool project_psd = false) const;
    /// Same, from a precomputed (clamped) SVD.
    Tensor4<dim> dPdF(const PolarSVD<dim>& svd, bool project_psd = false) const;

private:
    ElasticityModel model_;
    ElasticParams params_;
    double mu_, lambda_, K_;
};

/// dP/dF (row-major vec basis) of an isotropic energy given in diagonal space
/// by its Kirchhoff stress tau_i = dpsi/deps_i, dtau_i/deps_j and the
/// difference quotients (tau_i - tau_j) / (Sigma_i - Sigma_j) (closed form, so
/// that equal singular values are exact), at the polar SVD svd. With
/// project_psd the result is positive semi-definite (the Sigma block and each
/// twist/flip pair clamped).
template <int dim>
Tensor4<dim> isotropic_dPdF(const PolarSVD<dim>& svd, const Vec<dim>& tau, const Mat<dim>& dtau_deps,
                            const std::function<double(int, int)>& tau_quotient, bool project_psd);

/// A derivative given in the (U, V) frame of svd (entry (i d + j, k d + l): d(U^T dP V)_ij / d(U^T dF V)_kl)
/// in the row-major vec(F) basis: W A W^T, column i d + j of W being vec(u_i v_j^T).
template <int dim>
Tensor4<dim> to_f_space(const PolarSVD<dim>& svd, const Tensor4<dim>& A);

/// (log a - log b) / (a - b), exact as a -> b (1 / a there).
double log_difference_quotient(double a, double b);

/// Sigma with every entry raised to at least kSigmaMin (inverted -> kSigmaMin).
template <int dim>
Vec<dim> clamp_singular_values(const Vec<dim>& Sigma);

/// Polar SVD of F with clamped singular values; throws std::invalid_argument if
/// F has a non-finite entry (named by row and column).
template <int dim>
PolarSVD<dim> clamped_svd(const Mat<dim>& F);
/// The same, the SVD started from V_start (polar_svd's warm start).
template <int dim>
PolarSVD<dim> clamped_svd(const Mat<dim>& F, const Mat<dim>& V_start);

/// Throws std::invalid_argument naming `what` and the first non-finite entry.
template <int dim>
void require_finite(const Mat<dim>& F, const char* what);

}  // namespace pnet
