"""``daq``: record the rig (or its simulation) to MCAP; serve the simulated rig on a pty.

Order of every writing command (README "What is safe"): check the arguments, read the config, check
every output against the inputs and each other (daq.safeio), open the port; only then create the
files, as ``NAME.part`` renamed to ``NAME`` when the recording ends.
"""

from __future__ import annotations

import argparse
import collections
import queue
import signal
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from ident.cli import DURATION, REGIME_WINDOW, SEED, WINDOW, OneLineParser, number, run_guarded
from ident.live.pipeline import (Pipeline, PipelineConfig, check_window, kernels_cached, model_records, parse_gaps,
                                 rolling_config, warm_up)
from ident.live.regimes import MIN_PERIODS, RegimeConfig

from . import bench, calibrate
from .config import Config, load_config
from .driver import Acquisition, Event
from .eventlog import JsonlEvents
from .recorder import McapRecorder
from .safeio import Output, check_outputs, part_path
from .sim.device import DEFAULT_DEVICE_ID
from .transport import PtyServer, check_link
from .viewer import DEFAULT_BIND, RerunViewer, resolve_mode


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="daq", description="shaker-rig acquisition: serial frames to MCAP")
    sub = p.add_subparsers(dest="command", required=True, parser_class=OneLineParser)
    r = sub.add_parser("record", help="record the rig (default: the simulated rig) to an MCAP file")
    src = r.add_mutually_exclusive_group()
    src.add_argument("--port", help="serial device path (a /dev/serial/by-id/ path is best) or pyserial URL "
                                    "(rig://, loop://, ...)")
    src.add_argument("--sim", action="store_true", help="record the simulated rig over a pty (the default)")
    r.add_argument("--config", type=Path, help="rig and daq config (YAML); defaults if omitted")
    r.add_argument("-o", "--output", type=Path, help="MCAP file to write (default rig-YYYYmmdd-HHMMSS.mcap); "
                                                     "written as NAME.part until the recording ends")
    r.add_argument("--duration", type=DURATION, help="stop after this many seconds of samples")
    r.add_argument("--quiet", action="store_true", help="no live status line")
    r.add_argument("--force", action="store_true", help="replace existing output files")
    r.add_argument("--accel-json", action="store_true",
                   help="also one JSON message per sample on /rig/accel, plottable as is in Foxglove and "
                        "PlotJuggler (about 44 bytes per sample more than the 21 of the compact recording; the serial "
                        "bytes are kept either way; always so with --format lines)")
    add_link_options(r)
    add_live_options(r, "the recording")
    r.set_defaults(func=record)
    s = sub.add_parser("sim", help="serve the simulated rig on a pty and print its path")
    s.add_argument("--config", type=Path, help="rig and daq config (YAML)")
    s.add_argument("--link", type=Path, help="also make this symlink point at the pty (removed while the simulated "
                                             "cable is pulled, like /dev/serial/by-id)")
    s.add_argument("--duration", type=DURATION, help="stop after this many seconds")
    s.add_argument("--seed", type=SEED, help="noise seed (default from the config)")
    s.add_argument("--device-id", type=number(0, 2**32 - 1, integer=True), default=DEFAULT_DEVICE_ID,
                   help=f"the unit's id in its status frames (default {DEFAULT_DEVICE_ID:#x})")
    s.add_argument("--force", action="store_true", help="replace a --link symlink that points at something "
                                                        "other than a pty (the link, never a file)")
    s.add_argument("--format", choices=("frames", "lines"), help="send binary frames (default) or text lines")
    s.set_defaults(func=sim)
    bench.add_parser(sub)
    calibrate.add_parser(sub, add_link_options)
    return p


def add_link_options(p) -> None:
    """What the device sends and how fast the line runs (override the config's daq.format and daq.baudrate)."""
    p.add_argument("--format", choices=("frames", "lines"),
                   help="frames: binary frames v1 (the reference firmware, the simulated rig; the default); lines: "
                        "one sample per text line, read as the config's daq.lines says")
    p.add_argument("--baud", type=number(9600, 100_000_000, integer=True),
                   help="baud rate of a UART link (default: the config's daq.baudrate, 921600); USB devices such "
                        "as a Teensy ignore it")


def link_config(args) -> Config:
    """The config with --format and --baud applied (what is recorded as the resolved config)."""
    return load_config(args.config).with_link(getattr(args, "format", None), getattr(args, "baud", None))


