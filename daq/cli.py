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
    r.add_argument("--accel-json", action="store_true",
                   help="also one JSON message per sample on /rig/accel, plottable as is in Foxglove and "
                        "PlotJuggler (about 55 instead of 14 bytes per sample; the serial bytes are kept either way)")
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
    p.add_argument("--gaps", metavar="G1,G2", help="the tips' stopper gaps [m] for the regime monitor "
                   "(default: learned from the data)")


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
    rec = McapRecorder(out, cfg, port=port, accel_json=args.accel_json)
    acq = Acquisition(port, cfg)
    last_status = [time.monotonic()]
    live = None if args.no_identify else LiveProcessing(cfg.daq.rate_hz, args.viewer, out.with_suffix(".rrd"),
                                                         args.events, args.window, args.hop, args.gaps)

    def on_block(b):
        rec.write_block(b)
        if live is not None:
            live.submit(b)
            live.write_to(rec)
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
            live.write_to(rec)
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


class LiveProcessing:
    """The pipeline beside acquisition, in a worker thread, so a slow model fit never stalls the port.

    Blocks go in through a queue; pipeline events come back through another and
    are written by the acquisition thread (the recorder is not shared across
    threads). Latency: from a block's arrival to the model update that includes it.
    """

    def __init__(self, fs_hz: float, viewer_mode: str, rrd_path: Path, events_path: Path | None,
                 window_s: float = 4.0, hop_s: float = 1.0, gaps: str | None = None):
        import collections
        import queue

        from ident.live.pipeline import Pipeline, PipelineConfig, parse_gaps, rolling_config
        from ident.live.regimes import RegimeConfig

        from .eventlog import JsonlEvents
        from .viewer import RerunViewer

        self.pipe = Pipeline(PipelineConfig(fs_hz=fs_hz, rolling=rolling_config(fs_hz, window_s, hop_s),
                                            regime=RegimeConfig(fs_hz=fs_hz, gap_m=parse_gaps(gaps))))
        self.compile_s = compile_kernels()
        self.fs_hz = fs_hz
        self.viewer = RerunViewer(viewer_mode, rrd_path=rrd_path, fs_hz=fs_hz)
        self.jsonl = JsonlEvents(events_path) if events_path else None
        self.inq: queue.Queue = queue.Queue()
        self.outq: queue.Queue = queue.Queue()
        self.latencies: list[float] = []
        self.regimes: list[str] = []
        self.busy_s = 0.0
        self.error: str | None = None
        # device times of the samples submitted (the last ones, enough to reach back over a window):
        # pipeline times count samples, the recording's log times are device times
        self._submitted = 0
        self._device_t: collections.deque = collections.deque()
        self._keep = int((window_s + 2 * hop_s + 5.0) * fs_hz)
        self.thread = threading.Thread(target=self._work, daemon=True)
        self.thread.start()

    def submit(self, block) -> None:
        self._device_t.append((self._submitted, block.t_device_s))
        self._submitted += len(block)
        while self._device_t and self._device_t[0][0] + len(self._device_t[0][1]) < self._submitted - self._keep:
            self._device_t.popleft()
        self.inq.put((time.monotonic(), block.values))

    def device_time_s(self, t_stream_s: float) -> float | None:
        """The device time of the last sample before stream time t (samples counted from the start)."""
        k = int(round(t_stream_s * self.fs_hz)) - 1
        for start, t_dev in reversed(self._device_t):
            if start <= k < start + len(t_dev):
                return float(t_dev[k - start])
        return None

    def _work(self) -> None:
        last_window = -1.0
        while True:
            item = self.inq.get()
            if item is None:
                self._handle(self.pipe.finish())  # the last window's refined fit
                return
            arrived, values = item
            t0 = time.monotonic()
            out = self._handle(self.pipe.step, values)
            if out is None:
                continue
            done = time.monotonic()
            self.busy_s += done - t0
            if out.fits and out.fits[-1].t_s > last_window:  # a window's first model update (refits follow)
                last_window = out.fits[-1].t_s
                self.latencies.append(done - arrived)

    def _handle(self, step, *args):
        """Run a pipeline step (or take its output), show it, queue its models and events for the recorder."""
        from ident.live.pipeline import model_records

        from .driver import Event

        try:
            out = step(*args) if args else step
            self.viewer.log_step(out)
        except Exception as exc:  # noqa: BLE001 - processing must never stop the recording
            if self.error is None:
                self.error = f"{type(exc).__name__}: {exc}"
                self.outq.put(Event(0.0, "error", f"live processing stopped: {self.error}", "error"))
            return None
        for f in out.fits:
            self.outq.put(("model", f.t_s, model_records(f)))
        for e in out.events:
            if self.jsonl:
                self.jsonl.write(e)
            if e["kind"] == "regime":
                self.regimes.append(e["regime"])
            msg = (f"regime {e['regime']} (was {e['previous']})" if e["kind"] == "regime"
                   else f"beam {e.get('beam')} model changed: " + "; ".join(e.get("equations", [])))
            data = {k: v for k, v in e.items() if k not in ("t", "kind")}
            self.outq.put(Event(e["t"], e["kind"], msg, "info", data))
        return out

    def write_to(self, rec) -> None:
        """Write the events and per-window models produced since the last call to the recorder, stamped
        with the data time they describe (log_time; publish_time is now)."""
        while not self.outq.empty():
            item = self.outq.get_nowait()
            if isinstance(item, tuple) and item[0] == "model":
                t_dev = self.device_time_s(item[1])
                log_ns = rec.log_time_ns(t_dev) if t_dev is not None else None
                for m in item[2]:
                    rec.write_model(m, log_ns=log_ns)
            elif item.kind in ("regime", "model"):
                t_dev = self.device_time_s(item.t)
                rec.write_event(item, log_ns=rec.log_time_ns(t_dev) if t_dev is not None else None)
            else:
                rec.write_event(item)

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
                + (f"; kernels compiled in {self.compile_s:.1f} s before the first sample" if self.compile_s > 1.0
                   else "") + (f"; ERROR {self.error}" if self.error else ""))


def compile_kernels() -> float:
    """Compile the identification's numba kernels before data flows, so that no window waits for the
    compiler: from numba's disk cache this takes a moment; the first run after an install compiles for
    some seconds and says so on a terminal while it does. Seconds taken."""
    from ident.live.pipeline import warm_up
    from ident.simulate import kernels_cached

    cold = kernels_cached() is False
    tell = cold and sys.stderr.isatty()
    if tell:
        print("compiling the identification kernels before the first sample (first run after an install; "
              "numba caches them, so later runs start at once)...", end="", file=sys.stderr, flush=True)
    t0 = time.monotonic()
    warm_up()
    took = time.monotonic() - t0
    if tell:
        print(f" compiled in {took:.1f} s", file=sys.stderr, flush=True)
    return took


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return run_guarded(f"daq {args.command}", args.func, args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
