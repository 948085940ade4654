// Loading model files: the shipped models (pinned by models/MANIFEST) load and
// evaluate like LibTorch; every kind of bad file is a clear exception that
// starts with the file's path, never a crash.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <random>

#include "pnet/io/sha256.hpp"
#include "pnet/nn/fused_mlp.hpp"
#include "pnet/nn/model_file.hpp"
#include "pnet/nn/torchscript.hpp"

#include "support/temp_dir.hpp"

namespace pnet {
namespace {

using test::expect_error;
using test::TempDir;
using test::read_file;
using test::write_file;

namespace fs = std::filesystem;

const std::string kModels = PNET_MODELS_DIR;
const std::string kTestModels = std::string(PNET_TEST_DATA_DIR) + "/models";

const std::vector<std::string> kShipped = {"sand_2d.pt",      "snow_2d.pt",  "metal_2d.pt", "metal_nh_rm_2d.pt",
                                           "metal_nh_2d.pt",  "sand_3d.pt",  "snow_3d.pt",  "metal_3d.pt"};

class ShippedModel : public ::testing::TestWithParam<std::string> {};

TEST_P(ShippedModel, LoadsPinnedAndMatchesLibTorch) {
    const std::string path = kModels + "/" + GetParam();
    const ModelFile model = load_model_file(path);
    EXPECT_TRUE(model.pinned);
    EXPECT_EQ(model.sha256, sha256_file_hex(path));
    const ModelMetadata& meta = model.metadata;
    EXPECT_EQ(meta.widths, model.weights.widths);
    EXPECT_EQ(meta.input_width(), meta.kind == ModelKind::Energy ? 2 * meta.dim * meta.dim + meta.has_hardening
                                                                  : meta.dim + 1);
    EXPECT_EQ(meta.learned_return_map(), model.return_map != nullptr);

    // The fused kernel against the file's own forward() under autograd.
    const int m = meta.derivative_inputs(), in = meta.input_width();
    const FusedMlp fused(model.weights, m);
    const TorchAutograd reference = TorchAutograd::from_file(path);
    const std::size_t rows = 21;
    std::mt19937_64 rng(3);
    std::uniform_real_distribution<double> uniform(-1.2, 1.2);
    std::vector<double> x(rows * in);
    for (double& v : x) v = uniform(rng);
    std::vector<double> v(rows), g(rows * m), H(rows * m * m), rv(rows), rg(rows * m), rH(rows * m * m);
    fused.evaluate(x.data(), rows, FusedMlp::Order::Hessian, v.data(), g.data(), H.data());
    reference.evaluate(x.data(), rows, m, FusedMlp::Order::Hessian, rv.data(), rg.data(), rH.data());
    auto check = [&](const std::vector<double>& a, const std::vector<double>& b, std::size_t size, const char* what) {
        for (std::size_t r = 0; r < rows; ++r) {
            double diff = 0.0, scale = 0.0;
            for (std::size_t k = r * size; k < (r + 1) * size; ++k) {
                diff = std::max(diff, std::abs(a[k] - b[k]));
                scale = std::max(scale, std::abs(b[k]));
            }
            EXPECT_LE(diff, 1e-10 * scale) << what << " of row " << r;
        }
    };
    check(v, rv, 1, "value");
    if (m > 0) {
        check(g, rg, m, "gradient");
        check(H, rH, m * m, "Hessian");
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
                      BadFile{"bad_material.pt", "metadata.material.elasticity"}),
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
