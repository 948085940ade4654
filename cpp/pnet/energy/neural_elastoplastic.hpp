#pragma once
// The PlasticityNet elastoplastic energy of one particle or element (paper
// eqs. 8 and 11, docs/physics.md), evaluated in batches with the fused MLP kernel:
//
//   Psi(F; F0, h) = E [ N(F, F0, h) - c : F + w mu/2 ||F - F0||^2 ],
//   c = grad_F N(F0, F0, h) - Ptilde(F0, h),
//
// so that grad_F Psi(F0) = E Ptilde(F0, h) exactly. N, Ptilde and mu are at
// the training Young's modulus (1: the net is dimensionless) and E is the
// scene's. The network's hardening input is the h of docs/physics.md for the
// particle's state (Cam-Clay: min(a, 0)), clamped to the range the model was
// trained on (ModelMetadata::network_hardening); Ptilde(F0, h) in c uses the
// state itself, so grad Psi(F0) stays exact where the input was clamped. c is computed once per optimization
// (set_reference()); within it, the line search asks for values, Newton for gradients and Hessians
//   d2 Psi / dF2 = E [ Hess_F N + w mu I ]   (d^2 x d^2, row-major vec(F) basis),
// optionally projected to positive semi-definite (eigenvalue clamp).
//
// A parametric model (ModelMetadata::parameters) takes the object's material
// parameters as constant network inputs; Ptilde, mu and the tangent are then
// those of the object's material (Options::material).
//
// A model in one of the forms the paper rejected (ModelMetadata::energy_form,
// for the ablation of its Fig. 11) changes only c and the network's F0 input:
// c = grad_F N(I, F0, h) (local_identity), grad_F N(I, I, h) with the identity
// in the F0 slot (global_identity), or 0 with the identity in the slot
// (global); grad_F Psi(F0) is then not Ptilde(F0, h).
#include <cstddef>
#include <memory>
#include <optional>
#include <vector>

#include "pnet/material/material.hpp"
#include "pnet/math/types.hpp"
#include "pnet/nn/energy_network.hpp"
#include "pnet/nn/learned_return_map.hpp"
#include "pnet/nn/model_file.hpp"

namespace pnet {

/// The damping w of the symmetrized tangent under the Auto Hessian for non-associative flow
/// (NeuralElastoplasticEnergy::Options::tangent_damping, ImplicitOptions::tangent_damping).
inline constexpr double kDefaultTangentDamping = 0.3;

template <int dim>
class NeuralElastoplasticEnergy {
public:
    static constexpr int kM = dim * dim;

