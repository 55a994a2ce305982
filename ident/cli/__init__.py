"""Command line of ``ident``: the I/O edge of the science package.

Every ValueError or OSError raised by bad input becomes one line on stderr and
exit code 2; argparse's own errors are folded into one line too.
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


def build_parser() -> argparse.ArgumentParser:
    from . import bench, discover, duffing_report, fit

    parser = OneLineParser(prog="ident", description="SINDy identification of forced vibrations "
                           "(Lubricants 2019, 7(8), 64)")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=OneLineParser)
    duffing_report.add_parser(sub)
    fit.add_parser(sub)
    discover.add_parser(sub)
    bench.add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    return run_guarded(f"ident {args.command}", args.func, args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
