"""``ident batch FILES_OR_GLOB...``: analyse every recording of a campaign as a Dask task, one row per recording.

A command line composing readers, like ``ident discover``: each task reads its file with replay's readers
(``replay.formats``, chosen by suffix) and runs the pure science of ``ident.campaign`` and
``ident.discovery`` on it. The analyses (one or more):

- ``--regimes``: the regime monitor over the whole recording: its regimes as spans and their durations;
- ``--fit``: per beam, SINDy in physical coordinates on the segment from ``--start`` (default 5 s):
  equations, natural frequency, integration NRMSE; one-tone excitation is flagged (not identifiable);
- ``--discover [--model RIG.yaml]``: what the rig model (or a modal model fitted to the data) misses:
  the verdict, findings with parameters and held-out gains.

The table (``-o RESULTS.csv``) is CSV with JSON in the columns that hold lists (regimes, equations,
findings, discovery's notes): one file any spreadsheet, pandas (``pd.read_csv``) or the csv module opens, no further
dependency, and small enough (a few thousand rows) to be rewritten whole at every save, which keeps each
write atomic. Rows are sorted by file. A file that
fails is a row with its error and the batch goes on; the table is rewritten atomically (``daq.safeio``)
at most once a second while rows come in and at the end, so Ctrl-C keeps every finished row (a kill -9 the
last second's). Run again with the same table: a row is kept when the same file (size and modification
time) was analysed with the same settings without an error; the rest are analysed (again). A file that is
not such a table is never replaced without ``--force``, which also starts a table afresh.
"""

from __future__ import annotations

import csv
import glob
import hashlib
import json
import math
import os
import sys
import time
from contextlib import closing
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
from tqdm import tqdm

from daq.safeio import Output, check_outputs, safe_folder, safe_output, same_file
from replay.formats import FORMATS, format_of, mcap, read_samples

from ..jsonsafe import finite
from ..campaign import fit_beams, regime_durations, regime_record
from ..discovery import Channel, discover
from ..discovery.result import candidate_json
from ..discovery.signals import bridged
from ..live.regimes import MIN_PERIODS, RegimeConfig
from ..rig import RigParams
from . import DURATION, OFFSET, RATE_HZ, REGIME_WINDOW
from .batch_report import trusted_frequency, write_report
from .discover import load_model
from .engine import add_options, cores, session, unordered

ANALYSES = ("regimes", "fit", "discover")  # the order they run in, and their columns' order
COLUMNS = ("file", "format", "bytes", "modified", "settings", "fs_hz", "duration_s", "samples", "filled_samples",
           "regimes", "regime_durations_s", "regime_changes", "regime_note",
           "fit_segment_s", "beam1_natural_frequency_hz", "beam2_natural_frequency_hz", "beam1_nrmse",
           "beam2_nrmse", "beam1_equations", "beam2_equations", "fit_note",
           "verdict", "n_findings", "gain", "findings", "discover_notes",
           "error", "seconds")
# a table written before ``discover_notes`` (stop 74) is continued: its rows are kept, and those its --discover
# analysed are analysed again, since their notes (a dead sensor, a dropout, a clipped input) were not kept
BEFORE_NOTES = tuple(c for c in COLUMNS if c != "discover_notes")
WRITE_EVERY_S = 1.0


def add_parser(sub) -> None:
    p = sub.add_parser("batch", help="analyse a campaign of recordings as Dask tasks: one row per recording")
    p.add_argument("files", nargs="+", metavar="FILES_OR_GLOB",
                   help="recordings (.mcap, .csv, .mat, .uff, .tdms), folders (their recordings) or quoted "
                        "glob patterns ('campaign/**/*.mcap')")
    p.add_argument("--regimes", action="store_true", help="the regime monitor: regimes and their durations")
    p.add_argument("--regime-window", type=REGIME_WINDOW, default=RegimeConfig.window_s,
                   help=f"--regimes: the monitor's window (default {RegimeConfig.window_s:g} s); it must hold "
                        f"{MIN_PERIODS:g} periods of the drive: 1 s for a rig driven at 3.6-7.2 Hz")
    p.add_argument("--fit", action="store_true", help="each beam's equations and natural frequency")
    p.add_argument("--discover", action="store_true", help="what the model misses: findings and gains")
    p.add_argument("--model", type=Path, help="--discover: a rig config (YAML) whose rig model is the baseline "
                                              "(default: a modal model fitted to each recording)")
    p.add_argument("--start", type=OFFSET, default=5.0, help="--fit: seconds to skip (default 5: past ramps)")
    p.add_argument("--duration", type=DURATION, help="--fit: seconds to use (default: to the end)")
    p.add_argument("--time", dest="time_col", help="CSV, TDMS: time column")
    p.add_argument("--fs", type=RATE_HZ, dest="fs_hz", help="CSV, TDMS without a time column: sampling rate")
    p.add_argument("-o", "--output", type=Path, required=True, metavar="RESULTS.csv",
                   help="the table (CSV); an existing one of the same batch is continued")
    p.add_argument("--report", type=Path, help="write a summary report folder (markdown, PNG figures)")
    add_options(p, "local Dask worker processes (default: one per core); 0: run in this process, no Dask")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--force", action="store_true",
                   help="start the table afresh (replacing RESULTS), write into a non-empty --report")
    p.set_defaults(func=run)


