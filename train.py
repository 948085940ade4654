#!/usr/bin/env python3
"""Train a PlasticityNet model and export it as TorchScript (see plasticitynet/training/cli.py):

    python train.py --material {sand,snow,metal,metal_nh,metal_nh_rm} --dim {2,3} [--epochs N --batch N ...]

Works from any shell: an interpreter without torch (or without the plasticitynet package) re-runs
this script with the project's Python, .venv/bin/python (else /usr/bin/python3, Debian's torch).
"""

import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent
_GUARD = "PNET_TRAIN_REEXEC"


def _importable() -> bool:
    try:
        import plasticitynet.training  # noqa: F401
        import torch  # noqa: F401
    except ImportError:
        return False
    return True


def _ensure_environment() -> None:
    if _importable():
        return
    if not os.environ.get(_GUARD):
        venv = ROOT / ".venv"
        in_venv = Path(sys.prefix).resolve() == venv.resolve()
        for python in ([] if in_venv else [venv / "bin" / "python"]) + [Path("/usr/bin/python3")]:
            if python.exists() and str(python) != sys.executable:
                os.environ[_GUARD] = "1"
                os.execv(str(python), [str(python), str(Path(__file__).resolve()), *sys.argv[1:]])
    # Last resort (e.g. /usr/bin/python3 with torch but without the package installed).
    sys.path.insert(0, str(ROOT / "python"))
    if not _importable():
        sys.exit("train.py: needs torch and the plasticitynet package; run ./scripts/setup.sh (creates .venv)")


if __name__ == "__main__":
    _ensure_environment()
    from plasticitynet.training.cli import main

    sys.exit(main(root=ROOT))
