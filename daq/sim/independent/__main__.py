"""``python -m daq.sim.independent campaign OUT_DIR --cases N --seed S``: write a campaign of cases.

Case i uses seed S + i, so any case can be regenerated alone. OUT_DIR must be missing or empty; each
case gets a folder NNN_seedS_family_cause (case.csv, truth.json, and truth.csv: a regime case's per-sample
regimes, a discovery case's channels before their sensors' noise), and campaign.json lists them. With
``--twins`` each discovery case's twin (the same draws without the effect) follows it in a folder
NNN_seedS_family_none_twin.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from .cases import FAMILY_CAUSES, discovery_case
from .recording import jsonable, write_case
from .regimes import REGIMES, regime_case, steady_case


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="python -m daq.sim.independent")
    sub = p.add_subparsers(dest="command", required=True)
    c = sub.add_parser("campaign", help="write one folder per case")
    c.add_argument("out_dir", type=Path)
    c.add_argument("--cases", type=int, required=True)
    c.add_argument("--seed", type=int, required=True)
    c.add_argument("--kind", choices=["discovery", "regimes", "steady"], default="discovery")
    c.add_argument("--family", choices=sorted(FAMILY_CAUSES), help="discovery: only this family")
    c.add_argument("--cause", help="discovery: only this cause")
    c.add_argument("--twins", action="store_true", help="discovery: each case's twin too (without the effect)")
    c.add_argument("--regime", choices=list(REGIMES), help="steady: the regime (default: cycle through all)")
    c.add_argument("--minutes", type=float, default=10.0, help="steady: record length")
    c.add_argument("--fs", type=int, help="regimes/steady: output rate (Hz)")
    return p


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    out: Path = args.out_dir
    if out.exists() and any(out.iterdir()):
        print(f"{out} is not empty; refusing to write into it", file=sys.stderr)
        return 2
    out.mkdir(parents=True, exist_ok=True)
    index = []
    for i in range(args.cases):
        seed = args.seed + i
        t0 = time.perf_counter()
        if args.kind == "discovery":
            case = discovery_case(seed, family=args.family, cause=args.cause)
            label = f"{case.family}_{case.truth['cause']}"
        elif args.kind == "regimes":
            case = regime_case(seed, fs_hz=args.fs)
            label = "regimes"
        else:
            regime = args.regime or list(REGIMES)[i % len(REGIMES)]
            case = steady_case(seed, regime, minutes=args.minutes, fs_hz=args.fs or 1000)
            label = f"steady_{regime}"
        made = [(case, label)]
        if args.kind == "discovery" and args.twins:
            made.append((discovery_case(seed, family=args.family, cause=args.cause, twin=True),
                         f"{case.family}_none_twin"))
        for c, name in made:
            folder = write_case(c, out / f"{i:03d}_seed{seed}_{name}")
            seconds = time.perf_counter() - t0
            summary = {"folder": folder.name, "seed": seed, "family": c.family, "seconds": seconds}
            summary |= {k: c.truth[k] for k in ("cause", "location", "effect_strength", "regime_share", "twin_of")
                        if k in c.truth}
            index.append(summary)
            print(json.dumps(jsonable(summary)), flush=True)
    (out / "campaign.json").write_text(json.dumps(jsonable(index), indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
