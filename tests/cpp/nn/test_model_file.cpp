// Loading model files: the shipped models (pinned by models/MANIFEST) load and
// evaluate like LibTorch; every kind of bad file is a clear exception that
// starts with the file's path, never a crash.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>

#include "pnet/io/sha256.hpp"
#include "pnet/nn/energy_network.hpp"
#include "pnet/nn/fused_mlp.hpp"
#include "pnet/nn/model_file.hpp"
#include "pnet/nn/torchscript.hpp"

#include "support/mutator.hpp"
#include "support/temp_dir.hpp"

namespace pnet {
namespace {

using namespace test;  // TempDir, read_file, write_file, expect_error
namespace fs = std::filesystem;

const std::string kModels = PNET_MODELS_DIR;
const std::string kTestModels = std::string(PNET_TEST_DATA_DIR) + "/models";

const std::vector<std::string> kShipped = {"sand_2d.pt",     "snow_2d.pt", "metal_2d.pt", "metal_nh_rm_2d.pt",
                                           "metal_nh_2d.pt", "sand_3d.pt", "snow_3d.pt",  "metal_3d.pt",
                                           "sand_param_2d.pt", "snow_param_2d.pt", "metal_param_2d.pt",
                                           "sand_param_3d.pt", "snow_param_3d.pt"};

class ShippedModel : public ::testing::TestWithParam<std::string> {};

/// Max |a - b| per row relative to the row's largest |b|, checked against `tolerance`.
void expect_rows_close(const std::vector<double>& a, const std::vector<double>& b, std::size_t rows,
                       std::size_t size, double tolerance, const char* what) {
    for (std::size_t r = 0; r < rows; ++r) {
        double diff = 0.0, scale = 0.0;
        for (std::size_t k = r * size; k < (r + 1) * size; ++k) {
            diff = std::max(diff, std::abs(a[k] - b[k]));
            scale = std::max(scale, std::abs(b[k]));
        }
        EXPECT_LE(diff, tolerance * scale) << what << " of row " << r;
    }
}

/// The simulator's evaluation of an energy file (EnergyNetwork: the frame of F0
/// for a principal model, the fused MLP, the change of frame back) against the
/// file's own forward([F, F0, h, u]) under LibTorch autograd in F: value,
/// gradient and Hessian to 1e-10. u: a parametric model's inputs (one object).
template <int dim>
void expect_energy_matches_libtorch(const std::string& path, const ModelFile& model, const std::vector<Mat<dim>>& F0,
                                    std::uint64_t seed, const std::vector<double>& u = {}) {
    constexpr int m = dim * dim;
    const ModelMetadata& meta = model.metadata;
    const std::size_t rows = F0.size();
    const int in = meta.forward_input_width();
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> normal;
    std::uniform_real_distribution<double> uniform(0.0, 1.0);
    std::vector<Mat<dim>> F(rows);
    std::vector<double> h(rows, 0.0), x(rows * in);
    for (std::size_t r = 0; r < rows; ++r) {
        for (int k = 0; k < m; ++k) F[r](k / dim, k % dim) = F0[r](k / dim, k % dim) + 0.1 * normal(rng);
        h[r] = meta.has_hardening ? -0.3 * uniform(rng) : 0.0;
        for (int k = 0; k < m; ++k) {
            x[r * in + k] = F[r](k / dim, k % dim);
            x[r * in + m + k] = F0[r](k / dim, k % dim);
        }
        if (meta.has_hardening) x[r * in + 2 * m] = h[r];
        std::copy(u.begin(), u.end(), &x[r * in + 2 * m + (meta.has_hardening ? 1 : 0)]);
    }
    ASSERT_EQ(static_cast<int>(u.size()), meta.parameter_count());
    EnergyNetwork<dim> network(model.weights, meta.representation, meta.has_hardening, path, u);
    network.set_reference(F0.data(), h.data(), rows);
    std::vector<double> v(rows), g(rows * m), H(rows * m * m), rv(rows), rg(rows * m), rH(rows * m * m);
    network.evaluate(F.data(), FusedMlp::Order::Hessian, v.data(), g.data(), H.data());
    LoadOptions trusted;
    trusted.trusted = true;
    const TorchAutograd reference = TorchAutograd::from_file(path, trusted);
    ASSERT_EQ(reference.input_width(), in);
    reference.evaluate(x.data(), rows, m, FusedMlp::Order::Hessian, rv.data(), rg.data(), rH.data());
    expect_rows_close(v, rv, rows, 1, 1e-10, "value");
    expect_rows_close(g, rg, rows, m, 1e-10, "gradient");
    expect_rows_close(H, rH, rows, m * m, 1e-10, "Hessian");
    // Order::Value and Order::Gradient give the same numbers as Order::Hessian.
    std::vector<double> v1(rows), g1(rows * m);
    network.evaluate(F.data(), FusedMlp::Order::Gradient, v1.data(), g1.data());
    EXPECT_EQ(v1, v);
    EXPECT_EQ(g1, g);
}

/// Generic F0 (random stretch and rotation) and the states where the frame is
/// not unique: F0 = I, diagonal F0 with repeated entries, and (3D) a rotated
/// F0 with two equal singular values.
template <int dim>
std::vector<Mat<dim>> reference_states(std::size_t generic, std::uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::normal_distribution<double> normal;
    std::vector<Mat<dim>> F0;
    for (std::size_t r = 0; r < generic; ++r) {
        Mat<dim> A = Mat<dim>::Identity();
        for (int i = 0; i < dim; ++i)
            for (int j = 0; j < dim; ++j) A(i, j) += 0.3 * normal(rng);
        F0.push_back(A);
    }
    F0.push_back(Mat<dim>::Identity());
    Vec<dim> s = Vec<dim>::Constant(1.2);
    s[dim - 1] = 0.8;
    F0.push_back(s.asDiagonal());
    F0.push_back(Mat<dim>(Vec<dim>::Constant(0.9).asDiagonal()));
    return F0;
}

TEST_P(ShippedModel, LoadsPinnedAndMatchesLibTorch) {
    const std::string path = kModels + "/" + GetParam();
    const ModelFile model = load_model_file(path);
    EXPECT_TRUE(model.pinned);
    EXPECT_EQ(model.sha256, sha256_file_hex(path));
    const ModelMetadata& meta = model.metadata;
    EXPECT_EQ(meta.widths, model.weights.widths);
    const int d = meta.dim;
    const int mlp_in = meta.kind == ModelKind::ReturnMap                          ? d + 1
                       : meta.representation == EnergyRepresentation::Principal ? d * d + d + meta.has_hardening
                                                                                 : 2 * d * d + meta.has_hardening;
    EXPECT_EQ(meta.input_width(), mlp_in + meta.parameter_count());
    EXPECT_EQ(meta.learned_return_map(), model.return_map != nullptr);

    if (meta.parametric()) {  // at the ends of every range and inside (one object each)
        const std::size_t K = meta.parameters.size();
        std::mt19937_64 rng(11);
        std::uniform_real_distribution<double> uniform(-1.0, 1.0);
        std::vector<std::vector<double>> inputs = {std::vector<double>(K, -1.0), std::vector<double>(K, 1.0)};
        for (int k = 0; k < 3; ++k) {
            inputs.emplace_back(K);
            for (double& v : inputs.back()) v = uniform(rng);
        }
        for (std::size_t k = 0; k < inputs.size(); ++k) {
            SCOPED_TRACE("parameter inputs #" + std::to_string(k));
            if (d == 2)
                expect_energy_matches_libtorch<2>(path, model, reference_states<2>(18, 3), 4 + k, inputs[k]);
            else
                expect_energy_matches_libtorch<3>(path, model, reference_states<3>(18, 3), 4 + k, inputs[k]);
        }
        return;
    }
    if (meta.kind == ModelKind::Energy) {
        if (d == 2)
            expect_energy_matches_libtorch<2>(path, model, reference_states<2>(18, 3), 4);
        else
            expect_energy_matches_libtorch<3>(path, model, reference_states<3>(18, 3), 4);
        return;
    }
    // A return map: the fused kernel against the file's forward() (values only).
    const int in = meta.input_width();
    const FusedMlp fused(model.weights, 0);
    const TorchAutograd reference = TorchAutograd::from_file(path);
    const std::size_t rows = 21;
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<double> uniform(-1.2, 1.2);
    std::vector<double> x(rows * in);
    for (double& v : x) v = uniform(rng);
    std::vector<double> v(rows), rv(rows);
    fused.evaluate(x.data(), rows, FusedMlp::Order::Value, v.data());
    reference.evaluate(x.data(), rows, 0, FusedMlp::Order::Value, rv.data(), nullptr, nullptr);
    expect_rows_close(v, rv, rows, 1, 1e-10, "value");
}

TEST(ModelFile, PrincipalEnergiesMatchLibTorchIncludingRepeatedSingularValues) {
    LoadOptions trusted;
    trusted.trusted = true;
    for (const char* name : {"valid_principal_energy_2d.pt", "valid_principal_energy_3d.pt"}) {
        const std::string path = kTestModels + "/" + name;
        ASSERT_TRUE(fs::exists(path)) << path << " (regenerate with scripts/gen_test_models.py)";
        const ModelFile model = load_model_file(path, trusted);
        EXPECT_EQ(model.metadata.representation, EnergyRepresentation::Principal);
        EXPECT_EQ(model.metadata.forward_input_width(), 2 * model.metadata.dim * model.metadata.dim + 1);
        if (model.metadata.dim == 2)
            expect_energy_matches_libtorch<2>(path, model, reference_states<2>(40, 5), 6);
        else
            expect_energy_matches_libtorch<3>(path, model, reference_states<3>(40, 5), 6);
    }
}

INSTANTIATE_TEST_SUITE_P(Models, ShippedModel, ::testing::ValuesIn(kShipped),
                         [](const auto& info) { return info.param.substr(0, info.param.size() - 3); });

TEST(ModelFile, MissingFile) {
    const std::string path = kModels + "/no_such_model.pt";
    expect_error<FileNotFoundError>([&] { load_model_file(path); }, path, "no such file");
}

TEST(ModelFile, UnpinnedFilesNeedTrust) {
    TempDir dir;
    const std::string path = dir.file("copy.pt");
    write_file(path, read_file(kModels + "/sand_2d.pt"));
    expect_error<UntrustedModelError>([&] { load_model_file(path); }, path, "not pinned by a MANIFEST");
    LoadOptions trusted;
    trusted.trusted = true;
    EXPECT_FALSE(load_model_file(path, trusted).pinned);
}

TEST(ModelFile, ManifestMismatchIsRefused) {
    TempDir dir;
    const std::string path = dir.file("sand_2d.pt");
    write_file(path, read_file(kModels + "/sand_2d.pt"));
    write_file(dir.file("MANIFEST"),
          R"({"format": "plasticitynet-manifest", "models": [{"file": "sand_2d.pt", "sha256": ")" +
              std::string(64, '0') + R"("}]})");
    expect_error<UntrustedModelError>([&] { load_model_file(path); }, path, "does not match the MANIFEST");
    // With the right digest it is pinned.
    write_file(dir.file("MANIFEST"),
          R"({"format": "plasticitynet-manifest", "models": [{"file": "sand_2d.pt", "sha256": ")" +
              sha256_file_hex(path) + R"("}]})");
    EXPECT_TRUE(load_model_file(path).pinned);
    // A malformed MANIFEST names itself.
    write_file(dir.file("MANIFEST"), "{not json");
    try {
        load_model_file(path);
        FAIL() << "expected std::invalid_argument";
    } catch (const std::invalid_argument& e) {
        EXPECT_NE(std::string(e.what()).find("MANIFEST: not valid JSON"), std::string::npos) << e.what();
    }
}

