"""``daq``: record the rig (or its simulation) to MCAP; serve the simulated rig on a pty."""

from __future__ import annotations

import argparse
import signal
import sys
import tempfile
import threading
import time
from pathlib import Path

from ident.cli import OneLineParser, run_guarded

from .config import load_config


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="daq", description="shaker-rig acquisition: serial frames to MCAP")
    sub = p.add_subparsers(dest="command", required=True, parser_class=OneLineParser)
    r = sub.add_parser("record", help="record the rig (default: the simulated rig) to an MCAP file")
    src = r.add_mutually_exclusive_group()
    src.add_argument("--port", help="serial device path or pyserial URL (rig://, loop://, ...)")
    src.add_argument("--sim", action="store_true", help="record the simulated rig over a pty (the default)")
    r.add_argument("--config", type=Path, help="rig and daq config (YAML); defaults if omitted")
    r.add_argument("-o", "--output", type=Path, help="MCAP file to write (default rig-YYYYmmdd-HHMMSS.mcap)")
    r.add_argument("--duration", type=float, help="stop after this many seconds of samples")
    r.add_argument("--quiet", action="store_true", help="no live status line")
    add_live_options(r, "the recording")
    r.set_defaults(func=record)
    s = sub.add_parser("sim", help="serve the simulated rig on a pty and print its path")
    s.add_argument("--config", type=Path, help="rig and daq config (YAML)")
    s.add_argument("--link", type=Path, help="also make this symlink point at the pty (kept across reconnects)")
    s.add_argument("--duration", type=float, help="stop after this many seconds")
    s.add_argument("--seed", type=int, help="noise seed (default from the config)")
    s.set_defaults(func=sim)
    from . import bench

    bench.add_parser(sub)
    return p


def add_live_options(p, beside: str) -> None:
    """The live pipeline's options, shared by ``daq record`` and ``replay``."""
    p.add_argument("--viewer", choices=("auto", "spawn", "web", "save", "none"), default="auto",
                   help=f"rerun viewer: spawn, web, save (an .rrd next to {beside}), none; auto (default): "
                        "spawn or web in an interactive terminal, none otherwise")
    p.add_argument("--events", type=Path, help="write events as JSON lines here")
    p.add_argument("--no-identify", action="store_true", help="no rolling SINDy (filters and regimes only)")
    p.add_argument("--window", type=float, default=4.0, help="rolling SINDy window [s] (default 4)")
    p.add_argument("--hop", type=float, default=1.0, help="rolling SINDy hop [s] (default 1)")


def _check_duration(d: float | None) -> None:
    if d is not None and not (d > 0):
        raise ValueError(f"--duration must be a positive number of seconds, got {d}")


def sim(args) -> int:
    from .transport import PtyServer

    _check_duration(args.duration)
    cfg = load_config(args.config)
    server = PtyServer(cfg, args.link, args.seed)
    print(f"simulated rig on {server.path}" + (f" (link {args.link})" if args.link else ""), flush=True)
    _on_signals(server.stop)
    server.serve(args.duration)
    return 0


def _on_signals(stop) -> None:
    def handler(signum, frame):
        stop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, handler)


def record(args) -> int:
    from .driver import Acquisition
    from .recorder import McapRecorder
    from .transport import PtyServer

    _check_duration(args.duration)
    cfg = load_config(args.config)
    out = args.output or Path(time.strftime("rig-%Y%m%d-%H%M%S.mcap"))
    if out.exists() and out.is_dir():
        raise ValueError(f"-o {out} is a folder; give a file name ending in .mcap")
    server = thread = None
    tmp = None
    go = threading.Event()
    if args.port:
        port = args.port
    else:
        tmp = tempfile.TemporaryDirectory(prefix="daq-sim-")
        server = PtyServer(cfg, Path(tmp.name) / "rig")
        port = str(server.link)
        extra = None if args.duration is None else args.duration + 1.0
        thread = threading.Thread(target=server.serve, args=(extra, go), daemon=True)
        thread.start()
    rec = McapRecorder(out, cfg, port=port)
    acq = Acquisition(port, cfg)
    last_status = [time.monotonic()]
    live = None if args.no_identify else LiveProcessing(cfg.daq.rate_hz, args.viewer, out.with_suffix(".rrd"),
                                                         args.events, args.window, args.hop)

    def on_block(b):
        rec.write_block(b)
        if live is not None:
            live.submit(b)
            events, models = live.drain()
            for e in events:
                rec.write_event(e)
            for m in models:
                rec.write_model(m)
        now = time.monotonic()
        if now - last_status[0] >= 1.0:
            last_status[0] = now
            st = acq.status()
            rec.write_status(st)
            if not args.quiet:
                print(f"\r{st['samples']:9d} samples  {st['dropped_frames']} dropped  {st['crc_errors']} crc  "
                      f"{st['reconnects']} reconnects", end="", file=sys.stderr, flush=True)

    def on_event(e):
        rec.write_event(e)
        if live is not None:
            live.log_event(e)

    acq.on_block = on_block
    acq.on_raw = rec.write_raw
    acq.on_event = on_event
    _on_signals(acq.stop)
    try:
        acq.run(args.duration, opened=go)
    finally:
        if live is not None:
            live.close()
            events, models = live.drain()
            for e in events:
                rec.write_event(e)
            for m in models:
                rec.write_model(m)
        rec.write_status(acq.status())
        rec.close()
        if server is not None:
            server.stop()
            thread.join(timeout=5)
        if tmp is not None:
            tmp.cleanup()
    st = acq.status()
    size = out.stat().st_size
    if not args.quiet:
        print(file=sys.stderr)
    per = size / st["samples"] if st["samples"] else float("nan")
    print(f"{out}: {st['samples']} samples, {st['dropped_frames']} dropped, {st['crc_errors']} CRC errors, "
          f"{st['reconnects']} reconnects, {size} bytes ({per:.1f} bytes per 3-channel sample)")
    if live is not None:
        print(live.summary())
    return 0


