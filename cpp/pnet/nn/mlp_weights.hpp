#pragma once
// The parameters of a PlasticityNet MLP (paper appendix A.1, Table 2):
//
//   N(x) = W_L silu(... silu(W_1 x + b_1) ...) + b_L,   silu(z) = z / (1 + e^-z),
//
// SiLU after every linear layer but the last. Plain data with no LibTorch
// types, so that everything but the model loader compiles without its headers.
#include <string>
#include <vector>

namespace pnet {

struct MlpWeights {
    /// Layer widths [in, hidden..., 1].
    std::vector<int> widths;
    /// weight[k]: widths[k+1] x widths[k], row-major; bias[k]: widths[k+1].
    std::vector<std::vector<double>> weight;
    std::vector<std::vector<double>> bias;

    int input_width() const { return widths.empty() ? 0 : widths.front(); }
    int layer_count() const { return static_cast<int>(weight.size()); }

    /// Throws std::invalid_argument, prefixed by `context` (e.g. the file name),
    /// unless there are >= 2 layers, positive widths ending in 1, weight and bias
    /// sizes that match the widths, and only finite values.
    void validate(const std::string& context) const;

    /// N(x) in plain scalar double arithmetic (std::exp, one layer after the
    /// other): the reference the fused kernel is tested against, and what the
    /// loader compares a module's forward() with.
    double evaluate_reference(const double* x) const;
};

/// An MLP with the given widths and weights drawn uniformly from
/// [-scale / sqrt(fan_in), scale / sqrt(fan_in)] (PyTorch's default for scale 1),
/// from a fixed seed: test and benchmark networks.
MlpWeights random_mlp(const std::vector<int>& widths, unsigned seed, double scale = 1.0);

}  // namespace pnet
