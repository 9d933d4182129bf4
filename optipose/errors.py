"""User-facing errors.

Library code raises these; only the CLI turns them into a one-line message and a non-zero exit.
"""


class OptiposeError(Exception):
    """Base class for every error a user can cause (bad input, bad config)."""


class MeshError(OptiposeError):
    """A mesh is missing, empty, unreadable or not usable (NaN vertices, no faces, wrong units)."""


class ConfigError(OptiposeError):
    """A config, preset, layout or objective file is missing, malformed or inconsistent."""


class WorkerError(OptiposeError):
    """A worker process died (killed, out of memory) and the work it had could not be finished."""


class PoseError(OptiposeError):
    """A pose matrix is not a proper rigid transform."""


def read_toml(path, what: str = "") -> tuple[dict, str]:
    """A TOML file's table and its text; a syntax error is a :class:`ConfigError` naming the file as
    ``"<what> <path>: …"`` (``"<path>: …"`` without ``what``). Whether the file exists is the caller's to say."""
    import tomllib

    try:
        text = path.read_text()
        return tomllib.loads(text), text
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        reason = "not a text file" if isinstance(exc, UnicodeDecodeError) else exc
        raise ConfigError(f"{what} {path}: {reason}" if what else f"{path}: {reason}") from None


def shipped_toml(spec, folder, what: str):
    """The TOML file ``spec`` names: a shipped name (``folder/<spec>.toml``) or a path; a name that is
    neither, or a path that is no file, is one :class:`ConfigError` (``what``: "objective", "cell")."""
    from pathlib import Path

    path = Path(spec)
    if not path.suffix and not path.exists():
        path = Path(folder) / f"{spec}.toml"
        if not path.is_file():
            shipped = sorted(p.stem for p in Path(folder).glob("*.toml"))
            raise ConfigError(f"unknown {what} '{spec}' (shipped: {', '.join(shipped)}; or give a .toml path)")
    if not path.is_file():
        raise ConfigError(f"{what} file not found: {path}")
    return path


def is_interrupt(exc: BaseException) -> bool:
    """Ctrl-C: a ``KeyboardInterrupt``, or the ``SystemError`` a compiled (numba) function raises when the
    interrupt arrives while it runs ("returned a result with an exception set", the interrupt its context)."""
    while isinstance(exc, SystemError):  # numba may wrap it twice (its dispatcher, and an unpickling under it)
        exc = exc.__cause__ or exc.__context__
    return isinstance(exc, KeyboardInterrupt)


_INTERRUPTS: list[int] = []  # the Ctrl-Cs this process was sent since note_interrupts()


def note_interrupts() -> None:
    """Note every Ctrl-C (SIGINT) this process is sent before Python raises its ``KeyboardInterrupt``, so that
    code which catches that by mistake (a library's broad ``except``, a compiled function's ``SystemError``
    whose cause was lost) cannot hide it from :func:`interrupted`. Call it from the main thread; an ignored
    SIGINT stays ignored."""
    import signal

    _quiet_threads_after_interrupts()
    previous = signal.getsignal(signal.SIGINT)
    if previous in (signal.SIG_IGN, None) or getattr(previous, "notes_interrupts", False):
        return

    def handler(signum, frame):
        _INTERRUPTS.append(signum)
        if callable(previous):  # Python's own: raises KeyboardInterrupt
            return previous(signum, frame)
        raise KeyboardInterrupt

    handler.notes_interrupts = True
    signal.signal(signal.SIGINT, handler)


def _quiet_threads_after_interrupts() -> None:
    """Once a Ctrl-C was noted, a thread that dies while the interrupt unwinds (a pool's manager or queue feeder
    finding its workers' pipes closed) prints no traceback: the user asked to stop, and the one line saying what
    was kept and how to resume is the answer. Before any Ctrl-C a thread's error is printed as Python prints it."""
    import threading

    previous = threading.excepthook
    if getattr(previous, "quiet_after_interrupts", False):
        return

    def hook(args):
        if _INTERRUPTS:
            return
        previous(args)

    hook.quiet_after_interrupts = True
    threading.excepthook = hook


def interrupted() -> bool:
    """Whether this process was sent a Ctrl-C since :func:`note_interrupts` (always False before it)."""
    return bool(_INTERRUPTS)
