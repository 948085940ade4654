#pragma once
// PlasticityNet model files: the TorchScript archives written by
// python/plasticitynet/training/export.py, with a JSON entry "metadata.json" in
// `_extra_files` (format "plasticitynet-model", version 1). A file's forward(x)
// is the raw MLP N(x); the consumer applies the energy of docs/physics.md or the
// return-mapping clamp of eq. 12.
//
// TorchScript archives are code to LibTorch, so a file is read only if it is
// pinned by sha256 in a MANIFEST beside it (models/MANIFEST) or the caller
// says it trusts it. Reading the archive itself is in torchscript.cpp, the one
// translation unit that includes LibTorch headers; this part has none.
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "pnet/io/file_errors.hpp"
#include "pnet/material/material.hpp"
#include "pnet/nn/mlp_weights.hpp"

namespace pnet {

/// A model file neither pinned by a MANIFEST nor trusted by the caller.
class UntrustedModelError : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

enum class ModelKind { Energy, ReturnMap };

/// "energy" or "return_map".
std::string to_string(ModelKind kind);

/// What an energy's MLP sees (metadata "representation"; energy_network.hpp):
/// Raw, the paper's [vec F, vec F0, h]; Principal, [vec(U^T F V), Sigma0, h]
/// in the frame of F0 = U diag(Sigma0) V^T (frame-indifferent). The file's
/// forward() takes [vec F, vec F0, h] either way.
enum class EnergyRepresentation { Raw, Principal };

/// "raw" or "principal".
std::string to_string(EnergyRepresentation representation);

/// The energy's form (metadata "energy_form"; files without it are Eq8): the
/// paper's eq. 8, or one of the forms it tried and rejected (sec. 5.2, Fig. 11),
/// kept for that ablation (python/plasticitynet/training/energy.py):
///   Eq8             Psi = N(F, F0, h) - (grad_F N(F0, F0, h) - Ptilde(F0, h)) : F
///   LocalIdentity   Psi = N(F, F0, h) - grad_F N(I, F0, h) : F
///   GlobalIdentity  Psi = N(F, I, h) - grad_F N(I, I, h) : F
///   Global          Psi = N(F, I, h)
/// (plus the regularizer of eq. 11 in each). The global forms feed the identity
/// in the network's F0 slot.
enum class EnergyForm { Eq8, LocalIdentity, GlobalIdentity, Global };

/// "eq8", "local_identity", "global_identity" or "global".
std::string to_string(EnergyForm form);

/// A material parameter that a parametric energy takes as an input (metadata
/// "parameters", in input order, after h): the material field (its scene path,
/// e.g. "plasticity.friction_angle_deg") and the range it was trained over. The
/// network sees u = 2 (value - min) / (max - min) - 1.
struct ModelParameter {
    std::string field;
    double min = 0.0, max = 0.0;
    double input(double value) const { return 2.0 * (value - min) / (max - min) - 1.0; }
};

struct ModelMetadata {
    ModelKind kind = ModelKind::Energy;
    int dim = 2;
    std::vector<int> widths;
    bool has_hardening = false;         // energy: the input ends with h
    EnergyRepresentation representation = EnergyRepresentation::Raw;  // energy
    EnergyForm energy_form = EnergyForm::Eq8;                          // energy
    /// The range of the network's hardening input h it was trained on
    /// (recipe.distribution.h_range; energies with hardening and return maps).
    /// Models that do not record it get the training distribution of docs/physics.md
    /// for their plasticity and dimension.
    double hardening_min = 0.0, hardening_max = 0.0;
    double training_E = 1.0;            // Pa; the net is dimensionless, scaled by the scene's E
    MaterialDescription material;       // at the training E (a parametric model's: its family's reference)
    /// A parametric energy's inputs (empty for a model of one material).
    std::vector<ModelParameter> parameters;
    /// Energy models trained with the learned return mapping name its file
    /// (relative to the model's folder) and pin its sha256.
    std::string return_map_file, return_map_sha256;
    nlohmann::json json;                // the whole metadata entry