TEST(ModelFile, TruncatedAndRandomBytes) {
    TempDir dir;
    LoadOptions trusted;
    trusted.trusted = true;  // reach the archive reader
    const std::string bytes = read_file(kModels + "/snow_2d.pt");
    for (std::size_t keep : {std::size_t{0}, std::size_t{100}, bytes.size() / 2, bytes.size() - 30}) {
        const std::string path = dir.file("truncated_" + std::to_string(keep) + ".pt");
        write_file(path, bytes.substr(0, keep));
        expect_error<std::invalid_argument>([&] { load_model_file(path, trusted); }, path,
                                            "not a readable TorchScript archive");
    }
    std::mt19937 rng(1);
    std::string noise(4096, '\0');
    for (char& c : noise) c = static_cast<char>(rng());
    const std::string path = dir.file("noise.pt");
    write_file(path, noise);
    expect_error<std::invalid_argument>([&] { load_model_file(path, trusted); }, path,
                                        "not a readable TorchScript archive");
}

// Mutated model files (issue 21's fuzz harness): untrusted, every changed file is refused by its
// hash before LibTorch sees it; trusted, LibTorch's archive reader and the metadata checks must end
// each case in a valid load or std::invalid_argument, never a crash.
TEST(ModelFile, FuzzedFilesAreRefusedOrLoad) {
    TempDir dir;
    const std::string good = read_file(kModels + "/snow_2d.pt");
    test::Mutator mutate(2105);
    LoadOptions trusted;
    trusted.trusted = true;
    int untrusted_refused = 0, unchanged = 0, trusted_valid = 0, trusted_refused = 0;
    const int cases = test::fuzz_cases(200);
    for (int c = 0; c < cases; ++c) {
        const std::string bytes = mutate.bytes(good);
        unchanged += bytes == good;
        const std::string path = dir.file("case.pt");
        write_file(path, bytes);
        try {
            load_model_file(path);
        } catch (const UntrustedModelError&) {
            ++untrusted_refused;
        } catch (const std::exception& e) {
            ADD_FAILURE() << "case " << c << " (untrusted): " << e.what();
        }
        try {
            load_model_file(path, trusted);
            ++trusted_valid;
        } catch (const std::invalid_argument&) {
            ++trusted_refused;
        } catch (const std::exception& e) {
            ADD_FAILURE() << "case " << c << " (trusted): undocumented " << typeid(e).name() << ": " << e.what();
        }
    }
    std::printf("[fuzz] model files (load_model_file)   %d cases: untrusted %d refused (not pinned); trusted %d valid loads, "
                "%d clean errors\n", cases, untrusted_refused, trusted_valid, trusted_refused);
    // Pins live in the MANIFEST beside the file: a copy outside models/ (even byte-identical, as
    // `unchanged` of these are) is refused untrusted, before LibTorch reads a byte of it.
    EXPECT_EQ(untrusted_refused, cases) << unchanged << " of the cases were byte-identical";
}