def add_live_options(p, beside: str) -> None:
    """The live pipeline's options, shared by ``daq record`` and ``replay``."""
    p.add_argument("--viewer", choices=("auto", "spawn", "web", "save", "none"), default="auto",
                   help=f"rerun viewer: spawn, web, save (an .rrd next to {beside}), none; auto (default): "
                        "spawn or web in an interactive terminal, none otherwise")
    p.add_argument("--bind", default=DEFAULT_BIND,
                   help=f"address the viewer's servers listen on (default {DEFAULT_BIND}: this machine only; "
                        "0.0.0.0 opens the live data to the network without authentication)")
    p.add_argument("--events", type=Path, help="write events as JSON lines here")
    p.add_argument("--no-identify", action="store_true", help="no rolling SINDy (filters and regimes only)")
    p.add_argument("--window", type=WINDOW, default=4.0, help="rolling SINDy window [s] (default 4)")
    p.add_argument("--hop", type=WINDOW, default=1.0, help="rolling SINDy hop [s] (default 1)")
    p.add_argument("--gaps", metavar="G1,G2", type=_gaps, help="the tips' stopper gaps [m] for the regime monitor "
                   "(default: learned from the data)")
    p.add_argument("--regime-window", type=REGIME_WINDOW, default=RegimeConfig.window_s,
                   help=f"the regime monitor's window [s] (default {RegimeConfig.window_s:g}); it must hold "
                        f"{MIN_PERIODS:g} periods of the drive: 2 s for a rig driven at 2 Hz")


def _gaps(text: str) -> tuple[float, float]:
    """argparse type of --gaps G1,G2."""
    try:
        return parse_gaps(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("--gaps ")) from None


def check_live(args) -> None:
    """The live options, before any output is made (a refused run leaves no file behind)."""
    check_window(args.window, args.hop)


def sim(args) -> int:
    cfg = link_config(args)
    if args.link is not None:
        check_outputs([Output("--link", args.link)], [args.config], force=True)  # a folder or the config itself
        check_link(args.link, args.force)
    server = PtyServer(cfg, args.link, args.seed, args.device_id, force_link=args.force)
    print(f"simulated rig on {server.path}" + (f" (link {args.link})" if args.link else ""), flush=True)
    _on_signals(server.stop)
    server.serve(args.duration)
    return 0


def _on_signals(stop) -> None:
    def handler(signum, frame):
        stop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, handler)


def _port_input(port: str | None) -> Path | None:
    """A port that names a file is also an input: no output may be it."""
    return Path(port) if port and "://" not in port else None


def record(args) -> int:
    check_live(args)
    cfg = link_config(args)
    out = args.output or Path(time.strftime("rig-%Y%m%d-%H%M%S.mcap"))
    mode = resolve_mode(args.viewer)
    rrd = out.with_suffix(".rrd") if mode == "save" else None
    inputs = [args.config, _port_input(args.port)]
    outputs = [Output("-o", out), Output("-o", part_path(out), replaceable=False), Output("--events", args.events),
               Output("--viewer save", rrd)]
    outputs += [Output(o.label, part_path(o.path), replaceable=False) for o in outputs[2:] if o.path is not None]
    check_outputs(outputs, inputs, args.force)
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
    acq = Acquisition(port, cfg)
    live = None
    try:
        # before the port opens, so that a device's bytes do not wait in the port's buffer meanwhile
        compile_s = compile_kernels(identify=not args.no_identify)
        acq.open()  # a wrong port fails here, before any file exists
        # always: --no-identify leaves out the rolling SINDy only; the filters and the regime monitor run,
        # and its events go to the recording (and to --events)
        live = LiveProcessing(cfg.daq.rate_hz, mode, rrd, args.events, args.window, args.hop, args.bind,
                              force=args.force, inputs=inputs, identify=not args.no_identify, gaps=args.gaps,
                              regime_window_s=args.regime_window,
                              compile_s=compile_s)
        try:
            rec = McapRecorder(out, cfg, port=port, force=args.force, inputs=inputs, accel_json=args.accel_json)
        except BaseException:
            if live is not None:
                live.abort()
            raise
        return _record(args, acq, rec, live, out, go)
    finally:
        if server is not None:
            server.stop()
            thread.join(timeout=5)
        if tmp is not None:
            tmp.cleanup()


