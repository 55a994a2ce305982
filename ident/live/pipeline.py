"""One processing pipeline for live acquisition and replay: samples in, filtered signals, regimes, models out.

Pure science (no I/O, no threads): ``Pipeline.step(block)`` takes a block of
unfiltered samples (n, 3: base, tip1, tip2 in m/s^2) from any source and
returns what the sinks need: the causal 50 Hz low-pass of every channel (the
raw block is kept beside it, since impacts live above 50 Hz), relative
motions (tip minus base, filtered), the regime monitor's windows and changes,
the rolling identification's fits, and the events (``kind`` "regime_start"
once, at the window that decides it, the third (``regimes.decide``): the regime the stream starts in, with its
confidence; then "regime" at each change and "model"; "regime_note" once,
with a message, when the drive has stayed too slow for the regime monitor's
window for 2 s: see ``ident.live.regimes.MIN_PERIODS``). Times are seconds
since the start of the stream, counted in samples.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..ensemble import KERNELS as ENSEMBLE_KERNELS, block_bootstrap
from ..filters import CAUSAL_KERNELS, KERNELS as FILTER_KERNELS, design_lowpass, lowpass_block, lowpass_start
from ..library import PolynomialForcingLibrary
from ..physical import KERNELS as PHYSICAL_KERNELS
from ..simulate import KERNELS as INTEGRATION_KERNELS, PARALLEL_MIN_WORK, kernels_cached as _cached, simulate
from ..sindy import KERNELS as SINDY_KERNELS, integration_errors
from .regimes import (KERNELS as REGIME_KERNELS, RegimeChange, RegimeConfig, RegimeMonitor, RegimeWindow, SlowDriveWatch,
                      starting)
from .rolling import RollingConfig, RollingIdentifier, WindowFit, window_coordinates


@dataclass(frozen=True)
class PipelineConfig:
    fs_hz: float = field(default=2000.0, metadata={"gt": 0.0})
    cutoff_hz: float = field(default=50.0, metadata={"gt": 0.0})
    identify: bool = True
    regime: RegimeConfig = field(default_factory=RegimeConfig)
    rolling: RollingConfig = field(default_factory=RollingConfig)


@dataclass(frozen=True)
class StepOutput:
    t: np.ndarray  # (n,) s
    raw: np.ndarray  # (n, 3)
    filtered: np.ndarray  # (n, 3) causal low-pass
    relative: np.ndarray  # (n, 2) filtered tip - base
    windows: list[RegimeWindow]
    changes: list[RegimeChange]
    fits: list[WindowFit]
    events: list[dict]


def rolling_config(fs_hz: float, window_s: float = 4.0, hop_s: float = 1.0) -> RollingConfig:
    """The rolling identification's window and hop in seconds, checked (``check_window``)."""
    check_window(window_s, hop_s)
    return RollingConfig(fs_hz=fs_hz, window_s=window_s, hop_s=hop_s)


def check_window(window_s: float, hop_s: float) -> None:
    """--window and --hop as the rolling identification needs them, before any output is made."""
    if not (window_s > 0 and hop_s > 0):
        raise ValueError(f"--window and --hop must be positive seconds, got {window_s} and {hop_s}")
    if hop_s > window_s:
        raise ValueError(f"--hop {hop_s:g} s is longer than --window {window_s:g} s; windows would skip data")
    shortest = 4.0 / RollingConfig.f_lo_hz  # the integration's edges (``RollingIdentifier``)
    if window_s <= shortest:
        raise ValueError(f"--window {window_s:g} s is too short: the integration to displacement needs more than "
                         f"{shortest:g} s")


def _per_term(model, values: np.ndarray, keep: np.ndarray) -> dict[str, dict[str, float]]:
    """{"v'": {term: value}} for the terms where keep is true, the model's equation names."""
    names = model.library.names
    return {f"{s}'": {names[k]: float(values[k, i]) for k in range(len(names)) if keep[k, i]}
            for i, s in enumerate(model.state_names)}


