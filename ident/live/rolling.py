"""Rolling-window SINDy of the rig in physical coordinates, warm-started from the last window.

Per window (``window_s`` long, every ``hop_s``), per beam i, from the
unfiltered 2 kHz samples:

1. relative acceleration r_i = tip_i - base;
2. low-pass below 50 Hz (zero-phase inside the window), decimation to
   400 Hz, band-limited integration to v_i, z_i (ident.physical), decimation
   to ``fs_ident_hz``; the integration's edge transients are trimmed;
4. SINDy with states (z_i, v_i), derivatives (v_i, r_i) (measured, not
   differentiated) and the base acceleration as the forcing column. Warm
   start: while the previous window's model integrates the new window within
   ``keep_factor`` of the error it was fitted with (or below ``keep_nrmse``), it is kept (one
   integration, no regression); otherwise the sweep chosen by integration
   error runs and SQP refinement starts from the better of its choice and
   the previous model.

A window that needs a new model gives two fits: the first as soon as its last sample is in
(the sweep's choice, ``final`` False), the refined one with the next block or ``finish()``
(``final`` True); the refined model is the next window's warm start. So the first model update
of every window never waits for the optimiser, and the sequence of fits is the same for any
split of the stream into blocks.

The second equation reads v' = -w^2 z - 2 zeta w v + ... - a_base, so the
coefficient of z is the identified stiffness per mass (1/s^2) and its
square root over 2 pi the natural frequency. A change of active set from
one window to the next is a model-change event.

Uncertainty: every window's model comes with an ensemble (ident.ensemble: STLSQ on
``ensemble_models`` block-bootstrap resamples of the window's rows at half the model's smallest
active coefficient per equation, Fasel et al. 2022): per coefficient its standard deviation over
the ensemble and the probability that the term is active, and the natural frequency's spread. With the window's
displacement amplitude (sqrt(2) times the RMS of z) the natural frequency forms the beam's
backbone (frequency against amplitude). The resamples are drawn from a generator seeded by
the window's index, so the output does not depend on how the stream is cut into blocks.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..ensemble import block_bootstrap, column_rms, model_thresholds
from ..filters import lowpass_zero_phase
from ..library import PolynomialForcingLibrary
from ..model import SindyModel
from ..physical import edge_samples, integrate_band
from ..sindy import integration_errors, refine, sweep
from ..simulate import simulate


@dataclass(frozen=True)
class RollingConfig:
    fs_hz: float = field(default=2000.0, metadata={"gt": 0.0})
    window_s: float = field(default=4.0, metadata={"gt": 0.0})
    hop_s: float = field(default=1.0, metadata={"gt": 0.0})
    fs_ident_hz: float = field(default=200.0, metadata={"gt": 0.0})
    f_lo_hz: float = field(default=2.0, metadata={"gt": 0.0})
    degree: int = field(default=3, metadata={"min": 1, "max": 5})
    refine: bool = True
    # Warm start: keep the previous window's model while its integration error on the new
    # window stays within this factor of the error it had when it was fitted, or below
    # keep_nrmse. In a steady free regime the old model's error on the next window is a few
    # percent; an impacting beam's polynomial model predicts the next window at 0.1-0.3
    # however often it is refitted (its in-window fit is better, but only in-window); a
    # regime change puts the old model's error near 1.
    keep_factor: float = field(default=1.5, metadata={"gt": 1.0})
    keep_nrmse: float = field(default=0.3, metadata={"min": 0.0})
    ensemble_models: int = field(default=32, metadata={"min": 2})
    ensemble_blocks: int = field(default=8, metadata={"min": 2})


@dataclass(frozen=True)
class BeamFit:
    model: SindyModel
    error: float  # integration NRMSE on the window
    stiffness_per_mass: float  # -coefficient of z in v' [1/s^2]
    natural_frequency_hz: float
    active: tuple[str, ...]  # "v' : z", ... the non-zero terms
    changed: bool  # active set differs from the previous window's
    coefficient_std: np.ndarray  # (K, n) spread of each coefficient over the ensemble
    inclusion: np.ndarray  # (K, n) probability that each term is active (share of the ensemble)
    natural_frequency_std_hz: float  # spread of the natural frequency over the ensemble
    amplitude_m: float  # sqrt(2) RMS of the relative displacement z over the window (the backbone's abscissa)
    threshold: float  # the STLSQ threshold (unit-RMS columns) the model's active set came from
    term_rms: np.ndarray  # (K,) RMS of each library term over the window (a term's size is coefficient x this)


@dataclass(frozen=True)
class WindowFit:
    t_s: float  # end of the window, seconds since the start of the stream
    beams: tuple[BeamFit, BeamFit]
    t: np.ndarray  # times of the identification samples
    measured: np.ndarray  # (n, 2, 2): sample, beam, (z, v)
    predicted: np.ndarray  # (n, 2, 2): the model integrated over the window with the measured base
    final: bool = True  # False: a refined fit of this window follows (the first fit is the sweep's choice)
    base: np.ndarray | None = None  # (n,) the base acceleration at the identification samples [m/s^2]
    accel: np.ndarray | None = None  # (n, 2) the relative accelerations r_i = v_i' there [m/s^2]


def _active(model: SindyModel) -> tuple[str, ...]:
    return tuple(f"{eq}: {t}" for eq, terms in model.as_dict().items() for t in terms)


def _states(measured: np.ndarray, accel: np.ndarray, i: int) -> tuple[np.ndarray, np.ndarray]:
    """Beam i's states (z, v) and their derivatives (v, r) from a window's (n, 2, 2) states and (n, 2)
    relative accelerations, as contiguous (n, 2) arrays."""
    xs = np.ascontiguousarray(measured[:, i, :])
    return xs, np.column_stack([xs[:, 1], accel[:, i]])


def _divergence_bound(xs: np.ndarray) -> float:
    """A trajectory beyond 20 times the largest measured state has diverged (sweep's and refine's default)."""
    return 20 * float(np.abs(xs).max())


INTEGRATION_FS_HZ = 400.0  # integrate here: trapezoid error at 12.3 Hz is 0.3 % (1.2 % at 200 Hz)


def decimation(cfg: RollingConfig) -> tuple[int, float, int]:
    """(step to the integration rate, that rate, step from it to ``fs_ident_hz``): the two decimations
    of ``window_coordinates``, which ``window_sample_index`` and ``ident_rate`` must follow exactly."""
    step1 = max(1, int(cfg.fs_hz // INTEGRATION_FS_HZ))
    fs1 = cfg.fs_hz / step1
    return step1, fs1, max(1, int(round(fs1 / cfg.fs_ident_hz)))


def window_coordinates(x: np.ndarray, cfg: RollingConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(base, z (n, 2), v (n, 2), r (n, 2)) at fs_ident_hz from unfiltered (N, 3) samples, ends trimmed.

    Zero-phase low-pass below 50 Hz, decimation to about 400 Hz, band-limited
    integration there, then decimation to ``fs_ident_hz``.
    """
    step1, fs1, step2 = decimation(cfg)
    cut = min(50.0, 0.45 * min(fs1, cfg.fs_ident_hz))
    lp = lowpass_zero_phase(x, cfg.fs_hz, cut)[::step1]
    base = lp[:, 0]
    r = lp[:, 1:] - base[:, None]
    v, z = integrate_band(r, fs1, cfg.f_lo_hz)
    e = edge_samples(fs1, cfg.f_lo_hz)
    sl = slice(e, len(base) - e, step2)
    return base[sl], z[sl], v[sl], r[sl]


