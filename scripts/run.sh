#!/usr/bin/env bash
# Sets up whatever is missing, then runs the default job: the canonical
# sand_column_2d scene (docs/scenes.md) simulated with the `plasticitynet`
# implicit integrator at dt = 1e-3 s (the scene's integrator block; the learned
# sand energy models/sand_2d.pt). Writes per frame a PLY and a PNG, stats.csv,
# steps.csv (Newton/CG/fixed-point figures per step) and run.json to
# out/sand_column_2d/ (or --out DIR), plus the video sand_column_2d.mp4 (`pnet
# video`), and prints where everything is.
#
# Other arguments go to `pnet simulate` (e.g. --frames 10, --threads 1,
# --integrator explicit --dt 1e-5 for the ground truth).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
"$root/scripts/setup.sh"

build_dir="${PNET_BUILD_DIR:-build}"
scene="scenes/sand_column_2d.json"
out="out/sand_column_2d"
args=()
while (($#)); do
  case "$1" in
    --out) out="$2"; shift 2 ;;
    *) args+=("$1"); shift ;;
  esac
done

# The demo job replaces its own last run in $out (a resumed run, --resume, continues it instead).
overwrite=(--overwrite)
for a in "${args[@]+"${args[@]}"}"; do [[ "$a" == --resume ]] && overwrite=(); done
"$build_dir/cpp/pnet" simulate "$scene" --out "$out" "${overwrite[@]+"${overwrite[@]}"}" "${args[@]+"${args[@]}"}"

# The video: 50 frames per second = the scene's frame rate (frame_dt 0.02 s), real time
# (setup.sh installs ffmpeg).
"$build_dir/cpp/pnet" video "$out" --out "$out/sand_column_2d.mp4"
echo "frames: $out/frame_*.png and $out/frame_*.ply (open the PLYs in ParaView, Blender or Houdini)"
echo "statistics: $out/stats.csv (per frame), $out/steps.csv (per step), run: $out/run.json"
