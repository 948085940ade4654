#!/usr/bin/env bash
# A stand-in for sbatch: runs the job script ($1) in the background, its exit status to <pid>.status,
# and prints the job id (the process id), as `sbatch --parsable` does.
set -euo pipefail
queue="${PNET_LOCAL_QUEUE:-out/workflow/local-queue}"
mkdir -p "$queue"
script="$(realpath "$1")"
bash -c 'bash "$1" > "$2/$$.log" 2>&1; echo $? > "$2/$$.status"' _ "$script" "$queue" </dev/null >/dev/null 2>&1 &
echo $!
