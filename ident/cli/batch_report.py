"""``ident batch --report DIR``: the campaign's summary: a markdown page and figures of the table's rows.

Figures (only for the analyses the table holds): each beam's natural frequency across the campaign
(``natural_frequency.png``), the time in each regime per recording (``regimes.png``), discovery's findings
and their held-out gains (``findings.png``). Recordings are numbered in the table's order (by file); the
page lists them. Legends sit outside the axes, so they cover no data.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import matplotlib
import numpy as np

from ..live.regimes import LABELS

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402

REGIME_COLORS = {"linear": "tab:green", "localized-1": "tab:blue", "localized-2": "tab:orange",
                 "impacting-both": "tab:red"}
POOR_NRMSE = 0.3  # a fit whose integration NRMSE is above this does not reproduce the motion


def _float(text: str) -> float:
    try:
        return float(text)
    except (TypeError, ValueError):
        return float("nan")


def _loads(text: str, default):
    return json.loads(text) if text else default


def _finish(fig, ax, path: Path, ylabel: str, title: str) -> None:
    """The campaign axis (recordings by number), labels, the legend outside the data, saved and closed."""
    ax.xaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_xlabel("recording (number in the table's order, listed in README.md)")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0, fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _mark_errors(ax, rows: list[dict], x: np.ndarray, what: str) -> None:
    bad = [i for i, r in enumerate(rows) if r["error"]]
    if bad:
        ax.plot(x[bad], np.full(len(bad), 0.02), "x", color="tab:red", ms=6, transform=ax.get_xaxis_transform(),
                label=f"error ({what} missing)", clip_on=False)


HITTING = {1: ("localized-1", "impacting-both"), 2: ("localized-2", "impacting-both")}  # regimes a beam hits in


def distrust(row: dict, beam: int) -> str | None:
    """Why a beam's natural frequency in ``row`` is not to be trusted, or None: no fit, one-tone excitation (not
    identifiable), a fit that does not reproduce the motion (NRMSE above ``POOR_NRMSE``: an impacting beam's
    polynomial model), or, where the row has regimes, the beam hitting its stoppers during the fitted segment
    (the model then averages contact and free motion: seen 6 % off for 0.5 s of contact in 6 s)."""
    fn = _float(row[f"beam{beam}_natural_frequency_hz"])
    if not math.isfinite(fn):
        return "no fit"
    if row["fit_note"]:
        return "one tone"
    if not _float(row[f"beam{beam}_nrmse"]) <= POOR_NRMSE:
        return f"NRMSE > {POOR_NRMSE:g}"
    a, b = _loads(row["fit_segment_s"], [0.0, math.inf])
    for span in _loads(row["regimes"], []):
        if span["regime"] in HITTING[beam] and span["start_s"] < b and span["end_s"] > a:
            return "hit its stoppers"
    return None


def trusted_frequency(row: dict, beam: int) -> float:
    """A beam's natural frequency where it can be trusted (see :func:`distrust`), else nan."""
    return float("nan") if distrust(row, beam) else _float(row[f"beam{beam}_natural_frequency_hz"])


def figure_natural_frequency(rows: list[dict], path: Path) -> None:
    """Each beam's trusted natural frequency per recording; how many are left out, and why, in the legend."""
    x = np.arange(len(rows))
    fig, ax = plt.subplots(figsize=(10, 4.2))
    for beam, marker, color in ((1, "o", "tab:blue"), (2, "s", "tab:orange")):
        fn = np.array([trusted_frequency(r, beam) for r in rows])
        ok = np.isfinite(fn)
        ax.plot(x[ok], fn[ok], marker, ls="-", lw=0.6, ms=4, color=color, label=f"beam {beam} ({ok.sum()} fits)")
        why: dict[str, int] = {}
        for r in rows:
            reason = distrust(r, beam)
            if reason and reason != "no fit":
                why[reason] = why.get(reason, 0) + 1
        if why:  # an entry without a marker: what the figure leaves out
            ax.plot([], [], " ", label=f"beam {beam} left out: " + ", ".join(f"{k} {v}" for k, v in why.items()))
    _mark_errors(ax, rows, x, "fit")
    if not any(math.isfinite(trusted_frequency(r, b)) for r in rows for b in (1, 2)):
        ax.text(0.5, 0.5, "no natural frequency to trust (see the legend)", transform=ax.transAxes, ha="center")
    ax.set_xlim(-0.5, len(rows) - 0.5)
    ax.grid(alpha=0.3)
    _finish(fig, ax, path, "natural frequency [Hz]",
            "Natural frequency of each beam across the campaign (SINDy in physical coordinates)")