TEST(ModelFile, WrongDimensionOrKind) {
    LoadOptions options;
    options.expected_dim = 2;
    const std::string path3 = kModels + "/sand_3d.pt";
    expect_error<std::invalid_argument>([&] { load_model_file(path3, options); }, path3,
                                        "a 3D model where a 2D one is needed");
    options.expected_dim = 0;
    options.expected_kind = ModelKind::Energy;
    const std::string rm = kModels + "/metal_nh_rm_2d.pt";
    expect_error<std::invalid_argument>([&] { load_model_file(rm, options); }, rm,
                                        "kind \"return_map\" where kind \"energy\" is needed");
}

struct BadFile {
    std::string file, needle;
};

class BadModelFile : public ::testing::TestWithParam<BadFile> {};

TEST_P(BadModelFile, IsRefusedWithItsReason) {
    const std::string path = kTestModels + "/" + GetParam().file;
    ASSERT_TRUE(fs::exists(path)) << path << " (regenerate with scripts/gen_test_models.py)";
    LoadOptions trusted;
    trusted.trusted = true;
    expect_error<std::invalid_argument>([&] { load_model_file(path, trusted); }, path, GetParam().needle);
}

INSTANTIATE_TEST_SUITE_P(
    Files, BadModelFile,
    ::testing::Values(BadFile{"no_metadata.pt", "no metadata.json"}, BadFile{"bad_json.pt", "is not valid JSON"},
                      BadFile{"wrong_format_version.pt", "metadata.format_version: 99 is not supported"},
                      BadFile{"not_an_mlp.pt", "forward(x) is not the SiLU MLP of its layer parameters"},
                      BadFile{"wrong_activation.pt", "metadata.activation: \"relu\" is not supported"},
                      BadFile{"shape_mismatch.pt", "layers.2.weight has shape [8, 7], expected [8, 8]"},
                      BadFile{"nonfinite_weights.pt", "layer 1 weight entry (3, 5) is not finite"},
                      BadFile{"wrong_input_width.pt", "metadata.input_width: 9 differs from widths [7"},
                      BadFile{"bad_material.pt", "metadata.material.elasticity"},
                      BadFile{"wrong_representation.pt",
                              "metadata.representation: \"fancy\" is not \"raw\" or \"principal\""}),
    [](const auto& info) { return info.param.file.substr(0, info.param.file.size() - 3); });

