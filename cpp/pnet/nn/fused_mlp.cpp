#include "pnet/nn/fused_mlp.hpp"

#include <algorithm>
#include <stdexcept>

#include <omp.h>

#include "pnet/nn/simd.hpp"

namespace pnet {

namespace {


/// Rows per register block of gemv(): 8 independent accumulators cover the
/// FMA latency (5 cycles, 2 per cycle); smaller blocks only for short outputs.
constexpr int row_block(int n) { return n % 8 == 0 ? 8 : n % 4 == 0 ? 4 : n % 3 == 0 ? 3 : n % 2 == 0 ? 2 : 1; }

/// S itself, in a context where template arguments are not deduced (C++17 has no std::type_identity).
template <class T>
struct NonDeduced {
    using type = T;
};

/// out[j] = bias[j] + sum_i A[j][i] v[i] for j < Rows (bias may be null), with
/// the rows in register blocks so that each v[i] is loaded once per block.
template <int Rows, int Cols, class S, class V>
inline void gemv(const S (&A)[Rows][Cols], const typename NonDeduced<S>::type* bias, const V* v, V* out) {
    constexpr int R = row_block(Rows);
    for (int j = 0; j < Rows; j += R) {
        V acc[R];
        for (int r = 0; r < R; ++r) acc[r] = simd::splat<V>(bias ? bias[j + r] : S(0));
        for (int i = 0; i < Cols; ++i) {
            const V vi = v[i];
#pragma GCC unroll 8
            for (int r = 0; r < R; ++r) acc[r] += A[j + r][i] * vi;
        }
        for (int r = 0; r < R; ++r) out[j + r] = acc[r];
    }
}

/// J[j0 + r][c0 + c] = sum_i A[j0 + r][i] T[i][c0 + c] for r < R, c < C: R x C
/// accumulators in registers, R broadcasts and C loads per i.
template <int R, int C, int W, int M, class S, class V>
inline void tangent_tile(const S (&A)[W][W], const V (*T)[M], int j0, int c0, V (*J)[M]) {
    V acc[R][C];
    for (int r = 0; r < R; ++r)
        for (int c = 0; c < C; ++c) acc[r][c] = V{};
    for (int i = 0; i < W; ++i) {
        V t[C];
        for (int c = 0; c < C; ++c) t[c] = T[i][c0 + c];
#pragma GCC unroll 8
        for (int r = 0; r < R; ++r) {
            const V a = simd::splat<V>(A[j0 + r][i]);
#pragma GCC unroll 4
            for (int c = 0; c < C; ++c) acc[r][c] += a * t[c];
        }
    }
    for (int r = 0; r < R; ++r)
        for (int c = 0; c < C; ++c) J[j0 + r][c0 + c] = acc[r][c];
}

/// The tangent product J = A T (A: W x W scalars, T: W x M lanes) in tiles of
/// R rows and C columns: R C accumulators + C loaded tangents + 1 broadcast
/// must fit the 16 vector registers of AVX2 (5 x 2 for M = 4, 3 x 3 for M = 9).
template <int W, int M, class S, class V>
inline void tangent_product(const S (&A)[W][W], const V (*T)[M], V (*J)[M]) {
    constexpr int C = M % 2 == 0 ? 2 : M % 3 == 0 ? 3 : 1;
    constexpr int R = C == 2 ? 5 : C == 3 ? 3 : 8;
    constexpr int full = W - W % R;
    for (int c0 = 0; c0 < M; c0 += C) {
        for (int j0 = 0; j0 < full; j0 += R) tangent_tile<R, C>(A, T, j0, c0, J);
        if constexpr (W % R != 0) tangent_tile<W % R, C>(A, T, full, c0, J);
    }
}

/// H += D J J^T on the upper triangle (pairs c <= e, row by row).
template <int M, class V>
inline void add_outer(V* H, V D, const V* J) {
    int p = 0;
    for (int c = 0; c < M; ++c) {
        const V s = D * J[c];
        for (int e = c; e < M; ++e) H[p++] += s * J[e];
    }
}

/// Networks [In, W, W, W, 1] (three SiLU hidden layers of width W, Table 2),
/// derivatives in the first M inputs, computed in the precision of S (double
/// or float: the weights, every product and activation; inputs and results
/// are converted at the block's edges).
template <int In, int W, int M, class S>
class Kernel final : public FusedMlp::Kernel {
public:
    using V = typename simd::Pack<S>::V;
    static constexpr int kLanes = simd::Pack<S>::kLanes;
    static constexpr int kPairs = M * (M + 1) / 2;
    static constexpr int kM = M > 0 ? M : 1;  // array extents must be positive
    static constexpr int kP = kPairs > 0 ? kPairs : 1;

