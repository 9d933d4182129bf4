"""Files written whole or not at all: a killed run, a full disk or a crash mid-write never leaves a half
file under a result's name.

Every writer writes to a temporary file beside its target (``.<name>.tmp-<pid>``, same folder, so the same
file system) and ``os.replace``-s it over the target, which POSIX makes atomic: a reader sees the old file
or the new one. On an error (``ENOSPC``, a read-only disk) the temporary file is removed and the target
is left as it was. A process killed mid-write may leave its temporary file behind, never a torn target.
(Nothing is fsync-ed: the page cache outlives a killed process; a power cut is not covered.)
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator
from pathlib import Path

__all__ = ["atomic_path", "write_text", "write_bytes", "is_temporary", "reading"]


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path to write ``path``'s new content to; it replaces ``path`` when the block ends
    without an error and is removed when it raises (an ``OSError`` about it then names ``path``)."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        yield tmp
        os.replace(tmp, path)
    except OSError as exc:
        if exc.filename == str(tmp):  # the user's message names the file they know
            exc.filename = str(path)
        raise
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()


@contextlib.contextmanager
def reading(path: str | Path) -> Iterator[Path]:
    """Read (and parse) ``path`` in the block; a file that is missing or cannot be parsed — truncated,
    overwritten, another format: whatever the CSV, Parquet, NPZ or TOML reader raises — is one
    :class:`~optipose.errors.ConfigError` naming it, ``<path>: damaged (<the reader's first line>)``.
    A file the system will not let us read stays an ``OSError`` (permission denied is not damage)."""
    from optipose.errors import ConfigError, OptiposeError

    path = Path(path)
    try:
        yield path
    except (OptiposeError, PermissionError, IsADirectoryError, MemoryError):
        raise
    except FileNotFoundError:
        raise ConfigError(f"{path}: missing (the folder is incomplete)") from None
    except (
        Exception
    ) as exc:  # pyarrow's ArrowInvalid and OSError, pandas' ParserError, zipfile's BadZipFile, KeyError, ...
        text = str(exc).strip().splitlines()
        reason = text[0][:120] if text else type(exc).__name__
        reason = f"no {reason}" if isinstance(exc, KeyError) else reason  # a column or key it should have
        raise ConfigError(f"{path}: damaged ({reason})") from None


def write_text(path: str | Path, text: str) -> Path:
    """``path.write_text(text)`` (UTF-8), atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return Path(path)


def write_bytes(path: str | Path, data: bytes) -> Path:
    """``path.write_bytes(data)``, atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def is_temporary(path: str | Path) -> bool:
    """Whether ``path`` is a writer's temporary file (one a killed process can leave behind)."""
    name = Path(path).name
    return name.startswith(".") and ".tmp-" in name
