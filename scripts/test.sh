#!/usr/bin/env bash
# Sets up whatever is missing, then runs the whole test suite: the C++ tests
# (ctest) and the Python tests (pytest). Exits non-zero if any test fails.
set -uo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
"$root/scripts/setup.sh" || exit 1
build_dir="${PNET_BUILD_DIR:-build}"

status=0
echo "[test] C++ (ctest)"
ctest --test-dir "$build_dir" --output-on-failure -j "${PNET_JOBS:-$(nproc)}" || status=1
echo "[test] Python (pytest)"
.venv/bin/python -m pytest tests/python -q || status=1
if ((status)); then echo "[test] FAILED"; else echo "[test] all tests passed"; fi
exit $status
