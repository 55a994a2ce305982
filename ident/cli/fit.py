"""``ident fit FILE``: batch identification of a recording, the paper's experimental studies 1-3.

Reads the recording with replay's readers (a command line may compose any
package's readers), runs ident.paper.studies on a steady segment, prints the
equations and writes the coefficient tables and figures like the paper's
Tables 4-7 and Figs. 9-12. Outputs are checked before the recording is read and
written atomically (daq.safeio): never over the input, never over a file without ``--force``.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from daq.safeio import Output, check_outputs, safe_folder, safe_output
from replay.formats import read_samples

from ..paper.studies import run_study
from . import DURATION, OFFSET, RATE_HZ, number


def add_parser(sub) -> None:
    p = sub.add_parser("fit", help="identify a recording (.mcap, .csv, .mat, .uff, .tdms): the paper's studies 1-3")
    p.add_argument("file")
    p.add_argument("--study", type=int, choices=(1, 2, 3), default=1,
                   help="1: no impact, one blade, 2-D; 2: localized, both blades, 4 states; 3: both impacting")
    p.add_argument("--start", type=OFFSET, default=5.0, help="seconds to skip (default 5: past ramps and kicks)")
    p.add_argument("--duration", type=DURATION, help="seconds to use (default: to the end)")
    p.add_argument("--degree", type=number(1, 5, integer=True), action="append",
                   help="library degree p, 1 to 5 (repeat for several)")
    p.add_argument("--dimension", type=number(1, 10, integer=True), help="embedding dimension per signal (default: "
                                                                         "the study's)")
    p.add_argument("--delay", type=number(1, 10_000, integer=True), help="delay in samples at 200 Hz (default: "
                                                                         "first ACF zero)")
    p.add_argument("--derivative", choices=("tvregdiff", "savgol", "spectral", "gradient"))
    p.add_argument("--fs", type=RATE_HZ, dest="fs_hz", help="CSV input: sampling rate")
    p.add_argument("--time", dest="time_col", help="CSV input: time column")
    p.add_argument("--json", type=Path, help="write results as JSON")
    p.add_argument("--report", type=Path, help="write a report folder (markdown, CSV, PNG)")
    p.add_argument("--force", action="store_true", help="replace an existing --json, write into a non-empty --report")
    p.set_defaults(func=run)


def run(args) -> int:
    inputs = [args.file]
    check_outputs([Output("--json", args.json), Output("--report", args.report, folder=True)], inputs, args.force)
    s = read_samples(args.file, time_col=args.time_col, fs_hz=args.fs_hz)
    if args.start < 0 or args.start >= s.duration_s:
        raise ValueError(f"--start {args.start} s is outside the data (0 to {s.duration_s:.2f} s)")
    i0 = int(args.start * s.fs_hz)
    i1 = len(s.t) if args.duration is None else min(len(s.t), i0 + int(args.duration * s.fs_hz))
    res = run_study(s.values[i0:i1], s.fs_hz, args.study, degrees=tuple(args.degree) if args.degree else None,
                    dimension=args.dimension, delay=args.delay, derivative=args.derivative)
    js = to_json(res, args.file, args.start)
    print(f"study {res.study} ({res.title}) on {args.file}: delay {res.delay} samples at {res.fs_hz:g} Hz, "
          f"dimension {res.dimension} per signal")
    for f in js["fits"]:
        print(f"  p = {f['degree']}: {f['n_active']} terms; on x1: std error {f['error_percent']:.2f} % "
              f"(|std rec / std meas - 1|, the paper's eq. 16), NRMSE {f['nrmse']:.3f} (RMS error / std); "
              f"integration NRMSE of the fit {f['error_before_refinement']:.4f} -> {f['error_after_refinement']:.4f} "
              "by refinement")
        for e in f["equations"]:
            print(f"    {e}")
    if args.json:
        with safe_output(args.json, inputs=inputs, force=args.force, label="--json") as tmp:
            tmp.write_text(json.dumps(js, indent=2))
    if args.report:
        with safe_folder(args.report, inputs=inputs, force=args.force) as folder:
            write_report(folder, res, js)
        print(f"wrote {args.report / 'README.md'}")
    return 0


def to_json(res, source: str, start: float) -> dict:
    return {
        "source": str(source), "study": res.study, "title": res.title, "start_s": start, "fs_hz": res.fs_hz,
        "delay": res.delay, "dimension": res.dimension, "states": list(res.state_names),
        "fits": [{
            "degree": f.degree, "coefficients": f.ident.model.as_dict(), "equations": f.ident.model.equations(),
            "n_active": f.ident.model.n_active, "error_percent": f.error_percent, "nrmse": f.nrmse,
            "error_before_refinement": f.ident.refinement.error_before,
            "error_after_refinement": f.ident.refinement.error_after,
        } for f in res.fits],
    }


def cycles_window(x: np.ndarray, fs_hz: float, cycles: float = 4.0) -> float:
    """Seconds that hold ``cycles`` periods of the strongest frequency of x (the whole record if shorter)."""
    x = np.asarray(x, float) - np.mean(x)
    spec = np.abs(np.fft.rfft(x))
    spec[0] = 0.0
    f = np.fft.rfftfreq(len(x), 1 / fs_hz)[int(np.argmax(spec))]
    return min(len(x) / fs_hz, cycles / f) if f > 0 else len(x) / fs_hz


def _fit_figure(plt, res, f):
    """A few cycles at the start and at the end of the segment (measured vs identified, the errors named),
    the embedded phase portrait and the sparsification sweep."""
    fig, ax = plt.subplots(2, 2, figsize=(12, 7))
    span = cycles_window(res.states[:, 0], res.fs_hz)
    t0 = res.t[0]
    for a, (lo, where) in zip(ax[0], ((t0, "start"), (res.t[-1] - span, "end"))):
        m = (res.t >= lo) & (res.t <= lo + span)
        a.plot(res.t[m], res.states[m, 0], "k", lw=1.5, label="measured")
        a.plot(res.t[m], f.reconstructed[m, 0], "C1--", lw=1.5, label="identified model, integrated")
        a.set(xlabel="time in the segment [s]", ylabel=f"{res.state_names[0]}: relative acceleration [m/s²]",
              title=f"{where} of the segment: 4 cycles")
        lo_y, hi_y = a.get_ylim()
        a.set_ylim(lo_y, hi_y + 0.35 * (hi_y - lo_y))  # room for the legend above the data
        a.legend(fontsize=8, loc="upper center", ncol=2)
    fig.suptitle(f"Study {res.study}, p = {f.degree}: {f.ident.model.n_active} terms; on "
                 f"{res.state_names[0]}: std error {f.error_percent:.2f} % = |std rec / std meas - 1| (paper eq. 16), "
                 f"NRMSE {f.nrmse:.3f} = RMS error / std meas", fontsize=9)
    ax[1, 0].plot(res.states[:, 0], res.states[:, 1], "k", lw=0.6, label="measured")
    ax[1, 0].plot(f.reconstructed[:, 0], f.reconstructed[:, 1], "C1--", lw=0.6, label="identified")
    ax[1, 0].set(xlabel=f"{res.state_names[0]} [m/s²]", ylabel=f"{res.state_names[1]} [m/s²] (delayed)",
                 title=f"embedded phase portrait (delay {1e3 * res.delay / res.fs_hz:.1f} ms)")
    ax[1, 0].legend(fontsize=8)
    sw = f.ident.sweep
    fin = np.isfinite(sw.errors)
    ax[1, 1].semilogy(sw.n_nonzero[fin], sw.errors[fin], "o-", label="one threshold of the sweep")
    ax[1, 1].semilogy([sw.n_nonzero[sw.chosen]], [sw.errors[sw.chosen]], "rs", mfc="none", ms=11, label="chosen")
    ax[1, 1].set(xlabel="non-zero coefficients", ylabel="integration NRMSE [-]", title="sparsification sweep")
    ax[1, 1].legend(fontsize=8)
    return fig


def write_report(folder: Path, res, js: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    folder.mkdir(parents=True, exist_ok=True)
    md = [f"# Study {res.study}: {res.title}", "",
          f"Source `{js['source']}` from {js['start_s']} s; relative accelerations below 50 Hz at "
          f"{res.fs_hz:g} Hz, delay {res.delay} samples ({1e3 * res.delay / res.fs_hz:.1f} ms), dimension "
          f"{res.dimension} per signal, forcing = base acceleration.", ""]
    for f in res.fits:
        names = f.ident.model.term_names
        coefs = f.ident.model.coefficients
        used = [k for k in range(len(names)) if np.any(coefs[k] != 0)]
        header = ["term"] + [f"{s}'" for s in res.state_names]
        rows = [[names[k]] + [f"{c:.4g}" for c in coefs[k]] for k in used]
        with open(folder / f"table_p{f.degree}.csv", "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(header)
            w.writerows(rows)
        md += [f"## p = {f.degree}: {f.ident.model.n_active} terms, std error {f.error_percent:.2f} %, "
               f"NRMSE {f.nrmse:.3f}", "",
               f"On x1: std error = |std(reconstructed) / std(measured) - 1| (the paper's eq. 16, blind to phase); "
               f"NRMSE = RMS(reconstructed - measured) / std(measured); the sweep's integration NRMSE "
               f"{f.ident.refinement.error_before:.4f} -> {f.ident.refinement.error_after:.4f} after refinement.", "",
               "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        md += ["| " + " | ".join(r) + " |" for r in rows]
        md += ["", f"![p = {f.degree}](fit_p{f.degree}.png)", ""]
        fig = _fit_figure(plt, res, f)
        fig.tight_layout()
        fig.savefig(folder / f"fit_p{f.degree}.png", dpi=100)
        plt.close(fig)
    (folder / "README.md").write_text("\n".join(md))
    (folder / "result.json").write_text(json.dumps(js, indent=2))