TEST(ModelFile, ValidTestFilesLoadWhenTrusted) {
    LoadOptions trusted;
    trusted.trusted = true;
    const ModelFile energy = load_model_file(kTestModels + "/valid_energy_2d.pt", trusted);
    EXPECT_EQ(energy.metadata.kind, ModelKind::Energy);
    EXPECT_EQ(energy.weights.widths, (std::vector<int>{9, 8, 8, 8, 1}));
    const ModelFile rm = load_model_file(kTestModels + "/valid_return_map_2d.pt", trusted);
    EXPECT_EQ(rm.metadata.kind, ModelKind::ReturnMap);
    // float32 parameters are widened to float64 and give the same network.
    const ModelFile f32 = load_model_file(kTestModels + "/float32.pt", trusted);
    EXPECT_EQ(f32.weights.widths, (std::vector<int>{9, 8, 8, 8, 1}));
}

TEST(ModelFile, LearnedReturnMapIsLoadedAndPinnedByTheEnergy) {
    const ModelFile model = load_model_file(kModels + "/metal_nh_2d.pt");
    ASSERT_NE(model.return_map, nullptr);
    EXPECT_EQ(model.return_map->metadata.kind, ModelKind::ReturnMap);
    EXPECT_EQ(model.return_map->sha256, model.metadata.return_map_sha256);

    // A different return-map file under the pinned name is refused.
    TempDir dir;
    write_file(dir.file("metal_nh_2d.pt"), read_file(kModels + "/metal_nh_2d.pt"));
    write_file(dir.file("metal_nh_rm_2d.pt"), read_file(kTestModels + "/valid_return_map_2d.pt"));
    LoadOptions trusted;
    trusted.trusted = true;
    expect_error<UntrustedModelError>([&] { load_model_file(dir.file("metal_nh_2d.pt"), trusted); },
                                      dir.file("metal_nh_rm_2d.pt"), "differs from");
    fs::remove(dir.file("metal_nh_rm_2d.pt"));
    expect_error<FileNotFoundError>([&] { load_model_file(dir.file("metal_nh_2d.pt"), trusted); },
                                    dir.file("metal_nh_2d.pt"), "learned return mapping metal_nh_rm_2d.pt");
}

}  // namespace
}  // namespace pnet
