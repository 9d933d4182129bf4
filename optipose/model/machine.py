"""Arrays derived from a dense mesh, computed once per machine: the other processes of the machine (the
evaluator's workers, the hand layout's processes beside the search) read them from a file instead.

Each set of arrays is written to a file of the system's temporary folder named by what it is (``tag``) and
a digest of the arrays it was derived from; a file so named can only hold those arrays' results, so one left
behind by a killed process is still right, only disk space. The process that wrote a file removes it when
it exits. A mesh of at most :data:`SHARED_FACES` faces computes its own: it costs less than the file.
"""

from __future__ import annotations

import atexit
import contextlib
import hashlib
import os
import tempfile
from pathlib import Path

import numpy as np

__all__ = ["per_machine", "digest", "SHARED_FACES"]

SHARED_FACES = 100_000  # meshes with more faces share what is derived from them between the processes of a machine

_WRITTEN: list[Path] = []  # the files this process wrote, removed at its exit


@atexit.register
def _remove_written() -> None:
    for path in _WRITTEN:
        with contextlib.suppress(OSError):
            path.unlink()


def digest(*arrays: np.ndarray) -> str:
    """A digest of the arrays' values, shapes and types."""
    h = hashlib.sha1()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype.str}{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def per_machine(tag: str, key: str, compute, names: tuple[str, ...]) -> tuple[np.ndarray, ...]:
    """``compute()`` (a tuple of arrays, one per name), read from this machine's file for ``tag`` and ``key``
    when another process wrote it, else computed and written there."""
    path = Path(tempfile.gettempdir()) / f"optipose-{tag}-{key}.npz"
    with contextlib.suppress(Exception):  # missing, or being replaced: compute it
        with np.load(path) as data:
            return tuple(np.array(data[name]) for name in names)
    arrays = compute()
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        with open(tmp, "wb") as fh:
            np.savez(fh, **dict(zip(names, arrays)))
        os.replace(tmp, path)
        _WRITTEN.append(path)
    except OSError:  # a full or read-only temporary folder: every process computes its own
        with contextlib.suppress(OSError):
            tmp.unlink()
    return arrays
