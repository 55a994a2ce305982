"""``daq bench --regimes``: the regime monitor on the independent generator's rigs, across the ranges.

Each seed draws one rig from ``daq.sim.independent`` (its own finite-element beams, stoppers,
integrator and instrument chain; nothing from ``ident``): stoppers 2-1000 times the beam's
stiffness, one- or two-sided, 500 Hz to 5 kHz, beam 2 mistuned by up to 15 %, coupling 1-10 %,
noise 25-40 dB, sensors mounted either way up. Per seed:

- ``regime_case(seed)``: a programme through all four regimes (about two minutes), scored by
  ``ident.live.scoring`` (share of half-second windows right, the first second after each true
  change not counted; latency of each true change; false changes);
- ``steady_case(seed, regime, minutes)``: the same rig held in one regime (cycling none, beam 1,
  beam 2, both over the seeds) for ``--minutes`` (default 10); every reported change is false.

The monitor reads the three acceleration columns only, in serial-read-sized blocks, and never the
truth. With ``--config-gaps`` it also runs as if the rig's config gave the stopper gaps (the
generator's tip-equivalent gaps). Prints a row per seed and the figures per range (stopper
stiffness, sides, rate, mistuning, coupling, noise). Cases are simulated anew unless ``--cache DIR``
holds them (written there on first use, one ``.npz`` per case, atomically and never over an existing
file: daq.safeio): generating takes most of the time.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ident.cli import REGIME_WINDOW, SEED, number
from ident.live.regimes import LABELS, RegimeConfig, regime_start, regime_step
from ident.live.scoring import score_regimes, scored_windows, true_changes

from .safeio import safe_output
from .sim.independent.beams import BeamSpec, assemble_beam
from .sim.independent.modal import normal_modes
from .sim.independent.recording import jsonable
from .sim.independent.regimes import REGIMES, regime_case, steady_case

TARGET_SHARE = 0.95
BLOCK_S = 0.05  # serial-read-sized blocks


def add_arguments(p) -> None:
    g = p.add_argument_group("regime benchmark (--regimes)")
    g.add_argument("--regimes", action="store_true",
                   help="only the regime monitor on the independent generator's rigs (long: minutes per seed)")
    g.add_argument("--cases", type=number(1, 10_000, integer=True), default=24,
                   help="--regimes: number of seeds (default 24)")
    g.add_argument("--seed", type=SEED, default=1000, help="--regimes: first seed (default 1000)")
    g.add_argument("--minutes", type=number(0.0, 1440.0, gt=True, unit="min"), default=10.0,
                   help="--regimes: steady minutes per seed (default 10)")
    g.add_argument("--cache", type=Path, help="--regimes: folder to keep the generated cases in")
    g.add_argument("--config-gaps", action="store_true",
                   help="--regimes: also run with the stopper gaps given, as a config would")
    g.add_argument("--first-hz", metavar="LO,HI", type=_first_range, default=FIRST_RANGE_HZ,
                   help="--regimes: the range beam 1's first mode is drawn from (default 8,15 Hz; "
                        "3.5,6 for slow rigs)")
    g.add_argument("--regime-window", type=REGIME_WINDOW, default=RegimeConfig.window_s,
                   help=f"--regimes: the monitor's window (default {RegimeConfig.window_s:g} s)")


FIRST_RANGE_HZ = (8.0, 15.0)  # the generator's default draw of beam 1's first mode


def _first_range(text: str) -> tuple[float, float]:
    """argparse type of --first-hz LO,HI."""
    try:
        lo, hi = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"takes two frequencies in Hz, as 3.5,6; got {text!r}") from None
    if not 0.5 <= lo < hi <= 100.0:
        raise argparse.ArgumentTypeError(f"takes 0.5 <= LO < HI <= 100 Hz; got {text!r}")
    return lo, hi


@dataclass
class CaseData:
    fs_hz: float
    x: np.ndarray  # (n, 3) base, tip1, tip2
    achieved: np.ndarray  # (n,) truth regime code
    truth: dict


def _generate(kind: str, seed: int, regime: str | None, minutes: float, fs_hz: int | None,
              first: tuple[float, float]) -> CaseData:
    if kind == "regimes":
        case = regime_case(seed, fs_hz=fs_hz, first_range_hz=first)
    else:
        case = steady_case(seed, regime, minutes=minutes, fs_hz=int(fs_hz), first_range_hz=first)
    x = np.column_stack([case.columns[k] for k in ("base", "tip1", "tip2")])
    return CaseData(case.fs_hz, x, np.asarray(case.truth_series["achieved"], int), case.truth)


def load_case(kind: str, seed: int, regime: str | None = None, minutes: float = 10.0, fs_hz: int | None = None,
              cache: Path | None = None, first: tuple[float, float] = FIRST_RANGE_HZ) -> CaseData:
    """A generated case, from the cache folder when it holds it (one npz: the arrays and the truth as JSON
    text). A new case is written beside its name and renamed when complete, never over a file."""
    name = f"{kind}_{seed}" + (f"_{regime}_{minutes:g}min_{fs_hz}Hz" if kind == "steady" else "")
    name += f"_first{first[0]:g}-{first[1]:g}Hz" if tuple(first) != FIRST_RANGE_HZ else ""
    if cache is not None:
        path = cache / f"{name}.npz"
        if path.is_file():
            try:
                with np.load(path) as z:
                    return CaseData(float(z["fs_hz"]), z["x"], z["achieved"], json.loads(str(z["truth"])))
            except (OSError, ValueError, KeyError) as exc:
                raise ValueError(f"--cache: {path} is not a case this benchmark wrote ({exc}); remove it") from None
    data = _generate(kind, seed, regime, minutes, fs_hz, first)
    if cache is not None:
        with safe_output(path, label="--cache") as tmp, open(tmp, "wb") as fh:
            np.savez_compressed(fh, fs_hz=data.fs_hz, x=data.x, achieved=data.achieved,
                                truth=np.array(json.dumps(jsonable(data.truth))))
    return data


def run_monitor(data: CaseData, gaps: tuple[float, float] | None = None, window_s: float = RegimeConfig.window_s):
    """Windows and changes of the monitor on the case's three columns, fed in serial-read-sized blocks."""
    state = regime_start(RegimeConfig(fs_hz=data.fs_hz, gap_m=gaps, window_s=window_s))
    step = max(1, int(round(BLOCK_S * data.fs_hz)))
    windows, changes = [], []
    for k in range(0, len(data.x), step):
        state, w, c = regime_step(state, data.x[k:k + step])
        windows += w
        changes += c
    return windows, changes


