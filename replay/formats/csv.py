"""CSV files with a header row: other DAQs' exports, and ``replay export``'s own (``t,seq,base,tip1,tip2``).

Times come from a time column (``--time COL``; found by itself when a column is named ``t``, ``time``,
``time_s`` or ``t_s`` and neither ``--time`` nor ``--fs`` is given) or from a rate (``--fs HZ``). A time
column must be uniform within 1 %, except for holes of whole steps (frames a recording lost), which are
filled like a recording's. Cells are separated by commas, tabs, semicolons or aligned blanks (numbers
then may carry a decimal comma); the header is the last row before the numbers that names the columns asked
for, lines before it (an instrument's settings) are skipped, and so are rows of units after it: what other
labs' spreadsheets and analysers export. Every error names the file and the line or column.
"""

from __future__ import annotations

import csv
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from daq.safeio import safe_output

from .base import Columns, Samples, check_rate, missing_refused, on_grid

SUFFIXES = (".csv", ".txt")
TIME_NAMES = ("t", "time", "time_s", "t_s")
DELIMITERS = (",", "\t", ";", " ")  # " ": runs of blanks
PREAMBLE = 100  # lines searched for the header row
MAX_BYTES = 4 << 30


def _lines(path: Path) -> list[str]:
    try:
        if path.stat().st_size > MAX_BYTES:
            raise ValueError(f"{path}: larger than {MAX_BYTES >> 30} GiB")
        with open(path, newline="", encoding="utf-8-sig") as fh:  # (-sig: Excel's "CSV UTF-8" starts with a BOM)
            lines = fh.readlines()
    except FileNotFoundError:
        raise ValueError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise ValueError(f"{path}: is a folder; give a CSV file") from None
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not a text CSV file ({str(exc)[:60]})") from None
    while lines and not lines[-1].strip(" \t\r\n,;"):  # blank lines (or empty cells) at the end: read past
        lines.pop()
    return lines


def _cells(path: Path, lines: list[str], delimiter: str) -> list[list[str]]:
    """The lines' cells (" ": runs of blanks; a blank line is a row of no cells either way)."""
    if delimiter == " ":
        return [line.split() for line in lines]
    try:
        return list(csv.reader(lines, delimiter=delimiter))
    except csv.Error as exc:
        raise ValueError(f"{path}: not a text CSV file ({str(exc)[:60]})") from None


def _numeric(cell: str) -> bool:
    """Is the cell a number (with a decimal point or a decimal comma)?"""
    try:
        float(cell.replace(",", "."))
    except ValueError:
        return False
    return True


def _number(cell: str, blank: float | None, comma: bool = False) -> float:
    """A cell's number (``comma``: written with a decimal comma); an empty cell is ``blank`` where that is
    given (a missing value), else an error."""
    if blank is not None and not cell.strip():
        return blank
    return float(cell.replace(",", ".") if comma else cell)


def _layout(rows: list[list[str]], names: set[str]) -> tuple[int, int] | None:
    """(the header's row, the first data row) where a row among the first ``PREAMBLE`` names every column
    asked for, else None. The header is the last such row before the first row of numbers: lines before
    it are an instrument's preamble (its settings, a title, which may name the channels too); rows after it
    that hold no number and no empty cell are its units."""
    head = rows[:PREAMBLE]
    numbers = next((r for r, row in enumerate(head) if row and all(_numeric(c) for c in row)), len(head))
    named = [r for r, row in enumerate(head[:numbers]) if names <= {c.strip() for c in row}]
    if not named:
        return None
    at = named[-1]
    units = all(row and not any(_numeric(c) or not c.strip() for c in row) for row in rows[at + 1:numbers])
    return at, numbers if units else at + 1


