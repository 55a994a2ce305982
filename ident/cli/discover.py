"""``ident discover DATA --model RIG.yaml``: what the rig simulation gets wrong, its cause, the gain.

DATA is a recording of this tool (.mcap) or a CSV with a header row (columns
``--excitation`` base acceleration and ``--response`` tip accelerations;
``--time COL`` or ``--fs HZ``). START:STOP are sample indices, Python-slice
style. The JSON holds the baseline's and the extended model's test NRMSE, the
gain and the findings sorted by gain (empty when nothing was found).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from replay.formats import read_column_matrix as read_columns
from replay.formats import read_samples as open_samples

from ..config import build
from ..discovery import _beam_rhs, coordinates, discover, indices, simulated_tips, warm_up_s
from ..linear_discovery import KINDS_EXCITATION, KINDS_RESPONSE, discover_linear
from ..modal_discovery import F_LO_HZ, discover_modal
from ..physical import integrate_band
from ..rig import RigParams


def add_parser(sub) -> None:
    p = sub.add_parser("discover", help="find what the rig model misses in measured data, name it, extend it")
    p.add_argument("data")
    base = p.add_mutually_exclusive_group(required=True)
    base.add_argument("--model", type=Path, help="the rig config (YAML) whose model is the baseline")
    base.add_argument("--baseline", choices=("linear",), help="linear: a linear model fitted on the training segment")
    p.add_argument("--excitation", default="base",
                   help="column[:KIND] of the excitation, KIND base_acceleration (default) or force")
    p.add_argument("--response", action="append",
                   help="column[:KIND] of a response (repeat), KIND acceleration (default), velocity or displacement; "
                        "default tip1 and tip2")
    p.add_argument("--time", dest="time_col", help="CSV: time column [s]")
    p.add_argument("--fs", type=float, dest="fs_hz", help="CSV: sampling rate [Hz]")
    p.add_argument("--train", help="training samples START:STOP (default: rig model, 6 of 10 interleaved blocks; "
                                   "linear baseline, the first 60 %%)")
    p.add_argument("--test", help="held-out samples START:STOP (default: rig model, the 3rd, 5th, 8th and 10th "
                                  "of 10 blocks; linear baseline, the last 40 %%)")
    p.add_argument("--fit-data", type=Path, help="--baseline linear with a force: fit the linear baseline on this "
                                                   "file (same columns, e.g. a low-level test) instead of the "
                                                   "training segment")
    p.add_argument("--json", type=Path, help="write the result as JSON")
    p.add_argument("--report", type=Path, help="write a report folder (markdown, PNG)")
    p.set_defaults(func=run)


def parse_slice(text: str | None, n: int, name: str) -> slice | None:
    if text is None:
        return None
    parts = text.split(":")
    if len(parts) != 2:
        raise ValueError(f"--{name} must be START:STOP (sample indices, either may be empty), got {text!r}")
    try:
        start = int(parts[0]) if parts[0] else 0
        stop = int(parts[1]) if parts[1] else n
    except ValueError:
        raise ValueError(f"--{name} must hold integers, got {text!r}") from None
    s = slice(*slice(start, stop).indices(n)[:2])
    if s.stop - s.start < 100:
        raise ValueError(f"--{name} {text} selects {max(0, s.stop - s.start)} samples; give at least 100")
    return s


def _load(args):
    path = Path(args.data)
    if path.suffix.lower() == ".csv":
        resp = args.response or ["tip1", "tip2"]
        if len(resp) != 2:
            raise ValueError("the rig model has two tips: give two --response columns")
        kinds = [r.partition(":")[2] or "acceleration" for r in resp] + [args.excitation.partition(":")[2]
                                                                          or "base_acceleration"]
        if kinds[:2] != ["acceleration", "acceleration"] or kinds[2] != "base_acceleration":
            raise ValueError("with --model, responses must be accelerations and the excitation a base acceleration")
        return open_samples(path, time_col=args.time_col, fs_hz=args.fs_hz, base=args.excitation.partition(":")[0],
                            tip1=resp[0].partition(":")[0], tip2=resp[1].partition(":")[0])
    return open_samples(path)


def _model(path: Path):
    """The rig model (``ident.rig.RigParams``) from a YAML file: its ``rig`` section; the rest of a
    daq config (shaker programme, sensors, daq) is the simulated device's and is ignored here."""
    import yaml

    try:
        data = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        raise ValueError(f"{path}: model file not found") from None
    except yaml.YAMLError as exc:
        raise ValueError(f"{path}: not valid YAML: {exc}") from None
    if not isinstance(data, dict):
        raise ValueError(f"{path}: a rig model file is a mapping with a 'rig' section")
    return build(RigParams, data.get("rig"), str(path), "rig")


