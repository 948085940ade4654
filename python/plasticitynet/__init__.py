"""PlasticityNet: learned incremental potentials for elastoplastic MPM/FEM (Python half)."""

__version__ = "0.1.0"
