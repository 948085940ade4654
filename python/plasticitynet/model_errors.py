"""`python -m plasticitynet.model_errors MODEL [--samples N]`: accuracy of a trained model on held-out
samples (the implementation is plasticitynet.training.held_out)."""

import sys

from .training.held_out import evaluate, format_errors, main  # noqa: F401

if __name__ == "__main__":
    sys.exit(main())