# --- one recording (a Dask task) ----------------------------------------------------------------------


@dataclass(frozen=True)
class Settings:
    """What a row's results depend on besides the file (pickled to the workers with every task)."""

    analyses: tuple[str, ...]
    start_s: float = 5.0
    duration_s: float | None = None
    model: RigParams | None = None
    model_file: str = ""
    model_sha256: str = ""
    time_col: str | None = None
    fs_hz: float | None = None
    regime_window_s: float = RegimeConfig.window_s

    def signature(self) -> str:
        """The settings as one JSON text (a row is reused only under the same)."""
        sig: dict = {"analyses": list(self.analyses)}
        if "fit" in self.analyses:
            sig.update(start_s=self.start_s, duration_s=self.duration_s)
        if "discover" in self.analyses:
            sig.update(model=self.model_file or "modal baseline", model_sha256=self.model_sha256 or None)
        if self.time_col or self.fs_hz:
            sig.update(time=self.time_col, fs_hz=self.fs_hz)
        if "regimes" in self.analyses and self.regime_window_s != RegimeConfig.window_s:
            sig.update(regime_window_s=self.regime_window_s)
        return _json(sig)


def _json(v) -> str:
    return json.dumps(finite(v), separators=(",", ":"))


def identity(path: str) -> dict:
    """What tells a file's version apart: size and modification time (UTC, microseconds)."""
    st = os.stat(path)
    when = datetime.fromtimestamp(st.st_mtime_ns / 1e9, timezone.utc).isoformat(timespec="microseconds")
    return {"bytes": str(st.st_size), "modified": when}


