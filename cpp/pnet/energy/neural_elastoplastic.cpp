#include "pnet/energy/neural_elastoplastic.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>

#include "pnet/material/elastoplastic_tangent.hpp"
#include "pnet/math/psd.hpp"

namespace pnet {

template <int dim>
NeuralElastoplasticEnergy<dim>::NeuralElastoplasticEnergy(const ModelFile& model, const Options& options)
    : net_([&] {
          const ModelMetadata& meta = model.metadata;
          if (meta.kind != ModelKind::Energy)
              throw std::invalid_argument(model.path + ": a model of kind \"" + to_string(meta.kind) +
                                          "\", not an energy");
          if (meta.dim != dim)
              throw std::invalid_argument(model.path + ": a " + std::to_string(meta.dim) + "D energy where a " +
                                          std::to_string(dim) + "D one is needed");
          const MaterialDescription material =
              options.material ? material_for_object(meta, *options.material, model.path) : meta.material;
          return EnergyNetwork<dim>(model.weights, meta.representation, meta.has_hardening, model.path,
                                    parameter_inputs(meta, material));
      }()),
      training_material_(options.material ? material_for_object(model.metadata, *options.material, model.path)
                                          : model.metadata.material),
      metadata_(model.metadata),
      has_hardening_(model.metadata.has_hardening),
      relative_(options.relative_to_reference),
      E_(options.youngs_modulus / model.metadata.training_E),
      w_(options.regularizer_weight),
      mu_train_(training_material_.description().elastic.mu()),
      hessian_kind_(options.hessian),
      hessian_precision_(options.hessian_precision),
      reuse_(options.network_reuse) {
    if (!(std::isfinite(reuse_) && reuse_ >= 0.0))
        throw std::invalid_argument("network_reuse must be a tolerance >= 0, got " + std::to_string(reuse_));
    if (hessian_kind_ == Options::Hessian::Auto) {
        // The tangent for every material (docs/solver.md, measured); w = 0 for associative flow,
        // where the tangent is the exact Jacobian, and a damping otherwise.
        hessian_kind_ = Options::Hessian::Tangent;
        const bool associative = model.metadata.material.plasticity == PlasticityModel::VonMises;
        w_ = associative ? 0.0 : options.tangent_damping;
        keep_skew_ = !associative && options.nonsymmetric_tangent;
    }
    if (!(std::isfinite(options.youngs_modulus) && options.youngs_modulus > 0.0))
        throw std::invalid_argument(model.path + ": Young's modulus must be a positive number of Pa, got " +
                                    std::to_string(options.youngs_modulus));
    if (!(std::isfinite(w_) && w_ >= 0.0))
        throw std::invalid_argument("regularizer weight w (or the tangent's damping) must be >= 0, got " +
                                    std::to_string(w_));
    if (model.metadata.learned_return_map()) {
        if (!model.return_map)
            throw std::invalid_argument(model.path + ": trained with the learned return mapping " +
                                        model.metadata.return_map_file + ", which was not loaded");
        return_map_ = std::make_shared<const LearnedReturnMap<dim>>(*model.return_map);
    }
}

template <int dim>
Mat<dim> NeuralElastoplasticEnergy<dim>::elastoplastic_stress(const Mat<dim>& F, double hardening) const {
    const Mat<dim> P = return_map_ ? return_map_->elastoplastic_stress(F, hardening)
                                   : training_material_.elastoplastic_stress(F, hardening);
    return E_ * P;
}

template <int dim>
void NeuralElastoplasticEnergy<dim>::set_reference(const Mat<dim>* F0, const double* hardening, std::size_t n) {
    // The same reference again (a Coulomb floor's next friction pass starts where the last one ended):
    // c, the offset and the buffers stand, and no network pass is repeated.
    if (n > 0 && n == F0_.size() && std::memcmp(F0, F0_.data(), n * sizeof(Mat<dim>)) == 0 &&
        (hardening ? std::memcmp(hardening, hardening_.data(), n * sizeof(double)) == 0
                   : std::all_of(hardening_.begin(), hardening_.end(),
                                 [&](double h) { return h == training_material_.description().initial_hardening; })))
        return;
    F0_.assign(F0, F0 + n);
    const double initial = training_material_.description().initial_hardening;
    if (hardening)
        hardening_.assign(hardening, hardening + n);
    else
        hardening_.assign(n, initial);
    c_.resize(n);
    offset_.assign(n, 0.0);
    net_value_.resize(n);
    net_gradient_.resize(n * kM);
    const double h0 = training_material_.description().initial_hardening;
    const std::ptrdiff_t count = static_cast<std::ptrdiff_t>(n);
    network_h_.resize(has_hardening_ ? n : 0);
    std::size_t clamped = 0;
    if (has_hardening_) {
#pragma omp parallel for schedule(static) reduction(+ : clamped) if (count >= 1024)
        for (std::ptrdiff_t p = 0; p < count; ++p) {
            bool outside = false;
            network_h_[p] = metadata_.network_hardening(hardening ? hardening[p] : h0, &outside);
            clamped += outside;
        }
    }
    const EnergyForm form = metadata_.energy_form;
    if (form != EnergyForm::Eq8) identity_.assign(n, Mat<dim>::Identity());
    hardening_clamped_ = clamped;
    correction_ready_ = false;
    buffers_at_reference_ = false;
    iterate_at_reference_ = false;
    if (form == EnergyForm::Eq8) {
        stress_.resize(n);
        if (return_map_) {  // a learned return mapping: all states in one evaluation
            return_map_->elastoplastic_stress(F0, hardening_.data(), n, stress_.data());
        } else {  // the SVDs are kept for the tangent at F0
            svd0_.resize(n);
#pragma omp parallel for schedule(static) if (count >= 64)
            for (std::ptrdiff_t p = 0; p < count; ++p) {
                svd0_[p] = clamped_svd<dim>(F0[p]);
                stress_[p] = training_material_.elastoplastic_stress(svd0_[p], hardening_[p]);
            }
        }
    }
    if (!(form == EnergyForm::Eq8 && relative_)) ensure_correction();
}

template <int dim>
void NeuralElastoplasticEnergy<dim>::ensure_correction(double* hessian) const {
    if (correction_ready_) return;
    const std::size_t n = F0_.size();
    const std::ptrdiff_t count = static_cast<std::ptrdiff_t>(n);
    const EnergyForm form = metadata_.energy_form;
    // The network's F0 slot (F0, or the identity for a global form), set here: the first network
    // evaluation since set_reference.
    const bool global = form == EnergyForm::GlobalIdentity || form == EnergyForm::Global;
    net_.set_reference(global ? identity_.data() : F0_.data(), has_hardening_ ? network_h_.data() : nullptr, n);
    // N and grad_F N at F = F0: eq. 8's correction, the offset, and the next evaluation at F0 (with
    // Hess N too when the caller asks: Newton's Hessian at its iterate, in the same pass).
    // In single precision (Options::hessian_precision) N(F0) is float's too: the offset of Psi(F0) = 0
    // below, while trial points are valued as differences from F0 (value()); a double pass at another
    // point takes a double offset first (ensure_offset()).
    const bool single = single_at_reference();
    if (hessian && reusing()) return correction_with_reuse(hessian);
    count_pass(n);
    net_.evaluate(F0_.data(), hessian ? FusedMlp::Order::Hessian : FusedMlp::Order::Gradient, net_value_.data(),
                  net_gradient_.data(), hessian, single ? FusedMlp::Precision::Single : FusedMlp::Precision::Double);
    if (reuse_ > 0.0) {  // no cached Hessian is Newton's at this reference, and c is the network's
        cache_current_.assign(n, 0);
        c_exact_.assign(n, 1);
    }
    offset_exact_ = !single;
    if (form == EnergyForm::LocalIdentity || form == EnergyForm::GlobalIdentity) {
        // c = grad_F N(I, slot, h), the rejected forms' correction at the identity.
        identity_value_.resize(n);
        identity_gradient_.resize(n * kM);
        count_pass(n);
        net_.evaluate(identity_.data(), FusedMlp::Order::Gradient, identity_value_.data(), identity_gradient_.data());
    }
#pragma omp parallel for schedule(static) if (count >= 64)
    for (std::ptrdiff_t p = 0; p < count; ++p) {
        if (relative_) offset_[p] = net_value_[p];  // N(F0, slot, h)
        switch (form) {
            case EnergyForm::Eq8:  // c = grad_F N(F0, F0, h) - Ptilde(F0, h), at the training E.
                for (int k = 0; k < kM; ++k) c_[p][k] = net_gradient_[p * kM + k] - stress_[p](k / dim, k % dim);
                break;
            case EnergyForm::LocalIdentity:
            case EnergyForm::GlobalIdentity:
                for (int k = 0; k < kM; ++k) c_[p][k] = identity_gradient_[p * kM + k];
                break;
            case EnergyForm::Global: c_[p].setZero(); break;
        }
    }
    correction_ready_ = true;
    buffers_at_reference_ = !single;  // no later pass reads float buffers as double ones
}

template <int dim>
void NeuralElastoplasticEnergy<dim>::correction_with_reuse(double* hessian) const {
    const std::size_t n = F0_.size();
    const std::ptrdiff_t count = static_cast<std::ptrdiff_t>(n);
    if (cache_F0_.size() != n) {  // a new set of particles: nothing cached
        cache_F0_.assign(n, Mat<dim>::Zero());
        cache_h_.assign(n, 0.0);
        cache_valid_.assign(n, 0);
        cache_hessian_.resize(n);
        cache_gradient_.resize(n);
    }
    cache_current_.assign(n, 1);
    c_exact_.assign(n, 1);
    rows_.clear();
    for (std::size_t p = 0; p < n; ++p) {
        const bool covered = cache_valid_[p] && (F0_[p] - cache_F0_[p]).cwiseAbs().maxCoeff() <= reuse_ &&
                             (!has_hardening_ || std::abs(network_h_[p] - cache_h_[p]) <= reuse_);
        if (!covered) rows_.push_back(static_cast<int>(p));
        c_exact_[p] = !covered;
    }
    const std::size_t m = rows_.size();
    count_pass(m, n);
    if (m > 0) {
        rows_value_.resize(m);
        rows_gradient_.resize(m * kM);
        rows_hessian_.resize(m * kM * kM);
        net_.evaluate_rows(rows_.data(), m, F0_.data(), FusedMlp::Order::Hessian, rows_value_.data(),
                           rows_gradient_.data(), rows_hessian_.data(), FusedMlp::Precision::Single);
        const std::ptrdiff_t mm = static_cast<std::ptrdiff_t>(m);
#pragma omp parallel for schedule(static) if (mm >= 256)
        for (std::ptrdiff_t i = 0; i < mm; ++i) {
            const int p = rows_[i];
            cache_F0_[p] = F0_[p];
            cache_h_[p] = has_hardening_ ? network_h_[p] : 0.0;
            cache_valid_[p] = 1;
            cache_gradient_[p] = Eigen::Map<const Eigen::Matrix<double, kM, 1>>(&rows_gradient_[i * kM]);
            cache_hessian_[p] = Eigen::Map<const Eigen::Matrix<double, kM, kM>>(&rows_hessian_[i * kM * kM]);
        }
    }
#pragma omp parallel for schedule(static) if (count >= 256)
    for (std::ptrdiff_t p = 0; p < count; ++p) {
        // Where the row was just evaluated, c is exact. Where its Hessian was kept, c is provisional:
        // grad N(F0c) + Hess N(F0c) (F0 - F0c) misses how grad N moves with the network's F0 input
        // (first order in the shift). The expansion of a near trial point does not depend on c, and a
        // trial point the network values takes c from a gradient pass first (exact_correction).
        Eigen::Matrix<double, kM, 1> shift;
        for (int k = 0; k < kM; ++k) shift[k] = F0_[p](k / dim, k % dim) - cache_F0_[p](k / dim, k % dim);
        const Eigen::Matrix<double, kM, 1> g = cache_gradient_[p] + cache_hessian_[p] * shift;
        for (int k = 0; k < kM; ++k) c_[p][k] = g[k] - stress_[p](k / dim, k % dim);
        Eigen::Map<Eigen::Matrix<double, kM, kM>>(hessian + p * kM * kM) = cache_hessian_[p];
    }
    correction_ready_ = true;
    offset_exact_ = false;  // N(F0) is not known: a double pass elsewhere takes its own (ensure_offset)
    buffers_at_reference_ = false;
}

template <int dim>
void NeuralElastoplasticEnergy<dim>::exact_correction(const Mat<dim>* F) const {
    if (c_exact_.size() != F0_.size()) return;  // no Hessian kept since the last full pass
    rows_.clear();
    for (std::size_t p = 0; p < F0_.size(); ++p)
        if (!c_exact_[p] && (!F || (F[p] - F0_[p]).cwiseAbs().maxCoeff() > reuse_)) rows_.push_back(static_cast<int>(p));
    const std::size_t k = rows_.size();
    if (k == 0) return;
    count_pass(k, 0);
    rows_value_.resize(k);
    rows_gradient_.resize(k * kM);
    net_.evaluate_rows(rows_.data(), k, F0_.data(), FusedMlp::Order::Gradient, rows_value_.data(),
                       rows_gradient_.data(), nullptr, FusedMlp::Precision::Single);
    for (std::size_t i = 0; i < k; ++i) {
        const int p = rows_[i];
        for (int j = 0; j < kM; ++j) c_[p][j] = rows_gradient_[i * kM + j] - stress_[p](j / dim, j % dim);
        c_exact_[p] = 1;
    }
}

template <int dim>
void NeuralElastoplasticEnergy<dim>::change_with_reuse(const Mat<dim>* F) const {
    const std::size_t n = F0_.size();
    exact_correction(F);  // c of the kept particles the network values now
    rows_.clear();
    for (std::size_t p = 0; p < n; ++p)
        if (!cache_current_[p] || (F[p] - F0_[p]).cwiseAbs().maxCoeff() > reuse_) rows_.push_back(static_cast<int>(p));
    const std::size_t m = rows_.size();
    count_pass(m, n);
    if (m > 0) {
        rows_value_.resize(m);
        net_.difference_rows(rows_.data(), m, F, F0_.data(), rows_value_.data(), FusedMlp::Precision::Single);
    }
    // The expansion where the network was not evaluated: grad N(F0) : dF + dF : Hess N : dF / 2, with
    // grad N(F0) = c + Ptilde(F0) (finish() subtracts c : dF again, leaving Ptilde(F0) : dF).
    const std::ptrdiff_t count = static_cast<std::ptrdiff_t>(n);
#pragma omp parallel for schedule(static) if (count >= 1024)
    for (std::ptrdiff_t p = 0; p < count; ++p) {
        Eigen::Matrix<double, kM, 1> dF;
        for (int k = 0; k < kM; ++k) dF[k] = F[p](k / dim, k % dim) - F0_[p](k / dim, k % dim);
        double g_dF = 0.0;
        for (int k = 0; k < kM; ++k) g_dF += (c_[p][k] + stress_[p](k / dim, k % dim)) * dF[k];
        net_value_[p] = g_dF + 0.5 * dF.dot(cache_hessian_[p] * dF);
    }
    for (std::size_t i = 0; i < m; ++i) net_value_[rows_[i]] = rows_value_[i];
}

template <int dim>
void NeuralElastoplasticEnergy<dim>::ensure_offset() const {
    if (offset_exact_) return;
    count_pass(size());
    net_.evaluate(F0_.data(), FusedMlp::Order::Value, offset_.data());
    offset_exact_ = true;
}

template <int dim>
bool NeuralElastoplasticEnergy<dim>::single_at_reference() const {
    return hessian_precision_ == FusedMlp::Precision::Single && metadata_.energy_form == EnergyForm::Eq8 &&
           relative_;
}

template <int dim>
bool NeuralElastoplasticEnergy<dim>::is_reference(const Mat<dim>* F) const {
    return !F0_.empty() && std::memcmp(F, F0_.data(), F0_.size() * sizeof(Mat<dim>)) == 0;
}

template <int dim>
bool NeuralElastoplasticEnergy<dim>::exactly_at_reference(const Mat<dim>* F) const {
    return metadata_.energy_form == EnergyForm::Eq8 && relative_ && is_reference(F);
}

template <int dim>
bool NeuralElastoplasticEnergy<dim>::at_reference(const Mat<dim>* F) const {
    return buffers_at_reference_ && is_reference(F);
}

template <int dim>
Mat<dim> NeuralElastoplasticEnergy<dim>::correction(std::size_t p) const {
    ensure_correction();
    Mat<dim> c;
    for (int k = 0; k < kM; ++k) c(k / dim, k % dim) = E_ * c_.at(p)[k];
    return c;
}

/// psi = E (N - c : F + w mu/2 |F - F0|^2); gradient = E (grad N - c + w mu (F - F0)). Relative to the
/// reference, psi - Psi(F0) = E ((N - N0) - c : (F - F0) + w mu/2 |F - F0|^2), summed in that form so that
/// no large constant is formed and cancelled.
template <int dim>
void NeuralElastoplasticEnergy<dim>::finish(const Mat<dim>* F, double* psi, Mat<dim>* gradient,
                                            bool difference) const {
    const double wmu = (w_ + damping_) * mu_train_;
    const std::ptrdiff_t count = static_cast<std::ptrdiff_t>(size());
#pragma omp parallel for schedule(static) if (count >= 1024)
    for (std::ptrdiff_t p = 0; p < count; ++p) {
        double cF = 0.0, dF2 = 0.0;
        for (int k = 0; k < kM; ++k) {
            const double Fk = F[p](k / dim, k % dim), dFk = Fk - F0_[p](k / dim, k % dim);
            cF += c_[p][k] * (relative_ ? dFk : Fk);
            dF2 += dFk * dFk;
            if (gradient) (*(gradient + p))(k / dim, k % dim) = E_ * (net_gradient_[p * kM + k] - c_[p][k] + wmu * dFk);
        }
        const double dN = difference ? net_value_[p] : net_value_[p] - offset_[p];  // offset_: N0 or 0
        psi[p] = E_ * (dN - cF + 0.5 * wmu * dF2);
    }
}

template <int dim>
void NeuralElastoplasticEnergy<dim>::value(const Mat<dim>* F, double* psi) const {
    if (exactly_at_reference(F)) {
        std::fill(psi, psi + size(), 0.0);
        return;
    }
    ensure_correction();
    if (at_reference(F)) return finish(F, psi, nullptr);
    buffers_at_reference_ = false;
    if (iterate_at_reference_ && single_at_reference()) {
        // A trial point of a line search from the reference (the rebased Newton's every one), whose
        // value is 0 exactly: N(F) - N(F0) in one float pass of the change.
        if (reuse_ > 0.0 && cache_current_.size() == size()) {
            change_with_reuse(F);
        } else {
            count_pass(size());
            net_.difference(F, F0_.data(), net_value_.data(), FusedMlp::Precision::Single);
        }
        return finish(F, psi, nullptr, true);
    }
    ensure_offset();
    exact_correction(nullptr);
    count_pass(size());
    net_.evaluate(F, FusedMlp::Order::Value, net_value_.data());
    finish(F, psi, nullptr);
}

template <int dim>
void NeuralElastoplasticEnergy<dim>::values_at_reference(double* psi, Mat<dim>* gradient) const {
    std::fill(psi, psi + size(), 0.0);
    for (std::size_t p = 0; p < size(); ++p) gradient[p] = E_ * stress_[p];
}

template <int dim>
void NeuralElastoplasticEnergy<dim>::value_gradient(const Mat<dim>* F, double* psi, Mat<dim>* gradient) const {
    iterate_at_reference_ = exactly_at_reference(F);
    if (iterate_at_reference_) return values_at_reference(psi, gradient);
    ensure_correction();
    if (at_reference(F)) return finish(F, psi, gradient);
    ensure_offset();
    exact_correction(nullptr);
    buffers_at_reference_ = false;
    count_pass(size());
    net_.evaluate(F, FusedMlp::Order::Gradient, net_value_.data(), net_gradient_.data());
    finish(F, psi, gradient);
}

template <int dim>
void NeuralElastoplasticEnergy<dim>::value_gradient_hessian(const Mat<dim>* F, double* psi, Mat<dim>* gradient,
                                                            Tensor4<dim>* hessian, bool project_psd) const {
    static_assert(sizeof(Tensor4<dim>) == kM * kM * sizeof(double), "Tensor4 must be a plain d^2 x d^2 array");
    if (hessian_kind_ == Options::Hessian::Tangent) {
        value_gradient(F, psi, gradient);  // at F = F0: Ptilde(F0) without the network
        const double wmu = (w_ + damping_) * mu_train_;
        const std::ptrdiff_t count = static_cast<std::ptrdiff_t>(size());
        if (return_map_) {
            // A learned return mapping: every point's 2d + 1 stencil states in one network evaluation.
            constexpr int k = kTangentStencil<dim>;
            std::vector<PolarSVD<dim>> svd(count);
            std::vector<Vec<dim>> stencil(count * k);
            std::vector<double> h(count * k);
            std::vector<ReturnResult<dim>> returned(count * k);
#pragma omp parallel for schedule(static) if (count >= 64)
            for (std::ptrdiff_t p = 0; p < count; ++p) {
                svd[p] = clamped_svd<dim>(F[p]);
                tangent_stencil<dim>(svd[p].Sigma, &stencil[p * k]);
                for (int j = 0; j < k; ++j) h[p * k + j] = hardening_[p];
            }
            return_map_->return_map(stencil.data(), h.data(), stencil.size(), returned.data());
#pragma omp parallel for schedule(static) if (count >= 64)
            for (std::ptrdiff_t p = 0; p < count; ++p) {
                Vec<dim> Z[k];
                for (int j = 0; j < k; ++j) Z[j] = returned[p * k + j].Sigma;
                Tensor4<dim> H = elastoplastic_tangent_from<dim>(svd[p], training_material_.elasticity(), Z,
                                                                 project_psd, keep_skew_);
                H.diagonal().array() += wmu;
                hessian[p] = E_ * H;
            }
            return;
        }
        const bool at_F0 = exactly_at_reference(F);  // the usual case: the SVDs of set_reference
#pragma omp parallel for schedule(static) if (count >= 64)
        for (std::ptrdiff_t p = 0; p < count; ++p) {
            const PolarSVD<dim> svd = at_F0 ? svd0_[p] : clamped_svd<dim>(F[p]);
            Tensor4<dim> H = training_material_.elastoplastic_tangent(svd, hardening_[p], project_psd, keep_skew_);
            H.diagonal().array() += wmu;  // PSD plus w mu I stays PSD (the skew part adds nothing to x.Hx)
            hessian[p] = E_ * H;
        }
        return;
    }
    // Hess_F N is symmetric, so the row-major output is also the column-major
    // Eigen matrix.
    iterate_at_reference_ = exactly_at_reference(F);
    if (iterate_at_reference_ && reusing()) {
        // At the reference under network_reuse: the cached Hessians where they cover F0 (also at a
        // reference whose correction stands, a Coulomb floor's next pass), the network elsewhere.
        correction_ready_ = false;
        ensure_correction(reinterpret_cast<double*>(hessian));
        values_at_reference(psi, gradient);
    } else if (!correction_ready_ && metadata_.energy_form == EnergyForm::Eq8 && is_reference(F)) {
        // At the reference before its correction: N, grad N and Hess N at F0 in one pass, which gives
        // c and the offset too (the Newton outer iteration's iterates).
        ensure_correction(reinterpret_cast<double*>(hessian));
        finish(F, psi, gradient);
    } else if (iterate_at_reference_ && single_at_reference()) {
        // At a reference whose correction stands (a Coulomb floor's next pass starts there): the
        // Hessian pass in float, Psi and its gradient exact there.
        count_pass(size());
        net_.evaluate(F, FusedMlp::Order::Hessian, net_value_.data(), net_gradient_.data(),
                      reinterpret_cast<double*>(hessian), FusedMlp::Precision::Single);
        buffers_at_reference_ = false;
        values_at_reference(psi, gradient);
    } else {
        ensure_correction();
        ensure_offset();
        exact_correction(nullptr);
        buffers_at_reference_ = false;
        count_pass(size());
        net_.evaluate(F, FusedMlp::Order::Hessian, net_value_.data(), net_gradient_.data(),
                      reinterpret_cast<double*>(hessian));
        finish(F, psi, gradient);
    }
    const double wmu = (w_ + damping_) * mu_train_;
    const std::ptrdiff_t count = static_cast<std::ptrdiff_t>(size());
#pragma omp parallel for schedule(static) if (count >= 256)
    for (std::ptrdiff_t p = 0; p < count; ++p) {
        Tensor4<dim>& H = hessian[p];
        H.diagonal().array() += wmu;
        H *= E_;
        if (project_psd) H = pnet::project_psd<kM>(H);
    }
}

template class NeuralElastoplasticEnergy<2>;
template class NeuralElastoplasticEnergy<3>;

}  // namespace pnet
