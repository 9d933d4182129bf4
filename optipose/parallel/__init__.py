"""Where work runs: the executors of an evaluation's scans (``executors``), the CAD-surface reference shared
between processes (``shared``) and one call run beside the caller (``background``).

See ARCHITECTURE.md for how the packages fit together."""