def window_sample_index(n_window: int, cfg: RollingConfig) -> np.ndarray:
    """Indices into the window's samples of the rows window_coordinates keeps (trimmed ends, decimated)."""
    step1, fs1, step2 = decimation(cfg)
    n1 = len(range(0, n_window, step1))
    e = edge_samples(fs1, cfg.f_lo_hz)
    return np.arange(e, n1 - e, step2) * step1


def ident_rate(cfg: RollingConfig) -> float:
    """The rate of the window's coordinates (samples per second)."""
    _, fs1, step2 = decimation(cfg)
    return fs1 / step2


class RollingIdentifier:
    """Feed blocks of unfiltered samples; get a WindowFit every hop (windows end on multiples of the hop
    counted from the first sample, so the fits do not depend on how the stream is cut into blocks)."""

    def __init__(self, cfg: RollingConfig = RollingConfig()):
        if cfg.hop_s > cfg.window_s:
            raise ValueError("hop_s must not exceed window_s")
        if 2 * edge_samples(cfg.fs_hz, cfg.f_lo_hz) >= cfg.window_s * cfg.fs_hz / 2:
            raise ValueError(f"window_s {cfg.window_s} s is too short for integration above {cfg.f_lo_hz} Hz; "
                             f"give more than {4 / cfg.f_lo_hz:g} s")
        self.cfg = cfg
        self.n_window = int(round(cfg.window_s * cfg.fs_hz))
        self.n_hop = int(round(cfg.hop_s * cfg.fs_hz))
        self._buf = np.zeros((0, 3))
        self._since = 0
        self.n_seen = 0
        self._prev: list[SindyModel | None] = [None, None]
        self._prev_err = [np.inf, np.inf]
        self._prev_lam = [0.0, 0.0]
        self.windows = 0
        self.refits = 0  # windows that needed the full sweep (the rest kept the warm-start model)
        self._pending = None  # (the last window's first fit, the beams whose new models await SQP refinement)
        self.lib = PolynomialForcingLibrary(2, cfg.degree, True, ("z", "v"))

    def step(self, block: np.ndarray) -> list[WindowFit]:
        """The fits completed by this block: a window's first fit as soon as its last sample is in, and the
        refined fit of a window that needed a new model when the next block (or ``finish``) comes."""
        x = np.asarray(block, float)
        if x.ndim != 2 or x.shape[1] != 3:
            raise ValueError(f"rolling identification needs blocks of shape (n, 3), got {x.shape}")
        out = self.finish()
        i = 0
        while i < len(x):  # windows end on the hop grid, however the stream is cut into blocks
            piece = x[i:i + self.n_hop - self._since]
            i += len(piece)
            self._buf = np.concatenate([self._buf, piece])[-self.n_window:]
            self._since += len(piece)
            self.n_seen += len(piece)
            if self._since == self.n_hop:
                self._since = 0
                if len(self._buf) >= self.n_window:
                    out += self.finish()
                    out.append(self.fit_window(self._buf, self.n_seen / self.cfg.fs_hz))
        return out

    def finish(self) -> list[WindowFit]:
        """The refined fit of the last window, if one is pending (call at the end of a stream)."""
        if self._pending is None:
            return []
        (fit, beams), self._pending = self._pending, None
        return [self._refined(fit, beams)]

    def fit_window(self, x: np.ndarray, t_end: float) -> WindowFit:
        """A window's first fit: the warm-start model where it still holds, else the sweep's model; where a
        new model was needed its SQP refinement is left pending (``finish``), so that the first model
        update of every window comes without waiting for the optimiser."""
        cfg = self.cfg
        base, z, v, r = window_coordinates(x, cfg)
        # sample k of the stream is at k / fs and t_end = (index of the window's last sample + 1) / fs
        t = t_end - (len(x) - window_sample_index(len(x), cfg)) / cfg.fs_hz
        meas = np.stack([z, v], axis=2)  # (n, beam, (z, v))
        fits, pred = [], np.zeros_like(meas)
        index = self.windows
        self.windows += 1
        todo = []
        for i in range(2):
            xs, dx = _states(meas, r, i)
            bound = _divergence_bound(xs)
            prev = self._prev[i]
            keep_err = np.inf
            if prev is not None:
                keep_sim = simulate(self.lib, prev.coefficients, xs[0], t, base, bound=bound).x
                keep_err = float(integration_errors(keep_sim[None], xs)[0])
            lam = self._prev_lam[i]
            if prev is not None and (keep_err <= cfg.keep_factor * self._prev_err[i] or keep_err <= cfg.keep_nrmse):
                coefs, err = prev.coefficients, keep_err  # the warm-start model still holds
                pred[:, i, :] = keep_sim
            else:
                self.refits += 1
                sw = sweep(self.lib, xs, dx, t, base)
                # the better of the sweep's choice and the previous model (the sweep integrated its choice
                # with the same bound, the previous model was integrated above; a tie goes to the sweep)
                err = float(sw.errors[sw.chosen])
                if err <= keep_err:
                    coefs, lam = sw.coefficients[sw.chosen], float(sw.thresholds[sw.chosen])
                    pred[:, i, :] = simulate(self.lib, coefs, xs[0], t, base, bound=bound).x
                else:
                    coefs, err = prev.coefficients, keep_err
                    pred[:, i, :] = keep_sim
                self._prev_err[i] = err
                if cfg.refine and np.count_nonzero(coefs):
                    todo.append(i)
            fits.append(self._beam_fit(i, coefs, err, lam, xs, dx, base, prev, index, 0))
        fit = WindowFit(t_end, (fits[0], fits[1]), t, meas, pred, final=not todo, base=base, accel=r)
        if todo:
            self._pending = (fit, tuple(todo))
        return fit

    def _refined(self, fit: WindowFit, beams: tuple[int, ...]) -> WindowFit:
        """SQP refinement (Stender et al. 2019) of the window's new models, from the sweep's choice; the
        window is the last one fitted (its index ``windows - 1``, which seeds its ensemble)."""
        fits, pred = list(fit.beams), fit.predicted.copy()
        for i in beams:
            xs, dx = _states(fit.measured, fit.accel, i)
            quick = fits[i]
            ref = refine(self.lib, quick.model.coefficients, xs, fit.t, fit.base, maxiter=15, gradient="forward")
            self._prev_err[i] = ref.error_after
            # no previous model: a change of active set was reported with the first fit
            fits[i] = self._beam_fit(i, ref.coefficients, ref.error_after, quick.threshold, xs, dx, fit.base, None,
                                     self.windows - 1, 1)
            pred[:, i, :] = simulate(self.lib, ref.coefficients, xs[0], fit.t, fit.base, bound=_divergence_bound(xs)).x
        return replace(fit, beams=(fits[0], fits[1]), predicted=pred, final=True)

    def _beam_fit(self, i, coefs, err, lam, xs, dx, base, prev, index, stage) -> BeamFit:
        """The beam's fit with its ensemble; the model becomes the next window's warm start."""
        cfg = self.cfg
        model = SindyModel(self.lib, coefs)
        iz = self.lib.names.index("z")
        k = -model.coefficients[iz, 1]
        fn = float(np.sqrt(k) / (2 * np.pi)) if k > 0 else float("nan")
        act = _active(model)
        changed = prev is not None and act != _active(prev)
        theta = self.lib.transform(xs, base)
        rms = column_rms(theta)
        rng = np.random.default_rng((index, stage))  # the window's index: the same resamples for any block split
        ens = block_bootstrap(theta, dx, model_thresholds(theta, coefs, lam, rms=rms), n_models=cfg.ensemble_models,
                              n_blocks=cfg.ensemble_blocks, rng=rng, rms=rms)
        k_m = -ens.coefficients[:, iz, 1]
        fn_m = np.sqrt(k_m[k_m > 0]) / (2 * np.pi)
        fn_std = float(fn_m.std()) if fn_m.size > 1 else float("nan")
        amp = float(np.sqrt(2.0) * np.sqrt(np.mean(xs[:, 0] ** 2)))
        self._prev[i] = model
        self._prev_lam[i] = lam
        return BeamFit(model, err, float(k), fn, act, changed, ens.std, ens.inclusion, fn_std, amp, lam, rms)
