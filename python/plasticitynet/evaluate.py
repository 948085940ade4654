"""`python -m plasticitynet.evaluate MODEL [--samples N]`: accuracy of a trained model on held-out
samples (the implementation is plasticitynet.training.evaluate)."""

import sys

from .training.evaluate import evaluate, format_errors, main  # noqa: F401

if __name__ == "__main__":
    sys.exit(main())
