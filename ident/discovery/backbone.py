"""The backbone of a free decay: a mode's frequency against its amplitude, measured on the record.

A hammer-hit record holds the test a stepped sine at several levels would run: after each hit the
mode rings down through every amplitude from the hit's to the noise floor, and its frequency follows
the stiffness the motion sees. First-order harmonic balance (Worden & Tomlinson 2001, ch. 3; Nayfeh &
Mook 1979) gives the shape of that backbone for each smooth stiffness law:

- a cubic k3 z^3:        w(A) = w0 (1 + 3/8 k3 A^2 / w0^2)       the shift grows with A^2;
- k2 z |z|:              w(A) = w0 (1 + 4/(3 pi) k2 A / w0^2)     the shift grows with A;
- a stopper beyond gap g: no shift below g, then one that grows towards its stiffness's
  (``catalogue.describing_stiffness`` gives each law's equivalent stiffness, ``Backbone.shape_error``
  fits the measured backbone against it).

So where the held-out error cannot tell a cubic from a quadratic stiffness (both bend the decay's
frequency; the paired test over a few blocks has no power to separate them), the decay's own backbone
can. ``free_decay`` measures it: the response band-passed around the mode (0.6-1.6 of its frequency),
its analytic signal's phase rate and modulus, averaged over ten periods, from 20 ms after each hit
until the amplitude falls to a tenth of its start; ``Backbone.line(p)`` gives the best line
of frequency against amplitude^p and its RMS error.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import butter, find_peaks, hilbert, sosfiltfilt
from scipy.stats import f as fisher

SETTLE_S = 0.02  # after a hit: the hammer's contact and the band-pass's own ringing
FLOOR = 0.1  # the decay is followed down to this share of its starting amplitude
SMOOTH_PERIODS = 10
MIN_POINTS = 4
# the level of the backbone's tests (``Backbone.set_aside``); at five points the ratio it asks of two laws'
# RMS errors is 3.05, the constant ratio these tests replaced (stop 92)
ALPHA = 0.05


@dataclass(frozen=True)
class Backbone:
    """A mode's free-decay backbone at one response: amplitude (the response's own unit) and frequency
    (Hz), one point per ``SMOOTH_PERIODS`` periods, every decay after a hit in turn."""

    location: str
    mode_hz: float
    amplitude: np.ndarray
    frequency_hz: np.ndarray

    def line(self, power: float) -> tuple[float, float, float]:
        """(frequency at zero amplitude, shift at the largest amplitude, RMS error) of the best line of
        frequency against (amplitude / its largest)^power."""
        x = (self.amplitude / self.amplitude.max()) ** power
        X = np.column_stack([np.ones_like(x), x])
        coef = np.linalg.lstsq(X, self.frequency_hz, rcond=None)[0]
        rms = float(np.sqrt(np.mean((self.frequency_hz - X @ coef) ** 2)))
        return float(coef[0]), float(coef[1]), rms

    def shape_error(self, stiffness: np.ndarray) -> float:
        """RMS error (Hz) of the best line of frequency against a law's describing stiffness at each point's
        amplitude (``catalogue.describing_stiffness``), its slope kept >= 0: the law's shape, its scale
        free (a decay glides the way the law's own sign says, or the law fits it no better than no glide)."""
        x = np.asarray(stiffness, float)
        X = np.column_stack([np.ones_like(x), x])
        coef = np.linalg.lstsq(X, self.frequency_hz, rcond=None)[0]
        fit = X @ coef if coef[1] > 0 else np.full_like(x, self.frequency_hz.mean())
        return float(np.sqrt(np.mean((self.frequency_hz - fit) ** 2)))

    def set_aside(self, errors: dict[str, float]) -> set[str]:
        """The laws (name: ``shape_error``) whose shape fits this backbone significantly worse than the best
        law's, where the best law's glide is itself significant; empty where it is not (a linear decay
        separates nothing).

        Each law's line has two numbers; its residuals over the backbone's n points are close to
        independent (each point averages its own ``SMOOTH_PERIODS`` periods; the band-pass remembers a few),
        so the ratio of two laws' squared errors is read against Fisher's F(n - 2, n - 2), and the best
        line against no glide at all (the frequencies' own spread) by the nested F(1, n - 2), both at
        ``ALPHA``. A fixed ratio of 3 asked as much of five points as of fifteen: independent seed 970's
        hammer-hit beam (a membrane cubic, 14 points) fitted the cubic's shape to 0.111 Hz and a quadratic
        stiffness's to 0.255 Hz (F = 5.25, p = 0.004) and stayed "quadratic stiffness"."""
        n = self.frequency_hz.size
        best = min(errors.values(), default=np.inf)
        if n < MIN_POINTS or not np.isfinite(best):
            return set()
        rss, flat = n * max(best, 1e-300) ** 2, n * float(np.var(self.frequency_hz))
        if (flat - rss) / (rss / (n - 2)) < fisher.ppf(1 - ALPHA, 1, n - 2):
            return set()
        clear = fisher.ppf(1 - ALPHA, n - 2, n - 2)
        return {law for law, e in errors.items() if (e / max(best, 1e-300)) ** 2 >= clear}

    def as_json(self) -> dict:
        f0, shift, _ = self.line(2.0)
        return {"location": self.location, "mode_hz": self.mode_hz, "amplitude": self.amplitude.tolist(),
                "frequency_hz": self.frequency_hz.tolist(), "rms_hz_by_power": {p: self.line(p)[2] for p in (1, 2)},
                "linear_hz": f0, "shift_hz_at_largest": shift}


def hits(u: np.ndarray, fs_hz: float, share: float = 0.3, apart_s: float = 0.2) -> np.ndarray:
    """Samples where the hammer strikes: peaks of |u| above ``share`` of the largest, ``apart_s`` apart."""
    u = np.abs(np.asarray(u, float))
    if not u.size or u.max() <= 0:
        return np.zeros(0, int)
    return find_peaks(u, height=share * u.max(), distance=max(1, int(apart_s * fs_hz)))[0]


def free_decay(name: str, y: np.ndarray, u: np.ndarray, fs_hz: float, mode_hz: float) -> Backbone | None:
    """The backbone of the mode at ``mode_hz`` in response ``y`` (any kind: a rate of the displacement
    changes its amplitude by a constant factor per frequency, not its shape in a narrow band), after the
    hits of the excitation ``u``; None when the decays give fewer than ``MIN_POINTS`` points."""
    y = np.asarray(y, float)
    high = min(1.6 * mode_hz, 0.45 * fs_hz)
    if not 0 < 0.6 * mode_hz < high or y.size < 64:
        return None
    try:
        a = hilbert(sosfiltfilt(butter(4, [0.6 * mode_hz, high], "bandpass", fs=fs_hz, output="sos"), y))
    except ValueError:  # a record shorter than the filter's padding
        return None
    freq = np.gradient(np.unwrap(np.angle(a))) * fs_hz / (2 * np.pi)
    amp = np.abs(a)
    w = max(1, int(SMOOTH_PERIODS * fs_hz / mode_hz))
    kernel = np.ones(w) / w
    starts = hits(u, fs_hz)
    amps, freqs = [], []
    for p, end in zip(starts, list(starts[1:]) + [y.size]):
        seg = slice(p + int(SETTLE_S * fs_hz), end - int(SETTLE_S * fs_hz))
        aa, ff = amp[seg], freq[seg]
        if aa.size < 2 * w:
            continue
        ka, kf = np.convolve(aa, kernel, "valid"), np.convolve(ff, kernel, "valid")
        keep = ka > FLOOR * ka[0]
        # up to the first point below the floor: noise can lift a later stretch above it again
        stop = int(np.argmin(keep)) if not keep.all() else keep.size
        amps.append(ka[:stop:w])
        freqs.append(kf[:stop:w])
    if not amps or sum(x.size for x in amps) < MIN_POINTS:
        return None
    return Backbone(name, float(mode_hz), np.concatenate(amps), np.concatenate(freqs))
