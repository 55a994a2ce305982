"""Low-pass filtering below 50 Hz (the paper's pre-processing), streaming and one-shot, and decimation.

Function-first, like scipy.signal: a streaming stage is a pure function
(state, block) -> (state, output). The causal filter is a Butterworth in
second-order sections run as ``sosfilt`` runs them with its state carried between
blocks, so any split of the data into blocks gives exactly the one-shot
output (tests/test_filters.py proves it). Offline work uses the zero-phase
``sosfiltfilt``. Both run in compiled kernels that give scipy's numbers bit for
bit (the rolling fits filter every window anew and the pipeline every block;
scipy's per-call overhead was most of their time). The unfiltered signal is
never overwritten: impacts live above 50 Hz.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numba import njit
from scipy.signal import butter, sosfilt_zi, sosfiltfilt

DEFAULT_CUTOFF_HZ = 50.0


@lru_cache(maxsize=32)
def _butter_sos(order: int, cutoff_hz: float, btype: str, fs_hz: float) -> np.ndarray:
    return butter(order, cutoff_hz, btype=btype, fs=fs_hz, output="sos")


def design_lowpass(fs_hz: float, cutoff_hz: float = DEFAULT_CUTOFF_HZ, order: int = 4) -> np.ndarray:
    """Butterworth low-pass as second-order sections (designs are cached)."""
    if not 0 < cutoff_hz < fs_hz / 2:
        raise ValueError(f"cutoff {cutoff_hz} Hz must lie between 0 and the Nyquist frequency {fs_hz / 2} Hz")
    if order < 1:
        raise ValueError(f"filter order must be >= 1, got {order}")
    return _butter_sos(int(order), float(cutoff_hz), "low", float(fs_hz)).copy()


def design_highpass(fs_hz: float, cutoff_hz: float, order: int = 2) -> np.ndarray:
    """Butterworth high-pass as second-order sections (designs are cached)."""
    if not 0 < cutoff_hz < fs_hz / 2:
        raise ValueError(f"cutoff {cutoff_hz} Hz must lie between 0 and the Nyquist frequency {fs_hz / 2} Hz")
    return _butter_sos(int(order), float(cutoff_hz), "high", float(fs_hz)).copy()


@dataclass(frozen=True)
class LowpassState:
    sos: np.ndarray
    zi: np.ndarray  # (n_sections, 2, n_channels)


def lowpass_start(sos: np.ndarray, n_channels: int, first: np.ndarray | None = None) -> LowpassState:
    """Initial state: at rest (zeros), or settled at the value ``first`` (no start-up transient)."""
    base = np.zeros((sos.shape[0], 2, n_channels))
    if first is not None:
        base = sosfilt_zi(sos)[:, :, None] * np.asarray(first, float)[None, None, :]
    return LowpassState(sos, base)


def lowpass_block(state: LowpassState, x: np.ndarray) -> tuple[LowpassState, np.ndarray]:
    """Filter one block (n, channels) causally; returns the state to carry into the next block."""
    x = np.asarray(x, float)
    if x.ndim != 2 or x.shape[1] != state.zi.shape[2]:
        raise ValueError(f"block must have shape (n, {state.zi.shape[2]}), got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("block contains NaN or inf; the filter state would be poisoned for good")
    if x.shape[0] == 0:
        return state, x.copy()
    y, zi = _sosfilt(np.require(state.sos, float, "CW"), np.require(x, float, "CW"),
                     np.require(state.zi, float, "CW"))  # scipy's sosfilt's numbers without its per-call overhead
    return LowpassState(state.sos, zi), y


@lru_cache(maxsize=32)
def _steady_state(sos_bytes: bytes, n_sections: int) -> np.ndarray:
    return sosfilt_zi(np.frombuffer(sos_bytes).reshape(n_sections, 6))


def zero_phase(sos: np.ndarray, x: np.ndarray) -> np.ndarray:
    """scipy.signal.sosfiltfilt(sos, x, axis=0) (odd extension, default pad length), bit for bit: the
    filter's steady-state initial conditions cached per design and the extension, both passes and the
    trim in one compiled kernel (``zero_phase_kernel``, scipy's biquad recursion term by term), since the
    rolling fits filter every window anew and scipy's per-call overhead was most of the time."""
    x = np.asarray(x, float)
    sos, zi, pad = zero_phase_setup(sos)
    if x.shape[0] <= pad or x.ndim > 2:
        return sosfiltfilt(sos, x, axis=0)
    y = zero_phase_kernel(sos, zi, np.require(x.reshape(x.shape[0], -1), requirements="CW"), pad)  # one signature
    return y.reshape(x.shape)


def zero_phase_setup(sos: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """(sos as a contiguous float array, its steady-state initial conditions (cached per design), scipy's
    default pad length): what ``zero_phase_kernel`` takes."""
    sos = np.ascontiguousarray(sos, float)
    n_sec = sos.shape[0]
    pad = 3 * (2 * n_sec + 1 - min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum())))
    return sos, _steady_state(sos.tobytes(), n_sec), pad


