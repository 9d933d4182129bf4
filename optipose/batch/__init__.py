"""Batch studies: many parts and settings, each trial in its own result folder, on one machine or a cluster.

The flow, module by module: ``spec`` (the study file → trials) → ``threads`` (how the cores are split) →
``pools`` (this process, joblib's process pool or Dask) → ``trial`` (one trial in a worker, its folder
written whole) → ``results`` (its per-axis numbers read back) → ``records`` / ``index`` (one row per
trial, written atomically) → ``study`` (the loop that ties them) → ``summary`` (the table per part and
setting). ``optipose batch`` and ``optipose study`` (:mod:`optipose.cli.batch`) are the commands.

See ARCHITECTURE.md for how the packages fit together."""
