"""PlasticityNet: learned incremental potentials for elastoplastic MPM/FEM (Python half).

`load_model(path)` reads a trained model file (plasticitynet.model); the material library is
`plasticitynet.materials`, the training code `plasticitynet.training`."""

__version__ = "0.1.0"

from .model import load_model  # noqa: E402

__all__ = ["load_model", "__version__"]