def score_case(data: CaseData, windows, changes):
    t = np.array([w.t_s for w in windows])
    codes = np.array([LABELS.index(w.label) for w in windows])
    return score_regimes(t, codes, [(c.t_s, LABELS.index(c.regime)) for c in changes], data.achieved, data.fs_hz)


GAP_BAND = 0.03  # "at the gap": the beam's peak displacement within 3 % of its stopper's gap


def at_the_gap(data: CaseData, windows) -> tuple[int, int]:
    """(wrong beam-windows, of them where the beam's peak displacement lies within GAP_BAND of the
    generator's tip-equivalent gap) over the scored windows: a beam kissing its stopper, or touching it in
    some periods and not in others, is hitting or free by the truth's count of touched periods, which no
    spectrum of the window resolves."""
    t = np.array([w.t_s for w in windows])
    keep, idx = scored_windows(t, true_changes(data.achieved, data.fs_hz), len(data.achieved), data.fs_hz)
    gaps = [float(s["gap_eq_m"]) for s in data.truth["stoppers"]]
    wrong = near = 0
    for w, k, scored in zip(windows, idx, keep):
        if not scored:
            continue
        reported, truth = LABELS.index(w.label), int(data.achieved[k])
        for b in (0, 1):
            if (reported >> b & 1) != (truth >> b & 1):
                wrong += 1
                near += abs(w.beams[b].peak_displacement_m / gaps[b] - 1.0) <= GAP_BAND
    return wrong, near


def coupling_ratio(truth: dict) -> float:
    """The coupling spring over beam 1's first-mode stiffness at the coupling point (the generator's draw)."""
    st = truth["structure"]
    spec = BeamSpec(**st["beams"][0])
    bm = assemble_beam(spec)
    omega, phi = normal_modes(bm.mass, bm.stiffness)
    p = bm.point(st["coupling"]["x_m"][0])
    return float(st["coupling"]["stiffness_n_per_m"] / (omega[0] ** 2 / (p @ phi[:, 0]) ** 2))


