"""The shaker's programme: base acceleration and tip kicks as pure functions of absolute time.

A sine at ``frequency_hz`` (or a linear sweep) whose amplitude ramps up over
``ramp_s`` and then follows ``steps`` (each reached over ``STEP_TRANSITION_S``),
plus optional broadband noise (a seeded random-phase multisine, so it too is a
function of time, not of how the stream is cut into blocks). Kicks are
half-sine acceleration pulses on one tip whose area is the velocity change,
like a hammer blow; they move the rig between coexisting regimes.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

STEP_TRANSITION_S = 0.2
NOISE_COMPONENTS = 256


@dataclass(frozen=True)
class Step:
    t_s: float = field(metadata={"min": 0.0, "max": 1e7})
    amplitude_m_per_s2: float = field(metadata={"min": 0.0, "max": 1e4})


@dataclass(frozen=True)
class Kick:
    t_s: float = field(metadata={"min": 0.0, "max": 1e7})
    beam: int = field(default=1, metadata={"choices": (1, 2)})
    velocity_m_per_s: float = field(default=0.3, metadata={"min": -100.0, "max": 100.0})
    duration_s: float = field(default=0.005, metadata={"gt": 0.0, "max": 10.0})


@dataclass(frozen=True)
class Sweep:
    start_hz: float = field(metadata={"gt": 0.0, "max": 1e4})
    stop_hz: float = field(metadata={"gt": 0.0, "max": 1e4})
    duration_s: float = field(metadata={"gt": 0.0, "max": 1e7})


@dataclass(frozen=True)
class Excitation:
    frequency_hz: float = field(default=12.3, metadata={"gt": 0.0, "max": 1e4})
    amplitude_m_per_s2: float = field(default=1.93, metadata={"min": 0.0, "max": 1e4})
    ramp_s: float = field(default=2.0, metadata={"min": 0.0, "max": 1e6})
    steps: tuple[Step, ...] = field(default=(), metadata={"max_len": 1000})
    kicks: tuple[Kick, ...] = field(default=(), metadata={"max_len": 1000})
    sweep: Sweep | None = None
    noise_rms_m_per_s2: float = field(default=0.0, metadata={"min": 0.0, "max": 1e4})
    noise_band_hz: tuple[float, ...] = field(default=(2.0, 40.0), metadata={"len": 2, "gt": 0.0, "max": 1e4})
    seed: int = field(default=0, metadata={"min": 0, "max": 2**63 - 1})

    def __post_init__(self) -> None:
        if self.noise_band_hz[0] >= self.noise_band_hz[1]:
            raise ValueError(f"excitation.noise_band_hz must be [low, high] with low < high, got {list(self.noise_band_hz)}")


def amplitude(exc: Excitation, t: np.ndarray) -> np.ndarray:
    """Sine amplitude envelope at times ``t`` (ramp, then steps)."""
    t = np.asarray(t, float)
    a = np.full(t.shape, exc.amplitude_m_per_s2)
    prev = exc.amplitude_m_per_s2
    for st in sorted(exc.steps, key=lambda s: s.t_s):
        frac = np.clip((t - st.t_s) / STEP_TRANSITION_S, 0.0, 1.0)
        a = np.where(t >= st.t_s, prev + (st.amplitude_m_per_s2 - prev) * frac, a)
        prev = st.amplitude_m_per_s2
    if exc.ramp_s > 0:
        a = a * np.clip(t / exc.ramp_s, 0.0, 1.0)
    return a


def phase(exc: Excitation, t: np.ndarray) -> np.ndarray:
    """Phase of the sine in radians: constant frequency, or a linear sweep that then holds."""
    t = np.asarray(t, float)
    if exc.sweep is None:
        return 2 * np.pi * exc.frequency_hz * t
    s = exc.sweep
    k = (s.stop_hz - s.start_hz) / s.duration_s
    tc = np.minimum(t, s.duration_s)
    ph = 2 * np.pi * (s.start_hz * tc + 0.5 * k * tc**2)
    return ph + 2 * np.pi * s.stop_hz * np.maximum(t - s.duration_s, 0.0)


def _noise_components(exc: Excitation) -> tuple[np.ndarray, np.ndarray, float]:
    rng = np.random.default_rng([exc.seed, 7])
    lo, hi = exc.noise_band_hz
    freqs = np.linspace(lo, hi, NOISE_COMPONENTS)
    phases = rng.uniform(0, 2 * np.pi, NOISE_COMPONENTS)
    amp = exc.noise_rms_m_per_s2 * np.sqrt(2.0 / NOISE_COMPONENTS)
    return freqs, phases, amp


def base_acceleration(exc: Excitation, t: np.ndarray) -> np.ndarray:
    """Base acceleration [m/s^2] at times ``t``."""
    t = np.asarray(t, float)
    a = amplitude(exc, t) * np.sin(phase(exc, t))
    if exc.noise_rms_m_per_s2 > 0:
        freqs, phases, amp = _noise_components(exc)
        ramp = np.clip(t / exc.ramp_s, 0.0, 1.0) if exc.ramp_s > 0 else 1.0
        for f0, p0 in zip(freqs, phases):
            a = a + amp * ramp * np.sin(2 * np.pi * f0 * t + p0)
    return a


def kick_acceleration(exc: Excitation, t: np.ndarray) -> np.ndarray:
    """Extra tip accelerations (n, 2) from the kicks: half-sines whose area is the velocity change."""
    t = np.asarray(t, float)
    out = np.zeros(t.shape + (2,))
    for k in exc.kicks:
        inside = (t >= k.t_s) & (t <= k.t_s + k.duration_s)
        if inside.any():
            peak = np.pi * k.velocity_m_per_s / (2 * k.duration_s)
            out[inside, k.beam - 1] += peak * np.sin(np.pi * (t[inside] - k.t_s) / k.duration_s)
    return out
