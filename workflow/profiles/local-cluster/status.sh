#!/usr/bin/env bash
# The stand-in's job status: running while the job's process lives, then success or failed.
queue="${PNET_LOCAL_QUEUE:-out/workflow/local-queue}"
if [[ -f "$queue/$1.status" ]]; then
  [[ "$(cat "$queue/$1.status")" == 0 ]] && echo success || echo failed
elif kill -0 "$1" 2>/dev/null; then echo running
else echo failed
fi