def _clean(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def _equation(response: str, effect: str, parameters: dict) -> str:
    """One finding as the JSON's ``extended.equations`` lists it."""
    return f"{response}: {effect} ({_params_text(parameters)})"


def result_json(d) -> dict:
    return {
        "baseline": {"test_nrmse": _clean(d.baseline_test_nrmse)},
        "extended": {"test_nrmse": _clean(d.extended_test_nrmse),
                     "equations": [_equation(c.response, c.effect, c.parameters) for c in d.findings]},
        "gain": _clean(d.gain),
        "findings": [{"effect": c.effect, "response": c.response, "parameters": c.parameters,
                      "gain": _clean(c.gain)} for c in d.findings],
        "candidates": [{"effect": c.effect, "response": c.response, "parameters": c.parameters,
                        "gain": _clean(c.gain), "test_nrmse": _clean(c.test_nrmse), "fit_r2": c.fit_r2}
                       for c in d.candidates],
        "split": split_json(d.train, d.test),
        "residual_rms_m_per_s2": d.residual_rms,
    }


def _pairs(segs) -> list[list[int]]:
    return [[s.start, s.stop] for s in ((segs,) if isinstance(segs, slice) else segs)]


def split_json(train, test) -> dict:
    """Training and held-out samples as lists of [start, stop) pairs (one pair for a contiguous split)."""
    return {"train": _pairs(train), "test": _pairs(test)}


def _segments_text(segs) -> str:
    return ", ".join(f"{a}:{b}" for a, b in _pairs(segs))


def _split_kind(spec: str, default: str) -> tuple[str, str]:
    col, _, kind = spec.partition(":")
    return col, kind or default


def _columns(path: Path, cols: list[str], args) -> tuple[np.ndarray, float]:
    """Named columns of a CSV or MAT file, or channels (base, tip1, tip2) of a recording."""
    if path.suffix.lower() in (".csv", ".txt", ".mat"):
        return read_columns(path, cols, args.time_col, args.fs_hz)
    s = open_samples(path)
    roles = {"base": 0, "tip1": 1, "tip2": 2}
    for c in cols:
        if c not in roles:
            raise ValueError(f"a recording has the channels base, tip1, tip2; not {c!r}")
    return s.values[:, [roles[c] for c in cols]], s.fs_hz


def _params_text(parameters: dict) -> str:
    return ", ".join(f"{k} = {v:.4g}" if isinstance(v, float) else f"{k} = {v}" for k, v in parameters.items())


def run_linear(args) -> int:
    """--baseline linear: any CSV, MAT file or recording with an excitation and responses of given kinds."""
    exc_col, exc_kind = _split_kind(args.excitation, "base_acceleration")
    if exc_kind not in KINDS_EXCITATION:
        raise ValueError(f"excitation kind {exc_kind!r} is not one of {', '.join(KINDS_EXCITATION)}")
    specs = [_split_kind(r, "acceleration") for r in (args.response or ["tip1", "tip2"])]
    for col, kind in specs:
        if kind not in KINDS_RESPONSE:
            raise ValueError(f"response kind {kind!r} of {col!r} is not one of {', '.join(KINDS_RESPONSE)}")
    cols = [exc_col] + [c for c, _ in specs]
    names = [c for c, _ in specs]
    data, fs = _columns(Path(args.data), cols, args)
    n = len(data)
    train, test = parse_slice(args.train, n, "train"), parse_slice(args.test, n, "test")
    if exc_kind == "force":
        return _run_modal(args, data, fs, names, specs, cols, train, test)
    if args.fit_data:
        raise ValueError("--fit-data needs a force excitation (COL:force); with a base acceleration the linear "
                         "baseline is fitted on the training segment")
    d = discover_linear(data[:, 0], data[:, 1:], names, [k for _, k in specs], exc_kind, fs, train=train, test=test)
    js = {"baseline": {"test_nrmse": d.baseline_test_nrmse}, "extended": {
        "test_nrmse": d.extended_test_nrmse,
        "equations": [_equation(f["response"], f["effect"], f["parameters"]) for f in d.findings]},
        "gain": d.gain, "findings": d.findings, "candidates": d.candidates,
        "split": split_json(d.train, d.test),
        "residual_rms": d.residual_rms}
    print(f"linear baseline test NRMSE {d.baseline_test_nrmse:.4f}"
          + (" (its simulation diverges: capped at 1, the error of predicting nothing)"
             if d.baseline_test_nrmse >= 1.0 else ""))
    print("findings: " + ("; ".join(js["extended"]["equations"]) or "nothing found; residual force RMS "
                          + ", ".join(f"{k} {v:.3g}" for k, v in d.residual_rms.items())))
    print(f"extended test NRMSE {d.extended_test_nrmse:.4f}, gain {d.gain:.3f}")
    _write_json(args.json, js)
    if args.report:
        args.report.mkdir(parents=True, exist_ok=True)
        _plot_ranking(args.report / "ranking.png",
                      [(f"{c['effect']} ({c['response']})", c["gain"], c["gain"] > 0.05) for c in d.candidates])
        _write_report(args.report, js, [
            "# Discovery (linear baseline)", "",
            f"A linear model of the same structure (each response's relative acceleration linear in all "
            f"displacements, velocities and the excitation) fitted on samples {d.train.start}:{d.train.stop}, "
            f"simulated over {d.test.start}:{d.test.stop}: test NRMSE {d.baseline_test_nrmse:.4f}; extended "
            f"{d.extended_test_nrmse:.4f}; gain {d.gain:.3f}.", "",
            "Findings: " + ("; ".join(js["extended"]["equations"]) or _nothing(d.residual_rms, "m/s^2")), "",
            "| effect | response | gain | parameters |", "|---|---|---|---|",
            *[f"| {c['effect']} | {c['response']} | {c['gain']:.3f} | {_params_text(c['parameters'])} |"
              for c in d.candidates], "", "![ranking](ranking.png)", ""])
    return 0


def _nothing(residual_rms: dict, unit: str) -> str:
    return ("nothing found: no cause gains more than 5 % on the held-out segment. The residual (RMS "
            + ", ".join(f"{k} {v:.3g} {unit}" for k, v in residual_rms.items())
            + ") is what the baseline leaves; its spectrum and portraits below show its shape.")


def _run_modal(args, data, fs, names, specs, cols, train, test) -> int:
    """A force-excited structure: modal baseline, internal forces at or between the responses."""
    if any(k != "acceleration" for _, k in specs):
        raise ValueError("with a force excitation the linear baseline is a modal model of accelerations: "
                         "give acceleration responses (the first at the driving point)")
    fit = None
    if args.fit_data:
        fd, ffs = _columns(args.fit_data, cols, args)
        if abs(ffs - fs) > 1e-6 * fs:
            raise ValueError(f"{args.fit_data} is sampled at {ffs:g} Hz, {args.data} at {fs:g} Hz")
        fit = (fd[:, 0], fd[:, 1:])
    d = discover_modal(data[:, 0], data[:, 1:], names, fs, fit_data=fit, train=train, test=test)
    fit_where = f"{args.fit_data} (all of it)" if fit else f"samples {d.train.start}:{d.train.stop}"

    def cand(c):
        return {"effect": c.effect, "response": c.response, "parameters": c.parameters, "gain": _clean(c.gain),
                "test_nrmse": _clean(c.test_nrmse), "fit_r2": c.fit_r2,
                "fit_data_nrmse": _clean(c.fit_data_nrmse), "holds_at_fit_level": c.holds_at_fit_level}

    eqs = [_equation(c.response, c.effect, c.parameters) for c in d.findings]
    js = {"baseline": {"test_nrmse": d.baseline_test_nrmse, "fit_data_nrmse": _clean(d.baseline_fit_nrmse),
                       "fitted_on": fit_where,
                       "modes": [{"frequency_hz": float(f), "damping_ratio": float(z)}
                                 for f, z in zip(d.model.frequencies_hz, d.model.damping_ratios)]},
          "extended": {"test_nrmse": d.extended_test_nrmse, "equations": eqs},
          "gain": d.gain, "findings": [cand(c) for c in d.findings], "candidates": [cand(c) for c in d.candidates],
          "split": split_json(d.train, d.test),
          "residual_rms": d.residual_rms}
    holds = (" It does not hold on the baseline data (NRMSE there {:.3f} against the baseline's {:.3f}): no "
             "catalogue term explains both levels; the change depends on the amplitude.".format(
                 d.findings[0].fit_data_nrmse, d.baseline_fit_nrmse)
             if d.findings and not d.findings[0].holds_at_fit_level else "")
    print(f"modal baseline ({d.model.poles.size} modes, fitted on {fit_where}) test NRMSE "
          f"{d.baseline_test_nrmse:.4f}" + (f"; on its own data {d.baseline_fit_nrmse:.4f}" if fit else ""))
    print("findings: " + ("; ".join(eqs) or _nothing(d.residual_rms, "m/s^2")) + holds)
    print(f"extended test NRMSE {d.extended_test_nrmse:.4f}, gain {d.gain:.3f}")
    _write_json(args.json, js)
    if args.report:
        _report_modal(args.report, d, js, data, fs, names, fit_where, holds)
        print(f"wrote {args.report / 'README.md'}")
    return 0


def _write_json(path: Path | None, js: dict) -> None:
    if path:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(js, indent=2, default=_clean))


