"""Training half of PlasticityNet (paper sec. 4, 4.3, 5.1, appendix A; docs/physics.md):

- sampling:        seeded (F, F0, h) batches ("paper" and "near" sampling), return-map states
- nets:            the MLPs of Table 2 (SiLU) and the energy input layout [vec F, vec F0, h]
- targets:         Ptilde(F, h) from the material library at E = 1 (analytic or learned return mapping)
- energy:          the corrected energy of eq. 8 (+ regularizer of eq. 11), the loss of eq. 9, and the
                   forms the paper rejected (sec. 5.2, Fig. 11) for that ablation
- return_map_net:  the learned von Mises return mapping of eqs. 12-13
- trainer:         Adam + StepLR loop, CSV log, loss plot, resumable checkpoints
- export:          float64 TorchScript + metadata JSON (read back by plasticitynet.load_model)
- evaluate:        held-out accuracy (python -m plasticitynet.model_errors MODEL)
- cli:             the argument parser behind the repository's train.py
"""

from .energy import ENERGY_FORMS, correction, energy_loss, network_gradient, psi, psi_gradient
from .export import FORMAT, FORMAT_VERSION, energy_metadata, export_model, return_map_metadata, script_network
from .nets import MLP, energy_input, energy_widths, make_mlp, return_map_widths
from .sampling import (
    DeformationBatch,
    SamplingSpec,
    generator_for,
    random_rotations,
    sample_batch,
    sample_return_map_states,
    sampling_spec,
    small_rotations,
)
from .targets import TRAINING_E, ElastoplasticStress, nondimensional_material, with_young_modulus
from .trainer import MATERIALS, TrainConfig, Trainer, TrainResult, train

__all__ = [
    "ENERGY_FORMS", "correction", "energy_loss", "network_gradient", "psi", "psi_gradient",
    "FORMAT", "FORMAT_VERSION", "energy_metadata", "export_model", "return_map_metadata", "script_network",
    "MLP", "energy_input", "energy_widths", "make_mlp", "return_map_widths",
    "DeformationBatch", "SamplingSpec", "generator_for", "random_rotations", "sample_batch",
    "sample_return_map_states", "sampling_spec", "small_rotations",
    "TRAINING_E", "ElastoplasticStress", "nondimensional_material", "with_young_modulus",
    "MATERIALS", "TrainConfig", "Trainer", "TrainResult", "train",
]
