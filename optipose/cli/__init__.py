"""The ``optipose`` command line: :mod:`optipose.cli.app` and one module per command."""

from optipose.cli.app import main

__all__ = ["main"]
