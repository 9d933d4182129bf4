"""A Dask scheduler address checked before Dask is given it, and a cluster watched for its workers.

Dask's own client, given something that is not a scheduler, can wait for ever (a silent port, an HTTP
server such as a Dask dashboard: it waits for the scheduler's handshake) or read the answer of a
foreign service as the length of a frame and ask for exabytes. So :func:`check_scheduler` looks first,
with a plain socket and bounded waits: the address must parse (``tcp://HOST:PORT`` or ``HOST:PORT``),
something must accept a connection there, and it must speak first with what a Dask scheduler sends
on every new connection (a small length-prefixed handshake). Each failure is one ``ConfigError``.

:class:`WorkerWatch` is the study's view of a cluster that lost every worker: after ``after`` seconds
without one it says so once (``notify``), then either raises :class:`NoWorkers` (``policy="stop"``) or
keeps waiting (``"wait"``); a worker coming back resets it. docs/batch.md, "Failures, kills and resume".
"""

from __future__ import annotations

import os
import socket
import struct
import time
from collections.abc import Callable

from optipose.errors import ConfigError, WorkerError

__all__ = ["check_scheduler", "split_address", "scheduler_timeout", "WorkerWatch", "NoWorkers", "NO_WORKER_POLICIES"]

NO_WORKER_POLICIES = ("stop", "wait")
HANDSHAKE_MAX = 1 << 20  # a scheduler's handshake is a few hundred bytes; a foreign answer read as a length is not
TIMEOUT_ENV = "OPTIPOSE_SCHEDULER_TIMEOUT"  # seconds for each step of the check (tests make it short)
DEFAULT_TIMEOUT = 10.0


class NoWorkers(WorkerError):
    """The cluster has had no worker for longer than the user allowed."""


def scheduler_timeout() -> float:
    """Seconds each step of the scheduler check may take: ``$OPTIPOSE_SCHEDULER_TIMEOUT`` or 10."""
    try:
        value = float(os.environ.get(TIMEOUT_ENV, DEFAULT_TIMEOUT))
    except ValueError:
        raise ConfigError(f"{TIMEOUT_ENV}: expected seconds, got '{os.environ[TIMEOUT_ENV]}'") from None
    return value if value > 0 else DEFAULT_TIMEOUT


def split_address(address: str) -> tuple[str, str, int]:
    """``(scheme, host, port)`` of a scheduler address; ConfigError naming what is wrong with it."""
    hint = "use tcp://HOST:PORT, e.g. tcp://127.0.0.1:8786"
    text = address.strip()
    scheme, sep, rest = text.partition("://")
    if not sep:
        scheme, rest = "tcp", text
    if scheme not in ("tcp", "tls"):
        raise ConfigError(f"--scheduler {address}: unknown scheme '{scheme}' ({hint})")
    host, sep, port = rest.rpartition(":")
    host = host.strip("[]")
    if not sep:
        raise ConfigError(f"--scheduler {address}: no port ({hint})")
    if not port.isdigit() or not 0 < int(port) < 65536:
        raise ConfigError(f"--scheduler {address}: '{port}' is not a port number ({hint})")
    if not host:
        raise ConfigError(f"--scheduler {address}: no host ({hint})")
    return scheme, host, int(port)


def check_scheduler(address: str, timeout: float | None = None) -> str:
    """The address as Dask takes it (``tcp://HOST:PORT``) once a Dask scheduler answers there; a
    ConfigError in one line otherwise, within about two ``timeout`` (:func:`scheduler_timeout`)."""
    timeout = scheduler_timeout() if timeout is None else timeout
    scheme, host, port = split_address(address)
    url = f"{scheme}://{host}:{port}" if ":" not in host else f"{scheme}://[{host}]:{port}"
    try:
        sock = socket.create_connection((host, port), timeout=timeout)
    except socket.gaierror as exc:
        raise ConfigError(f"cannot reach the Dask scheduler at {url} (unknown host: {exc.strerror})") from None
    except OSError as exc:
        reason = "nothing answers there" if isinstance(exc, TimeoutError) else exc.strerror or exc
        raise ConfigError(f"cannot reach the Dask scheduler at {url} ({reason})") from None
    if scheme == "tls":  # the handshake is inside TLS: Dask's own client (with its timeout) checks the rest
        sock.close()
        return url
    with sock:
        _check_handshake(sock, url, timeout)
    return url


def _check_handshake(sock: socket.socket, url: str, timeout: float) -> None:
    """A Dask scheduler speaks first: 8 bytes of length, then that many bytes of handshake."""
    not_dask = f"{url} is not a Dask scheduler"
    hint = "the scheduler's port is the one `dask scheduler` prints, 8786 unless changed; 8787 is its dashboard"
    head = _read(sock, 8, timeout)
    if head is None:
        raise ConfigError(f"{not_dask}: it accepted the connection but said nothing in {timeout:g} s ({hint})")
    if head.startswith(b"HTTP/") or head[:1] in (b"<", b"{"):
        raise ConfigError(f"{not_dask}: it answers like a web server ({hint})")
    (size,) = struct.unpack("<Q", head.ljust(8, b"\0"))
    if len(head) < 8 or not 0 < size <= HANDSHAKE_MAX:
        raise ConfigError(f"{not_dask}: it answered {_shown(head)} ({hint})")
    body = _read(sock, size, timeout)
    if body is None or len(body) < size or b"pickle-protocol" not in body:
        raise ConfigError(f"{not_dask}: its answer is not a Dask handshake ({hint})")


def _read(sock: socket.socket, n: int, timeout: float) -> bytes | None:
    """Up to ``n`` bytes within ``timeout`` seconds in all: None if nothing came, fewer if it closed."""
    deadline, data = time.monotonic() + timeout, b""
    while len(data) < n:
        left = deadline - time.monotonic()
        if left <= 0:
            break
        sock.settimeout(left)
        try:
            chunk = sock.recv(n - len(data))
        except TimeoutError:
            break
        except OSError:
            break
        if not chunk:
            break
        data += chunk
    return data or None


def _shown(data: bytes) -> str:
    text = data.decode("ascii", "replace")
    return repr(text) if text.isprintable() else f"bytes {data.hex(' ')}"


class WorkerWatch:
    """Call :meth:`check` with the number of workers now, as often as convenient (see the module doc)."""

    def __init__(
        self,
        where: str,
        policy: str = "stop",
        after: float = 60.0,
        notify: Callable[[str], None] | None = None,
        clock: Callable[[], float] = time.monotonic,
    ):
        if policy not in NO_WORKER_POLICIES:
            raise ConfigError(f"--no-workers {policy}: use {' or '.join(NO_WORKER_POLICIES)}")
        if not after > 0:
            raise ConfigError(f"--no-workers-after {after:g}: expected a number of seconds above 0")
        self.where, self.policy, self.after = where, policy, float(after)
        self.notify, self.clock = notify or (lambda line: None), clock
        self._since: float | None = None
        self._said = False

    def check(self, n_workers: int) -> None:
        if n_workers > 0:
            if self._said:
                self.notify(f"the Dask cluster at {self.where} has {n_workers} worker(s) again: the study goes on")
            self._since, self._said = None, False
            return
        now = self.clock()
        self._since = now if self._since is None else self._since
        if now - self._since < self.after or self._said:
            return
        line = f"no Dask worker at {self.where} for {self.after:g} s"
        if self.policy == "stop":
            raise NoWorkers(f"{line}: the study stopped (start workers with `dask worker {self.where}`)")
        self._said = True
        self.notify(f"{line}: waiting for workers (--no-workers wait; Ctrl-C stops, --resume continues)")
