"""Excitation signals as functions of time, sampled on any uniform grid t = k / rate_hz, k = 0 .. n - 1.

- Programme: a sine whose frequency and amplitude are piecewise constant over segments, joined by
  raised-cosine transitions; the phase is the integral of 2 pi f(t), so it stays continuous (stepped sine,
  the regime programme).
- Sweep: linear, f(t) = f0 + (f1 - f0) t / T, phase 2 pi (f0 t + (f1 - f0) t^2 / (2 T)); or logarithmic
  (exponential), phase 2 pi f0 T / ln(f1 / f0) (exp(t ln(f1 / f0) / T) - 1) (Farina, AES 108th conv.,
  2000); up or down; raised-cosine fades at both ends.
- FourierSeries: sum of cosines on the lines k / P of a period P; band-limited random noise (Gaussian
  line amplitudes, uniform phases, P longer than the record so that it does not repeat) and random-phase
  odd multisines (odd lines only, one of each three consecutive odd lines left out at random: the
  "random-odd" design of Pintelon and Schoukens, System Identification, 2nd ed., 2012, sec. 2.7).
- Hammer: haversine pulses F sin^2(pi (t - t0) / T) on [t0, t0 + T], T = 0.3 to 2 ms, with an optional
  second, smaller hit a few ms later (a double hit).
- Gate (raised-cosine fade in and out), LinearGain (piecewise-linear amplitude), Sum, Scaled.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


def _times(rate_hz: float, n: int) -> np.ndarray:
    return np.arange(n) / rate_hz


def raised_cosine(x: np.ndarray) -> np.ndarray:
    """0 for x <= 0, 1 for x >= 1, (1 - cos(pi x)) / 2 between."""
    x = np.clip(x, 0.0, 1.0)
    return 0.5 - 0.5 * np.cos(np.pi * x)


class Signal:
    """A function of time; subclasses define sample() and describe()."""

    def sample(self, rate_hz: float, n: int) -> np.ndarray:
        raise NotImplementedError

    def describe(self) -> dict:
        raise NotImplementedError


@dataclass
class Segment:
    duration_s: float
    frequency_hz: float
    amplitude: float


@dataclass
class Programme(Signal):
    """Sine through segments; each segment's first transition_s blends from the previous one.

    The programme starts from initial_frequency_hz (default: the first segment's), initial_amplitude and
    phase_rad, so that consecutive programmes join smoothly (see final_phase_rad).
    """

    segments: list[Segment]
    transition_s: float = 1.0
    phase_rad: float = 0.0
    initial_frequency_hz: float | None = None
    initial_amplitude: float = 0.0

    def _phase_amplitude(self, rate_hz: float, n: int) -> tuple[np.ndarray, np.ndarray]:
        t = _times(rate_hz, n)
        prev_f = self.segments[0].frequency_hz if self.initial_frequency_hz is None else self.initial_frequency_hz
        prev_a = self.initial_amplitude
        freq = np.full(n, prev_f)
        amp = np.full(n, prev_a)
        start = 0.0
        for seg in self.segments:
            w = raised_cosine((t - start) / self.transition_s)
            inside = t >= start
            freq[inside] = (prev_f + (seg.frequency_hz - prev_f) * w)[inside]
            amp[inside] = (prev_a + (seg.amplitude - prev_a) * w)[inside]
            start += seg.duration_s
            prev_f, prev_a = seg.frequency_hz, seg.amplitude
        phase = self.phase_rad + 2 * np.pi * np.concatenate(([0.0], np.cumsum(0.5 * (freq[1:] + freq[:-1])))) / rate_hz
        return phase, amp

    def sample(self, rate_hz: float, n: int) -> np.ndarray:
        phase, amp = self._phase_amplitude(rate_hz, n)
        return amp * np.sin(phase)

    def final_phase_rad(self, rate_hz: float, n: int) -> float:
        """The phase at the last of n samples, to start the next programme from."""
        return float(self._phase_amplitude(rate_hz, n)[0][-1] % (2 * np.pi))

    def describe(self) -> dict:
        return {"type": "programme", "transition_s": self.transition_s,
                "initial_frequency_hz": self.initial_frequency_hz,
                "initial_amplitude": self.initial_amplitude,
                "segments": [{"duration_s": s.duration_s, "frequency_hz": s.frequency_hz,
                              "amplitude": s.amplitude} for s in self.segments]}


@dataclass
class Sweep(Signal):
    start_hz: float
    stop_hz: float
    duration_s: float
    amplitude: float
    law: str = "linear"  # linear | log
    fade_s: float = 0.5
    start_s: float = 0.0

    def sample(self, rate_hz: float, n: int) -> np.ndarray:
        t = _times(rate_hz, n) - self.start_s
        tt = np.clip(t, 0.0, self.duration_s)
        f0, f1, T = self.start_hz, self.stop_hz, self.duration_s
        if self.law == "linear":
            phase = 2 * np.pi * (f0 * tt + (f1 - f0) * tt**2 / (2 * T))
        elif self.law == "log":
            r = math.log(f1 / f0)
            phase = 2 * np.pi * f0 * T / r * (np.exp(tt * r / T) - 1.0)
        else:
            raise ValueError("law must be linear or log")
        gate = raised_cosine(t / self.fade_s) * raised_cosine((self.duration_s - t) / self.fade_s)
        return self.amplitude * gate * np.sin(phase)

    def describe(self) -> dict:
        return {"type": "sweep", "law": self.law, "start_hz": self.start_hz, "stop_hz": self.stop_hz,
                "duration_s": self.duration_s, "start_s": self.start_s, "amplitude": self.amplitude,
                "direction": "up" if self.stop_hz > self.start_hz else "down"}


@dataclass
class FourierSeries(Signal):
    """sum_k a_k cos(2 pi k t / P + phi_k); P in whole seconds so every integer rate has whole periods."""

    period_s: int
    lines: np.ndarray  # integer k
    amplitudes: np.ndarray
    phases_rad: np.ndarray
    info: dict = field(default_factory=dict)

    def sample(self, rate_hz: float, n: int) -> np.ndarray:
        n_per = self.period_s * rate_hz
        if abs(n_per - round(n_per)) > 1e-6:
            raise ValueError("the period must hold a whole number of samples")
        n_per = int(round(n_per))
        if self.lines.max() >= n_per // 2:
            raise ValueError("lines above the grid's Nyquist frequency")
        spec = np.zeros(n_per // 2 + 1, dtype=complex)
        spec[self.lines] = 0.5 * n_per * self.amplitudes * np.exp(1j * self.phases_rad)
        one = np.fft.irfft(spec, n_per)
        return np.tile(one, n // n_per + 1)[:n]

    @property
    def rms(self) -> float:
        return float(np.sqrt(0.5 * np.sum(self.amplitudes**2)))

    def describe(self) -> dict:
        return {**self.info, "period_s": self.period_s, "rms": self.rms,
                "band_hz": [float(self.lines.min() / self.period_s), float(self.lines.max() / self.period_s)]}


def band_random(low_hz: float, high_hz: float, rms: float, duration_s: float,
                rng: np.random.Generator) -> FourierSeries:
    """Gaussian band-limited noise (flat spectrum in [low, high]) that does not repeat within duration_s."""
    period = int(math.ceil(1.25 * duration_s))
    lines = np.arange(max(1, int(math.ceil(low_hz * period))), int(math.floor(high_hz * period)) + 1)
    amp = np.abs(rng.normal(size=len(lines)) + 1j * rng.normal(size=len(lines)))
    sig = FourierSeries(period, lines, amp, rng.uniform(0, 2 * np.pi, len(lines)), {"type": "band_random"})
    sig.amplitudes *= rms / sig.rms
    return sig


def odd_multisine(low_hz: float, high_hz: float, rms: float, period_s: int,
                  rng: np.random.Generator) -> FourierSeries:
    """Random-phase random-odd multisine with flat amplitude on the excited lines of [low, high]."""
    odd = np.arange(1, int(math.floor(high_hz * period_s)) + 1, 2)
    odd = odd[odd >= low_hz * period_s]
    keep = np.ones(len(odd), dtype=bool)
    for g in range(0, len(odd) - 2, 3):
        keep[g + rng.integers(3)] = False
    lines = odd[keep]
    sig = FourierSeries(period_s, lines, np.ones(len(lines)), rng.uniform(0, 2 * np.pi, len(lines)),
                        {"type": "odd_multisine"})
    sig.amplitudes *= rms / sig.rms
    return sig


@dataclass
class Hit:
    time_s: float
    peak: float
    width_s: float


@dataclass
class Hammer(Signal):
    hits: list[Hit]

    def sample(self, rate_hz: float, n: int) -> np.ndarray:
        t = _times(rate_hz, n)
        out = np.zeros(n)
        for h in self.hits:
            i0 = max(0, int(math.floor(h.time_s * rate_hz)))
            i1 = min(n, int(math.ceil((h.time_s + h.width_s) * rate_hz)) + 1)
            tt = t[i0:i1] - h.time_s
            inside = (tt >= 0) & (tt <= h.width_s)
            out[i0:i1] += np.where(inside, h.peak * np.sin(np.pi * tt / h.width_s) ** 2, 0.0)
        return out

    def describe(self) -> dict:
        return {"type": "hammer", "hits": [{"time_s": h.time_s, "peak": h.peak, "width_s": h.width_s}
                                           for h in self.hits]}


def hammer_hit(time_s: float, peak: float, width_s: float, double: bool,
               rng: np.random.Generator) -> list[Hit]:
    """One hit, or a hit followed 1-4 ms later by a bounce of 10-40 % of its peak."""
    hits = [Hit(time_s, peak, width_s)]
    if double:
        hits.append(Hit(time_s + width_s + rng.uniform(1e-3, 4e-3), peak * rng.uniform(0.1, 0.4),
                        width_s * rng.uniform(0.8, 1.2)))
    return hits


@dataclass
class Gate(Signal):
    signal: Signal
    start_s: float
    stop_s: float
    fade_s: float

    def sample(self, rate_hz: float, n: int) -> np.ndarray:
        t = _times(rate_hz, n)
        g = raised_cosine((t - self.start_s) / self.fade_s) * raised_cosine((self.stop_s - t) / self.fade_s)
        return g * self.signal.sample(rate_hz, n)

    def describe(self) -> dict:
        return {"type": "gate", "start_s": self.start_s, "stop_s": self.stop_s, "fade_s": self.fade_s,
                "signal": self.signal.describe()}


@dataclass
class LinearGain(Signal):
    signal: Signal
    times_s: list[float]
    gains: list[float]

    def sample(self, rate_hz: float, n: int) -> np.ndarray:
        return np.interp(_times(rate_hz, n), self.times_s, self.gains) * self.signal.sample(rate_hz, n)

    def describe(self) -> dict:
        return {"type": "linear_gain", "times_s": self.times_s, "gains": self.gains,
                "signal": self.signal.describe()}


@dataclass
class Sum(Signal):
    parts: list[Signal]

    def sample(self, rate_hz: float, n: int) -> np.ndarray:
        out = np.zeros(n)
        for p in self.parts:
            out += p.sample(rate_hz, n)
        return out

    def describe(self) -> dict:
        return {"type": "sum", "parts": [p.describe() for p in self.parts]}


@dataclass
class Scaled(Signal):
    signal: Signal
    factor: float

    def sample(self, rate_hz: float, n: int) -> np.ndarray:
        return self.factor * self.signal.sample(rate_hz, n)

    def describe(self) -> dict:
        return {"type": "scaled", "factor": self.factor, "signal": self.signal.describe()}