@njit(cache=True, nogil=True)
def zero_phase_kernel(sos, zi, x, pad):  # pragma: no cover - compiled
    """sosfiltfilt along axis 0 of x (n, channels) with the odd extension of ``pad`` samples at each end and
    the steady-state initial conditions zi (n_sections, 2) scaled by the first sample of each pass; every
    operation in scipy's order (``_biquads``), so the output is identical."""
    n, c = x.shape
    n_sec = sos.shape[0]
    m = n + 2 * pad
    ext = np.empty((m, c))
    for i in range(pad):
        for j in range(c):
            ext[i, j] = 2 * x[0, j] - x[pad - i, j]
    ext[pad:pad + n] = x
    for i in range(pad):
        for j in range(c):
            ext[pad + n + i, j] = 2 * x[n - 1, j] - x[n - 2 - i, j]
    z = np.empty((n_sec, 2, c))
    for direction in range(2):  # forward, then backward over the forward pass's output
        first = 0 if direction == 0 else m - 1
        for s in range(n_sec):
            for j in range(c):
                z[s, 0, j] = zi[s, 0] * ext[first, j]
                z[s, 1, j] = zi[s, 1] * ext[first, j]
        _biquads(sos, z, ext, direction == 0)
    return ext[pad:pad + n].copy()


@njit(cache=True, nogil=True)
def _sosfilt(sos, x, zi):  # pragma: no cover - compiled
    """scipy.signal.sosfilt(sos, x, axis=0, zi=zi) for x (n, channels), zi (n_sections, 2, channels):
    (y, final state), the same numbers."""
    y = x.copy()
    z = zi.copy()
    _biquads(sos, z, y, True)
    return y, z


@njit(cache=True, nogil=True, inline="always")
def _biquads(sos, z, y, forward):  # pragma: no cover - compiled
    """Run the cascade of second-order sections over y (m, channels) in place, forward or backward in time,
    from and into the state z (n_sections, 2, channels): scipy's recursion (scipy/signal/_sosfilt.pyx)
    term by term, the channels side by side (independent recursions the processor overlaps)."""
    m, c = y.shape
    n_sec = sos.shape[0]
    x_cur = np.empty(c)
    for k in range(m):
        i = k if forward else m - 1 - k
        for j in range(c):
            x_cur[j] = y[i, j]
        for s in range(n_sec):
            b0, b1, b2, a1, a2 = sos[s, 0], sos[s, 1], sos[s, 2], sos[s, 4], sos[s, 5]
            for j in range(c):
                x_new = b0 * x_cur[j] + z[s, 0, j]
                z[s, 0, j] = b1 * x_cur[j] - a1 * x_new + z[s, 1, j]
                z[s, 1, j] = b2 * x_cur[j] - a2 * x_new
                x_cur[j] = x_new
        for j in range(c):
            y[i, j] = x_cur[j]


KERNELS = (zero_phase_kernel,)  # the zero-phase filter's (the rolling fits')
CAUSAL_KERNELS = (_sosfilt,)  # the causal block filter's (the pipeline's, with or without identification)


def lowpass_zero_phase(x: np.ndarray, fs_hz: float, cutoff_hz: float = DEFAULT_CUTOFF_HZ,
                       order: int = 4) -> np.ndarray:
    """Offline zero-phase low-pass (forward and backward) along axis 0."""
    x = np.asarray(x, float)
    if not np.all(np.isfinite(x)):
        raise ValueError("signal contains NaN or inf: remove or interpolate those samples first")
    return zero_phase(design_lowpass(fs_hz, cutoff_hz, order), x)


def decimate_block(offset: int, x: np.ndarray, factor: int) -> tuple[int, np.ndarray]:
    """Keep every ``factor``-th sample of the whole stream (absolute index % factor == 0).

    ``offset`` is the absolute index of the block's first sample; returns the
    next block's offset and the kept samples. Low-pass first (alias!).
    """
    if factor < 1:
        raise ValueError(f"decimation factor must be >= 1, got {factor}")
    first = (-offset) % factor
    return offset + len(x), np.asarray(x)[first::factor]
