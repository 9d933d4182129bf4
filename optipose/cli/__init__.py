"""The ``optipose`` command line: :mod:`optipose.cli.app`, :mod:`optipose.cli.options` and one module per
command (scan, parts, evaluate, search)."""

__all__ = ["main"]


def main() -> None:
    """Run the ``optipose`` command line (the console script's entry point)."""
    # imported here, not above, so importing one command module does not build the whole app
    from optipose.cli.app import main as run

    try:
        run()
    finally:  # the command is done: its idle workers need not finish their own teardown first ...
        import contextlib
        import gc

        from optipose.parallel.executors import stop_workers

        with contextlib.suppress(Exception):  # a pool that will not stop now is stopped at the exit, as before
            stop_workers()
        # ... nor need the interpreter's last collections walk every object the command made (more than half
        # a second after a search; benchmarks/README.md, "bench_start.py"): the process ends, its memory with it
        gc.freeze()
