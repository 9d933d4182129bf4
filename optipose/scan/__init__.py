"""The virtual LLT scanner: ray casting, the measuring model (shadows, dropouts, noise) and the raw profile format.

See ARCHITECTURE.md for how the packages fit together."""
