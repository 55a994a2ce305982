"""``ident discover DATA``: what a model gets wrong in measured data, its cause, the extended model's gain.

DATA is a recording of this tool (.mcap: base, tip1, tip2), a CSV with a header row (``--time COL`` or
``--fs HZ``) or a MAT file (a ``1 x N`` variable is a column by its name, row i of a ``k x N`` one is NAMEi,
the rate from ``Fs``), a UFF file (datasets 58 by ID line 1) or a TDMS file (channels by name; replay.formats).
The baseline is the rig model of ``--model RIG.yaml``, or a modal model fitted to the
data (or to ``--fit-data``, e.g. a low-level test). Columns: ``--excitation COL:KIND`` (force,
base_acceleration or voltage) and ``--response COL:KIND`` (displacement, velocity or acceleration),
repeated; defaults are the rig's base, tip1 and tip2 accelerations. START:STOP are sample indices.
"""

from __future__ import annotations

import json
import re
import sys
import time
from collections.abc import Callable
from pathlib import Path

import matplotlib
import numpy as np
from scipy.signal import welch
from daq.config import parse_config, read_yaml_file
from daq.safeio import Output, check_outputs, safe_folder, safe_output
from replay.formats import read_column_matrix

from . import number, parse_split
from ..discovery import Channel, Discovery, Measurement, discover, to_json
from ..discovery.search import Settings, predict
from ..discovery.signals import EXCITATIONS, MAX_SAMPLES, RESPONSES, bridged
from ..rig import RigParams

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402

P_SIGNIFICANT, GAIN_FLOOR = Settings().alpha, Settings().gain_floor  # the search's defaults, drawn on ranking.png


def add_parser(sub) -> None:
    p = sub.add_parser("discover", help="find what a model misses in measured data, name the cause, extend it")
    p.add_argument("data")
    p.add_argument("--model", type=Path, help="a rig config (YAML) whose rig model is the baseline (default: a "
                                              "modal model fitted to the data)")
    p.add_argument("--baseline", choices=("modal", "linear"),
                   help="modal (also 'linear'): a modal model fitted to the data; the default without --model")
    p.add_argument("--excitation", default="base",
                   help="COL[:KIND] of the excitation, KIND " + ", ".join(EXCITATIONS) + " (default base:"
                        "base_acceleration)")
    p.add_argument("--response", action="append",
                   help="COL[:KIND] of a response (repeat), KIND " + ", ".join(RESPONSES)
                        + " (default acceleration); default tip1 and tip2")
    p.add_argument("--time", dest="time_col", help="CSV: time column [s]")
    p.add_argument("--fs", type=float, dest="fs_hz", help="CSV: sampling rate [Hz]")
    p.add_argument("--fit-data", type=Path, help="fit the modal baseline on this file (same columns, e.g. a "
                                                   "low-level test); causes must then hold there too")
    p.add_argument("--train", help="training samples START:STOP (default: interleaved blocks, 60 %%; with --test "
                                   "alone, the longer stretch beside it)")
    p.add_argument("--test", help="held-out samples START:STOP (default: every 5th block's 3rd and 5th, 40 %%; with "
                                  "--train alone, the longer stretch beside it)")
    p.add_argument("--max-samples", type=number(1000, integer=True), default=MAX_SAMPLES,
                   help="samples x responses analysed at most; a longer record is decimated to the band's needs, then "
                        f"cut to the span with the widest range of amplitudes (default {MAX_SAMPLES:,}, about 3.5 GB)")
    p.add_argument("--json", type=Path, help="write the result as JSON")
    p.add_argument("--report", type=Path, help="write a report folder (markdown, PNG)")
    p.add_argument("--force", action="store_true", help="replace an existing --json, write into a non-empty --report")
    p.set_defaults(func=run)


def load_model(path: Path) -> RigParams:
    """The rig model from a YAML file: a daq config (``daq.config``), checked whole as ``daq record`` checks
    it, whose ``rig`` section is the model (the defaults where it has none, as the simulated rig has; its
    other sections are the simulated device's). A misspelt section is refused, not read as the default rig."""
    data = read_yaml_file(path, "model file")
    if not isinstance(data, dict):
        raise ValueError(f"{path}: a rig model file is a mapping with a 'rig' section")
    return parse_config(data, str(path)).rig.rig


# what a column's name says it holds (a word of the name starting so, any case): a kind left off is the
# default, and a column whose name says another kind is refused rather than read as the default (a
# "displacement" read as an acceleration had given a cubic 2.5e7 times too large, exit 0)
NAMED_KINDS = {"disp": "displacement", "vel": "velocity", "acc": "acceleration", "force": "force", "volt": "voltage"}


