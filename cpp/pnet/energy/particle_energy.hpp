#pragma once
// The per-particle energy density of an implicit MPM step, the one face the
// incremental potential (mpm/incremental_potential.hpp) sees (docs/architecture.md):
// it never knows whether the energy is learned or analytic.
//
//   ElasticParticleEnergy: psi(F) of each particle's elasticity model, the
//     `lagged` baseline (plasticity applied after the step, docs/methods.md).
//   NeuralParticleEnergy:  the PlasticityNet energy Psi(F; F0, h) (paper eqs. 8
//     and 11) of each object's model, the `plasticitynet` integrator.
//
// Densities are per unit rest volume (J/m^3); gradients are first Piola-type
// stresses dpsi/dF (Pa) and Hessians d2psi/dF2 in the row-major vec(F) basis,
// projected to positive semi-definite for Newton.
#include <memory>
#include <vector>

#include "pnet/energy/neural_elastoplastic.hpp"
#include "pnet/material/material.hpp"
#include "pnet/math/types.hpp"
#include "pnet/nn/model_file.hpp"

namespace pnet {

template <int dim>
class ParticleEnergy {
public:
    /// What evaluate() computes: psi; psi and P; psi, P and the PSD Hessian.
    enum class Order { Value = 0, Gradient = 1, Hessian = 2 };

    virtual ~ParticleEnergy() = default;

    /// Starts an optimization: particle p has object object[p], reference
    /// deformation F0[p] and start-of-step hardening state hardening[p]. Energies
    /// without a reference (elastic) only record the object of each particle.
    virtual void set_reference(const std::vector<Mat<dim>>& F0, const std::vector<double>& hardening,
                               const std::vector<int>& object) = 0;

    /// A new step (before its first set_reference): whatever an energy carries from one reference to
    /// the next within a step (ReturnMappingEnergy's SVD warm start) is dropped, so that a step's
    /// result depends on its input state alone (a run resumed from a checkpoint equals the
    /// uninterrupted one).
    virtual void begin_step() {}

    /// psi[p] for every particle of the last set_reference(); for Order >=
    /// Gradient P[p] = dpsi/dF; for Order::Hessian H[p] = d2psi/dF2, projected
    /// to PSD when project_psd (what Newton needs; raw for derivative checks).
    /// The result does not depend on the thread count.
    virtual void evaluate(const std::vector<Mat<dim>>& F, Order order, double* psi, Mat<dim>* P, Tensor4<dim>* H,
                          bool project_psd = true) = 0;

    /// Particles of the last set_reference() whose hardening state was outside
    /// the range a learned energy was trained on (its input was clamped).
    virtual std::size_t hardening_clamped() const { return 0; }

    /// Objective::set_damping: an extra proximal weight lambda mu/2 ||F - F0||^2 about the reference
    /// (in units of each material's shear modulus). Returns whether the energy supports it.
    virtual bool set_damping(double /*lambda*/) { return false; }

    /// Whether the Hessian is the consistent tangent of the elastoplastic stress for every point
    /// (NeuralElastoplasticEnergy::Options::Hessian::Tangent) rather than the energy's own.
    virtual bool tangent_hessian() const { return false; }

    /// Whether evaluate()'s Hessians are symmetric. The learned energies' tangent keeps its skew part
    /// for non-associative flow (NeuralElastoplasticEnergy::Options::nonsymmetric_tangent), so that
    /// Newton steps with the residual's Jacobian: the forms that sum these Hessians report it
    /// (Form::symmetric_hessian()), and Newton then solves with GMRES (or BiCGSTAB).
    virtual bool symmetric_hessian() const { return true; }

    /// Passes of a learned energy's network over the points since construction (0 for energies
    /// without one): the integrators report its change per step (StepStats::network_evaluations).
    virtual long network_evaluations() const { return 0; }
    /// The points those passes evaluated, summed over the passes (StepStats::network_points).
    virtual long network_points() const { return 0; }
};

/// psi(F) of the elasticity model of each particle's material.
template <int dim>
class ElasticParticleEnergy final : public ParticleEnergy<dim> {
public:
    explicit ElasticParticleEnergy(const std::vector<Material<dim>>& materials) : materials_(materials) {}