def _record(args, acq: Acquisition, rec: McapRecorder, live: LiveProcessing | None, out: Path,
            opened: threading.Event) -> int:
    last_status = [time.monotonic()]

    status_shown = [False]  # a status line ends with \r, not \n: what follows it starts a line of its own

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
                status_shown[0] = True
                print(f"\r{st['samples']:9d} samples  {st['dropped_frames']} dropped  {st['crc_errors']} crc  "
                      f"{st['reconnects']} reconnects  {st['restarts']} restarts", end="", file=sys.stderr, flush=True)

    def on_event(e):
        rec.write_event(e)
        if live is not None:
            live.log_event(e)

    acq.on_block = on_block
    acq.on_raw = rec.write_raw
    acq.on_event = on_event
    acq.on_status = rec.write_device
    _on_signals(acq.stop)
    try:
        try:
            acq.run(args.duration, opened=opened)
        finally:
            if status_shown[0]:  # (a disk-full error had been printed on the status line's end)
                print(file=sys.stderr)
            if live is not None:
                live.close()
                live.write_to(rec)
            rec.write_status(acq.status())
            rec.close()
    except OSError as exc:  # the disk full, a file-size limit, the medium gone: say where the samples are
        part = part_path(out)
        to, k = out, 1
        while to.exists():  # (the target appeared meanwhile: a free name)
            to, k = out.with_name(f"{out.stem}-recovered{'' if k == 1 else f'-{k}'}{out.suffix}"), k + 1
        kept = (f"what came before is in {part}: recover it with `replay recover {part} -o {to}`"
                if part.exists() else f"what came before is in {out}" if out.exists() else "nothing was kept")
        raise ValueError(f"recording stopped: {exc.strerror or exc}; {kept}") from None
    st = acq.status()
    size = out.stat().st_size
    per = size / st["samples"] if st["samples"] else float("nan")
    link = (f"{st['malformed_lines']} malformed lines" if "malformed_lines" in st else f"{st['crc_errors']} CRC errors")
    print(f"{out}: {st['samples']} samples, {st['dropped_frames']} dropped, {st['duplicates']} duplicates, "
          f"{link}, {st['reconnects']} reconnects, {st['restarts']} device restarts, "
          f"{size} bytes ({per:.1f} bytes per 3-channel sample)")
    if live is not None:
        print(live.summary())
    if acq.error:
        raise ValueError(f"recording stopped: {acq.error}; what came before is kept in {out}")
    return 0


