"""The ``optipose`` command line: :mod:`optipose.cli.app`, :mod:`optipose.cli.options` and one module per
command (scan, parts, evaluate, search)."""

__all__ = ["main"]


def main() -> None:
    """Run the ``optipose`` command line (the console script's entry point)."""
    # imported here, not above, so importing one command module does not build the whole app
    from optipose.cli.app import main as run

    try:
        run()
    finally:  # the command is done: its idle workers need not finish their own teardown first
        from optipose.evaluate.executors import stop_workers

        stop_workers()