def _one_line(what: str, exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    if not isinstance(exc, (ValueError, OSError)):  # not bad input: name the exception
        text = f"{type(exc).__name__}: {text}" if text else type(exc).__name__
    return f"{what}: {text or type(exc).__name__}"


def _regimes(s, settings: Settings) -> dict:
    r = regime_record(s.values, s.fs_hz, settings.regime_window_s)
    slow = r.slow_drive
    return {"regimes": _json([{"regime": x.regime, "start_s": x.start_s, "end_s": x.end_s} for x in r.spans]),
            "regime_durations_s": _json(regime_durations(r.spans)), "regime_changes": len(r.spans) - 1,
            "regime_note": f"from {slow.t_s:g} s: {slow.message}" if slow else ""}


def _fit(s, settings: Settings) -> dict:
    f = fit_beams(s.values, s.fs_hz, settings.start_s, settings.duration_s)
    out: dict = {"fit_segment_s": _json([f.start_s, f.start_s + f.duration_s])}
    for b in f.beams:
        out[f"beam{b.beam}_natural_frequency_hz"] = b.natural_frequency_hz
        out[f"beam{b.beam}_nrmse"] = b.nrmse
        out[f"beam{b.beam}_equations"] = _json(list(b.equations))
    if f.one_tone_hz is not None:
        out["fit_note"] = (f"one-tone excitation ({f.one_tone_hz:.3g} Hz): stiffness, damping and forcing are not "
                           f"separately identifiable, the natural frequencies mean nothing")
    return out


def _discover(s, settings: Settings) -> dict:
    v = np.where(s.filled[:, None], np.nan, s.values)  # lost frames are missing, not measured: bridged, left out
    m = bridged(float(s.fs_hz), Channel("base", "base_acceleration", v[:, 0]),
                (Channel("tip1", "acceleration", v[:, 1]), Channel("tip2", "acceleration", v[:, 2])))
    d = discover(m, rig=settings.model)
    findings = [{**candidate_json(c, m.fs_hz), "ambiguous_with": [a.label for a in alike]}
                for c, alike in zip(d.findings, d.ambiguous)]
    return {"verdict": d.verdict(), "n_findings": len(findings), "gain": d.gain if findings else "",
            "findings": _json(findings), "discover_notes": _json(d.notes)}


RUN = {"regimes": _regimes, "fit": _fit, "discover": _discover}


def analyse(path: str, settings: Settings) -> dict:
    """One row: the file read with replay's readers and every chosen analysis; what fails is the row's
    error (each analysis on its own: one failing keeps the others' columns)."""
    t0 = time.perf_counter()
    row = {c: "" for c in COLUMNS}
    row.update(file=path, settings=settings.signature())
    errors = []
    try:
        row.update(identity(path))
        row["format"] = Path(path).suffix.lower().lstrip(".")
        fmt = format_of(path)
        options = {} if fmt is mcap else {"time_col": settings.time_col, "fs_hz": settings.fs_hz}
        s = read_samples(path, **options)
        row.update(fs_hz=float(s.fs_hz), duration_s=float(s.duration_s), samples=len(s.t),
                   filled_samples=int(np.count_nonzero(s.filled)))
    except Exception as exc:  # noqa: BLE001 - a file that fails is a row with its error; the batch goes on
        errors.append(_one_line("read", exc))
    else:
        for name in settings.analyses:
            try:
                row.update(RUN[name](s, settings))
            except Exception as exc:  # noqa: BLE001 - as above, per analysis
                errors.append(_one_line(name, exc))
    row["error"] = "; ".join(errors)
    row["seconds"] = round(time.perf_counter() - t0, 3)
    return {k: _cell(v) for k, v in row.items()}


def analyse_job(job: tuple[str, Settings]) -> dict:
    return analyse(*job)


def _cell(v) -> str:
    """A table cell: floats as their shortest exact text (the same numbers give the same table)."""
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    return str(v)


# --- the campaign ---------------------------------------------------------------------------------------


def _is_recording(path: str | Path) -> bool:
    try:
        format_of(path)
        return True
    except ValueError:
        return False


def expand(patterns: list[str]) -> list[str]:
    """Absolute paths of the recordings named: files as given, a folder's recordings (by suffix, hidden
    files left out), a glob pattern's matching recordings; each file once, in the order found."""
    out, seen = [], set()
    for a in patterns:
        p = Path(a)
        if p.is_dir():
            found = sorted(str(q) for q in p.iterdir() if q.is_file() and not q.name.startswith(".")
                           and _is_recording(q))
        elif p.exists():
            found = [a]
        elif glob.has_magic(a):
            found = sorted(m for m in glob.glob(a, recursive=True) if Path(m).is_file() and _is_recording(m))
        else:
            raise ValueError(f"{a}: no such file or folder")
        if not found:
            raise ValueError(f"{a} {'holds' if p.is_dir() else 'matches'} no recording (suffixes "
                             f"{', '.join(sorted(FORMATS))})")
        for f in found:
            key = os.path.realpath(f)
            if key not in seen:
                seen.add(key)
                out.append(os.path.abspath(f))
    return out


def read_table(path: Path) -> dict[str, dict]:
    """The rows of an existing table by file (one written before ``discover_notes`` with that column empty);
    refused (one line) if it is not a table of this command."""
    try:
        with open(path, newline="") as fh:
            reader = csv.DictReader(fh)
            if tuple(reader.fieldnames or ()) not in (COLUMNS, BEFORE_NOTES):
                raise ValueError(f"-o {path} exists and is not an ident batch table (its columns differ); give "
                                 f"--force to replace it, or another -o")
            return {r["file"]: {c: r.get(c, "") for c in COLUMNS} for r in reader}
    except (UnicodeDecodeError, csv.Error):
        raise ValueError(f"-o {path} exists and is not an ident batch table; give --force to replace it, or "
                         f"another -o") from None


def write_table(path: Path, rows: dict[str, dict], inputs: list, replace: bool) -> None:
    """The whole table, sorted by file, written beside and renamed (daq.safeio)."""
    with safe_output(path, inputs=inputs, force=replace, label="-o") as tmp:
        with open(tmp, "w", newline="") as fh:
            w = csv.DictWriter(fh, COLUMNS, lineterminator="\n")
            w.writeheader()
            w.writerows(rows[k] for k in sorted(rows))


class TableFile:
    """The table on disk, rewritten whole and atomically at most every ``WRITE_EVERY_S`` while rows come in:
    never over a file that appeared meanwhile unless it is ours (``ours``: continued or ``--force``; from its
    first write on it is)."""

    def __init__(self, path: Path, inputs: list, ours: bool):
        self.path, self.inputs, self.ours = path, inputs, ours
        self.last = time.monotonic()

    def save(self, rows: dict[str, dict], now: bool = False) -> None:
        if now or time.monotonic() - self.last >= WRITE_EVERY_S:
            write_table(self.path, rows, self.inputs, replace=self.ours)
            self.ours = True
            self.last = time.monotonic()


def is_done(row: dict | None, ident: dict, signature: str) -> bool:
    """The row holds this version of the file analysed with these settings, without an error, and (a row of a
    table from before ``discover_notes``) with its discovery's notes."""
    return (row is not None and not row["error"] and row["settings"] == signature and row["bytes"] == ident["bytes"]
            and row["modified"] == ident["modified"]
            and not ("discover" in json.loads(signature)["analyses"] and not row["discover_notes"]))


def _sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


@dataclass
class Plan:
    files: list[str]  # absolute paths, in the order named
    inputs: list  # what no output may be: the recordings and the model
    table: dict[str, dict]  # the rows kept from an existing table, by file
    ours: bool  # the table file is ours to replace (continued, or --force)
    settings: Settings
    todo: list[str]  # the files to analyse


def plan(args) -> Plan:
    """Everything checked before a file is read or a worker started: options, inputs, outputs, the table so far."""
    analyses = tuple(a for a in ANALYSES if getattr(args, a))
    if not analyses:
        raise ValueError("choose what to run: --regimes, --fit and/or --discover")
    if args.model and not args.discover:
        raise ValueError("--model is the baseline of --discover; give --discover too")
    if args.output.suffix.lower() != ".csv":
        raise ValueError(f"-o {args.output}: the table is CSV (with JSON columns); give a name ending in .csv")
    if args.scheduler and args.workers is not None:
        raise ValueError("give --scheduler ADDRESS (a running cluster) or --workers N (a local one), not both")
    files = expand(args.files)
    table, refusal = {}, None
    if args.output.is_file():
        try:
            table = read_table(args.output)
        except ValueError as exc:
            refusal = exc
    if refusal is None and args.output.is_file():  # our own table, matched by a pattern: not an input
        kept = [f for f in files if not same_file(f, args.output)]
        if len(kept) < len(files):
            print(f"ident batch: {args.output} is this batch's table, not a recording: left out")
        files = kept
    if not files:
        raise ValueError("no recording to analyse")
    inputs = files + [args.model]
    check_outputs([Output("-o", args.output)], inputs, force=True)  # an input, a folder: refused always
    check_outputs([Output("--report", args.report, folder=True)], inputs, args.force)
    if args.report is not None and same_file(args.report, args.output):
        raise ValueError(f"--report {args.report} and -o {args.output} are the same path; give two names")
    existing = args.output.exists() and not args.force
    if existing and refusal is not None:
        raise refusal
    if args.force:
        table = {}
    model = load_model(args.model) if args.model else None
    settings = Settings(analyses, args.start, args.duration, model, str(args.model or ""),
                        _sha256(args.model) if args.model else "", args.time_col, args.fs_hz, args.regime_window)
    sig = settings.signature()
    other = sorted({r["settings"] for r in table.values()} - {sig})
    if other:
        raise ValueError(f"-o {args.output} holds rows of other settings ({other[0]}); give another -o, or --force "
                         f"to start it afresh")
    todo = []
    for f in files:
        try:
            if is_done(table.get(f), identity(f), sig):
                continue
        except OSError:
            pass  # gone or unreadable: its task says so in its row
        todo.append(f)
    return Plan(files, inputs, table, existing or args.force, settings, todo)


def run(args) -> int:
    p = plan(args)
    table, todo = p.table, p.todo
    out = TableFile(args.output, p.inputs, ours=p.ours)
    workers = args.workers if args.workers is not None else (None if args.scheduler else cores())
    errors = 0
    interrupted = False
    jobs = [(f, p.settings) for f in todo]
    with session(args.scheduler if todo else None, workers if todo else 0) as client:
        where = "in this process" if client is None else (f"on {len(client.scheduler_info()['workers'])} Dask "
                                                          f"workers ({client.scheduler.address})")
        print(f"ident batch: {len(p.files)} recordings, {len(p.files) - len(todo)} already in {args.output}, "
              f"{len(todo)} to analyse ({', '.join(p.settings.analyses)}) {where}")
        with tqdm(total=len(todo), desc="batch", unit="file", disable=args.no_progress, file=sys.stderr) as bar:
            try:
                with closing(unordered(client, analyse_job, jobs, "batch")) as results:
                    for _, row in results:
                        table[row["file"]] = row
                        errors += bool(row["error"])
                        bar.update()
                        bar.set_postfix(errors=errors, refresh=False)
                        out.save(table)
            except KeyboardInterrupt:
                interrupted = True
            finally:
                out.save(table, now=True)
    rows = [table[k] for k in sorted(table)]
    if interrupted:
        print(f"ident batch: interrupted: {len(rows)} rows kept in {args.output}; run the same command again to "
              f"analyse the rest", file=sys.stderr)
        return 130
    print(summary(rows, args.output))
    if args.report:
        with safe_folder(args.report, inputs=p.inputs + [args.output], force=args.force) as folder:
            write_report(rows, folder, args.output)
        print(f"report: {args.report / 'README.md'}")
    named = set(p.files)  # (a row of a file no longer named stays in the table but is not this run's)
    return 1 if any(r["error"] for r in rows if r["file"] in named) else 0  # (a script should know)


def summary(rows: list[dict], path: Path) -> str:
    bad = [r for r in rows if r["error"]]
    lines = [f"{len(rows)} rows in {path}: {len(rows) - len(bad)} without error, {len(bad)} with an error"]
    for r in bad[:5]:
        lines.append(f"  {r['file']}: {r['error']}")
    if len(bad) > 5:
        lines.append(f"  ... and {len(bad) - 5} more (column 'error')")
    durations: dict[str, float] = {}
    for r in rows:
        for k, v in (json.loads(r["regime_durations_s"]) if r["regime_durations_s"] else {}).items():
            durations[k] = durations.get(k, 0.0) + v
    if durations:
        lines.append("time in each regime: " + ", ".join(f"{k} {v:.1f} s" for k, v in durations.items()))
    slow = [r for r in rows if r["regime_note"]]
    if slow:
        lines.append(f"regime window too short for the drive in {len(slow)} recording{'s' * (len(slow) > 1)} "
                     f"(column 'regime_note'; hitting there may be the window's leakage), first "
                     f"{Path(slow[0]['file']).name}: {slow[0]['regime_note']}")
    for beam in (1, 2):
        fn = [x for x in (trusted_frequency(r, beam) for r in rows if r["beam1_equations"]) if math.isfinite(x)]
        if any(r["beam1_equations"] for r in rows):
            lines.append(f"beam {beam} natural frequency: " + (f"median {np.median(fn):.3f} Hz, {min(fn):.3f} to "
                         f"{max(fn):.3f} Hz over {len(fn)} trusted fits" if fn else "no trusted fit")
                         + " (left out: one tone, poor fits, contact in the segment)")
    causes: dict[str, int] = {}
    for r in rows:
        for f in json.loads(r["findings"]) if r["findings"] else []:
            key = f"{f['effect']} at {f['response']}"
            causes[key] = causes.get(key, 0) + 1
    if any(r["verdict"] for r in rows):
        nothing = sum(1 for r in rows if r["verdict"] and r["n_findings"] == "0")
        lines.append("findings: " + (", ".join(f"{k} {v}" for k, v in sorted(causes.items(), key=lambda x: -x[1]))
                                     or "none") + f"; nothing found in {nothing}")
        noted = sum(1 for r in rows if json.loads(r["discover_notes"] or "[]"))
        if noted:
            lines.append(f"discovery left notes on {noted} recording{'s' * (noted > 1)} (a dead sensor, a dropout, a "
                         f"clipped input, a blow, a failed candidate: column 'discover_notes')")
    return "\n".join(lines)
