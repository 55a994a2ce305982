"""What every format reads into: ``Samples`` (the rig's three channels, uniformly sampled, with rate,
events and metadata) and ``Columns`` (any named signals and their rate, for discovery)."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Samples:
    """Base, tip1, tip2 [m/s^2] on a uniform grid (or, read with ``fill=False``, as recorded).

    ``seq`` is the device's sequence number of each row where the format has one, -1 where a lost
    frame was filled in by linear interpolation (so the pipeline's clock stays right).
    """

    t: np.ndarray  # (n,) seconds since the first sample
    values: np.ndarray  # (n, 3) base, tip1, tip2 [m/s^2]
    fs_hz: float
    seq: np.ndarray | None = None
    source: str = ""
    events: tuple[dict, ...] = ()
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)

    @property
    def duration_s(self) -> float:
        return len(self.t) / self.fs_hz

    @property
    def filled(self) -> np.ndarray:
        """Rows that are interpolated over lost frames, not measured."""
        return np.zeros(len(self.t), bool) if self.seq is None else self.seq < 0

    def blocks(self, start_s: float = 0.0, duration_s: float | None = None,
               block_s: float = 0.05) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        if not (start_s >= 0 and np.isfinite(start_s)) or (duration_s is not None and not (0 < duration_s < np.inf)):
            raise ValueError("--start must be >= 0 and --duration > 0, both finite")
        i0 = int(round(start_s * self.fs_hz))
        if i0 >= len(self.t):
            raise ValueError(f"--start {start_s} s is beyond the end of the data ({self.duration_s:.2f} s)")
        i1 = len(self.t) if duration_s is None else min(len(self.t), i0 + int(round(duration_s * self.fs_hz)))
        step = max(1, int(round(block_s * self.fs_hz)))
        for k in range(i0, i1, step):
            e = min(k + step, i1)
            yield self.t[k:e], self.values[k:e]


@dataclass(frozen=True)
class Columns:
    """Named signals of equal length and their sampling rate."""

    data: dict[str, np.ndarray]
    fs_hz: float
    source: str = ""

    def matrix(self, names: list[str] | None = None) -> np.ndarray:
        """(n, k) floats of the named columns (all, in order, by default)."""
        return np.column_stack([self.data[c] for c in (names or list(self.data))])


def on_grid(index: np.ndarray, values: np.ndarray, seq: np.ndarray | None, fs_hz: float, source: str,
            fill: bool = True, **extra) -> Samples:
    """Samples from rows at integer grid positions ``index`` (strictly increasing): holes filled by
    linear interpolation (``fill``), or the rows as they are with their true times."""
    index = np.asarray(index, np.int64)
    rel = index - index[0]
    seq = np.asarray(seq if seq is not None else rel, np.int64)
    if not fill or np.all(np.diff(rel) == 1):
        return Samples(rel / fs_hz, values, fs_hz, seq, source, **extra)
    full = np.arange(rel[-1] + 1)
    vals = np.column_stack([np.interp(full, rel, values[:, j]) for j in range(values.shape[1])])
    seq_full = np.full(full.size, -1, np.int64)
    seq_full[rel] = seq
    return Samples(full / fs_hz, vals, fs_hz, seq_full, source, **extra)


def missing_refused(path, data: np.ndarray, gaps: bool, where=lambda i: f"sample {i}",
                    fix: str = "") -> np.ndarray:
    """``data`` (n, k) when every value is a number; else, with ``gaps``, as it is (NaN where a value is
    missing: its reader, ``ident discover``, bridges and leaves such runs out), and without, refused with
    the first row that holds one (``where``: how the format names a row)."""
    bad = ~np.isfinite(data).all(axis=1)
    if bad.any() and not gaps:
        raise ValueError(f"{path}: {where(int(np.argmax(bad)))} holds NaN or inf{fix}")
    return data


TICK_SHARE = 0.9  # the median step stands for the rate where at least this share of the steps equal it


def typical_step(d: np.ndarray) -> float:
    """The sampling step from the steps ``d`` between consecutive samples: their median where nearly all
    (``TICK_SHARE``) equal it, as a rate of whole clock ticks gives with a stamp's jitter now and then; else
    the mean of those within half a step of the median (a lost frame's step is two or more). Stamps rounded
    to a clock's tick where the step is no whole tick alternate about it: a 3 kHz device's microsecond stamps
    step 333 and 334 us, and 1 / median had read 3003.003 Hz. NaN where there is no step."""
    d = np.asarray(d, float)
    d = d[d > 0]
    if not d.size:
        return float("nan")
    med = float(np.median(d))
    if np.count_nonzero(d == med) >= TICK_SHARE * d.size:
        return med
    return float(np.mean(d[np.abs(d - med) < 0.5 * med]))


def check_rate(fs_hz: float | None, what: str = "--fs") -> float:
    if fs_hz is None or not (1e-3 <= fs_hz <= 1e6):
        raise ValueError(f"{what} must be a sampling rate from 0.001 Hz to 1 MHz, got {fs_hz}")
    return float(fs_hz)


def even_grid(samples: Samples) -> tuple[np.ndarray, np.ndarray]:
    """Samples on their uniform grid for formats without holes (UFF 58, TDMS waveforms): values with lost
    frames filled by linear interpolation, and the sequence number of each row (-1 where filled). Takes
    samples read either way (``fill`` or not); fewer than two samples make no time history (ValueError)."""
    n = len(samples.t)
    if n < 2:
        raise ValueError(f"{samples.source}: fewer than two samples; nothing to write as a time history")
    seq = np.arange(n) if samples.seq is None else np.asarray(samples.seq, np.int64)
    if np.any(seq < 0):
        return samples.values, seq
    index = np.rint(np.asarray(samples.t) * samples.fs_hz).astype(np.int64)
    if np.any(np.diff(index) <= 0):
        raise ValueError(f"{samples.source}: sample times are not increasing; cannot write an even time history")
    g = on_grid(index, samples.values, seq, samples.fs_hz, samples.source, fill=True)
    return g.values, g.seq