    /// The MLP's input width (widths.front()).
    int input_width() const { return widths.empty() ? 0 : widths.front(); }
    /// The width of the file's forward() input: 2 d^2 (+1) for an energy in
    /// any representation, the MLP's for a return map.
    int forward_input_width() const {
        return kind == ModelKind::Energy ? 2 * dim * dim + (has_hardening ? 1 : 0) + parameter_count() : input_width();
    }
    bool parametric() const { return !parameters.empty(); }
    int parameter_count() const { return static_cast<int>(parameters.size()); }
    /// Inputs the simulator differentiates in: d^2 (F) for an energy, 0 otherwise.
    int derivative_inputs() const { return kind == ModelKind::Energy ? dim * dim : 0; }
    bool learned_return_map() const { return !return_map_file.empty(); }
    /// The network's hardening input for the material's hardening state
    /// (docs/physics.md): Cam-Clay h = min(a, 0), von Mises h = tau_Y / (2 mu)
    /// itself, clamped to [hardening_min, hardening_max]. *clamped (if given)
    /// is set when the clamp changed it.
    double network_hardening(double state, bool* clamped = nullptr) const;
};

/// The material a model's energy uses for an object of material `object` (E
/// aside, at the training E). A model of one material: its own, after checking
/// that `object` has the same constitutive model (constitutive_differences). A
/// parametric model: its reference with the parameter fields taken from
/// `object`, each within its trained range, every other constitutive field
/// equal. std::invalid_argument naming the model file and the field, e.g.
/// "models/sand_param_2d.pt: material.plasticity.friction_angle_deg = 50 is
/// outside the range [20, 45] this parametric model was trained for".
MaterialDescription material_for_object(const ModelMetadata& meta, const MaterialDescription& object,
                                        const std::string& model_path);

/// A parametric model's inputs u for a material returned by material_for_object
/// (empty for a model of one material).
std::vector<double> parameter_inputs(const ModelMetadata& meta, const MaterialDescription& material);

/// Parses and validates the metadata entry; std::invalid_argument naming
/// `context` (the file) and the field on any problem: unknown format or
/// version, kind, dim, representation, energy_form, widths (input width 2d^2 (+1) for a raw
/// energy, d^2 + d (+1) for a principal one, d+1 for a return map; output 1), activation other than "silu", layer parameter
/// names, material (validated as a material description of this dimension),
/// training_E, return_map reference, parameters (a known parameter of the
/// material's models, finite min < max, listed once; energies only).
ModelMetadata parse_model_metadata(const nlohmann::json& j, const std::string& context);

struct LoadOptions {
    /// Load a file that no MANIFEST pins (only files whose origin you trust:
    /// LibTorch runs the code inside).
    bool trusted = false;
    /// Reject a model of another dimension (0: any).
    int expected_dim = 0;
    /// Reject a model of another kind.
    std::optional<ModelKind> expected_kind;
};

/// A loaded, validated model: metadata and the layer weights (float64).
struct ModelFile {
    std::string path;
    std::string sha256;
    bool pinned = false;  // sha256 matched a MANIFEST entry
    ModelMetadata metadata;
    MlpWeights weights;
    /// An energy's learned return mapping (loaded beside it, pinned by the
    /// sha256 in the energy's metadata); null for the analytic one.
    std::shared_ptr<const ModelFile> return_map;
};

/// The sha256 that a MANIFEST in the model's folder pins for its file name, if
/// any. Throws std::invalid_argument naming the MANIFEST if it is malformed.
std::optional<std::string> manifest_sha256(const std::string& model_path);

/// Reads a model file (torchscript.cpp): checks trust (MANIFEST sha256 or
/// options.trusted), loads the archive with torch::jit::load, validates the
/// metadata, extracts the weights of the named layer parameters (shapes must
/// chain as the widths say, values finite; float32 weights are widened), and
/// checks that the module's forward() computes the MLP those weights describe
/// on probe inputs (so a module with another activation or extra terms is
/// refused). An energy with a learned return mapping loads that file too.
/// Errors: FileNotFoundError, UntrustedModelError, std::invalid_argument; each
/// message starts with the path.
ModelFile load_model_file(const std::string& path, const LoadOptions& options = {});

}  // namespace pnet