    struct Options {
        double youngs_modulus = 1.0;      // E of the scene's material, Pa
        double regularizer_weight = 1.0;  // w of eq. 11 (0: the paper's eq. 8 alone)
        /// Report Psi(F) - Psi(F0) (same gradient and Hessian): the constant
        /// N(F0, F0, h) - c : F0 is of the size of the elastic energy density
        /// at E, so an incremental potential summed over many particles would
        /// carry a large constant whose round-off hides the step's changes.
        bool relative_to_reference = false;
        /// The Hessian Newton gets: the network's, E [Hess_F N + w mu I] (paper eq. 11), or the
        /// consistent tangent of the elastoplastic stress, E [dPtilde/dF(F, h) + w mu I]
        /// (material/elastoplastic_tangent.hpp), the Jacobian of the true residual when F = F0.
        /// Auto: the tangent, with w = 0 for associative plasticity (von Mises: the tangent is the
        /// symmetric Jacobian, and w mu would only slow Newton on plastic flow, where the true
        /// stiffness is near zero) and w = tangent_damping otherwise (non-associative Drucker-Prager
        /// and Cam-Clay, whose symmetrized tangent is not the Jacobian; docs/solver.md).
        enum class Hessian { Auto, Network, Tangent } hessian = Hessian::Network;
        /// The object's material (E aside), checked against the model (material_for_object: a model
        /// of one material needs the same constitutive model; a parametric one takes its parameters
        /// from it, within their trained ranges). Unset: the model's own material.
        std::optional<MaterialDescription> material = std::nullopt;
        /// Auto's w for non-associative flow (Drucker-Prager, Cam-Clay), in units of the shear
        /// modulus: the damping of their symmetrized tangent, which is not the residual's Jacobian.
        /// It only shapes Newton's steps (the energy is evaluated at its reference, where the w term
        /// vanishes); the paper's w = 1 damped the steps so much that a solve stopped by its tolerance
        /// was still biased toward v* (docs/solver.md, measured).
        double tangent_damping = kDefaultTangentDamping;
        /// Auto, non-associative flow: keep the tangent's skew part (elastoplastic_tangent.hpp), so
        /// that the Hessian is the residual's Jacobian (its symmetric part projected to PSD) and no
        /// longer symmetric: for solvers that take one (Objective::hessian_symmetric(); the MPM
        /// particle energies). The symmetrized tangent made Newton chatter on stiff granular flow
        /// (docs/solver.md, measured).
        bool nonsymmetric_tangent = false;
        /// The arithmetic of the network's passes at and from the reference (eq. 8 relative to its
        /// reference; under the rebased Newton every iterate is one). Single: the Hessian pass there (N,
        /// grad N and Hess N at F = F0) in float (twice the particles per instruction), and each trial point
        /// of a line search from the reference valued by one float pass of the change N(F) - N(F0)
        /// (FusedMlp::difference: relative to the change, where float's N(F) - N(F0) would rank noise).
        /// c's grad N(F0) keeps float's 1e-6 relative error, which shifts the line search's slope by that
        /// fraction of the stress; the gradient Newton solves with is E Ptilde(F0), exact either way.
        /// Every other evaluation (a Newton iterate away from its reference: the paper's fixed point),
        /// and every one of the other energy forms, is double.
        FusedMlp::Precision hessian_precision = FusedMlp::Precision::Double;
        /// Under the single-precision passes at the reference (hessian_precision Single, eq. 8 relative
        /// to its reference: the rebased Newton), a tolerance tau on F (largest entry) below which the
        /// network is not evaluated again: a particle whose reference F0 (and hardening input) is within
        /// tau of the one its Hessian was taken at keeps that Hessian, its grad N(F0) for c extrapolated
        /// by it; and a line search's trial point within tau of F0 is valued by the energy's second-order
        /// expansion E [Ptilde(F0) : dF + dF : (Hess N + w mu) : dF / 2] (the cubic term it leaves out is
        /// tau / (the network's length scale) of the quadratic one). 0: every pass over every particle.
        double network_reuse = 0.0;
    };

    /// Throws std::invalid_argument (naming the model file) unless `model` is a
    /// dim-D energy with a compiled kernel, E > 0, w >= 0 and Options::material
    /// (if set) one the model was trained for.
    NeuralElastoplasticEnergy(const ModelFile& model, const Options& options);

    /// A new time step: the Hessians network_reuse keeps are dropped, so that a step's result depends on
    /// its input state alone (a run resumed from a checkpoint equals the uninterrupted one).
    void begin_step() { cache_F0_.clear(); }

    /// Starts an optimization: the reference state (F0, h) of n particles and
    /// their constants c. h is ignored by models without hardening input.
    void set_reference(const Mat<dim>* F0, const double* hardening, std::size_t n);
    std::size_t size() const { return F0_.size(); }
    /// Particles of the last set_reference() whose hardening input was outside
    /// the trained range (and was clamped to it).
    std::size_t hardening_clamped() const { return hardening_clamped_; }

    /// Psi per particle (the line search).
    void value(const Mat<dim>* F, double* psi) const;
    /// Psi and grad_F Psi per particle.
    void value_gradient(const Mat<dim>* F, double* psi, Mat<dim>* gradient) const;
    /// Psi, grad_F Psi and the d^2 x d^2 Hessian per particle (symmetric unless symmetric_hessian() is false),
    /// projected to PSD when project_psd.
    void value_gradient_hessian(const Mat<dim>* F, double* psi, Mat<dim>* gradient, Tensor4<dim>* hessian,
                                bool project_psd) const;

