"""PlasticityNet: learned incremental potentials for elastoplastic MPM/FEM (Python half).

`load_model(path)` reads a trained model file (plasticitynet.model); the material library is
`plasticitynet.materials`, the training code `plasticitynet.training`."""

__version__ = "0.1.0"

__all__ = ["load_model", "__version__"]


def __getattr__(name: str):
    """`load_model` on first use: importing the package (the workflow's jobs, the frame reader) does not
    pay for torch's import."""
    if name == "load_model":
        from .model import load_model
        return load_model
    raise AttributeError(f"module 'plasticitynet' has no attribute {name!r}")