    explicit Kernel(const MlpWeights& w) {
        for (int j = 0; j < W; ++j) {
            for (int i = 0; i < In; ++i) W1[j][i] = static_cast<S>(w.weight[0][j * In + i]);
            b1[j] = static_cast<S>(w.bias[0][j]);
            b2[j] = static_cast<S>(w.bias[1][j]);
            b3[j] = static_cast<S>(w.bias[2][j]);
            w4[j] = static_cast<S>(w.weight[3][j]);
            for (int i = 0; i < W; ++i) {
                W2[j][i] = static_cast<S>(w.weight[1][j * W + i]);
                W3[j][i] = static_cast<S>(w.weight[2][j * W + i]);
                W2T[i][j] = W2[j][i];
                W3T[i][j] = W3[j][i];
            }
        }
        b4 = static_cast<S>(w.bias[3][0]);
        for (int j = 0; j < W; ++j)
            for (int c = 0; c < M; ++c) {
                W1F[j][c] = W1[j][c];
                W1FT[c][j] = W1[j][c];
            }
        for (int j = 0; j < W; ++j) {
            int p = 0;
            for (int c = 0; c < M; ++c)
                for (int e = c; e < M; ++e) P1[j][p++] = W1F[j][c] * W1F[j][e];
        }
    }

    void evaluate(const double* x, std::size_t rows, FusedMlp::Order order, double* value, double* gradient,
                  double* hessian) const override {
        for_each_block(rows, [&](std::size_t first, int lanes) {
            block(x + first * In, lanes, order, value + first, gradient ? gradient + first * M : nullptr,
                  hessian ? hessian + first * M * M : nullptr);
        });
    }

    void difference(const double* x, const double* x0, std::size_t rows, double* change) const override {
        for_each_block(rows, [&](std::size_t first, int lanes) {
            block_difference(x + first * In, x0 + first * In, lanes, change + first);
        });
    }

private:
    /// run(first row, lanes) over the register blocks of `rows` rows.
    template <class Run>
    static void for_each_block(std::size_t rows, Run&& run) {
        const std::ptrdiff_t blocks = static_cast<std::ptrdiff_t>((rows + kLanes - 1) / kLanes);
        auto one = [&](std::ptrdiff_t b) {
            const std::size_t first = static_cast<std::size_t>(b) * kLanes;
            run(first, static_cast<int>(std::min<std::size_t>(kLanes, rows - first)));
        };
        // Small batches, and calls from inside a parallel loop (the learned return map of
        // one element), stay out of OpenMP: even an if(false) region builds a team, nested
        // ones with futex calls (metal_nh_frame_2d at 1e-3: 312,000 futex calls per frame
        // before, 165,000 after; 3 frames 7.50 -> 7.27 s at 2 threads, same frames).
        if (blocks < 16 || omp_in_parallel()) {
            for (std::ptrdiff_t b = 0; b < blocks; ++b) one(b);
            return;
        }
#pragma omp parallel for schedule(static)
        for (std::ptrdiff_t b = 0; b < blocks; ++b) one(b);
    }

