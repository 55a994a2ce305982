"""Recording formats, one module each (python-can's ``can/io`` habit), chosen through one suffix table.

| suffix | module | reads | writes |
|---|---|---|---|
| ``.mcap`` (and ``.mcap.part``) | :mod:`replay.formats.mcap` | samples, columns, every message | samples (``replay import``) |
| ``.csv``, ``.txt`` | :mod:`replay.formats.csv` | samples, columns | samples (``replay export``) |
| ``.mat`` | :mod:`replay.formats.mat` | samples, columns | samples (``replay export``) |
| ``.uff``, ``.unv`` | :mod:`replay.formats.uff` | samples, columns (UFF dataset 58 time histories) | samples (``replay export``) |
| ``.tdms`` | :mod:`replay.formats.tdms` | samples, columns (NI TDMS channels) | samples (``replay export``) |

Each module has ``read_samples(path, **options) -> Samples``, ``read_columns(path, names, time_col,
fs_hz, gaps) -> Columns`` and ``write_samples(path, samples, force=, inputs=)``; :func:`read_samples`,
:func:`read_columns` and :func:`write_samples` here pick the module by suffix. ``replay``, ``ident fit``,
``ident discover`` and ``daq bench`` read through here.
"""

from __future__ import annotations

from pathlib import Path
from types import ModuleType

import numpy as np

from . import csv, mat, mcap, tdms, uff
from .base import Columns, Samples

FORMATS: dict[str, ModuleType] = {suffix: module for module in (mcap, csv, mat, uff, tdms)
                                   for suffix in module.SUFFIXES}

__all__ = ["FORMATS", "Columns", "Samples", "format_of", "read_column_matrix", "read_columns", "read_samples",
           "write_samples"]


def format_of(path: str | Path) -> ModuleType:
    """The format module for a file name (``NAME.mcap.part`` is an MCAP file cut short)."""
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix == ".part":
        suffix = Path(p.stem).suffix.lower()
    if suffix not in FORMATS:
        raise ValueError(f"{p}: unknown format {suffix or '(no suffix)'}; give one of "
                         f"{', '.join(sorted(FORMATS))}")
    return FORMATS[suffix]


def read_samples(path: str | Path, **options) -> Samples:
    """Base, tip1, tip2 on a uniform grid; options as the format takes them (CSV: time_col, fs_hz,
    base, tip1, tip2; ``fill=False``: rows as recorded). Options given as None are ignored."""
    module = format_of(path)
    return module.read_samples(path, **{k: v for k, v in options.items() if v is not None})


def read_columns(path: str | Path, names: list[str], time_col: str | None = None,
                 fs_hz: float | None = None, gaps: bool = False) -> Columns:
    """Named signals ({name: array}) and their rate; with ``gaps``, NaN where a value is missing (a lost
    frame, an empty or NaN cell, a hole in a time column) instead of an error."""
    return format_of(path).read_columns(path, list(names), time_col, fs_hz, gaps)


def read_column_matrix(path: str | Path, names: list[str], time_col: str | None = None,
                       fs_hz: float | None = None, gaps: bool = False) -> tuple[np.ndarray, float]:
    """Named signals as one (n, len(names)) array, and the rate."""
    c = read_columns(path, names, time_col, fs_hz, gaps)
    return c.matrix(list(names)), c.fs_hz


def write_samples(path: str | Path, samples: Samples, **options) -> Path:
    """Write samples in the format of the suffix, atomically (daq.safeio); options: force, inputs."""
    return format_of(path).write_samples(path, samples, **options)
