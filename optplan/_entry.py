"""The ``optplan`` command's entry point: the signal handlers first, then the command line.

Importing :mod:`optplan.cli` takes ~0.1 s (NumPy among others); a Ctrl-C in that time used to end
the command with Python's ``KeyboardInterrupt`` traceback. This module imports only the standard
library (through :mod:`optplan.interrupt`) before it installs the handlers of
:func:`optplan.interrupt.before_start`, so that window shrinks to the interpreter's own start-up.
"""
from __future__ import annotations

from . import interrupt


def main() -> int:
    """``optplan ...``: :func:`optplan.cli.main` with the early signal handlers installed first."""
    interrupt.before_start()
    from .cli import main as cli_main

    return cli_main()