def _spec(text: str, kinds: tuple[str, ...], default: str, what: str) -> tuple[str, str]:
    col, _, kind = text.partition(":")
    if not kind:
        words = [w.lower() for w in re.findall(r"[A-Z]?[a-z]+|[A-Z]+(?![a-z])", col)]  # (tipDisp: tip, disp)
        said = sorted({k for word in words for part, k in NAMED_KINDS.items()
                       if word.startswith(part)})  # (words' starts: "tip_travel" says no velocity)
        said = [("base_acceleration" if k == "acceleration" and "base_acceleration" in kinds else k) for k in said]
        other = [k for k in said if k != default and k in kinds]
        if other:
            raise ValueError(f"{what} {col!r}: no kind given, and its name says {other[0].replace('_', ' ')} where "
                             f"the default is {default.replace('_', ' ')}: give {col}:{other[0]} (or {col}:{default})")
    kind = kind or default
    if kind not in kinds:
        raise ValueError(f"{what} {col!r}: kind {kind!r} is not one of {', '.join(kinds)}")
    return col, kind


def load_measurement(path: Path, args) -> Measurement:
    exc = _spec(args.excitation, EXCITATIONS, "base_acceleration", "excitation")
    resp = [_spec(r, RESPONSES, "acceleration", "response") for r in (args.response or ["tip1", "tip2"])]
    cols = [exc[0]] + [c for c, _ in resp]
    # NaN where a value is missing (a recording's lost frames, a table's empty or NaN cells, a time column's
    # holes): bridged here, and the blocks they reach left out by discover as a dropout's
    data, fs = read_column_matrix(path, cols, args.time_col, args.fs_hz, gaps=True)  # (an MCAP's: its own times)
    return bridged(float(fs), Channel(exc[0], exc[1], data[:, 0]),
                   tuple(Channel(c, k, data[:, 1 + i]) for i, (c, k) in enumerate(resp)))


def run(args) -> int:
    inputs = [args.data, args.model, args.fit_data]
    check_outputs([Output("--json", args.json), Output("--report", args.report, folder=True)], inputs, args.force)
    m = load_measurement(Path(args.data), args)
    fit = load_measurement(args.fit_data, args) if args.fit_data else None
    if args.model and args.baseline:
        raise ValueError("give --model (the rig model) or --baseline modal, not both")
    if args.model and fit is not None:
        raise ValueError("--fit-data fits a modal baseline; with --model the baseline is the config's rig model")
    rig = load_model(args.model) if args.model else None
    train, test = parse_split(args.train, args.test, m.n)
    d = discover(m, rig=rig, fit_data=fit, train=train, test=test, settings=Settings(max_samples=args.max_samples),
                 progress=stage_printer(sys.stderr))
    print(summary(d))
    if args.json:
        with safe_output(args.json, inputs=inputs, force=args.force, label="--json") as tmp:
            tmp.write_text(json.dumps(to_json(d), indent=2))
    if args.report:
        with safe_folder(args.report, inputs=inputs, force=args.force) as folder:
            write_report(d, folder)
        print(f"report: {args.report}/report.md")
    return 0


def stage_printer(stream) -> Callable[[str], None] | None:
    """Stage lines with the seconds since the start, on a terminal only: piped or redirected, stderr stays
    for errors (one line, exit code 2) and stdout for the answer."""
    if not stream.isatty():
        return None
    t0 = time.monotonic()
    return lambda line: print(f"[{time.monotonic() - t0:6.1f} s] {line}", file=stream, flush=True)


def summary(d: Discovery) -> str:
    model = d.baseline.model
    modes = ", ".join(f"{f:.3g} Hz" for f in model.frequencies_hz)
    count = f"{model.poles.size} mode{'' if model.poles.size == 1 else 's'}"
    lines = [f"baseline: {d.baseline.label} ({count}: {modes}); band {d.prep.band[0]:.3g}-"
             f"{d.prep.band[1]:.3g} Hz; held-out NRMSE {d.baseline_test_nrmse:.4f}"]
    lines += [f"  {n}" for n in d.prep.sign_notes if not n.startswith("signs: kept")]
    lines.append(d.verdict())
    if d.findings:
        lines.append(f"extended model: held-out NRMSE {d.extended_test_nrmse:.4f}, gain {d.gain:.3f} "
                     f"(against predicting zero: {d.gain_vs_zero:.3f})")
        for f in d.findings:
            lines.append("  " + ", ".join(f"{k} = {v:.4g}" if isinstance(v, float) else f"{k} = {v}"
                                         for k, v in f.parameters.items())
                         + (f"  [{', '.join(f'{k} = {v:.4g}' for k, v in f.physical.items())}]" if f.physical else ""))
    else:
        lines.append("residual RMS on training data: " + ", ".join(f"{k} {v:.3g}" for k, v in d.residual_rms.items()))
    lines += [f"note: {n}" for n in d.notes[1 if not d.findings else 0:]]
    return "\n".join(lines)