def model_records(fit: WindowFit) -> list[dict]:
    """One plain-data record per beam of a rolling-window fit: the model with its uncertainty.

    ``t`` is the window's end in data time (seconds since the start of the stream); ``coefficients``
    the model's non-zero terms; ``coefficient_std`` and ``inclusion_probability`` the ensemble's spread
    and the share of its models holding each term (every term some model holds); ``amplitude_m`` and
    ``natural_frequency_hz`` are the window's point on the beam's backbone. A window that needed a new
    model has two records: the sweep's (``final`` false) and the refined one that follows.
    """
    out = []
    for i, b in enumerate(fit.beams):
        c = b.model.coefficients
        held = (b.inclusion > 0) | (c != 0)
        out.append({"t": fit.t_s, "beam": i + 1, "equations": b.model.equations(), "coefficients": b.model.as_dict(),
                    "coefficient_std": _per_term(b.model, b.coefficient_std, held),
                    "inclusion_probability": _per_term(b.model, b.inclusion, held),
                    "active": list(b.active), "integration_nrmse": b.error,
                    "natural_frequency_hz": b.natural_frequency_hz,
                    "natural_frequency_std_hz": b.natural_frequency_std_hz, "amplitude_m": b.amplitude_m,
                    "stiffness_per_mass": b.stiffness_per_mass, "changed": b.changed, "final": fit.final})
    return out


MONITOR_KERNELS = CAUSAL_KERNELS + REGIME_KERNELS  # the causal filter's and the regime monitor's (always run)
IDENTIFY_KERNELS = (INTEGRATION_KERNELS + SINDY_KERNELS + ENSEMBLE_KERNELS + FILTER_KERNELS
                    + PHYSICAL_KERNELS)  # ... the rolling fits run


def kernels_cached(identify: bool = True) -> bool | None:
    """Whether numba's disk cache holds every kernel ``warm_up(identify)`` compiles (None: cannot tell)."""
    return _cached(MONITOR_KERNELS + (IDENTIFY_KERNELS if identify else ()))


def warm_up(identify: bool = True) -> None:
    """Compile the numba kernels the pipeline uses, on tiny inputs: the causal filter's and the regime
    monitor's always, and with ``identify`` the rolling identification's (the window's filters and integration; RK4
    integration: serial, lockstep, parallel; integration errors; the ensemble's STLSQ). numba caches the machine code on disk,
    so only the first run after an install pays (seconds); loading even a cached kernel costs a moment the
    first time in a process (a tenth of a second for the first), so callers run this before data flows and
    no window waits for the compiler or the loader."""
    lowpass_block(lowpass_start(design_lowpass(64.0, 10.0), 3), np.zeros((8, 3)))
    RegimeMonitor(RegimeConfig(fs_hz=64.0)).step(np.zeros((64, 3)))  # two windows of 32 samples
    if not identify:
        return
    window_coordinates(np.zeros((1600, 3)), RollingConfig(fs_hz=400.0, fs_ident_hz=200.0))
    lib = PolynomialForcingLibrary(2, 3, True, ("z", "v"))
    coefs = np.zeros((lib.n_terms, 2))
    coefs[lib.names.index("v"), 0] = 1.0
    coefs[lib.names.index("z"), 1] = -1.0
    t = np.linspace(0.0, 1.0, 64)
    simulate(lib, coefs, np.zeros(2), t, np.zeros_like(t))
    simulate(lib, np.stack([coefs, 2 * coefs]), np.zeros(2), t, np.zeros_like(t))  # one pattern: lockstep
    n_batch = PARALLEL_MIN_WORK // (len(t) - 1) + 1
    sim = simulate(lib, np.repeat(coefs[None], n_batch, axis=0), np.zeros(2), t, np.zeros_like(t))
    integration_errors(sim.x, np.ones((len(t), 2)))
    block_bootstrap(np.eye(4), np.ones((4, 2)), 0.5, n_models=2, n_blocks=2)


