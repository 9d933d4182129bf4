"""One call run in a process of its own while this one goes on: ``Background(fn, *args).result()``.

The process is a fresh interpreter (``spawn``: no thread or lock of this one is copied into it) whose
thread pools are capped before anything is imported (:func:`optipose.parallel.executors.thread_env`:
the call and its arguments travel as bytes and are unpickled only after the caps are set), so a call
given one thread takes one core. The answer comes back through a pipe; if the process dies (killed, out
of memory) the pipe says so at once, and :meth:`Background.result` raises
:class:`~optipose.errors.WorkerError` instead of waiting for ever. :meth:`Background.close` stops the
call whether it has finished or not. This module imports nothing heavy, so the process starts lean.
"""

from __future__ import annotations

import multiprocessing
import os
import pickle

from optipose.errors import WorkerError

__all__ = ["Background"]


class Background:
    """``fn(*args)`` in a process of its own, started at once; ``threads``: its thread pools' size;
    ``nice``: how much lower its scheduling priority is than this process's (0: the same), so that where
    both want a core this one goes first."""

    def __init__(self, fn, *args, threads: int = 1, nice: int = 0):
        from optipose.parallel.executors import thread_env

        context = multiprocessing.get_context("spawn")
        payload = pickle.dumps((fn, args), protocol=pickle.HIGHEST_PROTOCOL)
        self._receive, send = context.Pipe(duplex=False)
        self._process = context.Process(
            target=_serve,
            args=(send, thread_env(threads), nice, payload),
            daemon=True,
            name=f"optipose-{getattr(fn, '__name__', 'call')}",
        )
        try:
            self._process.start()
        except BaseException:
            self._receive.close()
            raise
        finally:
            send.close()  # this process's copy of the child's end: when the child dies, the pipe ends
        self._answer: tuple | None = None

    def result(self):
        """The call's return value, waiting for it; :class:`WorkerError` when the call raised, its process
        died, or the call was stopped by :meth:`close`."""
        if self._answer is None:
            if self._receive.closed:
                raise WorkerError("the background call was stopped before it answered")
            try:
                self._answer = self._receive.recv()
            except (EOFError, OSError):
                self._process.join(timeout=5)
                self._answer = (False, f"its process ended without an answer (exit code {self._process.exitcode})")
            self.close()
        ok, value = self._answer
        if not ok:
            raise WorkerError(f"background {self._process.name}: {value}")
        return value

    def close(self) -> None:
        """Stop the call (if it is still running) and release its process."""
        if self._process.is_alive():
            self._process.terminate()
            self._process.join(timeout=10)
            if self._process.is_alive():  # it did not stop on SIGTERM
                self._process.kill()
                self._process.join(timeout=10)
        self._receive.close()

    def __enter__(self) -> "Background":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _serve(send, env: dict, nice: int, payload: bytes) -> None:
    """The child's side: cap the thread pools and lower the priority, then unpickle and run the call, and
    send back ``(True, value)`` or ``(False, what went wrong)``."""
    os.environ.update(env)
    if nice:
        os.nice(nice)
    try:
        fn, args = pickle.loads(payload)
        answer = (True, fn(*args))
    except BaseException as exc:  # noqa: BLE001 - the parent reports it
        answer = (False, f"{type(exc).__name__}: {exc}")
    try:
        send.send(answer)
    except (BrokenPipeError, OSError):  # the parent stopped listening
        pass
    finally:
        send.close()