# --- report -------------------------------------------------------------------------------------------


def write_report(d: Discovery, folder: Path) -> None:
    _ranking(d, folder / "ranking.png")
    _time_and_spectrum(d, folder / "baseline_extended_measured.png")
    _restoring_force(d, folder / "restoring_force.png")
    rows = "\n".join(f"| {c.cause} | {c.location} | {c.gain:.3f} | {c.p_value:.2g} | {c.test_nrmse:.4f} | "
                     f"{'yes' if c.refined else 'no'} | {_params(c.parameters)} |" for c in d.candidates[:20])
    text = f"""# Discovery

{d.verdict()}

- Baseline: {d.baseline.label}; held-out NRMSE {d.baseline_test_nrmse:.4f}
- Analysis band: {d.prep.band[0]:.3g}-{d.prep.band[1]:.3g} Hz at {d.prep.fs_hz:.6g} Hz; held-out: {len(d.split.test)}
  blocks ({', '.join(f'{_seconds(d.prep, s.start)}-{_seconds(d.prep, s.stop)} s' for s in d.split.test)})
- Extended model: held-out NRMSE {d.extended_test_nrmse:.4f}, gain {d.gain:.3f}, against predicting zero
  {d.gain_vs_zero:.3f}
{''.join(f'- {n}{chr(10)}' for n in d.prep.sign_notes + d.notes)}
## Candidates (best 20 by held-out gain; p: paired test against the baseline over held-out pieces)

| cause | location | gain | p | held-out NRMSE | refined | parameters |
|---|---|---|---|---|---|---|
{rows}

![ranking](ranking.png)

![time and spectrum](baseline_extended_measured.png)

![restoring force](restoring_force.png)
"""
    (folder / "report.md").write_text(text)


def _seconds(prep, sample: int) -> str:
    """A sample of the analysed record as the record's time."""
    return f"{prep.start_s + sample / prep.fs_hz:.2f}"


def _params(p: dict) -> str:
    return ", ".join(f"{k} = {v:.4g}" if isinstance(v, float) else f"{k} = {v}" for k, v in p.items())


