"""The evaluation pipeline: every run, metric, table and figure of notebooks/results/ as keyed jobs
of a Snakemake workflow (workflow/Snakefile; docs/workflow.md).

  catalogue  what runs: runs, studies, sweeps, targets (declared once)
  plan       the configuration and catalogue as keyed jobs
  runner     one simulation into its keyed folder
  metrics    one comparison with the ground truth
  tables     a study's or sweep's results folder
  progress   the progress line and the time left
"""