class LiveProcessing:
    """The pipeline beside acquisition, in a worker thread, so a slow model fit never stalls the port.

    Blocks go in through a queue; pipeline events come back through another and
    are written by the acquisition thread (the recorder is not shared across
    threads). Latency: from a block's arrival to the model update that includes it.
    """

    def __init__(self, fs_hz: float, viewer_mode: str, rrd_path: Path | None, events_path: Path | None,
                 window_s: float = 4.0, hop_s: float = 1.0, bind: str = DEFAULT_BIND, *, force: bool = False,
                 inputs=(), identify: bool = True, gaps: tuple[float, float] | None = None,
                 regime_window_s: float = RegimeConfig.window_s,
                 compile_s: float = 0.0):
        self.identify = identify  # False: filters and the regime monitor only (no rolling SINDy)
        self.pipe = Pipeline(PipelineConfig(fs_hz=fs_hz, identify=identify,
                                            rolling=rolling_config(fs_hz, window_s, hop_s),
                                            regime=RegimeConfig(fs_hz=fs_hz, gap_m=gaps,
                                                                window_s=regime_window_s)))
        self.compile_s = compile_s  # how long the caller compiled the kernels before the first sample
        self.fs_hz = fs_hz
        self.jsonl = JsonlEvents(events_path, force=force, inputs=inputs) if events_path else None
        try:
            self.viewer = RerunViewer(viewer_mode, rrd_path=rrd_path, fs_hz=fs_hz,
                                      bind=bind, force=force, inputs=inputs)
        except BaseException:
            if self.jsonl:
                self.jsonl.abort()
            raise
        self.inq: queue.Queue = queue.Queue()
        self.outq: queue.Queue = queue.Queue()
        self.latencies: list[float] = []
        self.regimes: list[str] = []
        self.busy_s = 0.0
        self.error: str | None = None
        # timeline times of the samples submitted (the last ones, enough to reach back over a window):
        # pipeline times count samples, the recording's log times follow the timeline
        self._submitted = 0
        self._timeline: collections.deque = collections.deque()
        self._keep = int((window_s + 2 * hop_s + 5.0) * fs_hz)
        self.thread = threading.Thread(target=self._work, daemon=True)
        self.thread.start()

    def submit(self, block) -> None:
        self._timeline.append((self._submitted, np.asarray(block.t_s, float)))
        self._submitted += len(block)
        while self._timeline and self._timeline[0][0] + len(self._timeline[0][1]) < self._submitted - self._keep:
            self._timeline.popleft()
        self.inq.put((time.monotonic(), block.values))

    def timeline_s(self, t_stream_s: float) -> float | None:
        """The timeline time (``SampleBlock.t_s``, what the recording's log times follow) of the last sample
        before pipeline time t (the pipeline counts samples from the start)."""
        k = int(round(t_stream_s * self.fs_hz)) - 1
        for start, t in reversed(self._timeline):
            if start <= k < start + len(t):
                return float(t[k - start])
        return None

    def _work(self) -> None:
        last_window = -1.0
        while True:
            item = self.inq.get()
            if item is None:
                self._handle(self.pipe.finish)  # the last window's refined fit
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
        """Run a pipeline step, show it, queue its models and events for the recorder."""
        try:
            out = step(*args)
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
                   else e["message"] if e["kind"] == "regime_note"
                   else f"starting regime {e['regime']} (confidence {e['confidence']:.2f})"
                   if e["kind"] == "regime_start"
                   else f"beam {e.get('beam')} model changed: " + "; ".join(e.get("equations", [])))
            data = {k: v for k, v in e.items() if k not in ("t", "kind")}
            self.outq.put(Event(e["t"], e["kind"], msg, "warning" if e["kind"] == "regime_note" else "info", data))
        return out

    def write_to(self, rec) -> None:
        """Write the events and per-window models produced since the last call to the recorder, stamped
        with the data time they describe (log_time; publish_time is now)."""
        while not self.outq.empty():
            item = self.outq.get_nowait()
            if isinstance(item, tuple) and item[0] == "model":
                t = self.timeline_s(item[1])
                log_ns = rec.log_time_ns(t) if t is not None else None
                for m in item[2]:
                    rec.write_model(m, log_ns=log_ns)
            elif item.kind in ("regime_start", "regime", "model"):
                t = self.timeline_s(item.t)
                rec.write_event(item, log_ns=rec.log_time_ns(t) if t is not None else None)
            else:
                rec.write_event(item)

    def log_event(self, e) -> None:
        if self.jsonl:
            self.jsonl.write({"t": e.t, "kind": e.kind, "message": e.message, **e.data})

    def abort(self) -> None:
        self.viewer.abort()
        if self.jsonl:
            self.jsonl.abort()

    def close(self) -> None:
        self.inq.put(None)
        self.thread.join(timeout=60)
        self.viewer.close()
        if self.jsonl:
            self.jsonl.close()

    def summary(self) -> str:
        lat = np.array(self.latencies)
        p = (f"latency sample -> model update p50 {1e3 * np.percentile(lat, 50):.0f} ms, "
             f"p95 {1e3 * np.percentile(lat, 95):.0f} ms" if lat.size
             else "no model update" if self.identify else "no identification (--no-identify)")
        return (f"live: {len(self.latencies)} model updates, {len(self.regimes)} regime changes, {p}"
                + (f"; kernels compiled in {self.compile_s:.1f} s before the first sample" if self.compile_s > 1.0
                   else "") + (f"; ERROR {self.error}" if self.error else ""))


def compile_kernels(identify: bool = True) -> float:
    """Compile the pipeline's numba kernels (the regime monitor's, and the identification's unless
    ``identify`` is off) before data flows, so that no window waits for the compiler or the loader: from
    numba's disk cache this takes a moment; the first run after an install compiles for some seconds and
    says so on a terminal while it does. Seconds taken."""
    cold = kernels_cached(identify) is False
    tell = cold and sys.stderr.isatty()
    if tell:
        print("compiling the pipeline's kernels before the first sample (first run after an install; "
              "numba caches them, so later runs start at once)...", end="", file=sys.stderr, flush=True)
    t0 = time.monotonic()
    warm_up(identify)
    took = time.monotonic() - t0
    if tell:
        print(f" compiled in {took:.1f} s", file=sys.stderr, flush=True)
    return took


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return run_guarded(f"daq {args.command}", args.func, args)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