def _ranking(d: Discovery, path: Path) -> None:
    cands = [c for c in d.candidates if np.isfinite(c.gain)][:15]
    fig, ax = plt.subplots(figsize=(8.5, 0.35 * len(cands) + 2.0))
    chosen = {f.label for f in d.findings}
    labels = [f"{c.cause} at {c.location}{' (refined)' if c.refined else ''}" for c in cands]
    colors = ["tab:green" if c.label in chosen and c.refined else "tab:blue" if c.p_value < P_SIGNIFICANT else "tab:gray"
              for c in cands]
    ax.barh(range(len(cands)), [c.gain for c in cands], color=colors)
    for i, c in enumerate(cands):  # each bar's p-value, and the finding marked
        mark = "  <- chosen" if c.label in chosen and c.refined else ""
        ax.text(max(c.gain, GAIN_FLOOR) + 0.008, i, f"p = {c.p_value:.2g}{mark}", va="center", fontsize=7,
                fontweight="bold" if mark else "normal")
    ax.set_yticks(range(len(cands)), labels, fontsize=8)
    ax.invert_yaxis()
    ax.axvline(GAIN_FLOOR, color="k", ls="--", lw=1, label=f"gain floor {GAIN_FLOOR:g}")
    handles = [Patch(color="tab:green", label="the finding (chosen cause)"),
               Patch(color="tab:blue", label=f"significant: p < {P_SIGNIFICANT:g} (paired test, held-out pieces)"),
               Patch(color="tab:gray", label=f"not significant: p >= {P_SIGNIFICANT:g}")]
    ax.legend(handles=handles + ax.get_legend_handles_labels()[0], loc="lower right", fontsize=7)
    hi = max([c.gain for c in cands] + [GAIN_FLOOR])
    ax.set_xlim(right=hi + 0.25 * (hi - min([c.gain for c in cands] + [0.0])))
    ax.set_xlabel("held-out gain [-], 1 - NRMSE extended / NRMSE baseline")
    ax.set_title("Causes ranked by held-out gain\n" + ("finding: " + ", ".join(sorted(chosen)) if chosen
                                                         else "no finding: no cause passes both thresholds"),
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _time_and_spectrum(d: Discovery, path: Path) -> None:
    prep = d.prep
    blocks = list(d.split.test)[:3]
    k = len(prep.names)
    fig, axes = plt.subplots(k, len(blocks) + 1, figsize=(4 * (len(blocks) + 1), 2.6 * k), squeeze=False)
    units = {"displacement": "m", "velocity": "m/s", "acceleration": "m/s$^2$"}
    for j, seg in enumerate(blocks):
        base = predict(d.baseline, d.baseline.model, prep, seg, d.warm)
        own = d.findings[0].baseline if d.findings and d.findings[0].baseline else d.baseline
        ext = predict(own, d.extended, prep, seg, d.warm, d.extended_output)
        t = prep.start_s + np.arange(seg.start, seg.stop) / prep.fs_hz
        for i in range(k):
            ax = axes[i, j]
            ax.plot(t, prep.measured[seg, i], "k", lw=1, label="measured")
            ax.plot(t, base[:, i], "tab:red", lw=0.8, label="baseline")
            if d.findings:
                ax.plot(t, ext[:, i], "tab:green", lw=0.8, ls="--", label="extended")
            ax.set_title(f"{prep.names[i]}, held-out block {t[0]:.1f}-{t[-1] + 1 / prep.fs_hz:.1f} s",
                         fontsize=8)
            ax.set_xlabel("time [s]")
            ax.set_ylabel(f"{prep.kinds[i]} [{units[prep.kinds[i]]}]", fontsize=8)
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="upper right", ncol=len(labels), fontsize=8)  # above the panels, on no data
    tests = list(d.split.test)
    resid = [prep.measured[s] - predict(d.baseline, d.baseline.model, prep, s, d.warm) for s in tests]
    # Welch within each held-out block, averaged over the blocks: no segment spans two blocks
    shortest = min(s.stop - s.start for s in tests)
    nper = min(shortest, int(2 ** np.floor(np.log2(max(64, prep.fs_hz / prep.band[0] * 8)))))
    for i in range(k):
        ax = axes[i, -1]
        spectra = [welch(prep.measured[s, i], prep.fs_hz, nperseg=nper) for s in tests]
        f = spectra[0][0]
        p = np.mean([sp[1] for sp in spectra], axis=0)
        pr = np.mean([welch(r[:, i], prep.fs_hz, nperseg=nper)[1] for r in resid], axis=0)
        ax.semilogy(f, p, "k", lw=1, label="measured")
        ax.semilogy(f, pr, "tab:red", lw=0.8, label="baseline residual")
        ax.axvspan(prep.band[0], prep.band[1], color="0.9", zorder=0, label="analysis band")
        ax.set_xlim(0, 1.1 * prep.band[1])
        inband = (f >= prep.band[0]) & (f <= prep.band[1])
        floor = min(np.min(p[inband]), np.min(pr[inband])) if inband.any() else np.min(p)
        ax.set_ylim(bottom=max(floor / 10, 1e-300))  # the band's content, not the filter's stop band
        ax.set_xlabel("frequency [Hz]")
        ax.set_ylabel(f"PSD [({units[prep.kinds[i]]})$^2$/Hz]", fontsize=8)
        ax.set_title(f"{prep.names[i]}: spectra, mean over the held-out blocks", fontsize=8)
        ax.legend(fontsize=7)
    fig.suptitle(d.verdict(), fontsize=9, x=0.02, ha="left")
    fig.tight_layout(rect=(0, 0, 1, 0.95))
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _restoring_force(d: Discovery, path: Path) -> None:
    loc = d.findings[0].location if d.findings else max(d.characterisation,
                                                        key=lambda k: d.characterisation[k]["explained"])
    ch = d.characterisation.get(loc, {})
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(9, 3.4))
    if "displacement" in ch:
        a1.plot(np.array(ch["displacement"]) * 1e3, ch["stiffness_force_per_mass"], "o-", label="estimated")
        a2.plot(ch["velocity"], ch["damping_force_per_mass"], "o-", label="estimated")
    a1.set_xlabel("displacement [mm]")
    a1.set_ylabel("missing force per modal mass [m/s$^2$]")
    a1.set_title(f"stiffness curve at {loc}")
    a2.set_xlabel("velocity [m/s]")
    a2.set_ylabel("missing force per modal mass [m/s$^2$]")
    a2.set_title(f"damping curve at {loc}")
    share = ch.get("explained", 0.0)
    fig.suptitle(f"Restoring-force curves of what the baseline misses at {loc} "
                 f"(they explain {100 * share:.0f} % of the training residual)", fontsize=9)
    for a in (a1, a2):
        a.axhline(0, color="k", lw=0.5)
        a.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)