def figure_regimes(rows: list[dict], path: Path) -> None:
    x = np.arange(len(rows))
    durations = [_loads(r["regime_durations_s"], {}) for r in rows]
    fig, ax = plt.subplots(figsize=(10, 4.2))
    bottom = np.zeros(len(rows))
    for label in LABELS:
        h = np.array([d.get(label, 0.0) for d in durations])
        if np.any(h > 0):
            ax.bar(x, h, bottom=bottom, width=0.85, color=REGIME_COLORS.get(label), label=label)
            bottom += h
    _mark_errors(ax, rows, x, "regimes")
    _finish(fig, ax, path, "time in the regime [s]",
            "Regimes of each recording (regime monitor)")


def _first_finding(r: dict) -> str:
    f = _loads(r["findings"], [])
    if not f:
        return "nothing found"
    return f"{f[0]['effect']} at {f[0]['response']}" + (" (ambiguous)" if f[0].get("ambiguous_with") else "")


def figure_findings(rows: list[dict], path: Path) -> None:
    x = np.arange(len(rows))
    fig, ax = plt.subplots(figsize=(10, 4.2))
    kinds = sorted({_first_finding(r) for r in rows if r["verdict"]}, key=lambda k: (k == "nothing found", k))
    for j, kind in enumerate(kinds):
        idx = [i for i, r in enumerate(rows) if r["verdict"] and _first_finding(r) == kind]
        gain = [_float(rows[i]["gain"]) if rows[i]["gain"] else 0.0 for i in idx]
        if kind == "nothing found":
            ax.plot(x[idx], gain, "o", mfc="none", color="0.5", label="nothing found (gain 0)")
        else:
            ax.plot(x[idx], gain, "os^vD<>"[j % 7], ms=6, color=f"C{j % 10}", ls="none", label=kind)
    _mark_errors(ax, rows, x, "discovery")
    ax.axhline(0.03, color="k", ls="--", lw=0.8, label="gain floor 0.03")
    ax.set_xlim(-0.5, len(rows) - 0.5)
    _finish(fig, ax, path, "held-out gain, 1 - NRMSE extended / baseline",
            "Discovery's first finding per recording and the extended model's held-out gain")


def _fmt(text: str, digits: int = 3) -> str:
    v = _float(text)
    return f"{v:.{digits}f}" if math.isfinite(v) else "-"


def _cell(text: str) -> str:
    return text.replace("|", "/").replace("\n", " ")