def _table(path: Path, columns: list[str], time_col: str | None, fs_hz: float | None, gaps: bool = False):
    """(data (n, k) for [time_col] + columns, time_col used, the file's rows before the data); with ``gaps``,
    an empty value cell is NaN (the time column must be whole).

    The delimiter is the first of a comma, a tab, a semicolon and runs of blanks under which a row names
    every column asked for (a comma first: a comma-separated file may hold semicolons in a text column;
    a file separated by tabs or semicolons may write its numbers with decimal commas, which are then
    read): a European spreadsheet's ``t;force;x`` with ``0,0015``, a LabVIEW or analyser text export's
    tabs or aligned columns read as they are."""
    lines = _lines(path)
    if not lines:
        raise ValueError(f"{path}: empty file; expected a header row and data")
    names = set(columns) | ({time_col} if time_col else set())
    found = [(d, lay, cells) for d in DELIMITERS
             if (lay := _layout(cells := _cells(path, lines[:PREAMBLE], d), names)) is not None]
    # first where the first data row has the header's cells: a one-column file of decimal commas splits at
    # them under a comma ("0,1429" had read 0)
    even = [(d, lay) for d, lay, cells in found
            if lay[1] >= len(cells) or len(cells[lay[1]]) == len(cells[lay[0]])]
    delimiter, layout = (even or [(d, lay) for d, lay, _ in found] or [(",", None)])[0]
    rows = _cells(path, lines, delimiter)
    del lines  # (the rows hold the text now: a file of gigabytes is not kept twice)
    at, first = layout or (0, 1)  # line ``first + 1`` of the file is the first of data
    header = [h.strip() for h in rows[at]]
    comma = delimiter != ","  # 0,0015 (a cell without a comma reads the same)
    if time_col is None and fs_hz is None:
        time_col = next((c for c in TIME_NAMES if c in header), None)
        if time_col is None:
            raise ValueError(f"{path}: no time column ({', '.join(TIME_NAMES)}); give --time COL or --fs HZ")
    elif time_col is not None and fs_hz is not None:
        raise ValueError("CSV input needs exactly one of --time COL or --fs HZ")
    elif fs_hz is not None:
        _rate_agrees(path, rows[first:first + 1001], header, fs_hz, comma)
    wanted = ([time_col] if time_col else []) + list(columns)
    missing = [c for c in wanted if c not in header]
    if missing:
        raise ValueError(f"{path}: no column {missing[0]!r}; columns are: {', '.join(header)}")
    idx = [header.index(c) for c in wanted]
    blank = [None if time_col and j == 0 else (np.nan if gaps else None) for j in range(len(idx))]
    width = len(rows[at])
    data = np.empty((len(rows) - first, len(idx)))
    for r, row in enumerate(rows[first:], start=first + 1):
        try:
            data[r - first - 1] = [_number(row[i], b, comma) for i, b in zip(idx, blank)]
        except (ValueError, IndexError):
            raise ValueError(f"{path}: line {r} has a missing or non-numeric value in columns "
                             f"{', '.join(wanted)}") from None
        if len(row) > width and any(_numeric(c) for c in row[width:] if c.strip()):
            # a number in no column: the cells do not line up with the header, and which column a number
            # belongs to is a guess (a comma table written with decimal commas splits every number in two:
            # "0,001,3,2480" under "t,force" had read t = 0 and force = 1). Empty cells past the header
            # (a logger's trailing delimiter) and text there (a logger's unheaded remark) are read past
            hint = " (decimal commas in a comma-separated table?)" if delimiter == "," else ""
            raise ValueError(f"{path}: line {r} holds {len(row)} cells where the header names {width} "
                             f"columns{hint}; save it with one delimiter that no number holds and a name for "
                             "every column")
    if len(data) < 2:
        raise ValueError(f"{path}: needs at least two data rows")
    where = lambda i: f"line {i + first + 1}"  # noqa: E731
    if time_col:
        missing_refused(path, data[:, :1], False, where, "; repair or remove it")
    missing_refused(path, data, gaps, where, "; repair or remove it")
    return data, time_col, first


def _rate_agrees(path: Path, rows: list[list[str]], header: list[str], fs_hz: float, comma: bool) -> None:
    """``--fs`` given where a column is named for time: refused if the column steps at another rate (read as
    seconds, over its first rows), since one of the two is wrong (a 1 kHz table given --fs 400 had been read
    at 400 Hz, its modes at 0.4 of theirs)."""
    col = next((c for c in TIME_NAMES if c in header), None)
    if col is None or len(rows) < 2:
        return
    j = header.index(col)
    try:
        t = np.array([_number(r[j], None, comma) for r in rows])
        if not np.all(np.isfinite(t)):
            return  # a broken time column: the --fs decides (it is what --fs is for)
        _, rate = _grid(path, t, col)  # (the reader's own rate)
    except (ValueError, IndexError):
        return  # not a uniform column of seconds (sample numbers, milliseconds, text): the --fs decides
    if abs(fs_hz / rate - 1) > 0.01:
        raise ValueError(f"{path}: --fs {fs_hz:g} Hz, but column {col!r} steps at {rate:.6g} Hz (read as "
                         f"seconds): leave --fs out to take the column's times, or, if {col!r} is not in seconds, "
                         f"rename it ({', '.join(TIME_NAMES)} are taken for time)")