def _write_report(folder: Path, js: dict, lines: list[str]) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "README.md").write_text("\n".join(lines))
    (folder / "result.json").write_text(json.dumps(js, indent=2, default=_clean))


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _plot_ranking(path: Path, rows: list[tuple[str, float, bool]], floor: float = 0.05, top: int = 12) -> None:
    """Bar chart of candidate gains on the held-out segment; chosen ones in red."""
    plt = _plt()
    rows = [r for r in rows if r[1] is not None and np.isfinite(r[1])][:top]
    fig, ax = plt.subplots(figsize=(8, 0.35 * len(rows) + 1.2))
    ax.barh([r[0] for r in rows][::-1], [max(r[1], -1.0) for r in rows][::-1],
            color=["C3" if r[2] else "C7" for r in rows][::-1])
    ax.axvline(floor, color="k", lw=0.8, ls="--")
    ax.set(xlabel="gain on the held-out segment (1 - NRMSE extended / baseline)", title="candidate causes")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _plot_time_psd(path: Path, t, meas, base, ext, names: list[str], fs: float, fmax: float) -> None:
    """Per response: measured, baseline and extended over 3 s; spectra of the measurement and residuals."""
    from scipy.signal import welch

    plt = _plt()
    k = meas.shape[1]
    gaps = np.flatnonzero(np.diff(t) > 1.5 / fs)  # held-out blocks are concatenated: stay in the first
    show = slice(0, min(len(t), int(3 * fs), int(gaps[0]) + 1 if gaps.size else len(t)))
    nper = min(4096, len(meas))
    fig, ax = plt.subplots(k, 2, figsize=(12, 3.2 * k + 0.5), sharex="col", squeeze=False)
    for i in range(k):
        ax[i, 0].plot(t[show], meas[show, i], "k", lw=1.2, label="measured")
        ax[i, 0].plot(t[show], base[show, i], "C0--", lw=1, label="baseline")
        ax[i, 0].plot(t[show], ext[show, i], "C3:", lw=1.5, label="extended")
        ax[i, 0].set(ylabel=f"{names[i]} [m/s^2]")
        f, p_meas = welch(meas[:, i], fs, nperseg=nper)
        _, p_res = welch(meas[:, i] - base[:, i], fs, nperseg=nper)
        _, p_ext = welch(meas[:, i] - ext[:, i], fs, nperseg=nper)
        ax[i, 1].semilogy(f, p_meas, "k", lw=1, label="measured")
        ax[i, 1].semilogy(f, p_res, "C0", lw=1, label="residual of the baseline")
        ax[i, 1].semilogy(f, p_ext, "C3", lw=1, label="residual of the extended model")
        ax[i, 1].set(xlim=(0, fmax), ylim=(float(np.max(p_meas)) * 1e-8, float(np.max(p_meas)) * 10), ylabel="PSD")
    ax[0, 0].legend(fontsize=8)
    ax[0, 1].legend(fontsize=8)
    ax[-1, 0].set(xlabel="t [s] (held-out data)")
    ax[-1, 1].set(xlabel="frequency [Hz] (harmonics the baseline cannot make stand out)")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _plot_portraits(path: Path, rows: list[tuple[str, np.ndarray, np.ndarray, np.ndarray]], unit: str) -> None:
    """Residual against displacement and velocity of each coordinate: (name, z, v, residual)."""
    plt = _plt()
    fig, ax = plt.subplots(len(rows), 2, figsize=(11, 3.5 * len(rows)), squeeze=False)
    for i, (name, z, v, res) in enumerate(rows):
        ax[i, 0].plot(z * 1e3, res, ",", alpha=0.5)
        ax[i, 0].set(xlabel=f"{name} displacement [mm]", ylabel=f"residual [{unit}]",
                     title=f"{name}: residual against displacement")
        ax[i, 1].plot(v, res, ",", alpha=0.5)
        ax[i, 1].set(xlabel=f"{name} velocity [m/s]", title=f"{name}: residual against velocity")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def _report_modal(folder: Path, d, js: dict, data, fs: float, names: list[str], fit_where: str, holds: str) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    Y = data[:, 1:]
    te, tr = d.test, d.train
    _plot_time_psd(folder / "baseline_extended_measured.png", np.arange(te.start, te.stop) / fs, Y[te],
                   d.baseline_sim[te], d.extended_sim[te], names, fs, min(0.45 * fs, 60.0))
    _plot_ranking(folder / "ranking.png", [(f"{c.effect} ({c.response})", c.gain, c in d.findings)
                                           for c in d.candidates])
    v, z = integrate_band(Y, fs, F_LO_HZ)
    res = Y - d.baseline_sim
    rows = [(names[j], z[tr, j], v[tr, j], res[tr, j]) for j in range(Y.shape[1])]
    if d.findings and "-" in d.findings[0].response:
        a, b = (names.index(x) for x in d.findings[0].response.split("-"))
        rows.append((d.findings[0].response, z[tr, a] - z[tr, b], v[tr, a] - v[tr, b], res[tr, a] - res[tr, b]))
    _plot_portraits(folder / "residual_portraits.png", rows, "m/s^2")
    modes = ", ".join(f"{m['frequency_hz']:.2f} Hz ({100 * m['damping_ratio']:.2f} %)" for m in js["baseline"]["modes"])
    cand_rows = [f"| {c['effect']} | {c['response']} | {c['gain']:.3f} | {c['fit_data_nrmse'] or float('nan'):.3f} | "
                 f"{_params_text(c['parameters'])} |" for c in js["candidates"] if c["gain"] is not None]
    _write_report(folder, js, [
        "# Discovery (modal linear baseline, force excitation)", "",
        f"Baseline: a linear modal model (receptances with common poles by vector fitting of the H1 frequency "
        f"response, residues refitted in the time domain) fitted on {fit_where}, driven by the measured force "
        f"from rest. Modes (damping ratio): {modes}.", "",
        f"Test NRMSE (samples {te.start}:{te.stop}, accelerations, mean over responses): baseline "
        f"{d.baseline_test_nrmse:.4f}" + (f" (on its own data {d.baseline_fit_nrmse:.4f})"
                                          if np.isfinite(d.baseline_fit_nrmse) else "")
        + f"; extended {d.extended_test_nrmse:.4f}; gain {d.gain:.3f}.", "",
        "Findings: " + ("; ".join(js["extended"]["equations"]) or _nothing(d.residual_rms, "m/s^2")) + holds, "",
        "Physical coordinates: displacement and velocity of every response by trapezoid integration with a "
        f"zero-phase {F_LO_HZ:g} Hz high-pass after each integration (drift removed); a pair 'A-B' is the "
        "relative motion of A against B. A candidate is an internal force at a response (grounded) or between a "
        "pair (+f on A, -f on B), entering each mode through the gains reciprocity gives (response 1 is the "
        "driving point), so its parameters are in newtons and metres. Its coefficient is fitted by least squares "
        "to the residual on the training segment, then the extended model runs closed loop over the held-out "
        "segment. 'NRMSE on fit data' reruns it on the baseline's data: a cause that depends on amplitude "
        "must leave the low level as it was.", "",
        "## Candidates, ranked by gain on the held-out segment", "",
        "| effect | coordinate | gain | NRMSE on fit data | parameters |", "|---|---|---|---|---|", *cand_rows, "",
        "![ranking](ranking.png)", "",
        "## Baseline, extended model and measurement on the held-out segment", "",
        "![baseline, extended, measured](baseline_extended_measured.png)", "",
        "## Residual (measured minus baseline accelerations) against the states (training segment)", "",
        "![residual portraits](residual_portraits.png)", ""])