def model_records(fit) -> list[dict]:
    """One record per beam of a rolling-window fit: the model as a time series entry."""
    return [{"t": fit.t_s, "beam": i + 1, "equations": b.model.equations(), "coefficients": b.model.as_dict(),
             "active": list(b.active), "integration_nrmse": b.error, "natural_frequency_hz": b.natural_frequency_hz,
             "stiffness_per_mass": b.stiffness_per_mass, "changed": b.changed} for i, b in enumerate(fit.beams)]


class LiveProcessing:
    """The pipeline beside acquisition, in a worker thread, so a slow model fit never stalls the port.

    Blocks go in through a queue; pipeline events come back through another and
    are written by the acquisition thread (the recorder is not shared across
    threads). Latency: from a block's arrival to the model update that includes it.
    """

    def __init__(self, fs_hz: float, viewer_mode: str, rrd_path: Path, events_path: Path | None,
                 window_s: float = 4.0, hop_s: float = 1.0):
        import queue

        from ident.live.pipeline import Pipeline, PipelineConfig, rolling_config

        from .eventlog import JsonlEvents
        from .viewer import RerunViewer

        self.pipe = Pipeline(PipelineConfig(fs_hz=fs_hz, rolling=rolling_config(fs_hz, window_s, hop_s)))
        self.viewer = RerunViewer(viewer_mode, rrd_path=rrd_path, fs_hz=fs_hz)
        self.jsonl = JsonlEvents(events_path) if events_path else None
        self.inq: queue.Queue = queue.Queue()
        self.outq: queue.Queue = queue.Queue()
        self.latencies: list[float] = []
        self.regimes: list[str] = []
        self.busy_s = 0.0
        self.error: str | None = None
        self.thread = threading.Thread(target=self._work, daemon=True)
        self.thread.start()

    def submit(self, block) -> None:
        self.inq.put((time.monotonic(), block.values))

    def _work(self) -> None:
        from .driver import Event

        while True:
            item = self.inq.get()
            if item is None:
                return
            arrived, values = item
            t0 = time.monotonic()
            try:
                out = self.pipe.step(values)
                self.viewer.log_step(out)
            except Exception as exc:  # noqa: BLE001 - processing must never stop the recording
                if self.error is None:
                    self.error = f"{type(exc).__name__}: {exc}"
                    self.outq.put(Event(0.0, "error", f"live processing stopped: {self.error}", "error"))
                continue
            done = time.monotonic()
            self.busy_s += done - t0
            if out.fits:
                self.latencies.append(done - arrived)
            for f in out.fits:
                self.outq.put(("model", model_records(f)))
            for e in out.events:
                if self.jsonl:
                    self.jsonl.write(e)
                if e["kind"] == "regime":
                    self.regimes.append(e["regime"])
                msg = (f"regime {e['regime']} (was {e['previous']})" if e["kind"] == "regime"
                       else f"beam {e.get('beam')} model changed: " + "; ".join(e.get("equations", [])))
                data = {k: v for k, v in e.items() if k not in ("t", "kind")}
                self.outq.put(Event(e["t"], e["kind"], msg, "info", data))

    def drain(self) -> tuple[list, list]:
        """(events, per-window model records) produced since the last call."""
        events, models = [], []
        while not self.outq.empty():
            item = self.outq.get_nowait()
            if isinstance(item, tuple) and item[0] == "model":
                models += item[1]
            else:
                events.append(item)
        return events, models

    def log_event(self, e) -> None:
        if self.jsonl:
            self.jsonl.write({"t": e.t, "kind": e.kind, "message": e.message, **e.data})

    def close(self) -> None:
        self.inq.put(None)
        self.thread.join(timeout=60)
        self.viewer.close()
        if self.jsonl:
            self.jsonl.close()

    def summary(self) -> str:
        import numpy as np

        lat = np.array(self.latencies)
        p = (f"latency sample -> model update p50 {1e3 * np.percentile(lat, 50):.0f} ms, "
             f"p95 {1e3 * np.percentile(lat, 95):.0f} ms" if lat.size else "no model update")
        return (f"live: {len(self.latencies)} model updates, {len(self.regimes)} regime changes, {p}"
                + (f"; ERROR {self.error}" if self.error else ""))


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return run_guarded(f"daq {args.command}", args.func, args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
