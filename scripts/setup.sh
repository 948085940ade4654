#!/usr/bin/env bash
# Sets up whatever is missing for PlasticityNet on a Debian machine, idempotently:
#   1. Debian packages (apt-get; sudo when not root),
#   2. the C++ build (CMake + Ninja, Release) in build/,
#   3. the Python environment .venv (from /usr/bin/python3, which sees Debian's
#      torch and numpy) with the `plasticitynet` package installed editable and
#      the simulator module `plasticitynet_sim` linked in.
# Environment: PNET_BUILD_DIR (default build), PNET_JOBS (default: all cores).
set -euo pipefail

root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
build_dir="${PNET_BUILD_DIR:-build}"
jobs="${PNET_JOBS:-$(nproc)}"
say() { printf '[setup] %s\n' "$*"; }

# --- 1. Debian packages ------------------------------------------------------
packages=(
  build-essential cmake ninja-build pkg-config
  libeigen3-dev libsuitesparse-dev nlohmann-json3-dev pybind11-dev libgtest-dev libtorch-dev zlib1g-dev
  libpng-dev libssl-dev
  libgmsh-dev
  python3 python3-dev python3-venv python3-pip python3-setuptools python3-wheel
  python3-torch python3-numpy python3-matplotlib python3-tqdm python3-pytest
  # Debian's torch calls the system libblas.so.3; without OpenBLAS that is the
  # reference BLAS, and training runs 4-5x slower (scripts/bench_training.py).
  libopenblas0-openmp
  # Videos (pnet video, scripts/run.sh) and the notebooks (executed by the test suite).
  ffmpeg jupyter-nbconvert python3-nbformat python3-nbclient python3-ipykernel
  # The evaluation workflow (workflow/Snakefile, scripts/reproduce.sh).
  snakemake
)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  say "installing Debian packages: ${missing[*]}"
  if [[ $(id -u) -eq 0 ]]; then sudo=(); elif command -v sudo >/dev/null; then sudo=(sudo); else
    echo "[setup] error: need root or sudo to install: ${missing[*]}" >&2; exit 1
  fi
  "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -q
  "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "${missing[@]}"
else
  say "Debian packages: all present"
fi

# --- 2. C++ build ------------------------------------------------------------
if [[ ! -f "$build_dir/build.ninja" ]]; then
  say "configuring $build_dir (Release, Ninja)"
  cmake -S . -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=Release -DPython_EXECUTABLE=/usr/bin/python3
fi
say "building ($jobs jobs)"
cmake --build "$build_dir" -j "$jobs"

# --- 3. Python environment ---------------------------------------------------
if [[ ! -x .venv/bin/python ]]; then
  say "creating .venv from /usr/bin/python3 (--system-site-packages: Debian's torch, numpy)"
  /usr/bin/python3 -m venv --system-site-packages .venv
fi
# Editable install, offline: no build isolation, no dependency downloads (all
# dependencies are the Debian packages above).
if ! .venv/bin/python -c 'import plasticitynet, sys; sys.exit(0 if plasticitynet.__file__.startswith(sys.argv[1]) else 1)' \
     "$root/python/" 2>/dev/null; then
  say "installing the plasticitynet package (editable) into .venv"
  .venv/bin/python -m pip install --quiet --no-build-isolation --no-deps --no-index -e .
fi
# The simulator's Python module (built by CMake into $build_dir/python/): a
# symlink in .venv's site-packages, so that a rebuild is picked up at once.
site="$(.venv/bin/python -c 'import sysconfig; print(sysconfig.get_paths()["platlib"])')"
module=("$build_dir"/python/plasticitynet_sim*.so)
if [[ ! -e "${module[0]}" ]]; then
  echo "[setup] error: the build made no $build_dir/python/plasticitynet_sim*.so" >&2; exit 1
fi
ln -sfn "$(realpath "${module[0]}")" "$site/$(basename "${module[0]}")"
.venv/bin/python -c 'import torch, numpy, plasticitynet, plasticitynet_sim; print("[setup] python ok: torch", torch.__version__, "numpy", numpy.__version__, "plasticitynet_sim", plasticitynet_sim.__file__)'
