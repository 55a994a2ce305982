"""Sample sources for replay: an MCAP recording of this tool, or a CSV file from another DAQ.

Both give uniformly sampled (n, 3) blocks of base, tip1, tip2 in m/s^2 with
their times (seconds since the first sample), so the same pipeline runs on
them as on the live driver. One reader per format, chosen by suffix
(python-can's ``can.io`` habit).
"""

from __future__ import annotations

import csv
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import zstandard

from .reader import read_recording


@dataclass(frozen=True)
class Samples:
    t: np.ndarray  # (n,) seconds since the first sample
    values: np.ndarray  # (n, 3) base, tip1, tip2 [m/s^2]
    fs_hz: float
    seq: np.ndarray | None = None  # frame sequence numbers, where known
    source: str = ""

    @property
    def duration_s(self) -> float:
        return len(self.t) / self.fs_hz

    def blocks(self, start_s: float = 0.0, duration_s: float | None = None,
               block_s: float = 0.05) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        if start_s < 0 or (duration_s is not None and duration_s <= 0):
            raise ValueError("--start must be >= 0 and --duration > 0")
        i0 = int(round(start_s * self.fs_hz))
        if i0 >= len(self.t):
            raise ValueError(f"--start {start_s} s is beyond the end of the data ({self.duration_s:.2f} s)")
        i1 = len(self.t) if duration_s is None else min(len(self.t), i0 + int(round(duration_s * self.fs_hz)))
        step = max(1, int(round(block_s * self.fs_hz)))
        for k in range(i0, i1, step):
            e = min(k + step, i1)
            yield self.t[k:e], self.values[k:e]


def read_csv_columns(path: str | Path, columns: list[str], time_col: str | None = None,
                     fs_hz: float | None = None) -> tuple[np.ndarray, float]:
    """The named columns of a CSV with a header row as (n, len(columns)) floats, and the sampling rate.

    Times from ``time_col`` (seconds, uniform within 1 %) or the rate ``fs_hz``; every error names the
    file and the line or column.
    """
    path = Path(path)
    if (time_col is None) == (fs_hz is None):
        raise ValueError("CSV input needs exactly one of --time COL or --fs HZ")
    try:
        with open(path, newline="") as fh:
            rows = list(csv.reader(fh))
    except FileNotFoundError:
        raise ValueError(f"{path}: no such file") from None
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a text CSV file") from None
    if not rows:
        raise ValueError(f"{path}: empty file; expected a header row and data")
    header = [h.strip() for h in rows[0]]
    wanted = [c for c in ([time_col] if time_col else []) + list(columns)]
    missing = [c for c in wanted if c not in header]
    if missing:
        raise ValueError(f"{path}: no column {missing[0]!r}; columns are: {', '.join(header)}")
    idx = [header.index(c) for c in wanted]
    data = np.empty((len(rows) - 1, len(idx)))
    for r, row in enumerate(rows[1:], start=2):
        try:
            data[r - 2] = [float(row[i]) for i in idx]
        except (ValueError, IndexError):
            raise ValueError(f"{path}: line {r} has a missing or non-numeric value in columns "
                             f"{', '.join(wanted)}") from None
    if len(data) < 2:
        raise ValueError(f"{path}: needs at least two data rows")
    bad = ~np.isfinite(data).all(axis=1)
    if bad.any():
        raise ValueError(f"{path}: line {int(np.argmax(bad)) + 2} holds NaN or inf; repair or remove it")
    if time_col is None:
        if not fs_hz > 0:
            raise ValueError(f"--fs must be positive, got {fs_hz}")
        return data, float(fs_hz)
    dt = np.diff(data[:, 0])
    if np.any(dt <= 0):
        raise ValueError(f"{path}: column {time_col!r} is not strictly increasing (line {int(np.argmax(dt <= 0)) + 3})")
    med = float(np.median(dt))
    if np.max(np.abs(dt - med)) > 0.01 * med:
        raise ValueError(f"{path}: column {time_col!r} is not uniformly sampled (steps from "
                         f"{dt.min():.3g} to {dt.max():.3g} s); resample first or give --fs")
    return data[:, 1:], 1.0 / med


