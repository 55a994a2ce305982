"""rerun viewer sink: what a test engineer wants on screen while the rig runs (or a log replays).

Entities (all on the timeline ``time``, seconds since the start of the stream):

- ``accel/raw/{base,tip1,tip2}`` and ``accel/filtered/{...}``: accelerations, high-rate
  scalars sent in columns (``rr.send_columns``), never one call per sample;
- ``phase/tip1``: the filtered relative acceleration of tip 1, delay-embedded in 3D
  with the core's delay (first zero of the autocorrelation of the first two seconds;
  the last two seconds as a line strip), like the paper's phase portraits;
- ``model/beam{1,2}/coefficients``: the current identified coefficients (bar chart);
- ``model/beam{1,2}/z`` and ``.../z_pred``: measured and predicted relative
  displacement over the last window (the identified model's prediction);
- ``model/beam{1,2}/natural_frequency_hz`` and ``.../integration_nrmse``: the
  identified stiffness as a frequency and each window's integration error, over time;
- ``backbone/beam{1,2}``: each window's natural frequency [Hz] against its displacement
  amplitude [mm] (the beam's backbone), with the ensemble's +-1 standard deviation as a bar
  (``backbone/beam{1,2}/spread``); the frequency axis points up;
- ``regime``: the regime as a state timeline (``rr.StateChange``);
- ``events``: regime changes, model changes, drops, reconnects (``rr.TextLog``).

Modes: ``auto`` (``spawn`` in an interactive terminal, else ``none``),
``spawn`` (the native viewer, where there is a display; else ``web``),
``web`` (gRPC server plus the web viewer, URL printed), ``save``
(an .rrd file, written as ``.rrd.part`` and renamed when complete), ``none``.

Binding: rerun 0.41's in-process servers (``rr.serve_grpc``, ``rr.serve_web_viewer``, ``rr.spawn``)
take a port but no address and listen on every interface. So the servers run in the ``rerun``
executable, which takes ``--bind``: ``rerun --serve-web --bind ADDR`` (web) or ``rerun --bind ADDR``
(native viewer), on 127.0.0.1 unless ``--bind`` says otherwise, and the recording stream connects to
them as a client (``connect_grpc``); this process listens on nothing. The URL printed opens the live
recording directly: ``http://127.0.0.1:9090/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A9876%2Fproxy``
(the form the rerun executable itself prints).
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path
from urllib.parse import quote

import numpy as np

from ident.embedding import acf_delay

from .safeio import PartFile

CHANNELS = ("base", "tip1", "tip2")
PHASE_DELAY_S = 1 / (4 * 12.3)  # fallback: a quarter period of the rig's excitation
PHASE_SPAN_S = 2.0
PHASE_EVERY_S = 0.2  # refresh the portrait five times per second of stream time
VIEWER_MODES = ("auto", "spawn", "web", "save", "none")
GRPC_PORT, WEB_PORT = 9876, 9090
DEFAULT_BIND = "127.0.0.1"


def blueprint():
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.TimeSeriesView(origin="accel/raw", name="raw acceleration [m/s^2]"),
                rrb.TimeSeriesView(origin="accel/filtered", name="below 50 Hz [m/s^2]"),
                rrb.StateTimelineView(origin="regime", name="regime"),
                row_shares=[3, 3, 1],
            ),
            rrb.Vertical(
                rrb.Spatial3DView(origin="phase", name="embedded phase portrait (tip 1)"),
                rrb.Horizontal(
                    rrb.BarChartView(origin="model/beam1/coefficients", name="beam 1 coefficients"),
                    rrb.BarChartView(origin="model/beam2/coefficients", name="beam 2 coefficients"),
                ),
                rrb.Horizontal(
                    rrb.TimeSeriesView(origin="model", name="model prediction vs measurement",
                                       contents=["model/beam1/z", "model/beam1/z_pred", "model/beam2/z",
                                                 "model/beam2/z_pred"]),
                    rrb.Spatial2DView(origin="backbone", name="backbone: natural frequency [Hz] vs amplitude [mm]"),
                ),
                rrb.TextLogView(origin="events", name="events"),
            ),
        ),
        collapse_panels=True,
    )


ENTITIES = ("accel/raw/base", "accel/raw/tip1", "accel/raw/tip2", "accel/filtered/base", "accel/filtered/tip1",
            "accel/filtered/tip2", "phase/tip1", "model/beam1/coefficients", "model/beam2/coefficients",
            "model/beam1/z", "model/beam1/z_pred", "model/beam2/z", "model/beam2/z_pred",
            "model/beam1/natural_frequency_hz", "model/beam2/natural_frequency_hz", "model/beam1/integration_nrmse",
            "model/beam2/integration_nrmse", "backbone/beam1", "backbone/beam2", "backbone/beam1/spread",
            "backbone/beam2/spread", "regime", "events")
BACKBONE_POINTS = 600  # the last windows shown on the backbone (10 minutes at a 1 s hop)
BEAM_COLORS = ((230, 120, 30), (40, 140, 230))


def _has_display() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")) or sys.platform == "darwin"


def _rerun_exe() -> str:
    exe = os.path.join(os.path.dirname(sys.executable), "rerun")
    if os.path.exists(exe):
        return exe
    found = shutil.which("rerun")
    if not found:
        raise ValueError("the rerun executable (pip package rerun-sdk) was not found; use --viewer save or none")
    return found


def _host(bind: str) -> str:
    """The address to connect to a server bound to ``bind``, as it goes in a URL."""
    host = "127.0.0.1" if bind in ("0.0.0.0", "", "::") else bind
    return f"[{host}]" if ":" in host else host


def _family(bind: str) -> int:
    return socket.AF_INET6 if ":" in bind else socket.AF_INET


def port_free(bind: str, port: int) -> bool:
    with socket.socket(_family(bind), socket.SOCK_STREAM) as s:
        try:
            s.bind((bind, port))
        except OSError:
            return False
    return True


def free_port(bind: str, preferred: int) -> int:
    """``preferred`` if it can be bound on ``bind``, else a free port the system picks."""
    if port_free(bind, preferred):
        return preferred
    with socket.socket(_family(bind), socket.SOCK_STREAM) as s:
        s.bind((bind, 0))
        return s.getsockname()[1]


def _wait_listening(host: str, port: int, proc: subprocess.Popen, timeout_s: float = 20.0) -> None:
    end = time.monotonic() + timeout_s
    addr = host.strip("[]")
    while time.monotonic() < end:
        if proc.poll() is not None:
            raise ValueError(f"the rerun viewer exited at start (code {proc.returncode}); use --viewer save or none")
        try:
            with socket.create_connection((addr, port), timeout=0.5):
                return
        except OSError:
            time.sleep(0.1)
    raise ValueError(f"the rerun viewer did not listen on {addr}:{port} within {timeout_s:.0f} s")


def resolve_mode(mode: str) -> str:
    """``auto``: show it to a person at a terminal (native viewer with a display, else web); stay quiet in
    scripts, tests and CI."""
    if mode not in VIEWER_MODES:
        raise ValueError(f"unknown viewer {mode!r}; choose one of {', '.join(VIEWER_MODES)}")
    if mode == "auto":
        mode = "spawn" if sys.stdout.isatty() and sys.stdin.isatty() else "none"
    if mode == "spawn" and not _has_display():
        mode = "web"
    return mode


class RerunViewer:
    def __init__(self, mode: str, *, name: str = "shaker-rig", rrd_path: str | Path | None = None,
                 fs_hz: float = 2000.0, bind: str = DEFAULT_BIND, force: bool = False, inputs=()):
        asked = mode
        mode = resolve_mode(mode)
        self.mode = mode
        self.fs_hz = fs_hz
        self.url = None
        self.bind = bind
        self._proc: subprocess.Popen | None = None
        self._rrd: PartFile | None = None
        self._rel = np.zeros((0,))
        self._rel_t = np.zeros((0,))
        self._first = np.zeros((0,))  # the first seconds, for the core's choice of delay
        self._delay: int | None = None
        self._phase_t = -np.inf
        self._regime_started = False
        self._backbone: tuple[list, list] = ([], [])  # per beam: (amplitude mm, frequency Hz, spread Hz)
        if mode == "none":
            self.rec = None
            return
        import rerun as rr

        self.rr = rr
        self.rec = rr.RecordingStream(name)
        bp = blueprint()
        if mode == "web" and asked == "spawn":
            print("no display: serving the web viewer instead", file=sys.stderr)
        host = _host(bind)
        if mode == "spawn":
            port = GRPC_PORT
            if port_free(bind, port):  # else a viewer already listens there: use it, as rr.spawn does
                self._proc = subprocess.Popen([_rerun_exe(), "--bind", bind, "--port", str(port)],
                                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                              start_new_session=True)
                _wait_listening(host, port, self._proc)
            self.rec.connect_grpc(f"rerun+http://{host}:{port}/proxy", default_blueprint=bp)
        elif mode == "web":
            grpc, web = free_port(bind, GRPC_PORT), free_port(bind, WEB_PORT)
            self._proc = subprocess.Popen([_rerun_exe(), "--serve-web", "--bind", bind, "--port", str(grpc),
                                           "--web-viewer-port", str(web)],
                                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
            _wait_listening(host, grpc, self._proc)
            _wait_listening(host, web, self._proc)
            data = f"rerun+http://{host}:{grpc}/proxy"
            self.rec.connect_grpc(data, default_blueprint=bp)
            self.url = f"http://{host}:{web}/?url={quote(data, safe='')}"
            print(f"web viewer: {self.url} (listening on {bind} only; --bind ADDR to change)", file=sys.stderr,
                  flush=True)
        else:
            if rrd_path is None:
                raise ValueError("--viewer save needs a file name for the .rrd")
            self.rrd_path = Path(rrd_path)
            self._rrd = PartFile(self.rrd_path, inputs=inputs, force=force, label="--viewer save")
            self._rrd.file.close()  # rerun writes the file itself
            self.rec.save(str(self._rrd.part), default_blueprint=bp)
        # 2-D views draw y downwards: flip it so that frequency grows upwards on the backbone
        self.rec.log("backbone", rr.Transform3D(scale=[1.0, -1.0, 1.0]), static=True)

    def _time(self, t: np.ndarray):
        return [self.rr.TimeColumn("time", duration=np.asarray(t, float))]

    def _scalars(self, path: str, t: np.ndarray, v: np.ndarray) -> None:
        self.rr.send_columns(path, indexes=self._time(t), columns=self.rr.Scalars.columns(scalars=v),
                             recording=self.rec)

    def log_step(self, out) -> None:
        """One pipeline StepOutput (ident.live.pipeline)."""
        if self.rec is None or len(out.t) == 0:
            return
        rr = self.rr
        for j, ch in enumerate(CHANNELS):
            self._scalars(f"accel/raw/{ch}", out.t, out.raw[:, j])
            self._scalars(f"accel/filtered/{ch}", out.t, out.filtered[:, j])
        self._phase(out.t, out.relative[:, 0])
        for c in out.changes:
            self.rec.set_time("time", duration=c.t_s)
            self.rec.log("regime", rr.StateChange(state=c.regime))
        if out.windows and not self._regime_started:
            self._regime_started = True
            self.rec.set_time("time", duration=out.windows[0].t_s)
            self.rec.log("regime", rr.StateChange(state=out.windows[0].label))
        for f in out.fits:
            self.rec.set_time("time", duration=f.t_s)
            for i, b in enumerate(f.beams):
                pre = f"model/beam{i + 1}"
                self.rec.log(f"{pre}/coefficients", rr.BarChart(b.model.coefficients[:, 1]))
                self.rec.log(f"{pre}/natural_frequency_hz", rr.Scalars(b.natural_frequency_hz))
                self.rec.log(f"{pre}/integration_nrmse", rr.Scalars(b.error))
                self._scalars(f"{pre}/z", f.t, f.measured[:, i, 0])
                self._scalars(f"{pre}/z_pred", f.t, f.predicted[:, i, 0])
                self._backbone_point(i, b)
        for e in out.events:
            self.log_event(e)

    def _backbone_point(self, i: int, b) -> None:
        """Add a window's (amplitude, natural frequency) to beam i's backbone and show the last ones."""
        if not np.isfinite(b.natural_frequency_hz):
            return
        pts = self._backbone[i]
        pts.append((1e3 * b.amplitude_m, b.natural_frequency_hz, b.natural_frequency_std_hz))
        del pts[:-BACKBONE_POINTS]
        a = np.array(pts)
        self.rec.log(f"backbone/beam{i + 1}",
                     self.rr.Points2D(a[:, :2], colors=BEAM_COLORS[i], radii=self.rr.Radius.ui_points(3.0)))
        ok = np.isfinite(a[:, 2])
        bars = [[(x, f - s), (x, f + s)] for x, f, s in a[ok]]
        if bars:
            self.rec.log(f"backbone/beam{i + 1}/spread", self.rr.LineStrips2D(bars, colors=BEAM_COLORS[i]))

    def log_event(self, e: dict) -> None:
        if self.rec is None:
            return
        self.rec.set_time("time", duration=float(e["t"]))
        text = e.get("message") or ", ".join(f"{k}={v}" for k, v in e.items() if k not in ("t", "equations"))
        level = "WARN" if e.get("kind") in ("drop", "crc", "disconnect", "reconnect") else "INFO"
        self.rec.log("events", self.rr.TextLog(f"{e['kind']}: {text}", level=level))

    def _phase(self, t: np.ndarray, rel: np.ndarray) -> None:
        if self._delay is None:
            self._first = np.concatenate([self._first, rel])
            if len(self._first) < int(PHASE_SPAN_S * self.fs_hz):
                return
            try:  # the core's choice: first zero of the autocorrelation
                self._delay = acf_delay(self._first)
            except ValueError:
                self._delay = max(1, int(round(PHASE_DELAY_S * self.fs_hz)))
        d = self._delay
        keep = int(PHASE_SPAN_S * self.fs_hz) + 2 * d
        self._rel = np.concatenate([self._rel, rel])[-keep:]
        self._rel_t = np.concatenate([self._rel_t, t])[-keep:]
        if len(self._rel) <= 2 * d or self._rel_t[-1] - self._phase_t < PHASE_EVERY_S:
            return
        self._phase_t = float(self._rel_t[-1])
        pts = np.column_stack([self._rel[2 * d:], self._rel[d:-d], self._rel[:-2 * d]])[::4]
        self.rec.set_time("time", duration=float(self._rel_t[-1]))
        self.rec.log("phase/tip1", self.rr.LineStrips3D([pts]))

    def _stop_server(self, sig: int = signal.SIGTERM) -> None:
        """End the web server: its whole process group (the ``rerun`` script runs the viewer binary as a child)."""
        proc, self._proc = self._proc, None
        try:
            os.killpg(proc.pid, sig)
            proc.wait(timeout=5)
        except ProcessLookupError:
            return
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(timeout=5)

    def abort(self) -> None:
        """Stop the servers and remove an unfinished .rrd (the command failed before it started)."""
        if self.rec is not None:
            self.rec.disconnect()
        if self._rrd is not None:
            self._rrd.abort()
            self._rrd = None
        if self._proc is not None and self.mode == "web":
            self._stop_server(signal.SIGKILL)

    def close(self) -> None:
        if self.rec is not None:
            self.rec.flush()
            if self.mode in ("save", "web"):
                self.rec.disconnect()
            if self._rrd is not None:
                self._rrd.commit()
                self._rrd = None
        if self._proc is not None and self.mode == "web":  # the web server lives as long as the command
            self._stop_server()