def run(args) -> int:
    if args.baseline == "linear":
        return run_linear(args)
    s = _load(args)
    nominal = _model(args.model)
    n = len(s.t)
    train, test = parse_slice(args.train, n, "train"), parse_slice(args.test, n, "test")
    d = discover(s.values, s.fs_hz, nominal, train=train, test=test)
    js = result_json(d)
    split = "given" if args.train or args.test else "default: 10 equal blocks, the 3rd, 5th, 8th, 10th held out"
    print(f"baseline test NRMSE {d.baseline_test_nrmse:.4f}; split {split} "
          f"(train {_segments_text(d.train)}; test {_segments_text(d.test)})")
    if not d.findings:
        print(_nothing(d.residual_rms, "m/s^2"))
    for c in d.findings:
        print(f"found {c.effect} on {c.response}: {_params_text(c.parameters)}; gain {c.gain:.3f}")
    print(f"extended test NRMSE {d.extended_test_nrmse:.4f}, gain {d.gain:.3f}")
    _write_json(args.json, js)
    if args.report:
        _report(args.report, d, js, s)
        print(f"wrote {args.report / 'README.md'}")
    return 0


def _report(folder: Path, d, js: dict, s) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    fs = s.fs_hz
    base, tips, z, v, r, base_full = coordinates(s.values, fs)
    # held-out blocks, the one the baseline misses most first (its first 3 s are plotted)
    blocks = [(seg, *simulated_tips(d.nominal, base, tips, z, v, fs, (seg,))) for seg in d.test]
    blocks.sort(key=lambda b: -float(np.mean((b[1] - b[2]) ** 2)))
    test = tuple(b[0] for b in blocks)
    meas, base_sim = np.concatenate([b[1] for b in blocks]), np.concatenate([b[2] for b in blocks])
    _, ext_sim = simulated_tips(d.extended, base, tips, z, v, fs, test, d.extended_output)
    _plot_time_psd(folder / "baseline_extended_measured.png", indices(test) / fs, meas,
                   base_sim, ext_sim, ["tip 1", "tip 2"], fs, 60.0)
    _plot_ranking(folder / "ranking.png", [(f"{c['effect']} ({c['response']})", c["gain"], c["gain"] > 0.05)
                                           for c in js["candidates"]])
    tr = indices(d.train)
    _plot_portraits(folder / "residual_portraits.png",
                    [(f"tip {i + 1}", z[tr, i], v[tr, i], r[tr, i] - _beam_rhs(d.nominal, i, z[tr], v[tr],
                                                                              base_full[tr])) for i in range(2)],
                    "m/s^2 (force per mass)")
    rows = [f"| {c['effect']} | {c['response']} | {c['gain']:.3f} | {_params_text(c['parameters'])} |"
            for c in js["candidates"] if c["gain"] is not None]
    _write_report(folder, js, [
        "# Discovery", "",
        f"Baseline (the nominal rig model driven by the measured base acceleration) test NRMSE "
        f"{d.baseline_test_nrmse:.4f}; extended {d.extended_test_nrmse:.4f}; gain {d.gain:.3f}.", "",
        "Findings: " + ("; ".join(js["extended"]["equations"]) or _nothing(d.residual_rms, "m/s^2")), "",
        "Physical coordinates: relative acceleration (tip minus base), integrated to velocity and "
        "displacement by the trapezoid rule with a zero-phase 2 Hz high-pass after each integration "
        "(drift removed). Held-out samples " + _segments_text(d.test) + ", training " + _segments_text(d.train)
        + ". Scores: NRMSE of the tip accelerations below 50 Hz over the held-out samples, each block "
        f"simulated from the measured state {warm_up_s(d.nominal):.1f} s (five decay times) before it, so the "
        "start state's error has died out. Each cause's coefficients are regressed on the residual force, "
        "then the leading ones are refined by simulation error on training data (a contact's side, gap and "
        "stiffness whenever it explains 5 % of the residual force); a cause with more parameters must gain "
        "0.02 more than a simpler one.", "",
        "## Candidates, ranked by gain on the held-out data", "",
        "| effect | response | gain | parameters |", "|---|---|---|---|", *rows, "",
        "![ranking](ranking.png)", "",
        "## Baseline, extended model and measurement on the held-out data", "",
        "The held-out block the baseline misses most, then the spectra over all held-out blocks.", "",
        "![baseline, extended, measured](baseline_extended_measured.png)", "",
        "## Residual force against the states (training data)", "",
        "A dead zone (contact), a cubic, a step at zero velocity (friction) look different here.", "",
        "![residual portraits](residual_portraits.png)", ""])
