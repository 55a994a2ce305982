"""Rolling-window SINDy of the rig in physical coordinates, warm-started from the last window.

Per window (``window_s`` long, every ``hop_s``), per beam i, from the
unfiltered 2 kHz samples:

1. relative acceleration r_i = tip_i - base;
2. band-limited integration at the full rate to v_i, z_i (ident.physical);
3. low-pass below 50 Hz (zero-phase inside the window) and decimation to
   ``fs_ident_hz``; the integration's edge transients are trimmed;
4. SINDy with states (z_i, v_i), derivatives (v_i, r_i) (measured, not
   differentiated) and the base acceleration as the forcing column: the
   sweep chosen by integration error, then SQP refinement started from the
   better of the sweep's choice and the previous window's model (warm start).

The second equation reads v' = -w^2 z - 2 zeta w v + ... - a_base, so the
coefficient of z is the identified stiffness per mass (1/s^2) and its
square root over 2 pi the natural frequency. A change of active set from
one window to the next is a model-change event.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .filters import lowpass_zero_phase
from .library import PolynomialForcingLibrary
from .model import SindyModel
from .physical import edge_samples, integrate_band
from .sindy import integration_errors, refine, sweep
from .simulate import simulate


@dataclass(frozen=True)
class RollingConfig:
    fs_hz: float = field(default=2000.0, metadata={"gt": 0.0})
    window_s: float = field(default=4.0, metadata={"gt": 0.0})
    hop_s: float = field(default=1.0, metadata={"gt": 0.0})
    fs_ident_hz: float = field(default=200.0, metadata={"gt": 0.0})
    f_lo_hz: float = field(default=2.0, metadata={"gt": 0.0})
    degree: int = field(default=3, metadata={"min": 1, "max": 5})
    refine: bool = True


@dataclass(frozen=True)
class BeamFit:
    model: SindyModel
    error: float  # integration NRMSE on the window
    stiffness_per_mass: float  # -coefficient of z in v' [1/s^2]
    natural_frequency_hz: float
    active: tuple[str, ...]  # "v' : z", ... the non-zero terms
    changed: bool  # active set differs from the previous window's


@dataclass(frozen=True)
class WindowFit:
    t_s: float  # end of the window, seconds since the start of the stream
    beams: tuple[BeamFit, BeamFit]
    t: np.ndarray  # times of the identification samples
    measured: np.ndarray  # (n, 2, 2): sample, beam, (z, v)
    predicted: np.ndarray  # (n, 2, 2): the model integrated over the window with the measured base


def _active(model: SindyModel) -> tuple[str, ...]:
    return tuple(f"{eq}: {t}" for eq, terms in model.as_dict().items() for t in terms)


def window_coordinates(x: np.ndarray, cfg: RollingConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(base, z (n, 2), v (n, 2), r (n, 2)) at fs_ident_hz from unfiltered (N, 3) samples, ends trimmed."""
    base = x[:, 0]
    r = x[:, 1:] - base[:, None]
    v, z = integrate_band(r, cfg.fs_hz, cfg.f_lo_hz)
    step = max(1, int(round(cfg.fs_hz / cfg.fs_ident_hz)))
    fs_id = cfg.fs_hz / step
    cut = min(50.0, 0.45 * fs_id)
    allsig = lowpass_zero_phase(np.column_stack([base, z, v, r]), cfg.fs_hz, cut)
    e = edge_samples(cfg.fs_hz, cfg.f_lo_hz)
    keep = allsig[e:-e:step]
    return keep[:, 0], keep[:, 1:3], keep[:, 3:5], keep[:, 5:7]


class RollingIdentifier:
    """Feed blocks of unfiltered samples; get a WindowFit every hop."""

    def __init__(self, cfg: RollingConfig = RollingConfig()):
        if cfg.hop_s > cfg.window_s:
            raise ValueError("hop_s must not exceed window_s")
        if 2 * edge_samples(cfg.fs_hz, cfg.f_lo_hz) >= cfg.window_s * cfg.fs_hz / 2:
            raise ValueError(f"window_s {cfg.window_s} s is too short for integration above {cfg.f_lo_hz} Hz; "
                             f"give at least {4 / cfg.f_lo_hz:.1f} s")
        self.cfg = cfg
        self.n_window = int(round(cfg.window_s * cfg.fs_hz))
        self.n_hop = int(round(cfg.hop_s * cfg.fs_hz))
        self._buf = np.zeros((0, 3))
        self._since = 0
        self.n_seen = 0
        self._prev: list[SindyModel | None] = [None, None]
        self.lib = PolynomialForcingLibrary(2, cfg.degree, True, ("z", "v"))

    def step(self, block: np.ndarray) -> list[WindowFit]:
        x = np.asarray(block, float)
        if x.ndim != 2 or x.shape[1] != 3:
            raise ValueError(f"rolling identification needs blocks of shape (n, 3), got {x.shape}")
        out = []
        self._buf = np.concatenate([self._buf, x])[-self.n_window:]
        self._since += len(x)
        self.n_seen += len(x)
        if len(self._buf) >= self.n_window and self._since >= self.n_hop:
            self._since = 0
            out.append(self.fit_window(self._buf, self.n_seen / self.cfg.fs_hz))
        return out

    def fit_window(self, x: np.ndarray, t_end: float) -> WindowFit:
        cfg = self.cfg
        base, z, v, r = window_coordinates(x, cfg)
        n = len(base)
        t = t_end - (n - 1 - np.arange(n)) / (cfg.fs_hz / max(1, int(round(cfg.fs_hz / cfg.fs_ident_hz))))
        fits, pred = [], np.zeros((n, 2, 2))
        for i in range(2):
            xs = np.column_stack([z[:, i], v[:, i]])
            dx = np.column_stack([v[:, i], r[:, i]])
            sw = sweep(self.lib, xs, dx, t, base)
            cands = [sw.coefficients[sw.chosen]]
            prev = self._prev[i]
            if prev is not None:
                cands.append(prev.coefficients)
            sims = simulate(self.lib, np.stack(cands), xs[0], t, base, bound=20 * np.abs(xs).max())
            errs = integration_errors(sims.x, xs)
            start = cands[int(np.argmin(errs))]
            coefs, err = start, float(np.min(errs))
            if cfg.refine and np.count_nonzero(start):
                ref = refine(self.lib, start, xs, t, base, maxiter=30)
                coefs, err = ref.coefficients, ref.error_after
            model = SindyModel(self.lib, coefs)
            k = -model.coefficients[self.lib.names.index("z"), 1]
            fn = float(np.sqrt(k) / (2 * np.pi)) if k > 0 else float("nan")
            act = _active(model)
            changed = prev is not None and act != _active(prev)
            fits.append(BeamFit(model, err, float(k), fn, act, changed))
            self._prev[i] = model
            pred[:, i, :] = simulate(self.lib, coefs, xs[0], t, base, bound=20 * np.abs(xs).max()).x
        meas = np.stack([np.column_stack([z[:, i], v[:, i]]) for i in range(2)], axis=1)
        return WindowFit(t_end, (fits[0], fits[1]), t, meas, pred)
