#include "pnet/nn/mlp_weights.hpp"

#include <cmath>
#include <random>
#include <stdexcept>

namespace pnet {

namespace {

std::string shape_string(const std::vector<int>& widths) {
    std::string s = "[";
    for (std::size_t k = 0; k < widths.size(); ++k) s += (k ? ", " : "") + std::to_string(widths[k]);
    return s + "]";
}

}  // namespace

void MlpWeights::validate(const std::string& context) const {
    auto fail = [&](const std::string& problem) {
        throw std::invalid_argument(context + ": " + problem);
    };
    if (widths.size() < 2) fail("an MLP needs at least one layer, widths = " + shape_string(widths));
    for (int w : widths)
        if (w <= 0) fail("layer widths must be positive, widths = " + shape_string(widths));
    if (widths.back() != 1) fail("the output width must be 1, widths = " + shape_string(widths));
    const std::size_t layers = widths.size() - 1;
    if (weight.size() != layers || bias.size() != layers)
        fail("widths " + shape_string(widths) + " need " + std::to_string(layers) + " layers, got " +
             std::to_string(weight.size()) + " weights and " + std::to_string(bias.size()) + " biases");
    for (std::size_t k = 0; k < layers; ++k) {
        const std::size_t rows = widths[k + 1], cols = widths[k];
        if (weight[k].size() != rows * cols)
            fail("layer " + std::to_string(k) + " weight has " + std::to_string(weight[k].size()) +
                 " entries, expected " + std::to_string(rows) + " x " + std::to_string(cols));
        if (bias[k].size() != rows)
            fail("layer " + std::to_string(k) + " bias has " + std::to_string(bias[k].size()) +
                 " entries, expected " + std::to_string(rows));
        for (std::size_t i = 0; i < weight[k].size(); ++i)
            if (!std::isfinite(weight[k][i]))
                fail("layer " + std::to_string(k) + " weight entry (" + std::to_string(i / cols) + ", " +
                     std::to_string(i % cols) + ") is not finite");
        for (std::size_t i = 0; i < rows; ++i)
            if (!std::isfinite(bias[k][i]))
                fail("layer " + std::to_string(k) + " bias entry " + std::to_string(i) + " is not finite");
    }
}

double MlpWeights::evaluate_reference(const double* x) const {
    std::vector<double> a(x, x + input_width()), z;
    for (int k = 0; k < layer_count(); ++k) {
        const int rows = widths[k + 1], cols = widths[k];
        z.assign(rows, 0.0);
        for (int j = 0; j < rows; ++j) {
            double sum = bias[k][j];
            for (int i = 0; i < cols; ++i) sum += weight[k][j * cols + i] * a[i];
            const bool hidden = k + 1 < layer_count();
            z[j] = hidden ? sum / (1.0 + std::exp(-sum)) : sum;
        }
        a.swap(z);
    }
    return a[0];
}

MlpWeights random_mlp(const std::vector<int>& widths, unsigned seed, double scale) {
    MlpWeights mlp;
    mlp.widths = widths;
    std::mt19937_64 rng(seed);
    for (std::size_t k = 0; k + 1 < widths.size(); ++k) {
        const double bound = scale / std::sqrt(static_cast<double>(widths[k]));
        std::uniform_real_distribution<double> uniform(-bound, bound);
        mlp.weight.emplace_back(static_cast<std::size_t>(widths[k + 1]) * widths[k]);
        mlp.bias.emplace_back(widths[k + 1]);
        for (double& w : mlp.weight.back()) w = uniform(rng);
        for (double& b : mlp.bias.back()) b = uniform(rng);
    }
    mlp.validate("random_mlp");
    return mlp;
}

}  // namespace pnet
