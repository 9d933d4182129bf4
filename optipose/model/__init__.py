"""The cell: part, mesh, sensor and material models, layouts, the scan motion, and head collisions.

See ARCHITECTURE.md for how the packages fit together."""