    /// E Ptilde(F, h) with the model's return mapping (analytic or learned).
    Mat<dim> elastoplastic_stress(const Mat<dim>& F, double hardening) const;
    /// E c of particle p (set_reference()).
    Mat<dim> correction(std::size_t p) const;

    double youngs_modulus() const { return E_; }
    /// Shear modulus of the scene's material, Pa.
    double mu() const { return E_ * mu_train_; }
    /// The Hessian Newton gets (Options::hessian, Auto resolved) and the regularizer weight w.
    typename Options::Hessian hessian_kind() const { return hessian_kind_; }
    /// Whether the Hessian is symmetric: false only for the tangent with its skew part
    /// (Options::nonsymmetric_tangent).
    bool symmetric_hessian() const { return !keep_skew_; }
    /// An extra proximal weight added to w (value, gradient and Hessian), Newton's damping
    /// (Objective::set_damping); 0 by default.
    void set_damping(double lambda) { damping_ = lambda; }
    double regularizer_weight() const { return w_; }
    /// Passes of the network over the points since construction (each a value, gradient or Hessian
    /// evaluation of the batch, or of the part of it network_reuse does not cover): what the
    /// integrator's network counter reports.
    long network_passes() const { return network_passes_; }
    /// Points the network evaluated since construction (rows over all passes, a gradient pass for c
    /// included), and points it would have evaluated without network_reuse.
    long network_rows() const { return network_rows_; }
    long network_rows_without_reuse() const { return network_rows_full_; }
    bool has_hardening() const { return has_hardening_; }
    const LearnedReturnMap<dim>* learned_return_map() const { return return_map_.get(); }

private:
    /// Psi (and its gradient) from the network's buffers: N - N(F0) there, or with `difference` the
    /// change N(F) - N(F0) itself (value()'s float pass of the change).
    void finish(const Mat<dim>* F, double* psi, Mat<dim>* gradient, bool difference = false) const;

    mutable EnergyNetwork<dim> net_;  // its reference is set lazily (ensure_correction)
    Material<dim> training_material_;
    std::shared_ptr<const LearnedReturnMap<dim>> return_map_;
    ModelMetadata metadata_;
    bool has_hardening_;
    bool relative_;
    double E_;  // scene E / training E
    double w_;
    double damping_ = 0.0;  // set_damping(): added to w_
    double mu_train_;  // shear modulus at the training E
    typename Options::Hessian hessian_kind_;  // Network or Tangent (Auto resolved)
    FusedMlp::Precision hessian_precision_;   // of the Hessian pass at the reference (Options)
    bool keep_skew_ = false;                  // the tangent keeps its skew part

    std::vector<double> hardening_;  // per particle, the state (not the network's clamped input)