def describe(truth: dict, fs_hz: float) -> dict:
    st = truth["stoppers"]
    return {"fs_hz": fs_hz, "stiffness_ratio": float(np.mean([s["stiffness_ratio_to_static"] for s in st])),
            "sides": "two-sided" if st[0]["side"] == "both" else "one-sided",
            "mistuning": abs(float(truth["structure"]["mistuning"])), "coupling": coupling_ratio(truth),
            "snr_db": min(float(truth["snr_db"]["tip1"]), float(truth["snr_db"]["tip2"])),
            "settings_tried": truth.get("settings_tried", 1)}


BINS = (
    ("stopper stiffness / beam's", "stiffness_ratio", ((2, 10, "2-10 (soft)"), (10, 100, "10-100"),
                                                       (100, 1001, "100-1000 (rigid)"))),
    ("stoppers", "sides", (("two-sided",) * 3, ("one-sided",) * 3)),
    ("sample rate [Hz]", "fs_hz", ((0, 750, "500"), (750, 1500, "1000"), (1500, 3000, "2000-2500"),
                                   (3000, 6000, "5000"))),
    ("mistuning", "mistuning", ((0, 0.05, "0-5 %"), (0.05, 0.10, "5-10 %"), (0.10, 0.16, "10-15 %"))),
    ("coupling", "coupling", ((0, 0.04, "1-4 %"), (0.04, 0.07, "4-7 %"), (0.07, 0.2, "7-10 %"))),
    ("noise (tips' SNR)", "snr_db", ((0, 30, "25-30 dB"), (30, 35, "30-35 dB"), (35, 50, "35-40 dB"))),
)


def _in_bin(value, b) -> bool:
    if isinstance(value, str):
        return value == b[0]
    return b[0] <= value < b[1]


def _summary(rows: list[dict], key: str = "") -> str:
    w = sum(r[f"{key}windows"] for r in rows)
    right = sum(r[f"{key}right"] for r in rows)
    ch = sum(r[f"{key}changes"] for r in rows)
    intime = sum(r[f"{key}in_time"] for r in rows)
    false = sum(r[f"{key}false"] for r in rows)
    never = sum(r[f"{key}never_held"] for r in rows)
    steady_false = sum(r[f"{key}steady_false"] for r in rows)
    with_false = sum(1 for r in rows if r[f"{key}steady_false"] > 0)
    worst = min((r[f"{key}right"] / r[f"{key}windows"] for r in rows if r[f"{key}windows"]), default=float("nan"))
    steady_right = float(np.mean([r[f"{key}steady_right"] for r in rows]))
    return (f"{100 * right / max(w, 1):5.1f} % ({100 * worst:5.1f} worst) | {intime:3d}/{ch:3d} | {false:3d} "
            f"({never:2d} never held) | "
            f"{steady_false:3d} in {with_false}/{len(rows)} seeds | {100 * steady_right:5.1f} %")


