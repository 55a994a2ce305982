"""``replay``: play recordings through the live pipeline; info, export, import, recover.

    replay FILE [--rate X | --max] [--start S] [--duration D] [--loop] [--viewer MODE] [--events OUT.jsonl]
    replay info FILE
    replay export FILE --csv OUT
    replay import IN.csv -o OUT.mcap [--time COL | --fs HZ] [--base COL] [--tip1 COL] [--tip2 COL]
    replay recover BROKEN -o FIXED
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

from daq.cli import add_live_options
from ident.cli import OneLineParser, run_guarded

VERBS = ("info", "export", "import", "recover", "play")


def _csv_options(p) -> None:
    g = p.add_argument_group("CSV input")
    g.add_argument("--time", dest="time_col", help="column of times in seconds")
    g.add_argument("--fs", type=float, dest="fs_hz", help="sampling rate, when there is no time column")
    g.add_argument("--base", default="base", help="column of the base acceleration (default base)")
    g.add_argument("--tip1", default="tip1", help="column of tip 1 (default tip1)")
    g.add_argument("--tip2", default="tip2", help="column of tip 2 (default tip2)")


def _csv_kw(args) -> dict:
    if Path(args.file).suffix.lower() != ".csv":
        return {}
    return {"time_col": args.time_col, "fs_hz": args.fs_hz, "base": args.base, "tip1": args.tip1,
            "tip2": args.tip2}


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="replay", description="work with recordings of the shaker rig")
    sub = p.add_subparsers(dest="command", required=True, parser_class=OneLineParser)
    pl = sub.add_parser("play", help="play a recording or CSV through the live pipeline (the default verb)")
    pl.add_argument("file")
    pace = pl.add_mutually_exclusive_group()
    pace.add_argument("--rate", type=float, default=1.0, help="playback speed, 1 = recorded time (default)")
    pace.add_argument("--max", action="store_true", help="as fast as possible")
    pl.add_argument("--start", type=float, default=0.0, help="start this many seconds into the data")
    pl.add_argument("--duration", type=float, help="play this many seconds")
    pl.add_argument("--loop", action="store_true", help="start again at the end, until Ctrl-C")
    add_live_options(pl, "the input")
    pl.add_argument("--rrd", type=Path, help="with --viewer save: the .rrd to write")
    pl.add_argument("--models", type=Path, help="write each window's model (per beam) as JSON lines here")
    _csv_options(pl)
    pl.set_defaults(func=play_cmd)

    i = sub.add_parser("info", help="duration, rate, channels, drops, events")
    i.add_argument("file")
    i.set_defaults(func=info_cmd)
    e = sub.add_parser("export", help="export samples as CSV")
    e.add_argument("file")
    e.add_argument("--csv", type=Path, required=True)
    e.set_defaults(func=export_cmd)
    im = sub.add_parser("import", help="turn a CSV from another DAQ into an MCAP recording")
    im.add_argument("file")
    im.add_argument("-o", "--output", type=Path, required=True)
    _csv_options(im)
    im.set_defaults(func=import_cmd)
    r = sub.add_parser("recover", help="rebuild a readable MCAP file from a truncated one")
    r.add_argument("broken", type=Path)
    r.add_argument("-o", "--output", type=Path, required=True)
    r.set_defaults(func=recover_cmd)
    return p


def play_cmd(args) -> int:
    from daq.cli import compile_kernels
    from daq.eventlog import JsonlEvents
    from ident.live.pipeline import model_records, parse_gaps
    from daq.viewer import RerunViewer

    from .play import play
    from .sources import open_samples

    samples = open_samples(args.file, **_csv_kw(args))
    rrd = args.rrd or Path(args.file).with_suffix(".rrd")
    viewer = RerunViewer(args.viewer, rrd_path=rrd, fs_hz=samples.fs_hz)
    events = JsonlEvents(args.events) if args.events else None
    models = JsonlEvents(args.models) if args.models else None
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
            if e["kind"] == "regime":
                print(f"{e['t']:9.2f} s  regime {e['regime']}", flush=True)

    compile_s = 0.0 if args.no_identify else compile_kernels()  # before the clock starts: no window waits for it
    cpu0 = time.process_time()
    try:
        rep = play(samples, rate=None if args.max else args.rate, start_s=args.start, duration_s=args.duration,
                   loop=args.loop, identify=not args.no_identify, on_step=on_step, stop=lambda: stopped[0],
                   window_s=args.window, hop_s=args.hop, gaps=parse_gaps(args.gaps))
    finally:
        viewer.close()
        if events:
            events.close()
        if models:
            models.close()
    speed = rep.stream_s / rep.wall_s if rep.wall_s > 0 else float("inf")
    cpu = time.process_time() - cpu0
    print(f"played {rep.stream_s:.2f} s of data in {rep.wall_s:.2f} s ({speed:.1f} x real time; CPU {cpu:.2f} s, "
          f"{rep.stream_s / cpu if cpu > 0 else float('inf'):.1f} x); events: "
          + (", ".join(f"{k} {v}" for k, v in sorted(counts.items())) or "none")
          + (f"; viewer saved to {rrd}" if args.viewer == "save" else "")
          + (f"; kernels compiled in {compile_s:.1f} s before playing" if compile_s > 1.0 else ""))
    return 0


def info_cmd(args) -> int:
    path = Path(args.file)
    if path.suffix.lower() == ".csv":
        raise ValueError("info reads MCAP recordings; for a CSV, use replay import first")
    from .reader import read_recording

    rec = read_recording(path, raw=False)
    gaps = np.diff(rec.seq)
    lost = int(np.sum(gaps[gaps > 1] - 1)) if len(gaps) else 0
    kinds = Counter(e.get("kind", "?") for e in rec.events)
    print(f"file       {path}")
    print(f"samples    {len(rec.seq)}")
    print(f"duration   {rec.duration_s:.3f} s")
    print(f"rate       {rec.rate_hz:.3f} Hz")
    print("channels   base, tip1, tip2 [m/s^2] (/rig/accel)")
    print(f"drops      {lost} frame(s) in {int(np.count_nonzero(gaps > 1))} gap(s)")
    print("events     " + (", ".join(f"{k} {v}" for k, v in sorted(kinds.items())) or "none"))
    if rec.status:
        st = rec.status[-1]
        print(f"link       {st.get('crc_errors', 0)} CRC errors, {st.get('reconnects', 0)} reconnects, clock drift "
              f"{st.get('clock_drift_ppm')} ppm")
    return 0


def export_cmd(args) -> int:
    from .reader import read_recording

    rec = read_recording(args.file, raw=False)
    args.csv.parent.mkdir(parents=True, exist_ok=True)
    t = rec.t_device - (rec.t_device[0] if len(rec.t_device) else 0.0)
    data = np.column_stack([t, rec.seq, rec.values])
    np.savetxt(args.csv, data, delimiter=",", header="t,seq,base,tip1,tip2", comments="",
               fmt=["%.6f", "%d", "%.6g", "%.6g", "%.6g"])
    print(f"{args.csv}: {len(rec.seq)} rows (t in s from the first sample, accelerations in m/s^2)")
    return 0


def import_cmd(args) -> int:
    from daq.config import Config, DaqConfig
    from daq.driver import SampleBlock
    from daq.recorder import McapRecorder
    from daq.sim.rig import RigConfig

    from .sources import read_csv

    s = read_csv(args.file, time_col=args.time_col, fs_hz=args.fs_hz, base=args.base, tip1=args.tip1,
                 tip2=args.tip2)
    cfg = Config(RigConfig(), DaqConfig(rate_hz=s.fs_hz), source=f"imported from {args.file}")
    rec = McapRecorder(args.output, cfg, port=f"import:{args.file}", flush_s=3600.0, accel_json=True)  # no raw bytes
    n = len(s.t)
    now = time.time_ns()
    for k in range(0, n, 2000):
        e = min(n, k + 2000)
        rec.write_block(SampleBlock(np.arange(k, e, dtype=np.uint32), s.t[k:e], s.values[k:e],
                                    np.zeros((e - k, 3), np.int16), np.zeros(e - k, bool), now, 0.0))
    rec.close()
    print(f"{args.output}: {n} samples at {s.fs_hz:.6g} Hz imported from {args.file}")
    return 0


def recover_cmd(args) -> int:
    from .recover import recover

    rep = recover(args.broken, args.output)
    state = "complete file" if rep.complete else f"truncated input ({rep.stopped_at or 'no footer'})"
    topics = ", ".join(f"{k}: {v}" for k, v in sorted(rep.messages.items()))
    print(f"{args.output}: {rep.total_messages} messages recovered from {rep.chunks} chunks; {state}; {topics}")
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] not in VERBS and not argv[0].startswith("-"):
        argv.insert(0, "play")  # replay FILE ... means replay play FILE ...
    args = build_parser().parse_args(argv)
    return run_guarded(f"replay {args.command}", args.func, args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