    std::vector<Mat<dim>> F0_;
    std::vector<Mat<dim>> stress_;  // Ptilde(F0, h), dimensionless (eq. 8's form)
    std::vector<PolarSVD<dim>> svd0_;  // clamped SVD of F0 (eq. 8, the material's return mapping)
    std::vector<double> network_h_;    // the network's hardening input (clamped to its range)
    // The correction and offset need the network at F0: computed by ensure_correction() when an
    // evaluation first needs them (not at all where every evaluation is at the reference).
    mutable bool correction_ready_ = false;
    mutable std::vector<Eigen::Matrix<double, kM, 1>> c_;  // row-major vec of c (dimensionless)
    mutable std::vector<double> offset_;                   // N(F0) when relative_, else 0
    // Whether offset_ is a double pass's N(F0): a float Hessian pass at the reference gives float's,
    // enough for Psi(F0) = 0 there, and a double pass elsewhere takes a double offset (ensure_offset).
    mutable bool offset_exact_ = true;
    // The rejected energy forms only: identities (the F0 slot or the correction point) and N, grad N there.
    std::vector<Mat<dim>> identity_;
    mutable std::vector<double> identity_value_, identity_gradient_;
    std::size_t hardening_clamped_ = 0;
    mutable long network_passes_ = 0;
    mutable long network_rows_ = 0, network_rows_full_ = 0;
    // Options::network_reuse: the tolerance, and per particle the F0 and network hardening input its
    // cached Hess N (raw: at the training E, before w mu and the projection) and grad N were taken at.
    double reuse_ = 0.0;
    mutable std::vector<Mat<dim>> cache_F0_;
    mutable std::vector<double> cache_h_;
    mutable std::vector<char> cache_valid_;
    mutable std::vector<Eigen::Matrix<double, kM, kM>> cache_hessian_;
    mutable std::vector<Eigen::Matrix<double, kM, 1>> cache_gradient_;
    // Whether particle p's cached Hessian is the one Newton got at the present reference (its trial
    // points may then be valued by the expansion).
    mutable std::vector<char> cache_current_;
    // Whether particle p's c is the network's at the present reference: not where its Hessian was kept
    // (its c then extrapolates grad N by the kept Hessian, which does not see the F0 slot's change; the
    // expansion does not depend on c, and a trial point valued by the network takes c exactly first).
    mutable std::vector<char> c_exact_;
    mutable std::vector<int> rows_;  // the particles a partial pass evaluates
    mutable std::vector<double> rows_value_, rows_gradient_, rows_hessian_;
    bool reusing() const { return reuse_ > 0.0 && single_at_reference(); }
    /// Counts a pass of the network over `rows` of the `of` points it would evaluate without reuse
    /// (none: no pass).
    void count_pass(std::size_t rows, std::size_t of) const {
        network_passes_ += rows > 0;
        network_rows_ += static_cast<long>(rows);
        network_rows_full_ += static_cast<long>(of);
    }
    void count_pass(std::size_t rows) const { count_pass(rows, rows); }
    /// ensure_correction()'s pass under network_reuse: the Hessian pass over the particles whose cache
    /// does not cover F0, the cached Hessians and the extrapolated grad N(F0) for the others.
    void correction_with_reuse(double* hessian) const;
    /// c = grad N(F0) - Ptilde(F0) from a gradient pass over the kept particles whose c is extrapolated
    /// (those whose F is farther than the tolerance from F0; null F: all of them).
    void exact_correction(const Mat<dim>* F) const;
    /// value()'s pass of the change under network_reuse: the network on the trial points farther than
    /// the tolerance from F0, the expansion on the others; N(F) - N(F0) in net_value_.
    void change_with_reuse(const Mat<dim>* F) const;
    // Work arrays, sized by set_reference(): one evaluation at a time per object
    // (each evaluation is itself threaded).
    mutable std::vector<double> net_value_, net_gradient_;
    // net_value_ and net_gradient_ hold N and grad N at F0 (ensure_correction()'s pass) until another
    // evaluation: the fixed point's next solve starts at F(v) = F0 and reuses them.
    mutable bool buffers_at_reference_ = false;
    // Whether the last point Newton asked a gradient at (its iterate) was exactly the reference, whose
    // Psi is 0: its line search's trial points are then valued by the change from F0 (value()).
    mutable bool iterate_at_reference_ = false;
    /// Whether the passes at and from the reference run in float: Options::hessian_precision single,
    /// eq. 8 relative to its reference.
    bool single_at_reference() const;
    /// Makes offset_ a double pass's N(F0) (one value pass, once per reference, where it is float's).
    void ensure_offset() const;
    /// Whether F[0..size()) is bitwise the reference F0.
    bool is_reference(const Mat<dim>* F) const;
    /// Whether F[0..size()) is bitwise the reference F0 and the buffers still hold its pass.
    bool at_reference(const Mat<dim>* F) const;
    /// Eq. 8 relative to the reference, evaluated at F = F0 exactly: psi = 0 and grad = E Ptilde(F0)
    /// by construction, so no network pass is needed (the Newton outer iteration's every point).
    bool exactly_at_reference(const Mat<dim>* F) const;
    /// Psi = 0 and its gradient E Ptilde(F0) there, by construction (F = F0 exactly).
    void values_at_reference(double* psi, Mat<dim>* gradient) const;
    /// Evaluates the network at F0 for c and the offset (once per set_reference()); with `hessian`
    /// (n d^2 x d^2, row-major) also Hess N at F0, in the same pass.
    void ensure_correction(double* hessian = nullptr) const;
};

}  // namespace pnet
