"""Result folders: one timestamped folder per run with the config it ran, and a ``latest`` link.

``results/<part>-<command>-<YYYYmmdd-HHMMSS>/`` holds ``config.toml`` (the objective file as written, the
resolved SI config, part, layout, seed, package versions and ``format``, the folder layout's version:
``RESULT_FORMAT``, raised when a command's files or config keys change so that an older folder can be
told apart) beside the command's tables. Files are SI
(radians, metres); column names say so where it matters.
"""

from __future__ import annotations

import logging
import platform
import time
from importlib import metadata
from pathlib import Path

import numpy as np

from optipose.io.config import RunConfig, run_config

__all__ = [
    "make_result_dir",
    "write_config",
    "part_table",
    "read_config",
    "write_csv",
    "versions",
    "RESULTS_DIR",
    "RESULT_FORMAT",
]

log = logging.getLogger(__name__)
RESULTS_DIR = Path("results")
RESULT_FORMAT = 1  # config.toml's ``format``; folders written before it was recorded have none


def make_result_dir(part: str, command: str, out: Path | None = None, root: Path = RESULTS_DIR) -> Path:
    """Create the result folder (``out`` if given) and point ``<root>/latest`` at it."""
    if out is None:
        stamp = time.strftime("%Y%m%d-%H%M%S")
        out = root / f"{part}-{command}-{stamp}"
        n = 1
        while out.exists():  # two runs in the same second
            n += 1
            out = root / f"{part}-{command}-{stamp}-{n}"
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    _link_latest(out, out.parent)
    return out


def _link_latest(target: Path, root: Path) -> None:
    latest = root / "latest"
    try:
        if latest.is_symlink() or latest.exists():
            if not latest.is_symlink():
                return  # a real folder named latest: leave it alone
            latest.unlink()
        latest.symlink_to(target.name, target_is_directory=True)
    except OSError as exc:  # e.g. no symlinks on this file system
        log.warning("could not update %s: %s", latest, exc)


def versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for name in ("optipose", "numpy", "scipy", "open3d-cpu", "open3d", "trimesh", "embreex", "pandas"):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            continue
    return out


def write_config(folder: Path, table: dict) -> Path:
    """``config.toml`` of a result folder: what produced it (command, part, objective file, seed, versions)
    and the folder's ``format``."""
    import tomli_w

    from optipose.files import write_text

    return write_text(Path(folder) / "config.toml", tomli_w.dumps(_plain({"format": RESULT_FORMAT, **table})))


def part_table(name: str, source: str, units: str = "auto") -> dict:
    """``[part]`` of a config: its name, the file it was loaded from (relative to the repository's root when inside
    it) and, when given, its units (``--units`` that the part must be loaded with again)."""
    from optipose.model.part import repo_relative

    return {"name": name, "source": repo_relative(source), **({"units": units} if units and units != "auto" else {})}


def write_csv(frame, path: Path) -> Path:
    """A table as CSV (no index), whole or not at all (:mod:`optipose.files`)."""
    from optipose.files import atomic_path

    with atomic_path(path) as tmp:
        frame.to_csv(tmp, index=False)
    return Path(path)


def read_config(folder: Path) -> RunConfig:
    """The ``config.toml`` of a result folder as a :class:`~optipose.io.config.RunConfig`; ConfigError when
    there is none or it is broken."""
    from optipose.errors import ConfigError, read_toml

    path = Path(folder) / "config.toml"
    if not path.is_file():
        raise ConfigError(f"{folder}: no config.toml there (not an optipose result folder)")
    return run_config(read_toml(path)[0])


def _plain(value):
    """TOML-safe: tuples to lists, numpy to Python, None dropped."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items() if v is not None}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return str(value)
    return value
