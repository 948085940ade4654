#pragma once
// The derivatives of a step's state update by the return mapping, for the adjoint of an elastoplastic
// step (docs/adjoint.md): with F_trial = U diag(Sigma) V^T, the return-mapped elastic deformation
// F^E = U diag(Z(Sigma, h)) V^T and the new hardening h' = h'(Sigma, h), their derivatives with respect
// to F_trial and h. F^E is an isotropic matrix function of F_trial, so its derivative in the (U, V)
// frame is that of its singular values on the diagonal and, for each pair i < j, the 2 x 2 block
// [[a, b], [b, a]] on the (ij, ji) entries with a = (D + E) / 2, b = (D - E) / 2,
// D = (Z_i - Z_j) / (Sigma_i - Sigma_j), E = (Z_i + Z_j) / (Sigma_i + Sigma_j) (isotropic_dPdF's
// structure), D formed so that it is exact for equal singular values.
//
// Written for the materials whose return mapping has a closed form: elastic ones (F^E = F_trial),
// von Mises with StVK-Hencky (eq. 22: log Z = m 1 + h n with m the mean log strain and n the unit
// deviatoric direction, h' = h + xi (L - h), L = |dev log Sigma|, where L > h) and Drucker-Prager (its
// cone: log Z = tr/d 1 - c tr n with tr = tr(log Sigma), c = alpha(phi) (d lambda + 2 mu) / (2 mu), where
// ||dev log Sigma|| + c tr > 0 and tr <= 0; its apex, tr > 0: Z = 1; with the derivatives in the
// friction angle phi too). At a branch's boundary (the yield onset, the cone's edge, the apex) the
// derivative is one-sided, the branch the mapping takes there. Cam-Clay's exact variant (J kept; the paper's
// is refused) through forward-mode dual numbers of its own projection (CamClay::project_with, math/dual.hpp),
// with its pair quotients D = k (Sigma_i + Sigma_j) / (Z_i + Z_j), k the deviatoric scale; the hardening a
// and the parameters xi, beta and the friction angle (through M) too. Others (von Mises with another
// elasticity) throw std::invalid_argument.
#include <array>
#include <string>
#include <vector>

#include "pnet/material/material.hpp"

namespace pnet {

/// The plasticity parameters whose derivatives the adjoint takes: the friction angle (Drucker-Prager,
/// Cam-Clay; per degree) and Cam-Clay's xi and beta.
enum class PlasticityParameter : int { FrictionAngle = 0, Xi = 1, Beta = 2 };
constexpr int kPlasticityParameters = 3;

template <int dim>
struct ReturnMapDerivative {
    Tensor4<dim> dFE_dF = Tensor4<dim>::Identity();  // d vec(F^E) / d vec(F_trial), row-major vec
    Mat<dim> dFE_dh = Mat<dim>::Zero();              // d F^E / d h
    Mat<dim> dh_dF = Mat<dim>::Zero();               // d h' / d F_trial
    double dh_dh = 1.0;                              // d h' / d h
    Mat<dim> dP_dh = Mat<dim>::Zero();               // d Ptilde / d h: the return-mapped stress's
    /// In the plasticity parameters (indexed by PlasticityParameter; zero where the model has none): d F^E,
    /// d h' and d Ptilde at F_trial (Pa per unit; per degree for the friction angle).
    std::array<Mat<dim>, kPlasticityParameters> dFE_dparameter = {Mat<dim>::Zero(), Mat<dim>::Zero(), Mat<dim>::Zero()};
    std::array<double, kPlasticityParameters> dh_dparameter = {0.0, 0.0, 0.0};
    std::array<Mat<dim>, kPlasticityParameters> dP_dparameter = {Mat<dim>::Zero(), Mat<dim>::Zero(), Mat<dim>::Zero()};
    bool yielded = false;  // the plastic branch
};

/// Drucker-Prager's return-mapped stress Ptilde's derivative dPtilde/dF at F = svd, in closed form (its
/// skew part kept, unprojected; one-sided at the branches' boundaries): the exact Jacobian where the
/// consistent tangent's stencil averages two branches within its step of a boundary (the MPM adjoint's).
template <int dim>
Tensor4<dim> drucker_prager_tangent(const Material<dim>& material, const PolarSVD<dim>& svd);

/// The return-mapped stress's Jacobian dPtilde/dF at F = svd, the hardening held at h (its skew part kept,
/// unprojected): exact where the return mapping's derivative is written (Drucker-Prager, Cam-Clay's exact
/// variant, von Mises with StVK-Hencky; one-sided at the branches' boundaries, where the stencil would average
/// two branches), else Material::elastoplastic_tangent's stencil.
template <int dim>
Tensor4<dim> return_map_tangent(const Material<dim>& material, const PolarSVD<dim>& svd, double h);

/// The derivatives at F_trial = svd (the clamped polar SVD the step's return mapping used) and h. update false:
/// the return-mapped stress's alone (dP_dh, dP_dparameter), for a solve's stress at F (not the state's update).
template <int dim>
ReturnMapDerivative<dim> return_map_derivative(const Material<dim>& material, const PolarSVD<dim>& svd, double h,
                                               bool update = true);

/// The materials of a system with one material field (material_parameter's: "elasticity.nu",
/// "plasticity.hardening_coefficient", ...) moved by -delta and +delta where they have it, and delta: for a
/// parameter's derivative by central differences of the material's stress and return mapping (the adjoint of
/// the parameters with no closed-form derivative written).
template <int dim>
struct PerturbedMaterials {
    std::string field;
    double delta = 0.0;
    std::vector<Material<dim>> minus, plus;
    std::vector<char> has;  // per material: whether it has the field
};

/// The materials with `field` moved by -+ 1e-6 max(|p|, 1) (the largest |p| of those that have it); `who` prefixes
/// the std::invalid_argument thrown where none has it.
template <int dim>
PerturbedMaterials<dim> perturbed_materials(const std::vector<Material<dim>>& materials, const std::string& field,
                                            const std::string& who);
/// perturbed_materials of each field, in order.
template <int dim>
std::vector<PerturbedMaterials<dim>> perturbed_fields(const std::vector<Material<dim>>& materials,
                                                      const std::vector<std::string>& fields, const std::string& who) {
    std::vector<PerturbedMaterials<dim>> out;
    for (const std::string& field : fields) out.push_back(perturbed_materials<dim>(materials, field, who));
    return out;
}

}  // namespace pnet
