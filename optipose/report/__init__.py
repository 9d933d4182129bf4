"""What people look at: pictures of a part with its sensors.

See ARCHITECTURE.md for how the packages fit together."""