    /// N(x) - N(x0) of one register block: the reference's forward pass beside the change's,
    /// z_k = W_k a_{k-1} + b_k and dz_k = W_k da_{k-1}, da_k = silu(z_k + dz_k) - silu(z_k)
    /// without cancellation (simd::silu_change), dN = w4 . da_3. Its error is relative to the
    /// size of the change, not of N.
    void block_difference(const double* x, const double* x0, int lanes, double* change) const {
        V in0[In], din[In];
        for (int l = 0; l < kLanes; ++l) {
            const int row = std::min(l, lanes - 1) * In;
            for (int i = 0; i < In; ++i) {
                in0[i][l] = static_cast<S>(x0[row + i]);
                din[i][l] = static_cast<S>(x[row + i] - x0[row + i]);
            }
        }
        V z[W], dz[W], a[W], da[W];
        // (Measured: two products per layer are faster than one loop of both, whose blocks of rows
        // must halve to keep their accumulators in registers; keeping the reference's z and
        // sigmoid(z) from the Hessian pass cost that pass more in stores than it saved here.)
        auto layer = [&](const auto& A, const S* bias, const V* input, const V* dinput) {
            gemv(A, bias, input, z);
            gemv(A, nullptr, dinput, dz);
            for (int j = 0; j < W; ++j) {
                const simd::SiluChange<V> s = simd::silu_change(z[j], dz[j]);
                a[j] = s.value;
                da[j] = s.change;
            }
        };
        layer(W1, b1, in0, din);
        layer(W2, b2, a, da);
        layer(W3, b3, a, da);
        V dN = V{};
        for (int j = 0; j < W; ++j) dN += w4[j] * da[j];
        for (int l = 0; l < lanes; ++l) change[l] = dN[l];
    }

    void block(const double* x, int lanes, FusedMlp::Order order, double* value, double* gradient,
               double* hessian) const {
        using Order = FusedMlp::Order;
        const bool need_gradient = M > 0 && order != Order::Value;
        const bool need_hessian = M > 0 && order == Order::Hessian;

        // Inputs, one row per lane (a short last block repeats its last row).
        V in[In];
        for (int l = 0; l < kLanes; ++l) {
            const double* row = x + std::min(l, lanes - 1) * In;
            for (int i = 0; i < In; ++i) in[i][l] = static_cast<S>(row[i]);
        }

        // Forward: z_k, a_k = silu(z_k), d_k = silu'(z_k), dd_k = silu''(z_k).
        V z[W], a1[W], a2[W], a3[W], d1[W], d2[W], d3[W], dd1[W], dd2[W], dd3[W];
        auto activate = [&](V* a, V* d, V* dd) {
            if (!need_gradient) {
                for (int j = 0; j < W; ++j) a[j] = simd::silu(z[j]);
                return;
            }
            for (int j = 0; j < W; ++j) {
                const simd::Silu<V> s = simd::silu_with_derivatives(z[j]);
                a[j] = s.value;
                d[j] = s.d1;
                dd[j] = s.d2;
            }
        };
        gemv(W1, b1, in, z);
        activate(a1, d1, dd1);
        gemv(W2, b2, a1, z);
        activate(a2, d2, dd2);
        gemv(W3, b3, a2, z);
        activate(a3, d3, dd3);
        V N = simd::splat<V>(b4);
        for (int j = 0; j < W; ++j) N += w4[j] * a3[j];
        for (int l = 0; l < lanes; ++l) value[l] = N[l];
        if (!need_gradient) return;

        // Backward: g_2 = W3^T delta_3, g_1 = W2^T delta_2, grad = W1F^T delta_1.
        V delta[W], g2[W], g1[W], grad[kM];
        for (int j = 0; j < W; ++j) delta[j] = w4[j] * d3[j];
        gemv(W3T, nullptr, delta, g2);
        for (int j = 0; j < W; ++j) delta[j] = g2[j] * d2[j];
        gemv(W2T, nullptr, delta, g1);
        for (int j = 0; j < W; ++j) delta[j] = g1[j] * d1[j];
        gemv(W1FT, nullptr, delta, grad);
        for (int l = 0; l < lanes; ++l)
            for (int c = 0; c < M; ++c) gradient[l * M + c] = grad[c][l];
        if (!need_hessian) return;

        // Hessian: sum over layers of J_k^T diag(g_k silu''(z_k)) J_k.
        V H[kP];
        for (int p = 0; p < kPairs; ++p) H[p] = V{};
        // Layer 1: J_1 = W1F is the same for every lane; P1 holds its products.
        {
            constexpr int C = 8;  // pairs per register block
            for (int p0 = 0; p0 < kPairs; p0 += C) {
                const int count = std::min(C, kPairs - p0);
                V acc[C];
                for (int q = 0; q < C; ++q) acc[q] = V{};
                for (int j = 0; j < W; ++j) {
                    const V D = g1[j] * dd1[j];
#pragma GCC unroll 8
                    for (int q = 0; q < C; ++q)
                        if (q < count) acc[q] += D * P1[j][p0 + q];
                }
                for (int q = 0; q < count; ++q) H[p0 + q] += acc[q];
            }
        }
        // Layers 2 and 3: J_2 = W2 T_1 and J_3 = W3 T_2 with the tangents
        // T_k = diag(silu'(z_k)) J_k (T_1 = diag(d1) W1F).
        V T[W][kM], J[W][kM];
        for (int i = 0; i < W; ++i)
            for (int c = 0; c < M; ++c) T[i][c] = d1[i] * W1F[i][c];
        tangent_product<W, kM>(W2, T, J);
        for (int j = 0; j < W; ++j) {
            add_outer<M>(H, g2[j] * dd2[j], J[j]);
            for (int c = 0; c < M; ++c) T[j][c] = d2[j] * J[j][c];
        }
        tangent_product<W, kM>(W3, T, J);
        for (int j = 0; j < W; ++j) add_outer<M>(H, w4[j] * dd3[j], J[j]);

        for (int l = 0; l < lanes; ++l) {
            double* out = hessian + l * M * M;
            int p = 0;
            for (int c = 0; c < M; ++c)
                for (int e = c; e < M; ++e, ++p) out[c * M + e] = out[e * M + c] = H[p][l];
        }
    }

