"""Time-delay embedding of a single measured signal (Takens 1981).

Delay from the first zero of the autocorrelation function; dimension from the
false-nearest-neighbour test of Kennel, Brown & Abarbanel (1992, Phys. Rev. A
45, 3403), with a Theiler window so that a point's neighbour in time does not
count as its neighbour in state space. The embedded state at sample i is
[x(t_i), x(t_i - d), ..., x(t_i - (m-1) d)], so it lines up with the forcing at t_i.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree


@dataclass(frozen=True)
class Embedding:
    """Delay ``delay`` (samples), dimension ``dimension``, embedded ``states`` (N - (m-1)d, m).

    ``start`` is the index of the original sample that row 0 belongs to;
    ``fnn_fraction[k]`` is the fraction of false neighbours at dimension k + 1.
    """

    delay: int
    dimension: int
    states: np.ndarray
    start: int
    fnn_fraction: tuple[float, ...]


def _check(x: np.ndarray) -> np.ndarray:
    x = np.asarray(x, dtype=float)
    if x.ndim != 1:
        raise ValueError(f"embedding needs one 1-D signal, got shape {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("signal contains NaN or inf: remove or interpolate those samples first")
    if x.size < 16:
        raise ValueError(f"signal has {x.size} samples; delay embedding needs at least 16")
    if np.std(x) == 0:
        raise ValueError("signal is constant: a constant carries no dynamics to embed")
    return x


def autocorrelation(x: np.ndarray) -> np.ndarray:
    """Biased autocorrelation of the demeaned signal, normalised to 1 at lag 0 (via FFT)."""
    x = _check(x)
    y = x - x.mean()
    n = y.size
    spec = np.fft.rfft(y, 2 * n)
    acf = np.fft.irfft(spec * np.conj(spec), 2 * n)[:n]
    return acf / acf[0]


def acf_delay(x: np.ndarray) -> int:
    """First zero crossing of the autocorrelation (the lag nearest to it), in samples.

    For a sine of period P samples this is P/4.
    """
    acf = autocorrelation(x)
    neg = np.flatnonzero(acf <= 0)
    if neg.size == 0:
        raise ValueError("the autocorrelation never crosses zero: the series is too short "
                         "for its slowest oscillation, or it has a trend; record longer or detrend")
    k = int(neg[0])
    return k if abs(acf[k]) < abs(acf[k - 1]) else k - 1


def delay_embed(x: np.ndarray, delay: int, dimension: int) -> np.ndarray:
    """Rows [x(i), x(i-d), ..., x(i-(m-1)d)] for i = (m-1)d .. N-1."""
    x = np.asarray(x, dtype=float)
    if delay < 1 or dimension < 1:
        raise ValueError(f"delay and dimension must be >= 1, got {delay}, {dimension}")
    span = (dimension - 1) * delay
    if x.shape[0] <= span + 1:
        raise ValueError(
            f"series of {x.shape[0]} samples is too short for dimension {dimension} at delay "
            f"{delay} (needs more than {span + 1}); record longer or lower the delay"
        )
    start = span
    return np.stack([x[start - j * delay : x.shape[0] - j * delay] for j in range(dimension)], axis=-1)


def false_neighbour_fractions(
    x: np.ndarray,
    delay: int,
    max_dim: int = 8,
    *,
    rtol: float = 15.0,
    atol: float = 2.0,
    theiler: int | None = None,
    max_points: int = 4000,
) -> list[float]:
    """Fraction of false nearest neighbours at dimensions 1 .. max_dim (Kennel et al. 1992).

    A neighbour is false when adding the next delay coordinate stretches the
    distance by more than ``rtol`` (criterion 1) or beyond ``atol`` times the
    attractor size (criterion 2).
    """
    x = _check(x)
    theiler = delay if theiler is None else theiler
    r_a = np.std(x)
    fractions = []
    for m in range(1, max_dim + 1):
        emb = delay_embed(x, delay, m + 1)  # the (m+1)-th column is the test coordinate
        pts, nxt = emb[:, :m], emb[:, m]
        idx = np.arange(pts.shape[0])
        if pts.shape[0] > max_points:
            idx = np.linspace(0, pts.shape[0] - 1, max_points).astype(int)
        tree = cKDTree(pts)
        k = min(2 * theiler + 2, pts.shape[0])
        dist, nb = tree.query(pts[idx], k=k)
        far = np.abs(nb - idx[:, None]) > theiler
        has = far.any(axis=1)
        first = np.argmax(far, axis=1)
        rows = np.flatnonzero(has)
        d_m = dist[rows, first[rows]]
        j = nb[rows, first[rows]]
        i = idx[rows]
        extra = np.abs(nxt[i] - nxt[j])
        # Ratio test, with a floor far below the attractor size: on exactly
        # periodic data both distances are round-off and their ratio means nothing.
        floor = 1e-9 * r_a
        crit1 = (extra > rtol * d_m) & (extra > floor)
        crit2 = np.sqrt(d_m**2 + extra**2) / r_a > atol
        false = crit1 | crit2
        fractions.append(float(false.mean()) if false.size else 1.0)
    return fractions


def fnn_dimension(x: np.ndarray, delay: int, max_dim: int = 8, threshold: float = 0.01, **kw) -> tuple[int, list[float]]:
    """Smallest dimension whose false-neighbour fraction is below ``threshold``."""
    fr = false_neighbour_fractions(x, delay, max_dim, **kw)
    for m, f in enumerate(fr, start=1):
        if f < threshold:
            return m, fr
    return int(np.argmin(fr)) + 1, fr


def embed(x: np.ndarray, delay: int | None = None, dimension: int | None = None, max_dim: int = 8) -> Embedding:
    """Choose delay (ACF) and dimension (FNN) unless given, and embed ``x``."""
    x = _check(x)
    d = acf_delay(x) if delay is None else int(delay)
    fr: list[float] = []
    if dimension is None:
        m, fr = fnn_dimension(x, d, max_dim)
    else:
        m = int(dimension)
    states = delay_embed(x, d, m)
    return Embedding(d, m, states, (m - 1) * d, tuple(fr))
