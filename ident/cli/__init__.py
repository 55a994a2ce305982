"""The command lines' shared plumbing: one-line usage errors, bad input as one line and exit code 2.

``ident.cli`` is the I/O edge of the science package: the ``ident`` command (``ident.cli.main``) and
its subcommands live here, and only here may ``ident`` compose other packages' readers. ``daq`` and
``replay`` use this module's two helpers for their own commands.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable


class OneLineParser(argparse.ArgumentParser):
    """argparse that reports a usage error as one line and exits 2."""

    def error(self, message: str):  # noqa: D401 - argparse API
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog.split()[0]} --help)\n")


def run_guarded(prog: str, func: Callable[[argparse.Namespace], int], args: argparse.Namespace) -> int:
    """Run a command; bad input is one line on stderr and exit code 2, never a traceback."""
    try:
        return func(args)
    except (ValueError, OSError) as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
