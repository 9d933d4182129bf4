"""One CAD-surface reference per machine, shared by the evaluator's worker processes.

Without it, every worker process builds its own :class:`~optipose.registration.reference.SurfaceReference`
(about 400 bytes a face): n workers hold n copies. Here the evaluator's process builds it once, writes its
arrays into a temporary folder (:func:`~optipose.registration.reference.save_reference`), and the workers
map them read-only (:func:`~optipose.registration.reference.load_reference`): one copy in the page cache
for every process of the machine. A worker that does not find the folder (a Dask worker on another
machine) builds its own. Evaluators of one mesh in one process share one folder, removed when the last of
them closes (or, at the latest, when the process exits). A search acquires it before anything else needs it,
so that its surrogate (:func:`surface`), the hand layout's processes and the validation's workers all map the
one built. A folder is named by the process that made it: a process killed before its exit (SIGKILL, the
out-of-memory killer) leaves its folder behind, and the next one to make a folder on the machine removes it
(:func:`sweep`), so that killed runs do not fill the temporary folder (a dense mesh's reference is hundreds of MB).
"""

from __future__ import annotations

import atexit
import hashlib
import os
import shutil
import tempfile
import threading
from pathlib import Path

import numpy as np

__all__ = ["acquire", "release", "surface", "sweep", "PREFIX"]

PREFIX = "optipose-reference-"  # then the process's pid namespace and pid (_owner), a dash and tempfile's letters

_LOCK = threading.Lock()
_FOLDERS: dict[str, list] = {}  # mesh key -> [folder, users]


@atexit.register
def _remove_all() -> None:
    """The folders of evaluators never closed, at the process's exit."""
    for folder, _ in _FOLDERS.values():
        shutil.rmtree(folder, ignore_errors=True)


def _key(vertices: np.ndarray, faces: np.ndarray) -> str:
    digest = hashlib.sha1(np.ascontiguousarray(vertices, dtype=np.float64).tobytes())
    digest.update(np.ascontiguousarray(faces, dtype=np.int64).tobytes())
    return digest.hexdigest()


def acquire(vertices: np.ndarray, faces: np.ndarray) -> tuple[str, str]:
    """The folder holding the surface reference of this mesh, built and written on first use: (key, folder)."""
    from optipose.registration.reference import SurfaceReference, save_reference

    key = _key(vertices, faces)
    with _LOCK:
        if key not in _FOLDERS:
            sweep()
            folder = tempfile.mkdtemp(prefix=f"{PREFIX}{_owner(os.getpid())}-")
            try:
                save_reference(SurfaceReference(vertices, faces), folder)
            except BaseException:
                shutil.rmtree(folder, ignore_errors=True)
                raise
            _FOLDERS[key] = [folder, 0]
        _FOLDERS[key][1] += 1
        return key, _FOLDERS[key][0]


def sweep(root: str | None = None) -> list[str]:
    """Remove the reference folders in ``root`` (the temporary folder) whose process is gone: a process killed
    before its exit could not. A folder of a live process, of another user's, of another pid namespace or
    without a pid in its name (an older version's) is left. Returns the folders removed."""
    removed, ours = [], f"{PREFIX}{_namespace()}."
    for folder in Path(root or tempfile.gettempdir()).glob(f"{ours}*-*"):
        pid = folder.name[len(ours) :].split("-", 1)[0]
        if pid.isdigit() and not _alive(int(pid)) and folder.is_dir():
            shutil.rmtree(folder, ignore_errors=True)
            removed.append(str(folder))
    return removed


def _owner(pid: int) -> str:
    """``<namespace>.<pid>``: a pid means a process only within its pid namespace (a container sharing the
    temporary folder has its own), so a folder is swept only by a process of the same namespace."""
    return f"{_namespace()}.{pid}"


def _namespace() -> int:
    """This process's pid namespace (its inode; 0 without /proc: one namespace)."""
    try:
        return os.stat("/proc/self/ns/pid").st_ino
    except OSError:
        return 0


def _alive(pid: int) -> bool:
    """Whether a process of that pid runs (one of another user's counts: it cannot be signalled, but it runs)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # PermissionError: another user's
        return True
    return True


def release(key: str) -> None:
    """One user fewer of the folder of ``key``; the last one removes it."""
    with _LOCK:
        entry = _FOLDERS.get(key)
        if entry is None:
            return
        entry[1] -= 1
        if entry[1] <= 0:
            del _FOLDERS[key]
            shutil.rmtree(entry[0], ignore_errors=True)


def surface(vertices: np.ndarray, faces: np.ndarray):
    """The surface reference of this mesh: mapped from its folder when this process holds one
    (:func:`acquire`), else built here."""
    from optipose.registration.reference import SurfaceReference, load_reference

    with _LOCK:
        entry = _FOLDERS.get(_key(vertices, faces)) if _FOLDERS else None
        if entry is not None:
            return load_reference(entry[0])
    return SurfaceReference(vertices, faces)
