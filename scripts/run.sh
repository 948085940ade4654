#!/usr/bin/env bash
# Sets up whatever is missing, then runs the default job. Until the simulator
# exists this is the material report: return-mapping behaviour of every
# material (2D and 3D) on sample deformations, and PNGs of the elastic regions.
# Arguments are passed to the report (e.g. --out DIR).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
"$root/scripts/setup.sh"
exec .venv/bin/python -m plasticitynet.report "$@"
