#pragma once
// Fused evaluation of a PlasticityNet MLP with its gradient and Hessian with
// respect to the leading inputs (the entries of F), one row per SIMD lane: four
// per register in double precision, eight in single (Precision).
//
// For N(x) = w4 . a3 + b4, a_k = silu(z_k), z_k = W_k a_{k-1} + b_k, a_0 = x, and
// derivatives in the first m inputs (m = d^2):
//   backward:  delta_3 = w4 o silu'(z3),  g_k = W_{k+1}^T delta_{k+1},
//              delta_k = g_k o silu'(z_k),   grad N = W_1[:, :m]^T delta_1;
//   Hessian:   Hess N = sum_k J_k^T diag(g_k o silu''(z_k)) J_k, with g_3 = w4,
//              J_1 = W_1[:, :m] and J_{k+1} = W_{k+1} diag(silu'(z_k)) J_k
//              (forward-mode tangents; each row of J_k is used as soon as it is
//              formed, so only the tangents of the previous layer are stored).
// Every product is a small matrix product with compile-time sizes, templated on
// the input width, the hidden width and m; the exp of SiLU is vectorized too
// (simd.hpp). No allocation during evaluation.
#include <cstddef>
#include <memory>
#include <string>
#include <vector>

#include "pnet/nn/mlp_weights.hpp"

namespace pnet {

class FusedMlp {
public:
    /// What evaluate() computes: N; N and grad N; N, grad N and Hess N.
    enum class Order { Value = 0, Gradient = 1, Hessian = 2 };

    /// The arithmetic of an evaluation: Double, or Single (the weights rounded
    /// to float, every product and activation in float, about 1e-6 relative;
    /// inputs and results stay double arrays): twice the rows per instruction.
    enum class Precision { Double, Single };

    /// Derivatives are taken with respect to inputs [0, derivative_inputs)
    /// (0: value only, as for the return-mapping net). Throws
    /// std::invalid_argument for an architecture without a compiled kernel
    /// (see supported_architectures()).
    FusedMlp(const MlpWeights& weights, int derivative_inputs, Precision precision = Precision::Double);

    /// Human-readable list of the compiled (widths, derivative inputs) pairs.
    static std::string supported_architectures();
    static bool supports(const std::vector<int>& widths, int derivative_inputs);

    int input_width() const { return input_width_; }
    int derivative_inputs() const { return derivative_inputs_; }
    Precision precision() const { return precision_; }
    const std::vector<int>& widths() const { return widths_; }

    /// Evaluates `rows` inputs x (row-major, rows x input_width()):
    /// value[r] = N(x_r); for Order >= Gradient, gradient[r m + c] = dN/dx_c;
    /// for Order::Hessian, hessian[(r m + c) m + e] = d2N/dx_c dx_e (symmetric).
    /// Threaded with OpenMP over blocks of one register's rows when called outside a
    /// parallel region (and serial inside one); the result does not depend on
    /// the thread count.
    void evaluate(const double* x, std::size_t rows, Order order, double* value, double* gradient = nullptr,
                  double* hessian = nullptr) const;

    /// change[r] = N(x_r) - N(x0_r) (rows x input_width() each), computed as a
    /// forward pass of the change beside the reference's (da_k = silu(z_k + dz_k) -
    /// silu(z_k) without cancellation, simd::silu_change): its error is relative to
    /// the change, where the difference of two values loses the digits they share
    /// (float's 1e-7 of N against a change of 1e-6 of N near a converged Newton
    /// step). 0 where the rows are equal. Threaded like evaluate(). It costs about
    /// two value passes of this precision.
    void difference(const double* x, const double* x0, std::size_t rows, double* change) const;

    /// Floating-point operations per row in the matrix products of one
    /// evaluation (a multiply-add counts 2; activations not counted): the
    /// numerator of the benchmark's fraction of peak.
    double flops_per_row(Order order) const;

    /// The kernel of one architecture (implementation detail).
    struct Kernel {
        virtual ~Kernel() = default;
        virtual void evaluate(const double* x, std::size_t rows, Order order, double* value, double* gradient,
                              double* hessian) const = 0;
        virtual void difference(const double* x, const double* x0, std::size_t rows, double* change) const = 0;
    };

private:
    std::vector<int> widths_;
    int input_width_ = 0;
    int derivative_inputs_ = 0;
    Precision precision_ = Precision::Double;
    std::shared_ptr<const Kernel> kernel_;
};

}  // namespace pnet
