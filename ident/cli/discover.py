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
    p.add_argument("--train", help="training samples START:STOP (default: the first 60 %%)")
    p.add_argument("--test", help="held-out samples START:STOP (default: the last 40 %%)")
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
    from replay.sources import open_samples

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
    import yaml

    from ..config import build
    from ..rig import RigConfig

    try:
        data = yaml.safe_load(path.read_text())
    except FileNotFoundError:
        raise ValueError(f"{path}: model file not found") from None
    except yaml.YAMLError as exc:
        raise ValueError(f"{path}: not valid YAML: {exc}") from None
    if isinstance(data, dict):
        data = {k: v for k, v in data.items() if k != "daq"}  # a daq config file is accepted as is
    return build(RigConfig, data, str(path)).rig


def _clean(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def result_json(d) -> dict:
    def eq(c) -> str:
        p = ", ".join(f"{k} = {v:.6g}" if isinstance(v, float) else f"{k} = {v}" for k, v in c.parameters.items())
        return f"{c.response}: {c.effect} ({p})"

    return {
        "baseline": {"test_nrmse": _clean(d.baseline_test_nrmse)},
        "extended": {"test_nrmse": _clean(d.extended_test_nrmse), "equations": [eq(c) for c in d.findings]},
        "gain": _clean(d.gain),
        "findings": [{"effect": c.effect, "response": c.response, "parameters": c.parameters,
                      "gain": _clean(c.gain)} for c in d.findings],
        "candidates": [{"effect": c.effect, "response": c.response, "parameters": c.parameters,
                        "gain": _clean(c.gain), "test_nrmse": _clean(c.test_nrmse), "fit_r2": c.fit_r2}
                       for c in d.candidates],
        "split": {"train": [d.train.start, d.train.stop], "test": [d.test.start, d.test.stop]},
        "residual_rms_m_per_s2": d.residual_rms,
    }


def _split_kind(spec: str, default: str) -> tuple[str, str]:
    col, _, kind = spec.partition(":")
    return col, kind or default


def run_linear(args) -> int:
    """--baseline linear: any CSV (or recording) with an excitation and responses of given kinds."""
    from ..linear_discovery import KINDS_EXCITATION, KINDS_RESPONSE, discover_linear

    exc_col, exc_kind = _split_kind(args.excitation, "base_acceleration")
    if exc_kind not in KINDS_EXCITATION:
        raise ValueError(f"excitation kind {exc_kind!r} is not one of {', '.join(KINDS_EXCITATION)}")
    specs = [_split_kind(r, "acceleration") for r in (args.response or ["tip1", "tip2"])]
    for col, kind in specs:
        if kind not in KINDS_RESPONSE:
            raise ValueError(f"response kind {kind!r} of {col!r} is not one of {', '.join(KINDS_RESPONSE)}")
    path = Path(args.data)
    if path.suffix.lower() == ".csv":
        from replay.sources import read_csv_columns

        data, fs = read_csv_columns(path, [exc_col] + [c for c, _ in specs], args.time_col, args.fs_hz)
        u, Y = data[:, 0], data[:, 1:]
    else:
        from replay.sources import open_samples

        s = open_samples(path)
        roles = {"base": 0, "tip1": 1, "tip2": 2}
        for c in [exc_col] + [c for c, _ in specs]:
            if c not in roles:
                raise ValueError(f"a recording has the channels base, tip1, tip2; not {c!r}")
        u, Y, fs = s.values[:, roles[exc_col]], s.values[:, [roles[c] for c, _ in specs]], s.fs_hz
    n = len(u)
    train, test = parse_slice(args.train, n, "train"), parse_slice(args.test, n, "test")
    d = discover_linear(u, Y, [c for c, _ in specs], [k for _, k in specs], exc_kind, fs, train=train, test=test)
    js = {"baseline": {"test_nrmse": d.baseline_test_nrmse}, "extended": {
        "test_nrmse": d.extended_test_nrmse,
        "equations": [f"{f['response']}: {f['effect']} ({', '.join(f'{k} = {v}' for k, v in f['parameters'].items())})"
                      for f in d.findings]},
        "gain": d.gain, "findings": d.findings, "candidates": d.candidates,
        "split": {"train": [d.train.start, d.train.stop], "test": [d.test.start, d.test.stop]},
        "residual_rms": d.residual_rms}
    print(f"linear baseline test NRMSE {d.baseline_test_nrmse:.4f}"
          + (" (its simulation diverges: capped at 1, the error of predicting nothing)"
             if d.baseline_test_nrmse >= 1.0 else ""))
    print("findings: " + ("; ".join(js["extended"]["equations"]) or "nothing found; residual force RMS "
                          + ", ".join(f"{k} {v:.3g}" for k, v in d.residual_rms.items())))
    print(f"extended test NRMSE {d.extended_test_nrmse:.4f}, gain {d.gain:.3f}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(js, indent=2, default=_clean))
    if args.report:
        args.report.mkdir(parents=True, exist_ok=True)
        (args.report / "result.json").write_text(json.dumps(js, indent=2, default=_clean))
        rows = [f"| {c['effect']} | {c['response']} | {c['gain']:.3f} |" for c in d.candidates]
        (args.report / "README.md").write_text("\n".join([
            "# Discovery (linear baseline)", "",
            f"Linear baseline test NRMSE {d.baseline_test_nrmse:.4f}, extended {d.extended_test_nrmse:.4f}, "
            f"gain {d.gain:.3f}.", "", "| effect | response | gain |", "|---|---|---|", *rows, ""]))
    return 0


def run(args) -> int:
    if args.baseline == "linear":
        return run_linear(args)
    from ..discovery import discover

    s = _load(args)
    nominal = _model(args.model)
    n = len(s.t)
    train, test = parse_slice(args.train, n, "train"), parse_slice(args.test, n, "test")
    d = discover(s.values, s.fs_hz, nominal, train=train, test=test)
    js = result_json(d)
    split = "given" if args.train or args.test else "default: first 60 % train, last 40 % test"
    print(f"baseline test NRMSE {d.baseline_test_nrmse:.4f}; split {split} "
          f"(train {d.train.start}:{d.train.stop}, test {d.test.start}:{d.test.stop})")
    if not d.findings:
        print(f"nothing found: no cause gains more than 5 %; residual force RMS "
              + ", ".join(f"{k} {v:.3g} m/s^2" for k, v in d.residual_rms.items()))
    for c in d.findings:
        print(f"found {c.effect} on {c.response}: " + ", ".join(
            f"{k} = {v:.4g}" if isinstance(v, float) else f"{k} = {v}" for k, v in c.parameters.items())
            + f"; gain {c.gain:.3f}")
    print(f"extended test NRMSE {d.extended_test_nrmse:.4f}, gain {d.gain:.3f}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(js, indent=2))
    if args.report:
        _report(args.report, d, js, s)
        print(f"wrote {args.report / 'README.md'}")
    return 0


def _report(folder: Path, d, js: dict, s) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from scipy.signal import welch

    from ..discovery import _beam_rhs, coordinates, simulated_tips

    folder.mkdir(parents=True, exist_ok=True)
    fs = s.fs_hz
    meas, base_sim = simulated_tips(d.nominal, s.values, fs, d.test)
    _, ext_sim = simulated_tips(d.extended, s.values, fs, d.test, d.extended_output)
    t = (np.arange(len(meas)) + d.test.start) / fs
    show = slice(0, min(len(t), int(3 * fs)))
    fig, ax = plt.subplots(2, 2, figsize=(12, 6.5), sharex="col")
    for i in range(2):
        ax[i, 0].plot(t[show], meas[show, i], "k", lw=1.2, label="measured")
        ax[i, 0].plot(t[show], base_sim[show, i], "C0--", lw=1, label="baseline")
        ax[i, 0].plot(t[show], ext_sim[show, i], "C3:", lw=1.5, label="extended")
        ax[i, 0].set(ylabel=f"tip {i + 1} [m/s^2]")
        f, p_res = welch(meas[:, i] - base_sim[:, i], fs, nperseg=min(4096, len(meas)))
        f, p_meas = welch(meas[:, i], fs, nperseg=min(4096, len(meas)))
        _, p_ext = welch(meas[:, i] - ext_sim[:, i], fs, nperseg=min(4096, len(meas)))
        ax[i, 1].semilogy(f, p_meas, "k", lw=1, label="measured")
        ax[i, 1].semilogy(f, p_res, "C0", lw=1, label="residual of the baseline")
        ax[i, 1].semilogy(f, p_ext, "C3", lw=1, label="residual of the extended model")
        ax[i, 1].set(xlim=(0, 60), ylim=(float(np.max(p_meas)) * 1e-8, float(np.max(p_meas)) * 10), ylabel="PSD")
    ax[0, 0].legend(fontsize=8)
    ax[0, 1].legend(fontsize=8)
    ax[1, 0].set(xlabel="t [s] (held-out segment)")
    ax[1, 1].set(xlabel="frequency [Hz] (harmonics the baseline cannot make stand out)")
    fig.tight_layout()
    fig.savefig(folder / "baseline_extended_measured.png", dpi=90)
    plt.close(fig)
    ranked = [c for c in js["candidates"] if c["gain"] is not None][:12]
    fig, ax = plt.subplots(figsize=(8, 0.35 * len(ranked) + 1.2))
    ax.barh([f"{c['effect']} ({c['response']})" for c in ranked][::-1], [c["gain"] for c in ranked][::-1],
            color=["C3" if c["gain"] > 0.05 else "C7" for c in ranked][::-1])
    ax.axvline(0.05, color="k", lw=0.8, ls="--")
    ax.set(xlabel="gain on the held-out segment (1 - NRMSE extended / baseline)", title="candidate causes")
    fig.tight_layout()
    fig.savefig(folder / "ranking.png", dpi=90)
    plt.close(fig)
    base, tips, z, v, r, base_full = coordinates(s.values, s.fs_hz)
    tr = d.train
    fig, ax = plt.subplots(2, 2, figsize=(11, 7))
    for i in range(2):
        res = r[tr, i] - _beam_rhs(d.nominal, i, z[tr], v[tr], base_full[tr])
        ax[i, 0].plot(z[tr, i] * 1e3, res, ",", alpha=0.5)
        ax[i, 0].set(xlabel=f"z{i + 1} [mm]", ylabel="residual force per mass [m/s^2]",
                     title=f"tip {i + 1}: residual against displacement")
        ax[i, 1].plot(v[tr, i], res, ",", alpha=0.5)
        ax[i, 1].set(xlabel=f"v{i + 1} [m/s]", title=f"tip {i + 1}: residual against velocity")
    fig.tight_layout()
    fig.savefig(folder / "residual_portraits.png", dpi=90)
    plt.close(fig)
    rows = [f"| {c['effect']} | {c['response']} | {c['gain']:.3f} | " +
            ", ".join(f"{k} = {v:.4g}" if isinstance(v, float) else f"{k} = {v}" for k, v in c["parameters"].items())
            + " |" for c in js["candidates"] if c["gain"] is not None]
    md = ["# Discovery", "",
          f"Baseline (the nominal rig model driven by the measured base acceleration) test NRMSE "
          f"{d.baseline_test_nrmse:.4f}; extended {d.extended_test_nrmse:.4f}; gain {d.gain:.3f}.", "",
          "Findings: " + ("; ".join(js["extended"]["equations"]) or "nothing found"), "",
          "Physical coordinates: relative acceleration (tip minus base), integrated to velocity and "
          "displacement by the trapezoid rule with a zero-phase 2 Hz high-pass after each integration "
          "(drift removed); scores on accelerations below 50 Hz over the held-out segment.", "",
          "## Candidates, ranked by gain on the held-out segment", "",
          "| effect | response | gain | parameters |", "|---|---|---|---|", *rows, "",
          "![ranking](ranking.png)", "",
          "## Baseline, extended model and measurement on the held-out segment", "",
          "![baseline, extended, measured](baseline_extended_measured.png)", "",
          "## Residual force against the states (training segment)", "",
          "A dead zone (contact), a cubic, a step at zero velocity (friction) look different here.", "",
          "![residual portraits](residual_portraits.png)", ""]
    (folder / "README.md").write_text("\n".join(md))
    (folder / "result.json").write_text(json.dumps(js, indent=2))

