"""The optimiser: the surrogate problem, the NLopt driver, one module per stage, and the pipeline that runs them.

See ARCHITECTURE.md for how the packages fit together."""
