#!/usr/bin/env bash
# Snakemake's cluster-status for SLURM: prints running, success or failed for the job id in $1.
state="$(sacct -j "$1" --format=State --noheader --parsable2 2>/dev/null | head -n 1)"
[[ -n "$state" ]] || state="$(squeue -h -j "$1" -o %T 2>/dev/null | head -n 1)"
case "$state" in
  COMPLETED) echo success ;;
  ""|PENDING|RUNNING|CONFIGURING|COMPLETING|REQUEUED|RESIZING|SUSPENDED) echo running ;;
  *) echo failed ;;
esac