def _grid(path: Path, t: np.ndarray, time_col: str, first: int = 1) -> tuple[np.ndarray, float]:
    """Grid positions of the rows and the rate, from a time column: uniform, or with holes of whole steps
    (``first``: the rows of the file before the data)."""
    dt = np.diff(t)
    if np.any(dt <= 0):
        raise ValueError(f"{path}: column {time_col!r} is not strictly increasing "
                         f"(line {int(np.argmax(dt <= 0)) + first + 2})")
    med = float(np.median(dt))
    if med >= 1.0 and np.all(t == np.rint(t)):  # whole numbers a second or more apart: not seconds
        raise ValueError(f"{path}: column {time_col!r} counts in whole steps of {med:g} (sample numbers, or "
                         f"milliseconds?), which would be {1 / med:g} Hz in seconds: give the rate with --fs HZ "
                         f"instead, or a time column in seconds")
    k = dt / med
    if np.max(np.abs(k - np.rint(k))) > 0.01:
        step = _rounded_step(t)
        if step is None:
            raise ValueError(f"{path}: column {time_col!r} is not uniformly sampled (steps from "
                             f"{dt.min():.3g} to {dt.max():.3g} s); resample first or give --fs")
        return np.arange(t.size), check_rate(1.0 / step, "the time column's rate")
    index = np.concatenate([[0], np.cumsum(np.rint(k).astype(np.int64))])
    # the rate over the whole column (stamps rounded to fewer digits than the step: the median is a digit off)
    return index, check_rate(float(index[-1]) / float(t[-1] - t[0]), "the time column's rate")


ROUNDED = 0.1  # of a step: how far a stamp may lie from the straight line through all of them


def _rounded_step(t: np.ndarray) -> float | None:
    """The step of a time column whose stamps are uniform but written with fewer digits than the step
    needs, or jitter (a 2560 Hz analyser's 1/2560 s written to 10 us steps 0.00039 and 0.00040 s, 2.5 % off
    their median): the slope of the least-squares line through the stamps, where every stamp lies within
    ``ROUNDED`` of a step of that line (a sample missing or doubled moves every later stamp a whole step
    off it); else None."""
    i = np.arange(t.size, dtype=float)
    step, t0 = np.polyfit(i, t - t[0], 1)
    if not step > 0:
        return None
    return float(step) if np.max(np.abs(t - t[0] - (t0 + step * i))) <= ROUNDED * step else None


def read_columns(path: str | Path, names: list[str], time_col: str | None = None,
                 fs_hz: float | None = None, gaps: bool = False) -> Columns:
    """The named columns as floats and the sampling rate (a time column must be uniform here: no holes;
    with ``gaps``, a hole of whole steps is rows of NaN, and an empty value cell NaN)."""
    path = Path(path)
    if fs_hz is not None:
        check_rate(fs_hz)
    data, time_col, first = _table(path, list(names), time_col, fs_hz, gaps)
    if time_col is None:
        return Columns({c: data[:, j] for j, c in enumerate(names)}, float(fs_hz), str(path))
    index, fs = _grid(path, data[:, 0], time_col, first)
    if gaps and index[-1] != len(index) - 1:
        full = np.full((int(index[-1]) + 1, len(names)), np.nan)
        full[index] = data[:, 1:]
        return Columns({c: full[:, j] for j, c in enumerate(names)}, fs, str(path))
    if index[-1] != len(index) - 1:
        dt = np.diff(data[:, 0])
        raise ValueError(f"{path}: column {time_col!r} is not uniformly sampled (steps from "
                         f"{dt.min():.3g} to {dt.max():.3g} s); resample first or give --fs")
    return Columns({c: data[:, j + 1] for j, c in enumerate(names)}, fs, str(path))


def read_samples(path: str | Path, *, time_col: str | None = None, fs_hz: float | None = None,
                 base: str = "base", tip1: str = "tip1", tip2: str = "tip2", fill: bool = True) -> Samples:
    """Base, tip1, tip2 from the named columns; a time column's holes filled (``fill``)."""
    path = Path(path)
    if fs_hz is not None:
        check_rate(fs_hz)
    data, time_col, first = _table(path, [base, tip1, tip2], time_col, fs_hz)
    if time_col is None:
        return Samples(np.arange(len(data)) / fs_hz, data, float(fs_hz), np.arange(len(data)), str(path))
    index, fs = _grid(path, data[:, 0], time_col, first)
    return on_grid(index, data[:, 1:], index, fs, str(path), fill)


def write_samples(path: str | Path, samples: Samples, *, force: bool = False, inputs: Iterable = (),
                  label: str = "--csv") -> Path:
    """``t,seq,base,tip1,tip2``: t in s from the first sample, accelerations in m/s^2; rows as recorded
    (give samples read with ``fill=False``: lost frames are absent, not interpolated)."""
    keep = ~samples.filled
    seq = samples.seq if samples.seq is not None else np.arange(len(samples.t))
    data = np.column_stack([samples.t[keep], seq[keep], samples.values[keep]])
    with safe_output(path, inputs=inputs, force=force, label=label) as tmp:
        np.savetxt(tmp, data, delimiter=",", header="t,seq,base,tip1,tip2", comments="",
                   fmt=["%.6f", "%d", "%.9g", "%.9g", "%.9g"])
    return Path(path)
