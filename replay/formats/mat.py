"""MATLAB files (scipy.io.loadmat / savemat; version 7.3, which is HDF5, through h5py): signals by
variable name, the rate from ``Fs``.

A ``1 x N`` (or ``N x 1``) variable is a column by its name; row i of a ``k x N`` one is ``NAMEi``,
counted from 1 (``Acceleration2`` is row 2 of ``Acceleration``, as the F-16 benchmark names them).
``replay export --mat`` writes ``t``, ``seq``, ``base``, ``tip1``, ``tip2`` and ``Fs``.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import h5py
import numpy as np
from scipy.io import loadmat, savemat

from daq.safeio import safe_output

from .base import Columns, Samples, check_rate, missing_refused

SUFFIXES = (".mat",)


def _signals(path: Path) -> tuple[dict[str, np.ndarray], dict]:
    # checked first: scipy 1.17's loadmat says "Reader needs file name" for a missing path or a folder
    if Path(path).is_dir():
        raise ValueError(f"{path}: is a folder; give a MAT file")
    if not Path(path).exists():
        raise ValueError(f"{path}: no such file")
    try:
        mat = loadmat(path)
    except NotImplementedError:  # scipy reads versions 4 to 7; 7.3 (MATLAB's -v7.3, its large files) is HDF5
        mat = _hdf5_variables(path)
    except (ValueError, TypeError, OSError, KeyError, IndexError, MemoryError) as exc:
        raise ValueError(f"{path}: not a readable MAT file ({str(exc)[:80]})") from None
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
    return signals, mat


NUMERIC = {b"double", b"single", b"int8", b"uint8", b"int16", b"uint16", b"int32", b"uint32", b"int64", b"uint64"}


def _hdf5_variables(path: Path) -> dict[str, np.ndarray]:
    """The numeric variables of a version 7.3 MAT file, each as MATLAB shapes it: HDF5 keeps MATLAB's
    column-major array with its dimensions reversed (a ``1 x N`` variable is an ``N x 1`` dataset), so each
    is transposed back. Characters, cells, structures, complex and sparse variables are left out."""
    try:
        with h5py.File(path, "r") as f:
            out = {}
            for name, item in f.items():
                if not isinstance(item, h5py.Dataset) or item.attrs.get("MATLAB_class") not in NUMERIC:
                    continue
                if item.attrs.get("MATLAB_empty") or item.dtype.kind not in "fiu":
                    continue
                out[name] = np.asarray(item[()]).T
            return out
    except (OSError, ValueError, KeyError, TypeError, MemoryError) as exc:
        raise ValueError(f"{path}: not a readable MAT file (version 7.3, HDF5: {str(exc)[:80]})") from None


def read_columns(path: str | Path, names: list[str], time_col: str | None = None,
                 fs_hz: float | None = None, gaps: bool = False) -> Columns:
    """Named signals as floats, and the rate (``fs_hz`` or the file's ``Fs``)."""
    path = Path(path)
    if time_col is not None:
        raise ValueError("--time is for CSV files; a MAT file carries its rate (Fs) or takes --fs")
    signals, mat = _signals(path)
    missing = [c for c in names if c not in signals]
    if missing:
        raise ValueError(f"{path}: no signal {missing[0]!r}; signals are: {', '.join(sorted(signals))}")
    n = {len(signals[c]) for c in names}
    if len(n) != 1:
        raise ValueError(f"{path}: signals {', '.join(names)} differ in length")
    data = np.column_stack([signals[c] for c in names])
    data = missing_refused(path, data, gaps)
    if fs_hz is None:
        fs = np.asarray(mat.get("Fs", np.nan), float).ravel()
        if fs.size != 1 or not fs[0] > 0:
            raise ValueError(f"{path}: no sampling rate (variable Fs); give --fs HZ")
        fs_hz = float(fs[0])
    return Columns({c: data[:, j] for j, c in enumerate(names)}, check_rate(fs_hz), str(path))


def read_samples(path: str | Path, *, time_col: str | None = None, fs_hz: float | None = None,
                 base: str = "base", tip1: str = "tip1", tip2: str = "tip2", fill: bool = True) -> Samples:
    c = read_columns(path, [base, tip1, tip2], time_col, fs_hz)
    v = c.matrix([base, tip1, tip2])
    return Samples(np.arange(len(v)) / c.fs_hz, v, c.fs_hz, np.arange(len(v)), str(path))


def write_samples(path: str | Path, samples: Samples, *, force: bool = False, inputs: Iterable = (),
                  label: str = "--mat") -> Path:
    """Rows as recorded (lost frames absent), ``t``, ``seq``, ``base``, ``tip1``, ``tip2`` as 1 x N, ``Fs``."""
    keep = ~samples.filled
    seq = samples.seq if samples.seq is not None else np.arange(len(samples.t))
    out = {"t": samples.t[keep][None], "seq": seq[keep].astype(float)[None], "Fs": samples.fs_hz}
    for j, c in enumerate(("base", "tip1", "tip2")):
        out[c] = samples.values[keep, j][None]
    with safe_output(path, inputs=inputs, force=force, label=label) as tmp:
        savemat(tmp, out, appendmat=False)
    return Path(path)
