"""rerun viewer sink: what a test engineer wants on screen while the rig runs (or a log replays).

One colour per channel in every panel: base grey, tip 1 / beam 1 orange, tip 2 / beam 2 blue; where a
model is drawn over a measurement the model is black. Entities (timeline ``time``, seconds since the
start of the stream), and the blueprint's panels that show them (``PANELS``):

- ``accel/raw/{base,tip1,tip2}`` and ``accel/filtered/{...}``: accelerations [m/s^2], raw and causal
  below 50 Hz, sent in columns (``rr.send_columns``), never one call per sample;
- ``regime`` (the rig), ``regime/beam{1,2}`` (free / hitting): state timelines (``rr.StateChange``);
- ``model/beam{1,2}/equation``: the identified equation and a table of its terms (coefficient,
  ensemble standard deviation, normalised size, probability of being active) as markdown;
- ``model/beam{1,2}/terms``: one horizontal bar per term of the v' equation, labelled with the term,
  length = coefficient x RMS(term) / RMS(v') (the share of the acceleration the term explains, so a
  cubic coefficient of 1e9 and a damping of 1 are drawn on the same footing), with the ensemble's
  +-1 standard deviation as a line (``.../terms/spread``);
- ``model/beam{1,2}/z``, ``.../z_pred``: measured and predicted relative displacement [mm] (the
  newest hop of each window: the prediction integrated over the window from its start);
- ``model/beam{1,2}/natural_frequency_hz``: sqrt(k)/2pi of the identified linear stiffness;
- ``backbone/beam{1,2}``: natural frequency [Hz] against displacement amplitude [mm], one point
  per window, +-1 ensemble standard deviation as a bar; the frequency axis points up;
- ``spectra/transmissibility/tip{1,2}``, ``spectra/coherence/tip{1,2}``: the H1 estimate G_xy / G_xx
  (Welch cross- and auto-spectra, base x -> tip y) as a ratio, drawn where the ordinary coherence
  |G_xy|^2 / (G_xx G_yy) is at least ``COHERENCE_MIN``, and the coherence, over the last
  ``SPECTRUM_SPAN_S`` seconds, refreshed every ``SPECTRUM_EVERY_S``;
- ``spectra/psd/{base,tip1,tip2}``: running Welch PSD in dB re ``PSD_REF`` = 1e-6 (m/s^2)^2/Hz;
- ``restoring/beam{1,2}``: restoring-force scatter of the last window: -(r_i + base) / omega_n^2
  [mm] against z_i [mm] (force per unit mass over the identified linear stiffness, so a linear
  beam lies on the diagonal and a stopper bends the cloud), with the model's v' at v = 0 and no
  base acceleration as a black curve (``restoring/beam{1,2}/model``);
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
from scipy import signal as sg

from ident.live.regimes import starting

from .safeio import PartFile

CHANNELS = ("base", "tip1", "tip2")
VIEWER_MODES = ("auto", "spawn", "web", "save", "none")
GRPC_PORT, WEB_PORT = 9876, 9090
DEFAULT_BIND = "127.0.0.1"
COLORS = {"base": (120, 120, 120), "tip1": (230, 120, 30), "tip2": (40, 140, 230)}
BEAM_COLORS = (COLORS["tip1"], COLORS["tip2"])
MODEL_COLOR = (20, 20, 20)
LABELS = {"base": "base", "tip1": "tip 1", "tip2": "tip 2"}
BACKBONE_POINTS = 600  # the last windows shown on the backbone (10 minutes at a 1 s hop)
SPECTRUM_SPAN_S, SPECTRUM_EVERY_S, SPECTRUM_SEGMENT_S = 8.0, 1.0, 1.0  # 15 averages of 1 Hz resolution
SPECTRUM_MAX_HZ = 60.0  # a little above the analysis band (50 Hz), to show its edge
COHERENCE_MIN = 0.5  # transmissibility drawn where the coherence says the tip follows the base (15 averages:
# the coherence of unrelated signals is about 1/15)
TERM_MIN_P = 0.5  # a term is drawn when active or active in at least this share of the ensemble
TERM_ROWS = 6  # inactive terms likely in the ensemble are added up to this many rows

# the blueprint's panels: (kind, title, entities); the test checks that every entity holds data
PANELS = (
    ("series", "raw acceleration [m/s²]", tuple(f"accel/raw/{c}" for c in CHANNELS)),
    ("series", "acceleration below 50 Hz [m/s²]", tuple(f"accel/filtered/{c}" for c in CHANNELS)),
    ("state", "regime: rig, beam 1, beam 2", ("regime", "regime/beam1", "regime/beam2")),
    ("series", "beam 1: relative displacement z [mm], measured vs model", ("model/beam1/z", "model/beam1/z_pred")),
    ("series", "beam 2: relative displacement z [mm], measured vs model", ("model/beam2/z", "model/beam2/z_pred")),
    ("text", "beam 1: identified equation", ("model/beam1/equation",)),
    ("text", "beam 2: identified equation", ("model/beam2/equation",)),
    ("spatial", "beam 1: terms of v' (normalised, ± 1 std)", ("model/beam1/terms",
                                                                              "model/beam1/terms/spread")),
    ("spatial", "beam 2: terms of v' (normalised, ± 1 std)", ("model/beam2/terms",
                                                                              "model/beam2/terms/spread")),
    ("spatial", "backbone: natural frequency vs amplitude, one point per window",
     ("backbone/beam1", "backbone/beam2", "backbone/beam1/spread", "backbone/beam2/spread")),
    ("spatial", "transmissibility |H1| base → tip, where coherence ≥ 0.5",
     ("spectra/transmissibility/tip1", "spectra/transmissibility/tip2")),
    ("spatial", "coherence base → tip", ("spectra/coherence/tip1", "spectra/coherence/tip2")),
    ("spatial", "PSD of the last 8 s: base grey, tip 1 orange, tip 2 blue", tuple(f"spectra/psd/{c}" for c in CHANNELS)),
    ("spatial", "restoring force per stiffness vs z, last window; black: model at v = 0",
     ("restoring/beam1", "restoring/beam2", "restoring/beam1/model", "restoring/beam2/model")),
    ("log", "events", ("events",)),
)
ENTITIES = tuple(e for _, _, ents in PANELS for e in ents) + tuple(
    f"model/beam{i}/{q}" for i in (1, 2) for q in ("integration_nrmse", "natural_frequency_hz"))


def _view(kind: str, title: str, entities: tuple[str, ...]):
    import rerun.blueprint as rrb

    contents = [f"/{e}" for e in entities]
    if kind == "series":
        return rrb.TimeSeriesView(name=title, contents=contents, plot_legend=rrb.PlotLegend(
            corner=rrb.Corner2D.LeftTop, visible=True))
    if kind == "state":
        return rrb.StateTimelineView(name=title, contents=contents)
    if kind == "text":
        return rrb.TextDocumentView(name=title, contents=contents)
    if kind == "spatial":  # with the axes the viewer draws under the panel's root
        root = "/" + os.path.commonpath(entities)
        return rrb.Spatial2DView(name=title, origin=root, contents=contents + [f"{root}/axes/**"])
    if kind == "bars":
        return rrb.BarChartView(name=title, contents=contents, plot_legend=rrb.PlotLegend(
            corner=rrb.Corner2D.RightTop, visible=True))
    return rrb.TextLogView(name=title, contents=contents)


def blueprint():
    import rerun.blueprint as rrb

    v = {title: _view(kind, title, ents) for kind, title, ents in PANELS}
    p = [v[t] for _, t, _ in PANELS]
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(*p[0:5], row_shares=[3, 3, 2.2, 2, 2]),
            rrb.Vertical(rrb.Horizontal(p[5], p[6]), rrb.Horizontal(p[7], p[8]), p[9], row_shares=[3, 3, 3]),
            rrb.Vertical(p[10], p[11], p[12], p[13], p[14], row_shares=[2.2, 1.6, 2.2, 3, 1]),
            column_shares=[4, 4, 3],
        ),
        rrb.TimePanel(state="collapsed", play_state="following"),
        collapse_panels=True,
    )


FRAME_W, FRAME_H = 16.0, 10.0  # the 2-D panels draw their data into this box, with their own axes
SPECTRUM_W = 26.0  # the spectra's panels are wide


def nice_ticks(lo: float, hi: float, n: int = 5) -> np.ndarray:
    """Round tick values (1, 2 or 5 x 10^k apart) covering [lo, hi] with about n ticks."""
    span = hi - lo if hi > lo else max(abs(hi), 1.0)
    raw = span / max(n - 1, 1)
    step = 10 ** np.floor(np.log10(raw))
    step *= next(m for m in (1, 2, 5, 10) if m * step >= raw)
    return np.arange(np.ceil(lo / step) * step, hi + 1e-9 * span, step)


def limits(v: np.ndarray, pad: float = 0.05, symmetric: bool = False) -> tuple[float, float]:
    v = np.asarray(v, float)
    v = v[np.isfinite(v)]
    if len(v) == 0:
        return 0.0, 1.0
    lo, hi = float(v.min()), float(v.max())
    if symmetric:
        hi = max(abs(lo), abs(hi)) or 1.0
        lo = -hi
    span = hi - lo or max(abs(hi), 1e-9)
    return lo - pad * span, hi + pad * span


class Frame:
    """Maps data (x, y) into the FRAME_W x FRAME_H box of a 2-D panel (y up after the panel's flip)."""

    def __init__(self, xlim: tuple[float, float], ylim: tuple[float, float], width: float = FRAME_W):
        self.xlim, self.ylim, self.w = xlim, ylim, width

    def __call__(self, x, y) -> np.ndarray:
        (x0, x1), (y0, y1) = self.xlim, self.ylim  # 2-D views draw y downwards: flipped here, up on screen
        return np.column_stack([(np.asarray(x, float) - x0) / (x1 - x0) * self.w,
                                FRAME_H - (np.asarray(y, float) - y0) / (y1 - y0) * FRAME_H])

    def axes(self, rr, xlabel: str, ylabel: str, yticks: tuple[np.ndarray, list[str]] | None = None) -> list:
        """The box, tick marks and tick labels: (LineStrips2D, Points2D with labels)."""
        box = [[(0, 0), (self.w, 0), (self.w, FRAME_H), (0, FRAME_H), (0, 0)]]  # y up until the end
        xt = nice_ticks(*self.xlim)
        xt = xt[(xt >= self.xlim[0]) & (xt <= self.xlim[1])]
        if yticks is None:
            yt = nice_ticks(*self.ylim)
            yt = yt[(yt >= self.ylim[0]) & (yt <= self.ylim[1])]
            ylab = [f"{v:g}" for v in yt]
        else:
            yt, ylab = yticks
        up = lambda p: [(x, FRAME_H - y) for x, y in p]  # noqa: E731
        px = up(self(xt, np.full(len(xt), self.ylim[0])))
        py = up(self(np.full(len(yt), self.xlim[0]), yt))
        marks = [[(x, 0), (x, -0.25)] for x, _ in px] + [[(0, y), (-0.25, y)] for _, y in py]
        pos = ([(x, -0.9) for x, _ in px] + [(-(0.025 + 0.008 * len(t)) * self.w, y) for (_, y), t in zip(py, ylab)]
               + [(self.w / 2, -2.0), (-0.5, FRAME_H + 0.8)])
        labels = [f"{v:g}" for v in xt] + list(ylab) + [xlabel, ylabel]
        return [rr.LineStrips2D([up(s) for s in box + marks], colors=(150, 150, 150),
                                radii=rr.Radius.ui_points(1.0)),
                rr.Points2D(up(pos), labels=labels, radii=0.0, colors=(200, 200, 200), show_labels=True)]

    def log(self, rec, rr, root: str, xlabel: str, ylabel: str, yticks=None) -> None:
        lines, labels = self.axes(rr, xlabel, ylabel, yticks)
        rec.log(f"{root}/axes/lines", lines)
        rec.log(f"{root}/axes/labels", labels)


def transfer_estimates(x: np.ndarray, fs_hz: float, nperseg: int):
    """Welch estimates from (N, 3) samples base, tip1, tip2: frequencies, H1 = G_bt / G_bb (N_f, 2) of
    base -> tips, ordinary coherence |G_bt|^2 / (G_bb G_tt) (N_f, 2) and the auto-spectra (N_f, 3)."""
    x = x - x.mean(axis=0)
    f, pxx = sg.welch(x, fs_hz, nperseg=nperseg, axis=0)
    _, pxy = sg.csd(x[:, :1], x[:, 1:], fs_hz, nperseg=nperseg, axis=0)
    gbb = np.maximum(pxx[:, :1], 1e-300)
    h1 = pxy / gbb
    coh = np.abs(pxy) ** 2 / np.maximum(gbb * pxx[:, 1:], 1e-300)
    return f, h1, np.clip(coh, 0.0, 1.0), pxx


def _decades(logv: np.ndarray) -> tuple[float, float]:
    v = np.asarray(logv, float)
    v = v[np.isfinite(v)]
    if len(v) == 0:
        return -1.0, 1.0
    lo, hi = np.floor(np.percentile(v, 1)), np.ceil(v.max())
    return float(lo), float(hi if hi > lo else lo + 1)


def _decade_ticks(ylim: tuple[float, float]) -> tuple[np.ndarray, list[str]]:
    k = np.arange(np.ceil(ylim[0]), np.floor(ylim[1]) + 1)
    if len(k) > 6:
        k = k[::int(np.ceil(len(k) / 6))]
    return k, [f"1e{int(v)}" if v not in (0, 1) else ("1" if v == 0 else "10") for v in k]


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) of every run of True in mask."""
    d = np.diff(np.concatenate([[0], mask.astype(int), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)))


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
        self._buf = np.zeros((0, 3))  # the last SPECTRUM_SPAN_S of raw samples, for the spectra
        self._spectrum_t = -np.inf
        self._sent_t = -np.inf  # end of the prediction already shown
        self._regime_started = False
        self._started = False
        self._beam_state: list[str | None] = [None, None]
        self._backbone_pts: tuple[list, list] = ([], [])  # per beam: (amplitude mm, frequency Hz, spread Hz)
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
        else:
            if rrd_path is None:
                raise ValueError("--viewer save needs a file name for the .rrd")
            self.rrd_path = Path(rrd_path)
            self._rrd = PartFile(self.rrd_path, inputs=inputs, force=force, label="--viewer save")
            self._rrd.file.close()  # rerun writes the file itself
            self.rec.save(str(self._rrd.part), default_blueprint=bp)
        self._static()
        print(self.where() + (f" (listening on {bind} only; --bind ADDR to change)" if mode != "save" else ""),
              file=sys.stderr, flush=True)

    def where(self) -> str:
        """Where a person finds the view, for the command to print."""
        if self.mode == "web":
            return f"web viewer: {self.url}"
        if self.mode == "spawn":
            return "viewer: the native rerun window (rerun+http://" + _host(self.bind) + f":{GRPC_PORT}/proxy)"
        if self.mode == "save":
            return f"viewer: saving to {self.rrd_path} (open it with: rerun {self.rrd_path})"
        return "viewer: none"

    def _static(self) -> None:
        """Names, colours and axes that do not change: one colour per channel, the model in black."""
        rr, log = self.rr, self.rec.log
        for c in CHANNELS:
            for kind, label in (("raw", "raw"), ("filtered", "< 50 Hz")):
                log(f"accel/{kind}/{c}", rr.SeriesLines(colors=[COLORS[c]], names=[f"{LABELS[c]} {label}"],
                                                        widths=[1.0]), static=True)
        for i in range(2):
            pre, col = f"model/beam{i + 1}", BEAM_COLORS[i]
            log(f"{pre}/z", rr.SeriesLines(colors=[col], names=[f"measured z, beam {i + 1} [mm]"], widths=[2.5]),
                static=True)
            log(f"{pre}/z_pred", rr.SeriesLines(colors=[MODEL_COLOR], names=[f"model z, beam {i + 1} [mm]"],
                                                widths=[1.0]), static=True)
            log(f"{pre}/natural_frequency_hz", rr.SeriesPoints(colors=[col], names=[f"beam {i + 1} [Hz]"],
                                                               marker_sizes=[3.0]), static=True)
            log(f"{pre}/integration_nrmse", rr.SeriesLines(colors=[col], names=[f"beam {i + 1} NRMSE"]), static=True)

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
        if not self._started:
            self._started = True
            self.rec.set_time("time", duration=float(out.t[0]))
            self.rec.log("events", rr.TextLog(f"start: {', '.join(CHANNELS)} at {self.fs_hz:g} Hz", level="INFO"))
        for j, ch in enumerate(CHANNELS):
            self._scalars(f"accel/raw/{ch}", out.t, out.raw[:, j])
            self._scalars(f"accel/filtered/{ch}", out.t, out.filtered[:, j])
        self._spectra(out.t, out.raw)
        for c in out.changes:
            self.rec.set_time("time", duration=c.t_s)
            self.rec.log("regime", rr.StateChange(state=c.regime))
        first = starting(out.windows) if not self._regime_started else None
        if first is not None:
            self._regime_started = True
            self.rec.set_time("time", duration=first.t_s)
            self.rec.log("regime", rr.StateChange(state=first.label))
        for w in out.windows:
            if w.provisional:  # before the starting regime is decided, no beam has a state to show
                continue
            for i, b in enumerate(w.beams):
                state = "hitting" if b.hitting else "free"
                if state != self._beam_state[i]:
                    self._beam_state[i] = state
                    self.rec.set_time("time", duration=w.t_s)
                    self.rec.log(f"regime/beam{i + 1}", rr.StateChange(state=state))
        for f in out.fits:
            self.rec.set_time("time", duration=f.t_s)
            new = (f.t > self._sent_t) & f.final  # a refined fit of the window follows: show that one
            for i, b in enumerate(f.beams):
                pre = f"model/beam{i + 1}"
                contrib, spread = self._contributions(f, i, b)
                self.rec.log(f"{pre}/equation", rr.TextDocument(self._equation_text(f, i, b, contrib),
                                                                media_type=rr.MediaType.MARKDOWN))
                self._terms(pre, b, contrib, spread)
                self.rec.log(f"{pre}/natural_frequency_hz", rr.Scalars(b.natural_frequency_hz))
                self.rec.log(f"{pre}/integration_nrmse", rr.Scalars(b.error))
                if new.any():
                    self._scalars(f"{pre}/z", f.t[new], 1e3 * f.measured[new, i, 0])
                    self._scalars(f"{pre}/z_pred", f.t[new], 1e3 * f.predicted[new, i, 0])
            if f.final:  # one backbone point and restoring-force curve per window: its refined model's
                self._backbone(f)
                self._restoring(f)
            if f.final and len(f.t):
                self._sent_t = float(f.t[-1])
        for e in out.events:
            self.log_event(e)

    def _contributions(self, f, i: int, b) -> tuple[np.ndarray, np.ndarray]:
        """Each v' term's coefficient x RMS(term) / RMS(v') over the window, and the same for its std."""
        c = b.model.coefficients[:, 1]
        std = np.nan_to_num(np.asarray(b.coefficient_std)[:, 1]) if b.coefficient_std is not None else 0 * c
        if f.base is None or f.accel is None:
            return c, std
        rms_t = b.term_rms  # over the window, as the fit's ensemble scaled its columns
        rms_r = max(float(np.sqrt(np.mean(f.accel[:, i] ** 2))), 1e-12)
        return c * rms_t / rms_r, std * rms_t / rms_r

    def _equation_text(self, f, i: int, b, contrib: np.ndarray) -> str:
        m = b.model
        std = np.asarray(b.coefficient_std)[:, 1] if b.coefficient_std is not None else np.full(len(contrib), np.nan)
        p = np.asarray(b.inclusion)[:, 1] if b.inclusion is not None else np.full(len(contrib), np.nan)
        fn = f"{b.natural_frequency_hz:.2f} ± {b.natural_frequency_std_hz:.2f} Hz"
        lines = [f"**beam {i + 1}**, window ending {f.t_s:.1f} s: natural frequency {fn}, "
                 f"amplitude {1e3 * b.amplitude_m:.2f} mm, integration NRMSE {b.error:.3f}", "",
                 *[f"    {e}" for e in m.equations(precision=4)], "",
                 "| term of v' | coefficient | ± std | × RMS(term)/RMS(v') | P(active) |",
                 "|---|---:|---:|---:|---:|"]
        for k, name in enumerate(m.term_names):
            c = m.coefficients[k, 1]
            if c == 0 and not (p[k] >= TERM_MIN_P):
                continue
            lines.append(f"| {name} | {c:.4g} | {std[k]:.2g} | {contrib[k]:+.3f} | {p[k]:.2f} |")
        lines += ["", "z: relative displacement [m], v: its velocity [m/s], F: base acceleration [m/s²]; "
                  "± std and P(active) over a block-bootstrap ensemble of the window"]
        return "\n".join(lines)

    def _terms(self, pre: str, b, contrib: np.ndarray, spread: np.ndarray) -> None:
        """Horizontal bars, one per term shown (named on the axis, with its value), +-1 std as black lines."""
        m = b.model
        p = np.asarray(b.inclusion)[:, 1] if b.inclusion is not None else np.zeros(len(contrib))
        active = [k for k in range(len(contrib)) if m.coefficients[k, 1] != 0]
        likely = sorted((k for k in range(len(contrib)) if k not in active and p[k] >= TERM_MIN_P), key=lambda k: -p[k])
        show = sorted(active + likely[:max(0, TERM_ROWS - len(active))])
        if not show:
            return
        c, sd = contrib[show], spread[show]
        rows = np.arange(len(show), dtype=float)[::-1]  # the first term on top
        hi = max(1.0, float(np.nanmax(np.abs(c) + sd)))
        fr = Frame((-1.05 * hi, 1.05 * hi), (-0.6, len(show) - 0.4))
        left, right = fr(np.minimum(c, 0), rows), fr(np.maximum(c, 0), rows)
        half_h = 0.35 * FRAME_H / (len(show) + 0.2)
        col = BEAM_COLORS[int(pre[-1]) - 1]
        self.rec.log(f"{pre}/terms", self.rr.Boxes2D(
            centers=(left + right) / 2, half_sizes=np.column_stack([(right[:, 0] - left[:, 0]) / 2 + 1e-6,
                                                                    np.full(len(show), half_h)]),
            colors=col, radii=self.rr.Radius.ui_points(2.0)))
        zero = fr([0, 0], [-0.6, len(show) - 0.4])
        lines = [zero] + [fr([ci - si, ci + si], [y, y]) for ci, si, y in zip(c, sd, rows) if si > 0]
        self.rec.log(f"{pre}/terms/spread", self.rr.LineStrips2D(lines, colors=MODEL_COLOR,
                                                                 radii=self.rr.Radius.ui_points(1.5)))
        names = [f"{m.term_names[k]} {contrib[k]:+.2f}" for k in show]
        fr.log(self.rec, self.rr, pre + "/terms", "coefficient × RMS(term) / RMS(v')", "", (rows, names))

    def _restoring(self, f) -> None:
        """Restoring force per unit mass over the linear stiffness, -(r + base)/k [mm], against z [mm]."""
        if f.accel is None or f.base is None:
            return
        pts, curves = {}, {}
        for i, b in enumerate(f.beams):
            k = b.stiffness_per_mass
            if not k > 0:
                continue
            z = f.measured[:, i, 0]
            pts[i] = (1e3 * z, -1e3 * (f.accel[:, i] + f.base) / k)
            zg = np.linspace(z.min(), z.max(), 101)
            lib = b.model.library
            xs = np.column_stack([zg, 0 * zg])
            theta = lib.transform(xs, 0 * zg) if lib.forcing else lib.transform(xs)
            curves[i] = (1e3 * zg, -1e3 * (theta @ b.model.coefficients[:, 1]) / k)
        if not pts:
            return
        fr = Frame(limits(np.concatenate([p[0] for p in pts.values()]), symmetric=True),
                   limits(np.concatenate([p[1] for p in pts.values()]), symmetric=True))
        for i in pts:
            self.rec.log(f"restoring/beam{i + 1}", self.rr.Points2D(fr(*pts[i]), colors=BEAM_COLORS[i],
                                                                   radii=self.rr.Radius.ui_points(1.5)))
            g = fr(*curves[i])
            g = g[(g[:, 1] >= 0) & (g[:, 1] <= FRAME_H)]
            self.rec.log(f"restoring/beam{i + 1}/model", self.rr.LineStrips2D(
                [g], colors=MODEL_COLOR, radii=self.rr.Radius.ui_points(2.0)))
        fr.log(self.rec, self.rr, "restoring", "z [mm]", "−(r + base)/ωn² [mm]")

    def _spectra(self, t: np.ndarray, raw: np.ndarray) -> None:
        """H1 base -> tip, coherence and PSDs of the last SPECTRUM_SPAN_S, every SPECTRUM_EVERY_S."""
        fs = self.fs_hz
        self._buf = np.concatenate([self._buf, raw])[-int(SPECTRUM_SPAN_S * fs):]
        nper = int(SPECTRUM_SEGMENT_S * fs)
        if len(self._buf) < 2 * nper or t[-1] - self._spectrum_t < SPECTRUM_EVERY_S:
            return
        self._spectrum_t = float(t[-1])
        self.rec.set_time("time", duration=float(t[-1]))
        f, h1, coh, pxx = transfer_estimates(self._buf, fs, nper)
        keep = (f > 0) & (f <= SPECTRUM_MAX_HZ)
        f, h1, coh, pxx = f[keep], h1[keep], coh[keep], pxx[keep]
        xl = (0.0, SPECTRUM_MAX_HZ)
        # logarithmic magnitudes, drawn between round decades
        lp = np.log10(np.maximum(pxx, 1e-30))
        fr = Frame(xl, _decades(lp), SPECTRUM_W)
        for j, c in enumerate(CHANNELS):
            self.rec.log(f"spectra/psd/{c}", self.rr.LineStrips2D([fr(f, lp[:, j])], colors=COLORS[c],
                                                                 radii=self.rr.Radius.ui_points(1.2)))
        fr.log(self.rec, self.rr, "spectra/psd", "frequency [Hz]", "PSD [(m/s²)²/Hz]", _decade_ticks(fr.ylim))
        lh = np.log10(np.maximum(np.abs(h1), 1e-30))
        good = coh >= COHERENCE_MIN
        fh = Frame(xl, _decades(lh[good] if good.any() else np.array([-1.0, 1.0])), SPECTRUM_W)
        fc = Frame(xl, (0.0, 1.05), SPECTRUM_W)
        for j, c in enumerate(("tip1", "tip2")):
            runs = _runs(good[:, j])
            pts = [fh(f[a:b], lh[a:b, j]) for a, b in runs]
            dots = np.concatenate(pts) if pts else np.zeros((0, 2))
            self.rec.log(f"spectra/transmissibility/{c}", self.rr.Points2D(dots, colors=COLORS[c],
                                                                          radii=self.rr.Radius.ui_points(2.5)))
            self.rec.log(f"spectra/coherence/{c}", self.rr.LineStrips2D([fc(f, coh[:, j])], colors=COLORS[c],
                                                                       radii=self.rr.Radius.ui_points(1.2)))
        fh.log(self.rec, self.rr, "spectra/transmissibility", "frequency [Hz]", "|H1| tip/base [-]",
               _decade_ticks(fh.ylim))
        fc.log(self.rec, self.rr, "spectra/coherence", "frequency [Hz]", "coherence [-]")

    def _backbone(self, f) -> None:
        """Add the window's (amplitude, natural frequency) per beam to the backbones and show the last ones."""
        for i, b in enumerate(f.beams):
            if np.isfinite(b.natural_frequency_hz):
                pts = self._backbone_pts[i]
                pts.append((1e3 * b.amplitude_m, b.natural_frequency_hz, b.natural_frequency_std_hz))
                del pts[:-BACKBONE_POINTS]
        arrays = [np.array(p) for p in self._backbone_pts if p]
        if not arrays:
            return
        every = np.concatenate(arrays)
        fr = Frame((0.0, 1.1 * float(every[:, 0].max()) or 1.0), limits(every[:, 1], pad=0.3))
        for i, a in enumerate(np.array(p) for p in self._backbone_pts):
            if len(a) == 0:
                continue
            self.rec.log(f"backbone/beam{i + 1}", self.rr.Points2D(fr(a[:, 0], a[:, 1]), colors=BEAM_COLORS[i],
                                                                  radii=self.rr.Radius.ui_points(3.0)))
            ok = np.isfinite(a[:, 2])
            lo = np.maximum(a[ok, 1] - a[ok, 2], fr.ylim[0])
            hi = np.minimum(a[ok, 1] + a[ok, 2], fr.ylim[1])
            bars = [fr([x, x], [l, h]) for x, l, h in zip(a[ok, 0], lo, hi)]
            if bars:
                self.rec.log(f"backbone/beam{i + 1}/spread", self.rr.LineStrips2D(bars, colors=BEAM_COLORS[i]))
        fr.log(self.rec, self.rr, "backbone", "amplitude of z [mm]", "natural frequency [Hz]")

    def log_event(self, e: dict) -> None:
        if self.rec is None:
            return
        self.rec.set_time("time", duration=float(e["t"]))
        text = e.get("message") or ", ".join(f"{k}={v}" for k, v in e.items() if k not in ("t", "equations"))
        level = "WARN" if e.get("kind") in ("drop", "crc", "disconnect", "reconnect") else "INFO"
        self.rec.log("events", self.rr.TextLog(f"{e['kind']}: {text}", level=level))

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