    S W1[W][In], b1[W], W2[W][W], b2[W], W3[W][W], b3[W], w4[W], b4;
    S W2T[W][W], W3T[W][W];
    S W1F[W][kM], W1FT[kM][W], P1[W][kP];
};

using KernelFactory = std::shared_ptr<const FusedMlp::Kernel> (*)(const MlpWeights&, FusedMlp::Precision);

struct Architecture {
    int input_width, hidden_width, derivative_inputs;
    KernelFactory make;
};

template <int In, int W, int M>
std::shared_ptr<const FusedMlp::Kernel> make_kernel(const MlpWeights& w, FusedMlp::Precision precision) {
    if (precision == FusedMlp::Precision::Single) return std::make_shared<const Kernel<In, W, M, float>>(w);
    return std::make_shared<const Kernel<In, W, M, double>>(w);
}

// The shapes of Table 2: energy nets [2d^2 (+1 for h), W, W, W, 1] with
// derivatives in the d^2 entries of F (raw input) or [d^2 + d (+1), W, W, W, 1]
// with derivatives in the d^2 entries of G (principal input,
// energy_network.hpp), and return-mapping nets [d + 1, W, W, W, 1]; and the
// principal-input energies twice as wide (train.py --hidden 64 64 64 in 2D,
// 128 128 128 in 3D).
constexpr Architecture kArchitectures[] = {
    {8, 32, 4, make_kernel<8, 32, 4>},    {9, 32, 4, make_kernel<9, 32, 4>},
    {18, 64, 9, make_kernel<18, 64, 9>},  {19, 64, 9, make_kernel<19, 64, 9>},
    {6, 32, 4, make_kernel<6, 32, 4>},    {7, 32, 4, make_kernel<7, 32, 4>},
    {12, 64, 9, make_kernel<12, 64, 9>},  {13, 64, 9, make_kernel<13, 64, 9>},
    {3, 32, 0, make_kernel<3, 32, 0>},    {4, 64, 0, make_kernel<4, 64, 0>},
    {6, 64, 4, make_kernel<6, 64, 4>},    {7, 64, 4, make_kernel<7, 64, 4>},
    {12, 128, 9, make_kernel<12, 128, 9>}, {13, 128, 9, make_kernel<13, 128, 9>},
    // Parametric energies (train.py --parametric): the principal inputs and the material
    // parameters, sand 2D (+ friction angle, nu), metal 2D (+ h, hardening coefficient, nu),
    // snow 2D (+ h, friction angle, xi, beta, nu), sand 3D, snow 3D.
    {8, 64, 4, make_kernel<8, 64, 4>},    {9, 64, 4, make_kernel<9, 64, 4>},
    {11, 64, 4, make_kernel<11, 64, 4>},  {14, 128, 9, make_kernel<14, 128, 9>},
    {17, 128, 9, make_kernel<17, 128, 9>},
};

const Architecture* find_architecture(const std::vector<int>& widths, int derivative_inputs) {
    if (widths.size() != 5 || widths[1] != widths[2] || widths[2] != widths[3] || widths[4] != 1) return nullptr;
    for (const Architecture& a : kArchitectures)
        if (a.input_width == widths[0] && a.hidden_width == widths[1] && a.derivative_inputs == derivative_inputs)
            return &a;
    return nullptr;
}

}  // namespace

FusedMlp::FusedMlp(const MlpWeights& weights, int derivative_inputs, Precision precision)
    : widths_(weights.widths),
      input_width_(weights.input_width()),
      derivative_inputs_(derivative_inputs),
      precision_(precision) {
    weights.validate("FusedMlp");
    const Architecture* a = find_architecture(weights.widths, derivative_inputs);
    if (!a) {
        std::string shape = "[";
        for (std::size_t k = 0; k < widths_.size(); ++k) shape += (k ? ", " : "") + std::to_string(widths_[k]);
        throw std::invalid_argument("no fused kernel for widths " + shape + "] with derivatives in " +
                                    std::to_string(derivative_inputs) + " inputs; compiled: " +
                                    supported_architectures());
    }
    kernel_ = a->make(weights, precision);
}

std::string FusedMlp::supported_architectures() {
    std::string s;
    for (const Architecture& a : kArchitectures) {
        if (!s.empty()) s += ", ";
        s += "[" + std::to_string(a.input_width);
        for (int k = 0; k < 3; ++k) s += ", " + std::to_string(a.hidden_width);
        s += ", 1] (m = " + std::to_string(a.derivative_inputs) + ")";
    }
    return s;
}

bool FusedMlp::supports(const std::vector<int>& widths, int derivative_inputs) {
    return find_architecture(widths, derivative_inputs) != nullptr;
}

void FusedMlp::difference(const double* x, const double* x0, std::size_t rows, double* change) const {
    if (rows == 0) return;
    if (!x || !x0 || !change) throw std::invalid_argument("FusedMlp::difference: null input or output array");
    kernel_->difference(x, x0, rows, change);
}

void FusedMlp::evaluate(const double* x, std::size_t rows, Order order, double* value, double* gradient,
                        double* hessian) const {
    if (rows == 0) return;
    if (!x || !value) throw std::invalid_argument("FusedMlp::evaluate: null input or value array");
    if (order != Order::Value && derivative_inputs_ > 0 && !gradient)
        throw std::invalid_argument("FusedMlp::evaluate: the gradient array is required for this order");
    if (order == Order::Hessian && derivative_inputs_ > 0 && !hessian)
        throw std::invalid_argument("FusedMlp::evaluate: the Hessian array is required for Order::Hessian");
    kernel_->evaluate(x, rows, order, value, gradient, hessian);
}

double FusedMlp::flops_per_row(Order order) const {
    const double in = input_width_, W = widths_[1], m = derivative_inputs_;
    const double pairs = m * (m + 1) / 2;
    double fma = in * W + 2 * W * W + W;  // forward
    if (order != Order::Value && m > 0) fma += 2 * W * W + m * W;  // backward
    if (order == Order::Hessian && m > 0)
        fma += W * pairs                     // layer 1
               + 2 * (W * W * m)             // tangents J_2, J_3
               + 2 * W * (m + pairs)         // outer products of layers 2, 3
               + 2 * W * m;                  // T_1, T_2 scaling
    return 2 * fma;
}

}  // namespace pnet
