"""``replay``: play recordings through the live pipeline; info, export, import, recover.

    replay [play] FILE [--rate X | --max] [--start S] [--duration D] [--loop] [--viewer MODE] [--events OUT.jsonl]
    replay info FILE
    replay export FILE (--csv OUT.csv | --mat OUT.mat | --uff OUT.uff | -o OUT.{csv,mat,uff,unv,tdms})
    replay import IN.{csv,mat,uff,unv,tdms} -o OUT.mcap [--time COL | --fs HZ] [--base COL] [--tip1 COL] [--tip2 COL]
    replay recover BROKEN -o FIXED

``replay FILE ...`` is ``replay play FILE ...``: options may come before or after the file. Every
output is checked before anything is read or created (daq.safeio) and written atomically; ``--force``
replaces an existing output, never an input.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

from daq.cli import add_live_options, check_live, compile_kernels
from daq.eventlog import JsonlEvents
from daq.recorder import TOPICS
from daq.safeio import Output, check_outputs, part_path
from daq.viewer import RerunViewer, resolve_mode
from ident.cli import OFFSET, PLAY_RATE, RATE_HZ, DURATION, OneLineParser, run_guarded
from ident.live.pipeline import model_records, rolling_config

from . import formats
from .formats.mcap import read_recording
from .play import RemoteIdentifier, play
from .recover import recover

VERBS = ("info", "export", "import", "recover", "play")
TOP_LEVEL = ("-h", "--help", "--version")


def _csv_options(p) -> None:
    g = p.add_argument_group("CSV input")
    g.add_argument("--time", dest="time_col", help="column of times in seconds (found by itself when named t, time, "
                                                   "time_s or t_s)")
    g.add_argument("--fs", type=RATE_HZ, dest="fs_hz", help="sampling rate, when there is no time column")
    g.add_argument("--base", default="base", help="column of the base acceleration (default base)")
    g.add_argument("--tip1", default="tip1", help="column of tip 1 (default tip1)")
    g.add_argument("--tip2", default="tip2", help="column of tip 2 (default tip2)")


def _read_options(args) -> dict:
    """Reading options for the input's format: CSV/MAT columns and times (a recording's reader takes its own
    channels and refuses a time column or a rate: it carries its own times)."""
    return {"time_col": args.time_col, "fs_hz": args.fs_hz, "base": args.base, "tip1": args.tip1, "tip2": args.tip2}


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="replay", description="work with recordings of the shaker rig")
    sub = p.add_subparsers(dest="command", required=True, parser_class=OneLineParser)
    pl = sub.add_parser("play", help="play a recording or CSV through the live pipeline (the default verb)")
    pl.add_argument("file")
    pace = pl.add_mutually_exclusive_group()
    pace.add_argument("--rate", type=PLAY_RATE, default=1.0, help="playback speed, 1 = recorded time (default)")
    pace.add_argument("--max", action="store_true", help="as fast as possible")
    pl.add_argument("--start", type=OFFSET, default=0.0, help="start this many seconds into the data")
    pl.add_argument("--duration", type=DURATION, help="play this many seconds")
    pl.add_argument("--loop", action="store_true", help="start again at the end, until Ctrl-C")
    add_live_options(pl, "--events or --models, else in the current folder, never beside the input")
    pl.add_argument("--rrd", type=Path, help="with --viewer save: the .rrd to write")
    pl.add_argument("--models", type=Path, help="write each window's model (per beam) as JSON lines here")
    pl.add_argument("--force", action="store_true", help="replace existing output files")
    pl.add_argument("--one-process", action="store_true",
                    help="with --max: run the rolling identification in this process too (default: in a second "
                         "process beside the filters, the regime monitor and the outputs, where the machine has "
                         "two cores)")
    _csv_options(pl)
    pl.set_defaults(func=play_cmd)

    i = sub.add_parser("info", help="duration, rate, device, drops, damage, clock, events")
    i.add_argument("file")
    i.set_defaults(func=info_cmd)
    e = sub.add_parser("export", help="export the recorded samples as CSV, MAT, UFF 58 or TDMS")
    e.add_argument("file")
    out = e.add_mutually_exclusive_group(required=True)
    out.add_argument("--csv", type=Path, help="CSV to write: t,seq,base,tip1,tip2")
    out.add_argument("--mat", type=Path, help="MAT file to write: t, seq, base, tip1, tip2, Fs")
    out.add_argument("--uff", type=Path, help="UFF file to write: datasets 58 (time histories) base, tip1, tip2 in "
                                              "m/s^2, lost frames filled")
    out.add_argument("-o", "--output", type=Path, help="file to write, format by suffix (.csv, .mat, .uff, .unv, "
                                                       ".tdms)")
    e.add_argument("--force", action="store_true", help="replace an existing output")
    e.set_defaults(func=export_cmd)
    im = sub.add_parser("import", help="turn a CSV, MAT, UFF 58 or TDMS file from another DAQ into an MCAP "
                                       "recording")
    im.add_argument("file")
    im.add_argument("-o", "--output", type=Path, required=True)
    im.add_argument("--force", action="store_true", help="replace an existing output")
    _csv_options(im)
    im.set_defaults(func=import_cmd)
    r = sub.add_parser("recover", help="rebuild a readable MCAP file from a truncated or damaged one")
    r.add_argument("file", type=Path)
    r.add_argument("-o", "--output", type=Path, required=True)
    r.add_argument("--force", action="store_true", help="replace an existing output (never the input)")
    r.set_defaults(func=recover_cmd)
    return p


def default_rrd(args) -> Path:
    """Where ``--viewer save`` writes without ``--rrd``: beside an output (``--events``, ``--models``), else in
    the current folder; never beside the input (that would fill ``recordings/`` with views)."""
    name = Path(args.file).with_suffix(".rrd").name
    for out in (args.events, args.models):
        if out is not None:
            return Path(out).with_suffix(".rrd")
    return Path.cwd() / name


def play_cmd(args) -> int:
    check_live(args)
    mode = resolve_mode(args.viewer)
    rrd = (args.rrd or default_rrd(args)) if mode == "save" else None
    outputs = [Output("--events", args.events), Output("--models", args.models), Output("--viewer save", rrd)]
    outputs += [Output(o.label, part_path(o.path), replaceable=False) for o in list(outputs) if o.path is not None]
    check_outputs(outputs, [args.file], args.force)
    samples = formats.read_samples(args.file, **_read_options(args))
    events = JsonlEvents(args.events, force=args.force, inputs=[args.file]) if args.events else None
    models = (JsonlEvents(args.models, force=args.force, inputs=[args.file], label="--models")
              if args.models else None)
    try:
        viewer = RerunViewer(mode, rrd_path=rrd, fs_hz=samples.fs_hz, bind=args.bind, force=args.force,
                             inputs=[args.file])
    except BaseException:
        for sink in (events, models):
            if sink:
                sink.abort()
        raise
    counts: Counter = Counter()
    stopped = [False]

    def on_signal(signum, frame):
        stopped[0] = True

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, on_signal)

    def on_step(out):
        viewer.log_step(out)
        if models:
            for f in out.fits:
                for m in model_records(f):
                    models.write(m)
        for e in out.events:
            counts[e["kind"]] += 1
            if events:
                events.write(e)
            if e["kind"] in ("regime_start", "regime"):
                start = " (start)" if e["kind"] == "regime_start" else ""
                print(f"{e['t']:9.2f} s  regime {e['regime']}{start}", flush=True)
            elif e["kind"] == "regime_note":
                print(f"{e['t']:9.2f} s  note: {e['message']}", flush=True)

    remote = None
    try:
        # as fast as possible on two cores or more, the rolling identification works in a second process
        if args.max and not args.no_identify and not args.one_process and (os.cpu_count() or 1) >= 2:
            remote = RemoteIdentifier(rolling_config(samples.fs_hz, args.window, args.hop))
        compile_s = compile_kernels(identify=not args.no_identify)  # before the clock starts: no window waits
        if remote is not None:
            remote.ready()  # its kernels loaded (it started before ours compiled), before the clock too
        cpu0 = time.process_time()
        rep = play(samples, rate=None if args.max else args.rate, start_s=args.start, duration_s=args.duration,
                   loop=args.loop, identify=not args.no_identify, on_step=on_step, stop=lambda: stopped[0],
                   window_s=args.window, hop_s=args.hop, gaps=args.gaps, regime_window_s=args.regime_window,
                   identifier=remote)
    finally:
        if remote is not None:
            remote.close()
        viewer.close()
        if events:
            events.close()
        if models:
            models.close()
    speed = rep.stream_s / rep.wall_s if rep.wall_s > 0 else float("inf")
    filled = int(np.count_nonzero(samples.filled))
    cpu = time.process_time() - cpu0 + (remote.cpu_s if remote is not None else 0.0)
    print(f"played {rep.stream_s:.2f} s of data in {rep.wall_s:.2f} s ({speed:.1f} x real time; CPU {cpu:.2f} s, "
          f"{rep.stream_s / cpu if cpu > 0 else float('inf'):.1f} x"
          + ("; identification in a second process" if remote is not None else "") + "); events: "
          + (", ".join(f"{k} {v}" for k, v in sorted(counts.items())) or "none")
          + (f"; {filled} lost frame(s) filled by interpolation" if filled else "")
          + (f"; viewer saved to {rrd}" if mode == "save" else "")
          + (f"; kernels compiled in {compile_s:.1f} s before playing" if compile_s > 1.0 else ""))
    return 0


def _ranges(text: str) -> list[tuple[int, int]]:
    out = []
    for part in filter(None, text.split(",")):
        a, _, b = part.partition("-")
        if a.isdigit() and b.isdigit():
            out.append((int(a), int(b)))
    return out


def sequence_report(seq: np.ndarray, t_device: np.ndarray, lost_to_damage: list[tuple[int, int]]) -> dict:
    """Gaps in recorded sequence numbers: device drops, frames lost to file damage, device restarts."""
    step = np.diff(seq)
    back = (step <= 0) | (np.diff(t_device) < 0)
    gap = np.where(back, 0, step - 1)
    damage = np.zeros(gap.size, bool)
    for a, b in lost_to_damage:
        damage |= (seq[:-1] + 1 == a) & (seq[1:] - 1 == b)
    dev = (gap > 0) & ~damage
    return {"drops": int(gap[dev].sum()), "drop_gaps": int(dev.sum()), "damage": int(gap[damage].sum()),
            "damage_gaps": int(damage.sum()), "restarts": int(back.sum())}


def info_cmd(args) -> int:
    path = Path(args.file)
    if formats.format_of(path) is not formats.mcap:
        raise ValueError("info reads MCAP recordings; for a CSV, MAT, UFF or TDMS file, use replay import first")
    rec = read_recording(path, raw=False)
    print(f"file       {path}")
    print(f"samples    {len(rec.seq)}")
    if len(rec.seq) < 2:
        print("duration   - (fewer than two samples)")
        print("rate       - (fewer than two samples)")
    else:
        print(f"duration   {rec.duration_s:.3f} s")
        print(f"rate       {rec.rate_hz:.3f} Hz")
    how = "decoded from the serial bytes of " if rec.samples_topic == TOPICS["raw"] else ""
    print(f"channels   base, tip1, tip2 [m/s^2] ({how}{rec.samples_topic})")
    if rec.devices:
        d0, d1 = rec.devices[0], rec.devices[-1]
        sessions = len({d["session_id"] for d in rec.devices})
        print(f"device     {d0['device_id']}, firmware {d0['firmware']}, protocol {d0['protocol']}, "
              f"{d0['rate_hz']:g} Hz; {sessions} session(s) (last {d1['session_id']})")
    cal = rec.metadata.get("calibration", {})
    for c in ("base", "tip1", "tip2"):
        sensor = ", ".join(x for x in (cal.get(f"{c}.sensor_model", ""), cal.get(f"{c}.serial_number", "")
                                       and f"SN {cal[f'{c}.serial_number']}") if x)
        if sensor or f"{c}.sensitivity_counts_per_m_per_s2" in cal or f"{c}.sensitivity_mv_per_g" in cal:
            scale = float(cal.get(f"{c}.scale_m_per_s2_per_count", "nan"))
            print(f"sensor     {c}: {sensor or 'model not given'}; {scale:.6g} m/s^2 per count from "
                  f"{cal.get(f'{c}.scale_from', '?')}" + (f" ({cal[f'{c}.calibrated']})" if cal.get(f"{c}.calibrated")
                                                          else ""))
    recovery = rec.metadata.get("recovery", {})
    rep = sequence_report(rec.seq, rec.t_device, _ranges(recovery.get("lost_seq", "")))
    print(f"drops      {rep['drops']} frame(s) in {rep['drop_gaps']} gap(s) (lost by the device or the link)")
    if rec.status and rec.status[-1].get("duplicates"):
        print(f"duplicates {rec.status[-1]['duplicates']} frame(s) received twice, kept once")
    if rep["restarts"]:
        print(f"restarts   {rep['restarts']} device restart(s): sequence or device time went back")
    if recovery:
        damage = recovery.get("damage", "")
        print(f"damage     recovered from {recovery.get('source', '?')}: {len([d for d in damage.split(';') if d])} "
              f"damaged region(s); {rep['damage']} frame(s) lost with them in {rep['damage_gaps']} gap(s)")
    kinds = Counter(e.get("kind", "?") for e in rec.events)
    print("events     " + (", ".join(f"{k} {v}" for k, v in sorted(kinds.items())) or "none"))
    if rec.status:
        st = rec.status[-1]
        errors = (f"{st['malformed_lines']} malformed lines" if "malformed_lines" in st
                  else f"{st.get('crc_errors', 0)} CRC errors")
        print(f"link       {errors}, {st.get('reconnects', 0)} reconnects")
        print("clock      " + _clock_text(st))
    return 0


def _clock_text(st: dict) -> str:
    ratio = st.get("device_rate_ratio")
    drift = st.get("clock_drift_ppm")
    if ratio is None and drift is not None:  # recordings before the ratio was kept
        ratio = 1.0 + drift * 1e-6
    if ratio is None or not np.isfinite(ratio):
        return "drift - (too few reads to estimate)"
    if abs(ratio - 1.0) > 0.05:
        return (f"drift - (not a real-time source: the device's clock ran {1 / ratio:.1f} x the host's, "
                f"e.g. rig:// without realtime=1)")
    return f"drift {(ratio - 1.0) * 1e6:+.1f} ppm (host seconds per device second, minus 1)"


def export_cmd(args) -> int:
    out, label = next((p, lab) for p, lab in ((args.csv, "--csv"), (args.mat, "--mat"), (args.uff, "--uff"),
                                               (args.output, "-o")) if p is not None)
    module = formats.format_of(out)
    if module is formats.mcap:
        raise ValueError(f"{label} {out}: export writes CSV, MAT, UFF or TDMS; the input already is a recording")
    if label == "--uff" and module is not formats.uff:
        raise ValueError(f"--uff {out}: give a file name ending in .uff or .unv")
    check_outputs([Output(label, out)], [args.file], args.force)
    samples = formats.read_samples(args.file, fill=False)
    module.write_samples(out, samples, force=args.force, inputs=[args.file], label=label)
    rows = int(np.count_nonzero(~samples.filled))
    if module in (formats.uff, formats.tdms):  # even time histories: the lost frames are filled
        n = int(round((samples.t[-1] - samples.t[0]) * samples.fs_hz)) + 1 if len(samples.t) else 0
        print(f"{out}: base, tip1, tip2 in m/s^2, {n} samples at {samples.fs_hz:.6g} Hz ({n - rows} lost frame(s) "
              f"filled by linear interpolation)")
    else:
        print(f"{out}: {rows} rows (t in s from the first sample, accelerations in m/s^2)")
    return 0


def import_cmd(args) -> int:
    if formats.format_of(args.output) is not formats.mcap:
        raise ValueError(f"-o {args.output}: import writes an MCAP recording (.mcap)")
    check_outputs([Output("-o", args.output), Output("-o", part_path(args.output), replaceable=False)],
                  [args.file], args.force)
    s = formats.read_samples(args.file, **_read_options(args))
    formats.mcap.write_samples(args.output, s, force=args.force, inputs=[args.file],
                               source=f"imported from {args.file}")
    print(f"{args.output}: {len(s.t) - int(np.count_nonzero(s.filled))} samples at {s.fs_hz:.6g} Hz imported "
          f"from {args.file}")
    return 0


def recover_cmd(args) -> int:
    rep = recover(args.file, args.output, force=args.force)
    if rep.complete:
        state = "the input was whole"
    else:
        state = f"{len(rep.damage)} damaged region(s) skipped" if rep.damage else "the input was cut short"
        if rep.damage:
            state += " (" + "; ".join(d.describe() for d in rep.damage[:3]) + ("; ..." if len(rep.damage) > 3 else "") + ")"
    topics = ", ".join(f"{k}: {v}" for k, v in sorted(rep.messages.items()))
    lost = (f"; frames lost with the damage: {sum(b - a + 1 for a, b in rep.lost_seq)}"
            if rep.lost_seq else "")
    print(f"{args.output}: {rep.total_messages} messages recovered from {rep.chunks} intact chunks; {state}; "
          f"{topics}{lost}")
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] not in VERBS and argv[0] not in TOP_LEVEL:
        argv.insert(0, "play")  # replay [OPTIONS] FILE [OPTIONS] means replay play ...
    args = build_parser().parse_args(argv)
    return run_guarded(f"replay {args.command}", args.func, args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
