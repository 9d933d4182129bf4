"""The paper's protocol: objective files, perturbations, the evaluator and its executors, statistics, Table 1, verdicts.

See ARCHITECTURE.md for how the packages fit together."""
