"""Low-pass filtering below 50 Hz (the paper's pre-processing), streaming and one-shot, and decimation.

Function-first, like scipy.signal: a streaming stage is a pure function
(state, block) -> (state, output). The causal filter is a Butterworth in
second-order sections run by ``sosfilt`` with its state carried between
blocks, so any split of the data into blocks gives exactly the one-shot
output (tests/test_filters.py proves it). Offline work uses the zero-phase
``sosfiltfilt``. The unfiltered signal is never overwritten: impacts live
above 50 Hz.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from scipy.signal import butter, sosfilt, sosfilt_zi, sosfiltfilt

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
    y, zi = sosfilt(state.sos, x, axis=0, zi=state.zi)
    return LowpassState(state.sos, zi), y


@lru_cache(maxsize=32)
def _steady_state(sos_bytes: bytes, n_sections: int) -> np.ndarray:
    return sosfilt_zi(np.frombuffer(sos_bytes).reshape(n_sections, 6))


def zero_phase(sos: np.ndarray, x: np.ndarray) -> np.ndarray:
    """scipy.signal.sosfiltfilt(sos, x, axis=0) (odd extension, default pad length), with the filter's
    steady-state initial conditions cached per design: the rolling fits filter every window anew."""
    x = np.asarray(x, float)
    n_sec = sos.shape[0]
    pad = 3 * (2 * n_sec + 1 - min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum())))
    if x.shape[0] <= pad:
        return sosfiltfilt(sos, x, axis=0)
    ext = np.concatenate([2 * x[:1] - x[pad:0:-1], x, 2 * x[-1:] - x[-2:-pad - 2:-1]])
    zi = _steady_state(np.ascontiguousarray(sos, float).tobytes(), n_sec)
    zi = zi.reshape(n_sec, 2, *([1] * (x.ndim - 1)))
    y, _ = sosfilt(sos, ext, axis=0, zi=zi * ext[:1])
    y, _ = sosfilt(sos, y[::-1], axis=0, zi=zi * y[-1:])
    return y[::-1][pad:-pad]


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
