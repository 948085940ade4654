#pragma once
// The LibTorch boundary. torchscript.cpp is the only translation unit of the
// project that includes LibTorch headers: it implements load_model_file()
// (model_file.hpp) and this autograd reference, which tests and benchmarks
// compare the fused evaluator with. The simulators never call LibTorch.
#include <cstddef>
#include <memory>
#include <string>

#include "pnet/nn/fused_mlp.hpp"
#include "pnet/nn/model_file.hpp"

namespace pnet {

/// N(x), grad N and Hess N through LibTorch autograd, in float64 (how the
/// paper evaluated its networks): reverse mode for the gradient, then one
/// reverse pass per input for the Hessian, batched over rows.
class TorchAutograd {
public:
    /// The TorchScript module of a model file, run through its own forward();
    /// the same trust rules and validation as load_model_file().
    static TorchAutograd from_file(const std::string& path, const LoadOptions& options = {});
    /// The MLP of `weights`, built from torch::linear and torch::silu.
    static TorchAutograd from_weights(const MlpWeights& weights);

    /// The contract of FusedMlp::evaluate(), derivatives in inputs [0, m).
    void evaluate(const double* x, std::size_t rows, int m, FusedMlp::Order order, double* value,
                  double* gradient = nullptr, double* hessian = nullptr) const;

    int input_width() const;

    /// LibTorch's intra-op thread count (at::set_num_threads), which is also
    /// OpenMP's: the way to set the simulator's thread count, since LibTorch's
    /// first operation on a thread resets OpenMP's count to its own.
    static void set_threads(int threads);

    struct Impl;

private:
    std::shared_ptr<const Impl> impl_;
};

}  // namespace pnet
