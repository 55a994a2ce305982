"""Physical coordinates from accelerations: relative motion and band-limited integration.

A tip accelerometer minus the base accelerometer gives the relative
acceleration r = z'' of the tip against the clamp. Velocity and displacement
follow by integrating twice, but plain integration drifts without bound (any
offset or low-frequency noise grows like t and t^2). We integrate by the
trapezoid rule and remove the drift after each integration with a zero-phase
high-pass (Butterworth, ``f_lo_hz``, run forward and backward, so the
integrated signal keeps its phase at the rig's frequency) plus the mean. The
first and last 1 / f_lo_hz seconds carry the filter's edge transient; callers
that need clean ends trim them (``edge_samples``).
"""

from __future__ import annotations

import numpy as np
from scipy.integrate import cumulative_trapezoid
from .filters import design_highpass, zero_phase


def edge_samples(fs_hz: float, f_lo_hz: float) -> int:
    return int(np.ceil(fs_hz / f_lo_hz))


def integrate_band(a: np.ndarray, fs_hz: float, f_lo_hz: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """Velocity and displacement (drift removed above ``f_lo_hz``) from acceleration, along axis 0."""
    a = np.asarray(a, float)
    if not np.all(np.isfinite(a)):
        raise ValueError("acceleration contains NaN or inf: remove or interpolate those samples first")
    if not 0 < f_lo_hz < fs_hz / 2:
        raise ValueError(f"f_lo_hz must lie between 0 and Nyquist ({fs_hz / 2} Hz), got {f_lo_hz}")
    if a.shape[0] < 3 * edge_samples(fs_hz, f_lo_hz):
        raise ValueError(f"{a.shape[0]} samples are too few to integrate above {f_lo_hz} Hz; need at least "
                         f"{3 * edge_samples(fs_hz, f_lo_hz)} (three periods of the high-pass)")
    sos = design_highpass(fs_hz, f_lo_hz, 2)
    dt = 1.0 / fs_hz

    def integ(x):
        y = cumulative_trapezoid(x - x.mean(axis=0), dx=dt, axis=0, initial=0.0)
        y = zero_phase(sos, y)
        return y - y.mean(axis=0)

    v = integ(a)
    return v, integ(v)