def read_mat_columns(path: str | Path, columns: list[str], fs_hz: float | None = None) -> tuple[np.ndarray, float]:
    """Named signals of a MATLAB file (scipy.io.loadmat) as (n, len(columns)) floats, and the rate.

    A column is a variable holding one signal (``Force``), or row i of a variable holding several
    (``Acceleration2`` is row 2 of ``Acceleration``, counted from 1: the CSV export's naming). The
    rate is ``fs_hz`` or the file's ``Fs`` variable.
    """
    from scipy.io import loadmat

    path = Path(path)
    try:
        mat = loadmat(path)
    except FileNotFoundError:
        raise ValueError(f"{path}: no such file") from None
    except (ValueError, TypeError, OSError, NotImplementedError) as exc:
        raise ValueError(f"{path}: not a readable MAT file ({exc})") from None
    signals: dict[str, np.ndarray] = {}
    for name, value in mat.items():
        if name.startswith("__") or not isinstance(value, np.ndarray) or value.dtype.kind not in "fiu":
            continue
        arr = np.squeeze(value.astype(float))
        if arr.ndim == 1:
            signals[name] = arr
        elif arr.ndim == 2:
            rows = arr if arr.shape[0] < arr.shape[1] else arr.T
            for i, row in enumerate(rows, start=1):
                signals[f"{name}{i}"] = row
    missing = [c for c in columns if c not in signals]
    if missing:
        raise ValueError(f"{path}: no signal {missing[0]!r}; signals are: {', '.join(sorted(signals))}")
    n = {len(signals[c]) for c in columns}
    if len(n) != 1:
        raise ValueError(f"{path}: signals {', '.join(columns)} differ in length")
    data = np.column_stack([signals[c] for c in columns])
    if not np.all(np.isfinite(data)):
        raise ValueError(f"{path}: sample {int(np.argmax(~np.isfinite(data).all(axis=1)))} holds NaN or inf")
    if fs_hz is None:
        fs = np.asarray(mat.get("Fs", np.nan), float).ravel()
        if fs.size != 1 or not fs[0] > 0:
            raise ValueError(f"{path}: no sampling rate (variable Fs); give --fs HZ")
        fs_hz = float(fs[0])
    if not fs_hz > 0:
        raise ValueError(f"--fs must be positive, got {fs_hz}")
    return data, float(fs_hz)


def read_columns(path: str | Path, columns: list[str], time_col: str | None = None,
                 fs_hz: float | None = None) -> tuple[np.ndarray, float]:
    """Named columns of a CSV (header row) or a MAT file, by suffix."""
    if Path(path).suffix.lower() == ".mat":
        if time_col is not None:
            raise ValueError("--time is for CSV files; a MAT file carries its rate (Fs) or takes --fs")
        return read_mat_columns(path, columns, fs_hz)
    return read_csv_columns(path, columns, time_col, fs_hz)


def read_csv(path: str | Path, *, time_col: str | None = None, fs_hz: float | None = None,
             base: str = "base", tip1: str = "tip1", tip2: str = "tip2") -> Samples:
    """A CSV with a header row; times from ``time_col`` (seconds) or a sampling rate ``fs_hz``."""
    vals, fs = read_csv_columns(path, [base, tip1, tip2], time_col, fs_hz)
    return Samples(np.arange(len(vals)) / fs, vals, fs, None, str(path))


def read_mcap(path: str | Path) -> Samples:
    """Samples of a recording: decoded in bulk from its raw bytes (fast), else from /rig/accel."""
    from .fastread import read_raw_samples

    fs = None
    try:
        fast = read_raw_samples(path)
    except FileNotFoundError:
        raise ValueError(f"{path}: no such file") from None
    except (ValueError, struct.error, zstandard.ZstdError):
        fast = None
    if fast is not None and len(fast[0]) >= 2:
        seq, values, fs = fast
        fs = fs if np.isfinite(fs) and fs > 0 else None
    if fs is None:
        rec = read_recording(path, raw=False)
        if len(rec.seq) < 2:
            raise ValueError(f"{path}: holds fewer than two samples")
        seq, values, fs = rec.seq, rec.values, rec.rate_hz
    # Frames lost in acquisition are holes in the sequence; fill them by linear interpolation
    # so the stream stays uniform (the pipeline counts time in samples); `replay info` reports them.
    rel = seq - seq[0]
    if np.any(np.diff(rel) != 1):
        full = np.arange(rel[0], rel[-1] + 1)
        vals = np.column_stack([np.interp(full, rel, values[:, j]) for j in range(3)])
        return Samples(full / fs, vals, fs, full + seq[0], str(path))
    return Samples(rel / fs, values, fs, seq, str(path))


def open_samples(path: str | Path, **csv_options) -> Samples:
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == ".mcap":
        return read_mcap(p)
    if suffix in (".csv", ".txt"):
        return read_csv(p, **csv_options)
    raise ValueError(f"{p}: unknown format {suffix or '(no suffix)'}; give an .mcap recording or a .csv file")