    void set_reference(const std::vector<Mat<dim>>& F0, const std::vector<double>& hardening,
                       const std::vector<int>& object) override;
    void evaluate(const std::vector<Mat<dim>>& F, typename ParticleEnergy<dim>::Order order, double* psi, Mat<dim>* P,
                  Tensor4<dim>* H, bool project_psd = true) override;

private:
    const std::vector<Material<dim>>& materials_;
    std::vector<int> object_;
};

/// Psi(F; F0, h) of each object's PlasticityNet model, scaled to the object's
/// Young's modulus. Objects are evaluated in turn, each as one batch of the
/// fused kernel.
template <int dim>
class NeuralParticleEnergy final : public ParticleEnergy<dim> {
public:
    /// models[k] is object k's energy model; materials[k] its material (the
    /// scene's). Throws std::invalid_argument naming `context[k]` (e.g.
    /// "scene.json: objects[0].model") when a model is missing, of another
    /// dimension, or trained for another material (any field of
    /// constitutive_differences(): elasticity model, nu, plasticity model and
    /// parameters; E may differ, the energy is scaled). Psi is evaluated
    /// relative to the reference, Psi(F) - Psi(F0) (see
    /// NeuralElastoplasticEnergy::Options::relative_to_reference).
    NeuralParticleEnergy(const std::vector<std::shared_ptr<const ModelFile>>& models,
                         const std::vector<Material<dim>>& materials, const std::vector<std::string>& context,
                         double regularizer_weight,
                         typename NeuralElastoplasticEnergy<dim>::Options::Hessian hessian =
                             NeuralElastoplasticEnergy<dim>::Options::Hessian::Network,
                         double tangent_damping = kDefaultTangentDamping);
    /// The same with a regularizer weight w per object (regularizer_weights[k], k as materials).
    NeuralParticleEnergy(const std::vector<std::shared_ptr<const ModelFile>>& models,
                         const std::vector<Material<dim>>& materials, const std::vector<std::string>& context,
                         const std::vector<double>& regularizer_weights,
                         typename NeuralElastoplasticEnergy<dim>::Options::Hessian hessian,
                         double tangent_damping = kDefaultTangentDamping,
                         FusedMlp::Precision hessian_precision = FusedMlp::Precision::Double,
                         double network_reuse = 0.0);

    void set_reference(const std::vector<Mat<dim>>& F0, const std::vector<double>& hardening,
                       const std::vector<int>& object) override;
    /// Drops the Hessians each object's network_reuse keeps (NeuralElastoplasticEnergy::begin_step).
    void begin_step() override {
        for (Group& g : objects_) g.energy->begin_step();
    }
    void evaluate(const std::vector<Mat<dim>>& F, typename ParticleEnergy<dim>::Order order, double* psi, Mat<dim>* P,
                  Tensor4<dim>* H, bool project_psd = true) override;

    /// Object k's energy (its learned return mapping, if any, included).
    const NeuralElastoplasticEnergy<dim>& object_energy(std::size_t k) const { return *objects_[k].energy; }
    std::size_t hardening_clamped() const override { return hardening_clamped_; }
    bool set_damping(double lambda) override {
        for (Group& g : objects_) g.energy->set_damping(lambda);
        return true;
    }
    bool tangent_hessian() const override {
        for (const Group& g : objects_)
            if (g.energy->hessian_kind() != NeuralElastoplasticEnergy<dim>::Options::Hessian::Tangent) return false;
        return !objects_.empty();
    }
    bool symmetric_hessian() const override {
        for (const Group& g : objects_)
            if (!g.energy->symmetric_hessian()) return false;
        return true;
    }
    long network_evaluations() const override {
        long passes = 0;
        for (const Group& g : objects_) passes += g.energy->network_passes();
        return passes;
    }
    long network_points() const override {
        long points = 0;
        for (const Group& g : objects_) points += g.energy->network_rows();
        return points;
    }

private:
    struct Group {
        std::unique_ptr<NeuralElastoplasticEnergy<dim>> energy;
        std::vector<int> particles;  // indices of this object's particles
        std::vector<Mat<dim>> F, P;  // gathered inputs and outputs
        std::vector<double> psi;
        std::vector<Tensor4<dim>> H;
    };
    std::vector<Group> objects_;
    std::size_t hardening_clamped_ = 0;
};

}  // namespace pnet
