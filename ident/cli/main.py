"""The ``ident`` command: the paper's Duffing study, ``fit``, ``discover``, ``batch`` and the benchmarks."""

from __future__ import annotations

import argparse
import sys

from . import OneLineParser, batch, bench, discover, duffing_report, fit, run_guarded


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(prog="ident", description="SINDy identification of forced vibrations "
                           "(Lubricants 2019, 7(8), 64)")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=OneLineParser)
    duffing_report.add_parser(sub)
    fit.add_parser(sub)
    discover.add_parser(sub)
    batch.add_parser(sub)
    bench.add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    return run_guarded(f"ident {args.command}", args.func, args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
