"""What a campaign's table says about one recording: its regimes and their durations, each beam's identified
equations and natural frequency, discovery's findings. Pure: samples in, dataclasses out (``ident batch``,
in ``ident.cli.batch``, reads the files and runs these as Dask tasks).

- :func:`regime_record`: the regime monitor (``ident.live.regimes``) run over the whole recording, its
  reported (debounced) regime as spans of time, and whether the drive was too slow for the window (the live
  pipeline's ``regime_note``, by the same rule). This one function is the campaign's only contact with the
  monitor's API.
- :func:`fit_beams`: per beam, SINDy in physical coordinates on one segment, as one window of the rolling
  identification (``ident.live.rolling``): relative acceleration r = tip - base low-passed, integrated
  band-limited to v and z, states (z, v), derivatives (v, r) measured, the base acceleration as the forcing
  column; the sweep chosen by integration error, then SQP refinement (Stender et al., Lubricants 2019, 7(8),
  64, eqs. 12-15). The second equation reads v' = -w^2 z - 2 zeta w v + ... - a_base, so the natural
  frequency is sqrt(-coefficient of z) / 2 pi.
- :func:`one_tone`: whether the excitation is one sine. Under one tone z, v and the forcing all lie in the
  plane of that sinusoid and stiffness, damping and forcing gain are not separately identifiable: the
  natural frequency of such a fit means nothing, and the row says so.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .library import PolynomialForcingLibrary
from .live.regimes import RegimeConfig, RegimeMonitor, SlowDrive, SlowDriveWatch, starting
from .live.rolling import RollingConfig, ident_rate, window_coordinates
from .model import SindyModel
from .sindy import refine, sweep

MIN_FIT_S = 2.0  # the band-limited integration above 2 Hz needs this much (its edge transients are trimmed)
ONE_TONE_SHARE = 0.9  # share of the excitation's power within one line (+-2 bins) that makes it one tone


@dataclass(frozen=True)
class RegimeSpan:
    regime: str  # linear, localized-1, localized-2, impacting-both
    start_s: float  # seconds since the first sample
    end_s: float


@dataclass(frozen=True)
class BeamIdentification:
    beam: int  # 1 or 2
    equations: tuple[str, ...]  # "z' = ...", "v' = ..."
    coefficients: dict[str, dict[str, float]]  # SindyModel.as_dict()
    stiffness_per_mass: float  # -coefficient of z in v' [1/s^2]
    natural_frequency_hz: float  # nan where the stiffness is not positive
    nrmse: float  # integration NRMSE of (z, v) over the segment


@dataclass(frozen=True)
class BeamsFit:
    start_s: float
    duration_s: float
    fs_ident_hz: float
    beams: tuple[BeamIdentification, BeamIdentification]
    one_tone_hz: float | None  # the excitation's frequency when it is one tone, else None


@dataclass(frozen=True)
class RegimeRecord:
    spans: tuple[RegimeSpan, ...]
    slow_drive: SlowDrive | None  # the first time the drive stayed too slow for the window (2 s running), if any


def regime_record(values: np.ndarray, fs_hz: float, window_s: float = RegimeConfig.window_s) -> RegimeRecord:
    """The reported regime over the recording as spans: the first from 0 s, each change ends one span and
    starts the next at the change's time, the last ends at the end of the data.

    The monitor reports a window's regime at the window's end (windows of window_s, 0.5 s by default, every
    0.25 s, a new regime after two windows); the starting regime, decided at the third window, holds from the
    start of the data. A window
    must hold ``MIN_PERIODS`` periods of the drive (3.6: 0.5 s down to 7.2 Hz; see ``ident.live.regimes``);
    where the drive held fewer for 2 s running, ``slow_drive`` says when and which window would do.
    """
    x = np.asarray(values, float)
    duration = len(x) / fs_hz
    windows, changes = RegimeMonitor(RegimeConfig(fs_hz=fs_hz, window_s=window_s)).step(x)
    if not windows:
        raise ValueError(f"{duration:.2f} s is shorter than one regime window; nothing to report")
    first = starting(windows) or windows[-1]  # a stream too short to decide the start: its last guess
    spans, start, label = [], 0.0, first.label
    for c in changes:
        spans.append(RegimeSpan(label, start, c.t_s))
        start, label = c.t_s, c.regime
    spans.append(RegimeSpan(label, start, duration))
    return RegimeRecord(tuple(spans), SlowDriveWatch(window_s).update(windows))


def regime_durations(spans: tuple[RegimeSpan, ...]) -> dict[str, float]:
    """Seconds spent in each regime (only regimes that occur), in the monitor's label order."""
    out: dict[str, float] = {}
    for s in spans:
        out[s.regime] = out.get(s.regime, 0.0) + (s.end_s - s.start_s)
    return out


