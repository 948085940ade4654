#include "pnet/nn/energy_network.hpp"

#include <algorithm>
#include <stdexcept>
#include <utility>

#include "pnet/math/svd.hpp"

namespace pnet {

namespace {

template <int dim>
int mlp_width(EnergyRepresentation representation, bool has_hardening, int parameters) {
    const int base = representation == EnergyRepresentation::Raw ? 2 * dim * dim : dim * dim + dim;
    return base + (has_hardening ? 1 : 0) + parameters;
}

template <int dim>
Mat<dim> row_matrix(const double* x) {
    Mat<dim> A;
    for (int i = 0; i < dim; ++i)
        for (int j = 0; j < dim; ++j) A(i, j) = x[i * dim + j];
    return A;
}

}  // namespace

template <int dim>
EnergyNetwork<dim>::EnergyNetwork(const MlpWeights& weights, EnergyRepresentation representation,
                                  bool has_hardening, const std::string& context,
                                  std::vector<double> parameter_inputs)
    : mlp_([&] {
          const int expected =
              mlp_width<dim>(representation, has_hardening, static_cast<int>(parameter_inputs.size()));
          if (weights.input_width() != expected)
              throw std::invalid_argument(context + ": a " + std::to_string(dim) + "D " + to_string(representation) +
                                          " energy network" +
                                          (parameter_inputs.empty()
                                               ? std::string()
                                               : " with " + std::to_string(parameter_inputs.size()) + " parameters") +
                                          " takes " + std::to_string(expected) + " inputs, not " +
                                          std::to_string(weights.input_width()));
          if (!FusedMlp::supports(weights.widths, kM))
              throw std::invalid_argument(context + ": no fused kernel for this architecture; compiled: " +
                                          FusedMlp::supported_architectures());
          return FusedMlp(weights, kM);
      }()),
      mlp_single_(weights, kM, FusedMlp::Precision::Single),
      representation_(representation),
      has_hardening_(has_hardening),
      parameter_inputs_(std::move(parameter_inputs)),
      input_width_(weights.input_width()) {}

template <int dim>
void EnergyNetwork<dim>::mlp_input(EnergyRepresentation representation, bool has_hardening, const double* x,
                                   double* out, int parameters) {
    const int h_at = 2 * kM;
    const int tail = (has_hardening ? 1 : 0) + parameters;  // [h, u] after F0 in both layouts
    if (representation == EnergyRepresentation::Raw) {
        std::copy(x, x + h_at + tail, out);
        return;
    }
    const PolarSVD<dim> frame = polar_svd<dim>(row_matrix<dim>(x + kM));
    const Mat<dim> G = frame.U.transpose() * row_matrix<dim>(x) * frame.V;
    for (int i = 0; i < dim; ++i)
        for (int j = 0; j < dim; ++j) out[i * dim + j] = G(i, j);
    for (int i = 0; i < dim; ++i) out[kM + i] = frame.Sigma[i];
    std::copy(x + h_at, x + h_at + tail, out + kM + dim);
}

template <int dim>
void EnergyNetwork<dim>::set_reference(const Mat<dim>* F0, const double* h, std::size_t n) {
    size_ = n;
    inputs_.resize(n * input_width_);
    const bool principal = representation_ == EnergyRepresentation::Principal;
    U_.resize(principal ? n : 0);
    V_.resize(principal ? n : 0);
    const std::ptrdiff_t count = static_cast<std::ptrdiff_t>(n);
#pragma omp parallel for schedule(static) if (count >= 1024)
    for (std::ptrdiff_t p = 0; p < count; ++p) {
        double* x = &inputs_[p * input_width_];
        int next;
        if (principal) {
            const PolarSVD<dim> frame = polar_svd<dim>(F0[p]);
            U_[p] = frame.U;
            V_[p] = frame.V;
            for (int i = 0; i < dim; ++i) x[kM + i] = frame.Sigma[i];
            next = kM + dim;
        } else {
            for (int i = 0; i < dim; ++i)
                for (int j = 0; j < dim; ++j) x[kM + i * dim + j] = F0[p](i, j);
            next = 2 * kM;
        }
        if (has_hardening_) x[next++] = h ? h[p] : 0.0;
        std::copy(parameter_inputs_.begin(), parameter_inputs_.end(), x + next);
    }
}

template <int dim>
void EnergyNetwork<dim>::write_F_slot(std::size_t p, const Mat<dim>& F, double* x) const {
    const Mat<dim> G = representation_ == EnergyRepresentation::Principal ? Mat<dim>(U_[p].transpose() * F * V_[p]) : F;
    for (int i = 0; i < dim; ++i)
        for (int j = 0; j < dim; ++j) x[i * dim + j] = G(i, j);
}

template <int dim>
void EnergyNetwork<dim>::set_rows(const Mat<dim>* F, std::vector<double>& rows) const {
    if (&rows != &inputs_) rows = inputs_;  // the reference's slots
    const std::ptrdiff_t count = static_cast<std::ptrdiff_t>(size_);
#pragma omp parallel for schedule(static) if (count >= 1024)
    for (std::ptrdiff_t p = 0; p < count; ++p) write_F_slot(p, F[p], &rows[p * input_width_]);
}

template <int dim>
void EnergyNetwork<dim>::pack_rows(const int* rows, std::size_t count, const Mat<dim>* F,
                                   std::vector<double>& packed) const {
    packed.resize(count * input_width_);
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(count);
#pragma omp parallel for schedule(static) if (n >= 1024)
    for (std::ptrdiff_t i = 0; i < n; ++i) {
        const int p = rows[i];
        double* x = &packed[i * input_width_];
        std::copy(&inputs_[p * input_width_], &inputs_[(p + 1) * input_width_], x);
        write_F_slot(p, F[p], x);
    }
}

template <int dim>
void EnergyNetwork<dim>::difference(const Mat<dim>* F, const Mat<dim>* from, double* change,
                                    FusedMlp::Precision precision) const {
    set_rows(from, from_inputs_);
    set_rows(F, inputs_);
    mlp(precision).difference(inputs_.data(), from_inputs_.data(), size_, change);
}

template <int dim>
void EnergyNetwork<dim>::difference_rows(const int* rows, std::size_t count, const Mat<dim>* F, const Mat<dim>* from,
                                         double* change, FusedMlp::Precision precision) const {
    if (count == 0) return;
    pack_rows(rows, count, from, packed_from_);
    pack_rows(rows, count, F, packed_);
    mlp(precision).difference(packed_.data(), packed_from_.data(), count, change);
}

template <int dim>
void EnergyNetwork<dim>::evaluate_rows(const int* rows, std::size_t count, const Mat<dim>* F, FusedMlp::Order order,
                                       double* value, double* gradient, double* hessian,
                                       FusedMlp::Precision precision) const {
    if (count == 0) return;
    pack_rows(rows, count, F, packed_);
    mlp(precision).evaluate(packed_.data(), count, order, value, gradient, hessian);
    to_frame_of_F(rows, count, order, gradient, hessian);
}

template <int dim>
void EnergyNetwork<dim>::evaluate(const Mat<dim>* F, FusedMlp::Order order, double* value, double* gradient,
                                  double* hessian, FusedMlp::Precision precision) const {
    set_rows(F, inputs_);
    mlp(precision).evaluate(inputs_.data(), size_, order, value, gradient, hessian);
    to_frame_of_F(nullptr, size_, order, gradient, hessian);
}

template <int dim>
void EnergyNetwork<dim>::to_frame_of_F(const int* rows, std::size_t count, FusedMlp::Order order, double* gradient,
                                       double* hessian) const {
    if (representation_ != EnergyRepresentation::Principal || order == FusedMlp::Order::Value) return;
    const bool second = order == FusedMlp::Order::Hessian;
    using Map = Eigen::Matrix<double, kM, kM, Eigen::RowMajor>;
    const std::ptrdiff_t n = static_cast<std::ptrdiff_t>(count);
#pragma omp parallel for schedule(static) if (n >= 256)
    for (std::ptrdiff_t i = 0; i < n; ++i) {
        const std::size_t p = rows ? static_cast<std::size_t>(rows[i]) : static_cast<std::size_t>(i);
        const Mat<dim>& U = U_[p];
        const Mat<dim>& V = V_[p];
        const Mat<dim> gF = U * row_matrix<dim>(&gradient[i * kM]) * V.transpose();
        for (int a = 0; a < dim; ++a)
            for (int b = 0; b < dim; ++b) gradient[i * kM + a * dim + b] = gF(a, b);
        if (!second) continue;
        Map M;  // vec G = M vec F: M((ab), (kl)) = U_ka V_lb
        for (int a = 0; a < dim; ++a)
            for (int b = 0; b < dim; ++b)
                for (int k = 0; k < dim; ++k)
                    for (int l = 0; l < dim; ++l) M(a * dim + b, k * dim + l) = U(k, a) * V(l, b);
        Eigen::Map<Map> H(hessian + i * kM * kM);
        const Map HG = H;
        H.noalias() = M.transpose() * (HG * M);
    }
}

template class EnergyNetwork<2>;
template class EnergyNetwork<3>;

}  // namespace pnet
