"""``replay``: recordings after the fact (``recover`` now; playback arrives with its issue)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ident.cli import OneLineParser, run_guarded


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="replay", description="work with recordings of the shaker rig")
    sub = p.add_subparsers(dest="command", required=True, parser_class=OneLineParser)
    r = sub.add_parser("recover", help="rebuild a readable MCAP file from a truncated one")
    r.add_argument("broken", type=Path)
    r.add_argument("-o", "--output", type=Path, required=True)
    r.set_defaults(func=recover_cmd)
    return p


def recover_cmd(args) -> int:
    from .recover import recover

    rep = recover(args.broken, args.output)
    state = "complete file" if rep.complete else f"truncated input ({rep.stopped_at or 'no footer'})"
    topics = ", ".join(f"{k}: {v}" for k, v in sorted(rep.messages.items()))
    print(f"{args.output}: {rep.total_messages} messages recovered from {rep.chunks} chunks; {state}; {topics}")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return run_guarded(f"replay {args.command}", args.func, args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
