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
from numba import njit

from .filters import design_highpass, zero_phase_kernel, zero_phase_setup


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
    sos, zi, pad = zero_phase_setup(design_highpass(fs_hz, f_lo_hz, 2))
    a2 = np.require(a.reshape(a.shape[0], -1), requirements="CW")  # (n, channels), one compiled signature
    v = _integrate(a2, 1.0 / fs_hz, sos, zi, pad)
    return v.reshape(a.shape), _integrate(v, 1.0 / fs_hz, sos, zi, pad).reshape(a.shape)


@njit(cache=True, nogil=True)
def _integrate(x, dt, sos, zi, pad):  # pragma: no cover - compiled
    """One integration along axis 0 of x (n, channels): the mean removed, the cumulative trapezoid
    (scipy.integrate.cumulative_trapezoid with initial 0: (dt (x_k + x_k-1)) / 2 summed in order), the
    zero-phase high-pass (``ident.filters.zero_phase``) and the mean removed again, each in the order numpy
    and scipy computed it before (``_column_means``), so the result is the same bit for bit; one compiled
    call instead of a dozen numpy and scipy calls on small arrays."""
    n, c = x.shape
    y = np.empty((n, c))
    m = _column_means(x)
    for j in range(c):
        y[0, j] = 0.0
        prev = x[0, j] - m[j]
        for i in range(1, n):
            cur = x[i, j] - m[j]
            y[i, j] = y[i - 1, j] + dt * (cur + prev) / 2.0
            prev = cur
    y = zero_phase_kernel(sos, zi, y, pad)
    m = _column_means(y)
    for i in range(n):
        for j in range(c):
            y[i, j] -= m[j]
    return y


@njit(cache=True, nogil=True)
def _column_means(x):  # pragma: no cover - compiled
    """x.mean(axis=0) with each column summed pairwise (``_pairwise_sum``), as numpy sums a column stored
    contiguously; the integration's inputs were such columns (scipy's filters return time along the last
    axis), so these are the means it always had, bit for bit, and pairwise sums are the more accurate."""
    n, c = x.shape
    m = np.empty(c)
    for j in range(c):
        m[j] = _pairwise_sum(x, j, 0, n) / n
    return m


@njit(cache=True, nogil=True)
def _pairwise_sum(x, j, lo, n):  # pragma: no cover - compiled
    """Sum of x[lo:lo + n, j] in numpy's pairwise order (numpy/_core/src/umath/loops_utils.h.src): the range
    halved (the first half a multiple of 8 long) until at most 128 terms are left (``_pairwise_leaf``), the
    halves' sums added on the way back. Numpy recurses; this walks the same tree with an explicit stack
    (numba's disk cache crashed on loading a recursive kernel)."""
    if n <= 128:
        return _pairwise_leaf(x, j, lo, n)
    st_lo, st_n, st_done = np.empty(128, np.int64), np.empty(128, np.int64), np.empty(128, np.bool_)
    vals = np.empty(128)
    top, nv = 1, 0
    st_lo[0], st_n[0], st_done[0] = lo, n, False
    while top > 0:
        top -= 1
        a, m, done = st_lo[top], st_n[top], st_done[top]
        if m <= 128:
            vals[nv] = _pairwise_leaf(x, j, a, m)
            nv += 1
        elif done:  # both halves summed: left, then right on the value stack
            vals[nv - 2] = vals[nv - 2] + vals[nv - 1]
            nv -= 1
        else:
            m2 = m // 2
            m2 -= m2 % 8
            st_lo[top], st_n[top], st_done[top] = a, m, True
            st_lo[top + 1], st_n[top + 1], st_done[top + 1] = a + m2, m - m2, False  # right, summed second
            st_lo[top + 2], st_n[top + 2], st_done[top + 2] = a, m2, False  # left, summed first
            top += 3
    return vals[0]


@njit(cache=True, nogil=True)
def _pairwise_leaf(x, j, lo, n):  # pragma: no cover - compiled
    """numpy's pairwise sum of at most 128 terms: below 8 in sequence, else eight interleaved partial sums
    combined as a tree, then the remainder in sequence."""
    if n < 8:
        res = 0.0
        for i in range(lo, lo + n):
            res += x[i, j]
        return res
    r0, r1, r2, r3 = x[lo, j], x[lo + 1, j], x[lo + 2, j], x[lo + 3, j]
    r4, r5, r6, r7 = x[lo + 4, j], x[lo + 5, j], x[lo + 6, j], x[lo + 7, j]
    i = 8
    while i < n - (n % 8):
        k = lo + i
        r0 += x[k, j]
        r1 += x[k + 1, j]
        r2 += x[k + 2, j]
        r3 += x[k + 3, j]
        r4 += x[k + 4, j]
        r5 += x[k + 5, j]
        r6 += x[k + 6, j]
        r7 += x[k + 7, j]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += x[lo + i, j]
        i += 1
    return res


KERNELS = (_integrate,)  # the compiled kernels (ident.live.pipeline.warm_up)
