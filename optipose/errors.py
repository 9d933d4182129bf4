"""User-facing errors.

Library code raises these; only the CLI turns them into a one-line message and a non-zero exit.
"""


class OptiposeError(Exception):
    """Base class for every error a user can cause (bad input, bad config)."""


class MeshError(OptiposeError):
    """A mesh is missing, empty, unreadable or not usable (NaN vertices, no faces, wrong units)."""


class ConfigError(OptiposeError):
    """A config, preset, layout or objective file is missing, malformed or inconsistent."""


class PoseError(OptiposeError):
    """A pose matrix is not a proper rigid transform."""
