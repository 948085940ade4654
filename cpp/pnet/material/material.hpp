#pragma once
// A material = an elasticity model + a plastic return mapping + its hardening
// state, with the elastoplastic stress Ptilde(F, h) = tau(Z(F, h)) F^{-T}
// (paper eq. 5-6; docs/physics.md).
#include <string>
#include <variant>
#include <vector>

#include "pnet/material/cam_clay.hpp"
#include "pnet/material/drucker_prager.hpp"
#include "pnet/material/elasticity.hpp"
#include "pnet/material/von_mises.hpp"

namespace pnet {

enum class PlasticityModel { None, DruckerPrager, CamClay, VonMises };

/// "none", "drucker_prager", "cam_clay", "von_mises".
std::string to_string(PlasticityModel model);
PlasticityModel plasticity_model_from_string(const std::string& name);

/// Everything that defines a material; the same fields as the JSON description
/// (material_json.hpp) used by scenes, test vectors and model metadata.
struct MaterialDescription {
    std::string name = "custom";
    double density = 1000.0;          // kg/m^3
    double initial_hardening = 0.0;   // a (Cam-Clay) or h = tau_Y/(2 mu) (von Mises)
    ElasticityModel elasticity = ElasticityModel::StvkHencky;
    ElasticParams elastic;
    PlasticityModel plasticity = PlasticityModel::None;
    DruckerPragerParams drucker_prager;
    CamClayParams cam_clay;
    VonMisesParams von_mises;

    /// Throws std::invalid_argument naming the field and the problem.
    void validate() const;
};

/// A field in which two material descriptions differ: its JSON path (as in a
/// scene, e.g. "plasticity.friction_angle_deg") and both values as text.
struct MaterialDifference {
    std::string field, first, second;
};

/// The fields of the constitutive model (elasticity model and nu, plasticity
/// model and every one of its parameters) in which a and b differ; numbers are
/// equal to 1e-9 relative. Young's modulus, density and the initial hardening
/// are not compared: a learned energy is scaled by E, and the others are state.
std::vector<MaterialDifference> constitutive_differences(const MaterialDescription& a, const MaterialDescription& b);

/// The constitutive parameter at a scene path for d's models: "elasticity.nu",
/// and per plasticity model "plasticity.friction_angle_deg" (Drucker-Prager,
/// Cam-Clay), "plasticity.xi", "plasticity.beta" (Cam-Clay),
/// "plasticity.hardening_coefficient" (von Mises); null for any other field.
/// What a parametric energy varies (model_file.hpp).
const double* material_parameter(const MaterialDescription& d, const std::string& field);
double* material_parameter(MaterialDescription& d, const std::string& field);

/// The materials of docs/physics.md: "sand", "snow", "metal", "metal_nh".
MaterialDescription material_preset(const std::string& name);
std::vector<std::string> material_preset_names();

template <int dim>
class Material {
public:
    explicit Material(const MaterialDescription& description);

    const MaterialDescription& description() const { return description_; }
    const Elasticity<dim>& elasticity() const { return elasticity_; }
    /// The plasticity model when it is a Model (DruckerPrager<dim>, CamClay<dim>, VonMises<dim>), else null.
    template <typename Model>
    const Model* plasticity_model() const {
        return std::get_if<Model>(&plasticity_);
    }

    /// Z(Sigma, h) on clamped singular values. Throws std::invalid_argument for
    /// a non-finite hardening state (or a negative von Mises one).
    ReturnResult<dim> return_map(const Vec<dim>& Sigma, double hardening) const;

    /// The yield function of the plasticity model at (Sigma, h); <= 0 inside
    /// the elastic region. Units: Pa (Drucker-Prager), Pa^2 (Cam-Clay, von
    /// Mises). Zero for plasticity "none".
    double yield_function(const Vec<dim>& Sigma, double hardening) const;
    /// Size of the terms of yield_function() (same units), so that
    /// |y| / yield_scale is a relative distance to the surface.
    double yield_scale(const Vec<dim>& Sigma, double hardening) const;

    /// Ptilde(F, h) = U diag(tau(Z)_i / Sigma_i) V^T.
    Mat<dim> elastoplastic_stress(const Mat<dim>& F, double hardening) const;
    /// The same at a precomputed clamped SVD of F.
    Mat<dim> elastoplastic_stress(const PolarSVD<dim>& svd, double hardening) const;
    /// Its consistent tangent dPtilde/dF at the clamped SVD of F, the hardening held at h
    /// (material/elastoplastic_tangent.hpp), the return mapping evaluated in Hencky strain.
    Tensor4<dim> elastoplastic_tangent(const PolarSVD<dim>& svd, double hardening, bool project_psd,
                                       bool keep_skew = false) const;

    /// The return mapping in F space: F_elastic = U diag(Z) V^T.
    struct Projection {
        Mat<dim> F_elastic;
        double hardening;
        ReturnBranch branch;
    };
    Projection project(const Mat<dim>& F, double hardening) const;

private:
    /// yield_function() or, with scale, yield_scale().
    double yield(const Vec<dim>& Sigma, double hardening, bool scale) const;

    MaterialDescription description_;
    Elasticity<dim> elasticity_;
    std::variant<std::monostate, DruckerPrager<dim>, CamClay<dim>, VonMises<dim>> plasticity_;
};

}  // namespace pnet