def one_tone(base: np.ndarray, fs_hz: float) -> float | None:
    """The frequency [Hz] of a sine that holds at least ``ONE_TONE_SHARE`` of the excitation's power (its
    Hann-windowed spectrum's strongest line, +-2 bins), or None for a broadband, swept or stepped-sine mix."""
    b = np.asarray(base, float) - np.mean(base)
    if b.size < 16 or not np.any(b):
        return None
    p = np.abs(np.fft.rfft(b * np.hanning(b.size))) ** 2
    p[0] = 0.0
    k = int(np.argmax(p))
    share = p[max(0, k - 2):k + 3].sum() / p.sum()
    return float(k * fs_hz / b.size) if share >= ONE_TONE_SHARE else None


def fit_beams(values: np.ndarray, fs_hz: float, start_s: float = 5.0, duration_s: float | None = None,
              degree: int = 3) -> BeamsFit:
    """Each beam's model in physical coordinates on the segment from ``start_s`` (``duration_s`` long, or to
    the end): the rolling identification's coordinates and selection on one window, without warm start."""
    x = np.asarray(values, float)
    if x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"expected samples of base, tip1, tip2 (n, 3), got {x.shape}")
    total = len(x) / fs_hz
    if not 0 <= start_s < total:
        raise ValueError(f"--start {start_s:g} s is outside the recording (0 to {total:.2f} s)")
    i0 = int(round(start_s * fs_hz))
    i1 = len(x) if duration_s is None else min(len(x), i0 + int(round(duration_s * fs_hz)))
    seg = x[i0:i1]
    seg_s = len(seg) / fs_hz
    if seg_s < MIN_FIT_S:
        raise ValueError(f"--start {start_s:g} s leaves {seg_s:.2f} s of the {total:.2f} s recording; the fit "
                         f"needs at least {MIN_FIT_S:g} s")
    if not np.all(np.isfinite(seg)):
        raise ValueError("the segment holds NaN or inf samples")
    cfg = RollingConfig(fs_hz=fs_hz, window_s=seg_s, hop_s=seg_s, degree=degree)
    base, z, v, r = window_coordinates(seg, cfg)
    fs_ident = ident_rate(cfg)
    t = np.arange(len(base)) / fs_ident
    lib = PolynomialForcingLibrary(2, degree, True, ("z", "v"))
    beams = []
    for i in range(2):
        xs = np.column_stack([z[:, i], v[:, i]])
        dx = np.column_stack([v[:, i], r[:, i]])
        sw = sweep(lib, xs, dx, t, base)
        coefs, err = sw.coefficients[sw.chosen], float(sw.errors[sw.chosen])
        if np.count_nonzero(coefs):
            ref = refine(lib, coefs, xs, t, base, maxiter=15, gradient="forward")
            coefs, err = ref.coefficients, float(ref.error_after)
        model = SindyModel(lib, coefs)
        k = float(-model.coefficients[lib.names.index("z"), 1])
        fn = float(np.sqrt(k) / (2 * np.pi)) if k > 0 else float("nan")
        beams.append(BeamIdentification(i + 1, tuple(model.equations()), model.as_dict(), k, fn, err))
    return BeamsFit(start_s, seg_s, fs_ident, (beams[0], beams[1]), one_tone(base, fs_ident))