def parse_gaps(text: str | None) -> tuple[float, float] | None:
    """--gaps G1,G2: the tips' stopper gaps in metres for the regime monitor (None: it learns them)."""
    if text is None:
        return None
    try:
        gaps = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise ValueError(f"--gaps takes two gaps in metres, as 0.0027,0.0027; got {text!r}") from None
    if len(gaps) != 2 or not all(np.isfinite(g) and g > 0 for g in gaps):
        raise ValueError(f"--gaps takes two positive gaps in metres (tip 1, tip 2), as 0.0027,0.0027; got {text!r}")
    return gaps


class Pipeline:
    """``identifier``: what runs the rolling identification, where a caller wants it elsewhere than in
    this process (``replay.play.RemoteIdentifier``: in a second process, its fits a few blocks behind);
    anything with ``cfg`` (the pipeline's rolling config), ``step(block)`` and ``finish()`` giving
    WindowFits. Default: a ``RollingIdentifier(cfg.rolling)`` here."""

    def __init__(self, cfg: PipelineConfig = PipelineConfig(), identifier=None):
        if cfg.regime.fs_hz != cfg.fs_hz or cfg.rolling.fs_hz != cfg.fs_hz:
            cfg = replace(cfg, regime=replace(cfg.regime, fs_hz=cfg.fs_hz),
                          rolling=replace(cfg.rolling, fs_hz=cfg.fs_hz))
        self.cfg = cfg
        self._lp = lowpass_start(design_lowpass(cfg.fs_hz, cfg.cutoff_hz), 3)
        self.monitor = RegimeMonitor(cfg.regime)
        if not cfg.identify:
            identifier = None
        elif identifier is None:
            identifier = RollingIdentifier(cfg.rolling)
        elif identifier.cfg != cfg.rolling:
            raise ValueError("the identifier's rolling config is not the pipeline's")
        self.rolling = identifier
        self.n_seen = 0
        self._started = False
        self._slow = SlowDriveWatch(cfg.regime.window_s)  # the regime_note about too short a regime window

    def step(self, block: np.ndarray) -> StepOutput:
        x = np.asarray(block, float)
        if x.ndim != 2 or x.shape[1] != 3:
            raise ValueError(f"pipeline blocks must have shape (n, 3): base, tip1, tip2; got {x.shape}")
        if not np.all(np.isfinite(x)):
            raise ValueError("block contains NaN or inf samples; the source must drop or repair them")
        t = (self.n_seen + np.arange(len(x))) / self.cfg.fs_hz
        self.n_seen += len(x)
        self._lp, y = lowpass_block(self._lp, x)
        rel = y[:, 1:] - y[:, :1]
        windows, changes = self.monitor.step(x)
        # after the monitor: an identifier in another process works on this block while this one goes on
        fits = self.rolling.step(x) if self.rolling is not None else []
        return self._output(t, x, y, rel, windows, changes, fits)

    def finish(self) -> StepOutput:
        """At the end of a stream: what is still pending (the last window's refined fit, if any)."""
        fits = self.rolling.finish() if self.rolling is not None else []
        e = np.zeros((0, 3))
        return self._output(np.zeros(0), e, e, np.zeros((0, 2)), [], [], fits)

    def _output(self, t, x, y, rel, windows, changes, fits) -> StepOutput:
        events = []
        w = starting(windows) if not self._started else None
        if w is not None:
            self._started = True
            events.append({"t": w.t_s, "kind": "regime_start", "regime": w.label,
                           "confidence": w.confidence})
        slow = self._slow.update(windows)
        if slow is not None:
            events.append({"t": slow.t_s, "kind": "regime_note", "message": slow.message})
        events += [{"t": c.t_s, "kind": "regime", "regime": c.regime, "previous": c.previous,
                    "confidence": c.confidence} for c in changes]
        for f in fits:
            for i, b in enumerate(f.beams):
                if b.changed:
                    events.append({"t": f.t_s, "kind": "model", "beam": i + 1, "equations": b.model.equations(),
                                   "natural_frequency_hz": b.natural_frequency_hz})
        events.sort(key=lambda e: e["t"])
        return StepOutput(t, x, y, rel, windows, changes, fits, events)