def write_report(rows: list[dict], folder: Path, table: Path) -> None:
    """README.md and the figures of the analyses the rows hold."""
    has = {"regimes": any(r["regimes"] for r in rows), "fit": any(r["beam1_equations"] for r in rows),
           "discover": any(r["verdict"] for r in rows)}
    bad = [r for r in rows if r["error"]]
    settings = sorted({r["settings"] for r in rows})
    md = [f"# Campaign: {len(rows)} recordings", "",
          f"Table `{table}`: {len(rows) - len(bad)} rows without error, {len(bad)} with an error.",
          "Settings: " + "; ".join(f"`{s}`" for s in settings), ""]
    if has["regimes"]:
        figure_regimes(rows, folder / "regimes.png")
        total: dict[str, float] = {}
        for r in rows:
            for k, v in _loads(r["regime_durations_s"], {}).items():
                total[k] = total.get(k, 0.0) + v
        md += ["## Regimes", "", "| regime | time [s] | recordings in it |", "|---|---|---|"]
        for label in LABELS:
            if label in total:
                n = sum(1 for r in rows if label in _loads(r["regime_durations_s"], {}))
                md.append(f"| {label} | {total[label]:.1f} | {n} |")
        md += ["", "![regimes](regimes.png)", ""]
        slow = [r for r in rows if r["regime_note"]]
        if slow:
            md += [f"The drive was too slow for the regime window in {len(slow)} recording(s) (column `regime_note`): "
                   "there a free beam may read as hitting.", ""]
            md += [f"- `{Path(r['file']).name}`: {r['regime_note']}" for r in slow[:10]]
            if len(slow) > 10:
                md.append(f"- ... and {len(slow) - 10} more")
            md.append("")
    if has["fit"]:
        figure_natural_frequency(rows, folder / "natural_frequency.png")
        md += ["## Natural frequencies", ""]
        stats = []
        for beam in (1, 2):
            fn = [v for v in (trusted_frequency(r, beam) for r in rows) if math.isfinite(v)]
            if fn:
                stats.append(f"| {beam} | {len(fn)} | {np.median(fn):.3f} | {min(fn):.3f} | {max(fn):.3f} |")
        if stats:
            md += ["| beam | trusted fits | median [Hz] | min [Hz] | max [Hz] |", "|---|---|---|---|---|", *stats, ""]
        one = sum(1 for r in rows if r["fit_note"])
        md += [f"Trusted: a fit whose excitation was not one tone, whose model reproduces the segment (integration "
               f"NRMSE at most {POOR_NRMSE:g}) and, where the regimes were run, whose beam did not hit its stoppers "
               f"in the segment. {one} recordings were driven by one tone: from one sinusoid, stiffness, damping and "
               "forcing are not separately identifiable (column `fit_note`). The figure leaves the others out and "
               "says how many and why.", "", "![natural frequency](natural_frequency.png)", ""]
    if has["discover"]:
        figure_findings(rows, folder / "findings.png")
        counts: dict[str, int] = {}
        for r in rows:
            if r["verdict"]:
                counts[_first_finding(r)] = counts.get(_first_finding(r), 0) + 1
        md += ["## Findings (first finding per recording)", "", "| finding | recordings |", "|---|---|"]
        md += [f"| {k} | {v} |" for k, v in sorted(counts.items(), key=lambda kv: -kv[1])]
        md += ["", "![findings](findings.png)", ""]
        noted = [(r, _loads(r["discover_notes"], [])) for r in rows]
        noted = [(r, n) for r, n in noted if n]
        if noted:
            md += [f"Discovery left notes on {len(noted)} recording(s) (column `discover_notes`), the first three of "
                   "each here:", ""]
            for r, notes in noted[:10]:
                md.append(f"- `{Path(r['file']).name}`: " + "; ".join(_cell(n) for n in notes[:3])
                          + (f"; ... {len(notes) - 3} more" if len(notes) > 3 else ""))
            if len(noted) > 10:
                md.append(f"- ... and {len(noted) - 10} more")
            md.append("")
    if bad:
        md += ["## Errors", "", "| # | file | error |", "|---|---|---|"]
        md += [f"| {rows.index(r)} | `{Path(r['file']).name}` | {_cell(r['error'])} |" for r in bad]
        md.append("")
    md += ["## Recordings", "", "Natural frequencies marked (?) are not trusted (see above; the reason in brackets).", "",
           "| # | file | duration [s] | regimes | beam 1 [Hz] | beam 2 [Hz] | verdict | error |",
           "|---|---|---|---|---|---|---|---|"]
    for i, r in enumerate(rows):
        reg = " > ".join(s["regime"] for s in _loads(r["regimes"], []))
        fn = [(_fmt(r[f"beam{b}_natural_frequency_hz"]) + (f" (? {distrust(r, b)})" if distrust(r, b) else ""))
              if r["beam1_equations"] else "" for b in (1, 2)]
        md.append(f"| {i} | `{Path(r['file']).name}` | {_fmt(r['duration_s'], 2)} | {reg} | {fn[0]} | {fn[1]} | "
                  f"{_cell(r['verdict'])} | {_cell(r['error'])} |")
    (folder / "README.md").write_text("\n".join(md) + "\n")
