// The only translation unit that includes LibTorch (see torchscript.hpp).
#include "pnet/nn/torchscript.hpp"

#include "pnet/nn/energy_network.hpp"

#include <ATen/Parallel.h>
#include <torch/csrc/autograd/autograd.h>
#include <torch/script.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <random>
#include <sstream>

#include "pnet/io/sha256.hpp"

namespace pnet {

namespace {

namespace fs = std::filesystem;
using torch::indexing::Slice;

constexpr const char* kMetadataKey = "metadata.json";
constexpr int kProbeRows = 16;

std::string first_line(const std::string& text) { return text.substr(0, text.find('\n')); }

/// The last non-empty line (the error itself, after a TorchScript traceback).
std::string last_line(std::string text) {
    while (!text.empty() && (text.back() == '\n' || text.back() == ' ')) text.pop_back();
    const std::size_t start = text.rfind('\n');
    return start == std::string::npos ? text : text.substr(start + 1);
}

std::string read_bytes(const std::string& path) {
    if (!fs::exists(path)) throw FileNotFoundError(path + ": no such file");
    if (!fs::is_regular_file(path)) throw std::invalid_argument(path + ": not a regular file");
    std::ifstream in(path, std::ios::binary);
    std::ostringstream bytes;
    bytes << in.rdbuf();
    if (!in && !in.eof()) throw std::invalid_argument(path + ": cannot read the file");
    return bytes.str();
}

/// Trust: the sha256 of the bytes about to be loaded must match the MANIFEST
/// entry (or `required_sha256`, when another trusted model pins this file),
/// unless the caller trusts the file.
void check_trust(const std::string& path, const std::string& sha256, const LoadOptions& options,
                 const std::string& required_sha256, bool& pinned) {
    pinned = false;
    if (!required_sha256.empty()) {
        if (sha256 != required_sha256)
            throw UntrustedModelError(path + ": sha256 " + sha256 + " differs from " + required_sha256 +
                                      ", the one the model that refers to it was trained with");
        pinned = true;
        return;
    }
    const std::optional<std::string> expected = manifest_sha256(path);
    if (expected && *expected == sha256) {
        pinned = true;
        return;
    }
    if (options.trusted) return;
    if (expected)
        throw UntrustedModelError(path + ": sha256 " + sha256 + " does not match the MANIFEST entry " + *expected +
                                  " (file changed? update the MANIFEST with scripts/make_manifest.py, or load it "
                                  "as trusted)");
    throw UntrustedModelError(path +
                              ": not pinned by a MANIFEST beside it; a TorchScript file is code that LibTorch "
                              "runs, so load it only as trusted (trusted = true, pnet --trust-model) if you "
                              "trust where it came from");
}

/// Copies a parameter tensor of the expected shape into `out` (float64).
void copy_parameter(const std::string& path, const std::string& name, const torch::Tensor& t,
                    const std::vector<int64_t>& shape, std::vector<double>& out) {
    if (t.sizes().vec() != shape) {
        std::ostringstream s;
        s << path << ": parameter " << name << " has shape " << t.sizes() << ", expected " << c10::IntArrayRef(shape)
          << " from metadata.widths (layers that do not chain)";
        throw std::invalid_argument(s.str());
    }
    if (t.scalar_type() != torch::kFloat64 && t.scalar_type() != torch::kFloat32)
        throw std::invalid_argument(path + ": parameter " + name + " has dtype " +
                                    std::string(c10::toString(t.scalar_type())) + ", expected float64");
    const torch::Tensor c = t.detach().to(torch::kCPU, torch::kFloat64).contiguous();
    out.assign(c.data_ptr<double>(), c.data_ptr<double>() + c.numel());
}

/// Deterministic probe inputs: deformation-like F and F0 entries and h.
std::vector<double> probe_inputs(int input_width) {
    std::mt19937_64 rng(20240611);
    std::uniform_real_distribution<double> uniform(-1.0, 1.0);
    std::vector<double> x(static_cast<std::size_t>(kProbeRows) * input_width);
    for (double& v : x) v = uniform(rng);
    return x;
}

struct Archive {
    ModelFile model;
    torch::jit::Module module;
};

Archive read_archive(const std::string& path, const LoadOptions& options, const std::string& required_sha256) {
    Archive archive;
    ModelFile& model = archive.model;
    model.path = path;
    const std::string bytes = read_bytes(path);
    model.sha256 = sha256_hex(bytes);
    check_trust(path, model.sha256, options, required_sha256, model.pinned);

    torch::jit::ExtraFilesMap extra{{kMetadataKey, ""}};
    try {
        std::istringstream in(bytes);
        archive.module = torch::jit::load(in, torch::kCPU, extra);
    } catch (const c10::Error& e) {
        throw std::invalid_argument(path + ": not a readable TorchScript archive (" +
                                    first_line(e.what_without_backtrace()) + ")");
    } catch (const std::exception& e) {
        throw std::invalid_argument(path + ": not a readable TorchScript archive (" + first_line(e.what()) + ")");
    }
    archive.module.eval();

    const std::string& text = extra[kMetadataKey];
    if (text.empty())
        throw std::invalid_argument(path + ": no " + kMetadataKey +
                                    " in the archive's extra files: not a PlasticityNet model (models are "
                                    "written by plasticitynet.training.export)");
    nlohmann::json j;
    try {
        j = nlohmann::json::parse(text);
    } catch (const nlohmann::json::exception& e) {
        throw std::invalid_argument(path + ": " + kMetadataKey + " is not valid JSON (" + e.what() + ")");
    }
    model.metadata = parse_model_metadata(j, path);
    const ModelMetadata& meta = model.metadata;
    if (options.expected_dim != 0 && meta.dim != options.expected_dim)
        throw std::invalid_argument(path + ": a " + std::to_string(meta.dim) + "D model where a " +
                                    std::to_string(options.expected_dim) + "D one is needed");
    if (options.expected_kind && meta.kind != *options.expected_kind)
        throw std::invalid_argument(path + ": a model of kind \"" + to_string(meta.kind) + "\" where kind \"" +
                                    to_string(*options.expected_kind) + "\" is needed");

    // Weights of the named layer parameters, and nothing else.
    std::map<std::string, torch::Tensor> parameters;
    for (const auto& p : archive.module.named_parameters(/*recurse=*/true)) parameters[p.name] = p.value;
    const torch::ScalarType parameters_dtype =
        parameters.empty() ? torch::kFloat64 : parameters.begin()->second.scalar_type();
    MlpWeights& w = model.weights;
    w.widths = meta.widths;
    const nlohmann::json& names = meta.json.at("layer_parameters");
    for (std::size_t k = 0; k + 1 < meta.widths.size(); ++k) {
        const int64_t rows = meta.widths[k + 1], cols = meta.widths[k];
        w.weight.emplace_back();
        w.bias.emplace_back();
        const std::string weight_name = names[k][0], bias_name = names[k][1];
        for (const std::string& name : {weight_name, bias_name})
            if (!parameters.count(name))
                throw std::invalid_argument(path + ": metadata.layer_parameters names " + name +
                                            ", which the module does not have");
        copy_parameter(path, weight_name, parameters.at(weight_name), {rows, cols}, w.weight.back());
        copy_parameter(path, bias_name, parameters.at(bias_name), {rows}, w.bias.back());
        parameters.erase(weight_name);
        parameters.erase(bias_name);
    }
    if (!parameters.empty())
        throw std::invalid_argument(path + ": parameter " + parameters.begin()->first +
                                    " is not a layer of the MLP described by metadata.layer_parameters");
    w.validate(path);

    // forward() must be the MLP of those weights (a SiLU MLP, nothing added),
    // run in the precision of its parameters.
    const int in = meta.forward_input_width(), mlp_in = meta.input_width();
    const torch::ScalarType dtype = parameters_dtype;
    const double tolerance = dtype == torch::kFloat64 ? 1e-9 : 1e-4;
    std::vector<double> x = probe_inputs(in);
    std::vector<double> mlp_x(static_cast<std::size_t>(kProbeRows) * mlp_in);
    for (int r = 0; r < kProbeRows; ++r) {
        const double* row = &x[static_cast<std::size_t>(r) * in];
        double* out = &mlp_x[static_cast<std::size_t>(r) * mlp_in];
        if (meta.kind == ModelKind::ReturnMap)
            std::copy(row, row + in, out);
        else if (meta.dim == 2)
            EnergyNetwork<2>::mlp_input(meta.representation, meta.has_hardening, row, out, meta.parameter_count());
        else
            EnergyNetwork<3>::mlp_input(meta.representation, meta.has_hardening, row, out, meta.parameter_count());
    }
    torch::Tensor out;
    try {
        torch::NoGradGuard no_grad;
        const torch::Tensor input = torch::from_blob(x.data(), {kProbeRows, in}, torch::kFloat64).to(dtype);
        out = archive.module.forward({input}).toTensor();
    } catch (const std::exception& e) {
        std::string what = e.what();
        if (const auto* c10_error = dynamic_cast<const c10::Error*>(&e)) what = c10_error->what_without_backtrace();
        throw std::invalid_argument(path + ": forward(x) fails on a (" + std::to_string(kProbeRows) + ", " +
                                    std::to_string(in) + ") input (" + last_line(what) + ")");
    }
    if (out.sizes().vec() != std::vector<int64_t>{kProbeRows, 1})
        throw std::invalid_argument(path + ": forward(x) returns shape " + c10::str(out.sizes()) + ", expected [" +
                                    std::to_string(kProbeRows) + ", 1]");
    out = out.to(torch::kFloat64).contiguous();
    for (int r = 0; r < kProbeRows; ++r) {
        const double expected = w.evaluate_reference(&mlp_x[static_cast<std::size_t>(r) * mlp_in]);
        const double got = out.data_ptr<double>()[r];
        if (!(std::abs(got - expected) <= tolerance * (1.0 + std::abs(expected))))
            throw std::invalid_argument(path + ": forward(x) is not the SiLU MLP of its layer parameters (probe " +
                                        std::to_string(r) + ": " + std::to_string(got) + " vs " +
                                        std::to_string(expected) + ")");
    }

    if (meta.kind == ModelKind::Energy && meta.learned_return_map()) {
        const std::string rm_path = (fs::path(path).parent_path() / meta.return_map_file).string();
        LoadOptions rm_options;
        rm_options.expected_dim = meta.dim;
        rm_options.expected_kind = ModelKind::ReturnMap;
        try {
            model.return_map =
                std::make_shared<const ModelFile>(read_archive(rm_path, rm_options, meta.return_map_sha256).model);
        } catch (const FileNotFoundError&) {
            throw FileNotFoundError(path + ": trained with the learned return mapping " + meta.return_map_file +
                                    ", which is not at " + rm_path);
        }
    }
    return archive;
}

}  // namespace

ModelFile load_model_file(const std::string& path, const LoadOptions& options) {
    return read_archive(path, options, "").model;
}

// ---------------------------------------------------------------------------
// Autograd reference

struct TorchAutograd::Impl {
    int input_width = 0;
    std::function<torch::Tensor(const torch::Tensor&)> forward;
};

TorchAutograd TorchAutograd::from_file(const std::string& path, const LoadOptions& options) {
    Archive archive = read_archive(path, options, "");
    auto impl = std::make_shared<Impl>();
    impl->input_width = archive.model.metadata.forward_input_width();
    auto module = std::make_shared<torch::jit::Module>(std::move(archive.module));
    impl->forward = [module](const torch::Tensor& x) { return module->forward({x}).toTensor(); };
    TorchAutograd reference;
    reference.impl_ = impl;
    return reference;
}

TorchAutograd TorchAutograd::from_weights(const MlpWeights& weights) {
    weights.validate("TorchAutograd::from_weights");
    auto layers = std::make_shared<std::vector<std::pair<torch::Tensor, torch::Tensor>>>();
    for (int k = 0; k < weights.layer_count(); ++k) {
        const int64_t rows = weights.widths[k + 1], cols = weights.widths[k];
        layers->emplace_back(torch::tensor(weights.weight[k], torch::kFloat64).reshape({rows, cols}),
                             torch::tensor(weights.bias[k], torch::kFloat64));
    }
    auto impl = std::make_shared<Impl>();
    impl->input_width = weights.input_width();
    impl->forward = [layers](const torch::Tensor& x) {
        torch::Tensor a = x;
        for (std::size_t k = 0; k < layers->size(); ++k) {
            a = torch::linear(a, (*layers)[k].first, (*layers)[k].second);
            if (k + 1 < layers->size()) a = torch::silu(a);
        }
        return a;
    };
    TorchAutograd reference;
    reference.impl_ = impl;
    return reference;
}

int TorchAutograd::input_width() const { return impl_->input_width; }

void TorchAutograd::set_threads(int threads) { at::set_num_threads(threads); }

void TorchAutograd::evaluate(const double* x, std::size_t rows, int m, FusedMlp::Order order, double* value,
                             double* gradient, double* hessian) const {
    const int64_t n = static_cast<int64_t>(rows), in = impl_->input_width;
    const torch::Tensor X = torch::from_blob(const_cast<double*>(x), {n, in}, torch::kFloat64);
    if (order == FusedMlp::Order::Value || m == 0) {
        torch::NoGradGuard no_grad;
        const torch::Tensor N = impl_->forward(X).contiguous();
        std::copy_n(N.data_ptr<double>(), rows, value);
        return;
    }
    const torch::Tensor XF = X.index({Slice(), Slice(0, m)}).clone().requires_grad_(true);
    const torch::Tensor input = torch::cat({XF, X.index({Slice(), Slice(m, torch::indexing::None)})}, 1);
    const torch::Tensor N = impl_->forward(input);
    const bool second = order == FusedMlp::Order::Hessian;
    const torch::Tensor G = torch::autograd::grad({N.sum()}, {XF}, {}, /*retain_graph=*/second,
                                                  /*create_graph=*/second)[0];
    {
        const torch::Tensor Nc = N.detach().contiguous(), Gc = G.detach().contiguous();
        std::copy_n(Nc.data_ptr<double>(), rows, value);
        std::copy_n(Gc.data_ptr<double>(), rows * m, gradient);
    }
    if (!second) return;
    for (int c = 0; c < m; ++c) {
        const torch::Tensor Hc = torch::autograd::grad({G.index({Slice(), c}).sum()}, {XF}, {},
                                                       /*retain_graph=*/c + 1 < m, /*create_graph=*/false,
                                                       /*allow_unused=*/true)[0];
        const torch::Tensor H = Hc.defined() ? Hc.contiguous() : torch::zeros({n, m}, torch::kFloat64);
        const double* h = H.data_ptr<double>();
        for (std::size_t r = 0; r < rows; ++r)
            for (int e = 0; e < m; ++e) hessian[(r * m + c) * m + e] = h[r * m + e];
    }
}

}  // namespace pnet