def run(args) -> int:
    if args.cache is not None and args.cache.exists() and not args.cache.is_dir():
        raise ValueError(f"--cache {args.cache} is a file; give a folder (made if missing)")
    if args.cache is not None:
        args.cache.mkdir(parents=True, exist_ok=True)
    names = list(REGIMES)
    rows = []
    print(f"regime monitor on the independent generator: seeds {args.seed}..{args.seed + args.cases - 1}, "
          f"{args.minutes:g} steady minutes each, beam 1's first mode drawn in "
          f"{args.first_hz[0]:g}-{args.first_hz[1]:g} Hz, "
          f"windows of {args.regime_window:g} s" + (f", cases kept in {args.cache}" if args.cache else ""),
          flush=True)
    head = (" seed |   fs | stopper k/k_beam  side | mist | coup |  SNR | windows right | changes <= 1 s (max) "
            "| false (never held) | steady regime false")
    print(head)
    for seed in range(args.seed, args.seed + args.cases):
        t0 = time.perf_counter()
        reg = load_case("regimes", seed, cache=args.cache, first=args.first_hz)
        regime = names[seed % 4]
        steady = load_case("steady", seed, regime, args.minutes, int(reg.fs_hz), cache=args.cache,
                           first=args.first_hz)
        t_gen = time.perf_counter() - t0
        info = describe(reg.truth, reg.fs_hz)
        row = dict(seed=seed, **info, steady_regime=regime)
        variants = [("", None)]
        if args.config_gaps:
            variants.append(("gap_", tuple(float(s["gap_eq_m"]) for s in reg.truth["stoppers"])))
        for key, gaps in variants:
            t1 = time.perf_counter()
            reg_w, reg_c = run_monitor(reg, gaps, args.regime_window)
            sc = score_case(reg, reg_w, reg_c)
            wrong_beams, at_gap = at_the_gap(reg, reg_w)
            sw, sch = run_monitor(steady, gaps, args.regime_window)
            ss = score_case(steady, sw, sch)
            row |= {f"{key}windows": sc.windows, f"{key}right": sc.windows_right,
                    f"{key}changes": len(sc.true_changes), f"{key}in_time": sc.changes_in_time,
                    f"{key}latency_max": max(sc.latencies_s, default=0.0), f"{key}false": sc.false_changes,
                    f"{key}never_held": sc.false_never_held, f"{key}wrong_beams": wrong_beams, f"{key}at_gap": at_gap,
                    f"{key}steady_false": len(sch), f"{key}steady_right": ss.share_right,
                    f"{key}monitor_s": time.perf_counter() - t1}
        rows.append(row)
        print(f" {seed:4d} | {info['fs_hz']:4.0f} | {info['stiffness_ratio']:6.1f} {info['sides']:>13} | "
              f"{100 * info['mistuning']:3.0f}% | {100 * info['coupling']:3.1f}% | {info['snr_db']:4.1f} | "
              f"{100 * row['right'] / max(row['windows'], 1):5.1f} % of {row['windows']:3d} | "
              f"{row['in_time']:2d}/{row['changes']:2d} ({row['latency_max']:5.2f} s) | "
              f"{row['false']:5d} ({row['never_held']:2d})        | "
              f"{regime:>6} {row['steady_false']:3d} ({100 * row['steady_right']:5.1f} % right)"
              + (f" | with gaps: {100 * row['gap_right'] / max(row['gap_windows'], 1):5.1f} %, "
                 f"{row['gap_in_time']}/{row['gap_changes']}, steady {row['gap_steady_false']}"
                 if args.config_gaps else "") + f"   [{t_gen:.0f} s]", flush=True)
    print()
    print("range                        | windows right (worst seed) | changes <= 1 s | false changes in "
          "regime runs (of them to a regime the truth held nowhere in the second before) | false changes in "
          "steady runs | steady windows right (mean over seeds)")
    for title, key, bins in BINS:
        for b in bins:
            sel = [r for r in rows if _in_bin(r[key], b)]
            if sel:
                print(f"{title:>26} {b[2]:>16} | {_summary(sel)}  ({len(sel)} seeds)")
    print(f"{'all':>43} | {_summary(rows)}")
    if args.config_gaps:
        print(f"{'all, gaps from the config':>43} | {_summary(rows, 'gap_')}")
    for key, title in (("", ""),) + ((("gap_", ", gaps from the config"),) if args.config_gaps else ()):
        wrong = sum(r[f"{key}wrong_beams"] for r in rows)
        near = sum(r[f"{key}at_gap"] for r in rows)
        print(f"wrong beam-windows in the regime runs{title}: {wrong}; of them with the beam's peak displacement "
              f"within {100 * GAP_BAND:g} % of its stopper's gap: {near} ({100 * near / max(wrong, 1):.0f} %)")
    total_w = sum(r["windows"] for r in rows)
    share = sum(r["right"] for r in rows) / max(total_w, 1)
    late = sum(r["changes"] - r["in_time"] for r in rows)
    steady_false = sum(r["steady_false"] for r in rows)
    print(f"targets: >= {100 * TARGET_SHARE:.0f} % windows right: {'met' if share >= TARGET_SHARE else 'NOT met'} "
          f"({100 * share:.1f} %); every change within 1 s: {'met' if late == 0 else f'NOT met ({late} late)'}; "
          f"no false change in {args.minutes:g} steady minutes: "
          f"{'met' if steady_false == 0 else f'NOT met ({steady_false})'}")
    return 0
