"""NI TDMS files (LabVIEW, DIAdem, FlexLogger, NI SignalExpress); via ``npTDMS``.

Reading: every channel with numeric data (DAQmx raw data scaled by npTDMS) is a column, named by its channel
name, and always also ``GROUP/CHANNEL`` (the only name of a channel whose name two groups share). The rate is
``--fs``, else the channels' waveform increment (property ``wf_increment``), else a time channel given with
``--time`` (seconds, uniform within 1 %). Units from the property ``unit_string``: ``g`` and ``mm/s^2`` are
converted to m/s^2, anything else kept as is.

Writing (``replay export -o NAME.tdms``): group ``rig`` with the channels ``base``, ``tip1``, ``tip2`` (float64,
m/s^2, waveform properties ``wf_increment``, ``wf_start_offset`` 0, ``wf_samples``, ``unit_string`` ``m/s^2``,
and the sensor's model, serial number and sensitivity where the recording's calibration names them), ``t``
(s) and ``seq`` (int64: the device's sequence number, -1 where a lost frame was filled by linear
interpolation), so the waveform is even and the holes stay marked: reading such a file back (``replay import``)
keeps them as holes.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np
from nptdms import ChannelObject, GroupObject, RootObject, TdmsFile, TdmsWriter

from daq.safeio import safe_output

from .base import Columns, Samples, check_rate, even_grid, missing_refused, typical_step
from .uff import CHANNELS, unit_factor

SUFFIXES = (".tdms",)
MAX_BYTES = 4 << 30


def _channels(path: Path) -> dict[str, dict]:
    """Numeric channels by name (and GROUP/NAME): data (converted to m/s^2 where the unit is g or mm/s^2),
    waveform increment (or None), unit."""
    try:
        if path.stat().st_size > MAX_BYTES:
            raise ValueError(f"{path}: larger than {MAX_BYTES >> 30} GiB")
    except FileNotFoundError:
        raise ValueError(f"{path}: no such file") from None
    if path.is_dir():
        raise ValueError(f"{path}: is a folder; give a TDMS file")
    try:
        f = TdmsFile.read(str(path))
        found = []
        for g in f.groups():
            for c in g.channels():
                data = c[:]
                if not isinstance(data, np.ndarray) or data.dtype.kind not in "fiu" or data.ndim != 1:
                    continue
                unit = str(c.properties.get("unit_string", "") or "")
                inc = c.properties.get("wf_increment")
                found.append((g.name, c.name, {"data": data.astype(np.float64) * unit_factor(unit),
                                               "increment": float(inc) if inc is not None else None,
                                               "unit": "m/s^2" if unit_factor(unit) != 1 else unit}))
    except ValueError as exc:
        if str(exc).startswith(str(path)):
            raise
        raise ValueError(f"{path}: not a readable TDMS file ({' '.join(str(exc).split())[:80]})") from None
    except Exception as exc:  # noqa: BLE001 - npTDMS raises many kinds on a damaged file
        raise ValueError(f"{path}: not a readable TDMS file ({type(exc).__name__}: "
                         f"{' '.join(str(exc).split())[:80]})") from None
    if not found:
        raise ValueError(f"{path}: no channel with numeric data")
    out: dict[str, dict] = {}
    names = [n for _, n, _ in found]
    for group, name, ch in found:
        out[f"{group}/{name}"] = ch
        if names.count(name) == 1:
            out[name] = ch
    return out


def read_columns(path: str | Path, names: list[str], time_col: str | None = None,
                 fs_hz: float | None = None, gaps: bool = False) -> Columns:
    """Named channels as floats and their rate (``fs_hz``, the waveform increment, or a time channel)."""
    path = Path(path)
    chans = _channels(path)
    wanted = list(names) + ([time_col] if time_col else [])
    missing = [c for c in wanted if c not in chans]
    if missing:
        shown = [c for c in chans if "/" not in c or c.split("/", 1)[1] not in chans]
        raise ValueError(f"{path}: no channel {missing[0]!r}; channels are: {', '.join(shown)}")
    if len({chans[c]["data"].size for c in wanted}) != 1:
        raise ValueError(f"{path}: channels {', '.join(wanted)} differ in length")
    data = np.column_stack([chans[c]["data"] for c in names])
    data = missing_refused(path, data, gaps)
    if fs_hz is not None and time_col is not None:
        raise ValueError("give --fs or --time, not both")
    if fs_hz is not None:
        fs = check_rate(fs_hz)
    elif time_col is not None:
        t = chans[time_col]["data"]
        dt = np.diff(t)
        if t.size < 2 or not np.all(np.isfinite(t)) or np.any(dt <= 0) or \
                np.max(np.abs(dt / np.median(dt) - 1)) > 0.01:
            raise ValueError(f"{path}: channel {time_col!r} is not a uniform, increasing time in seconds")
        fs = check_rate(1.0 / typical_step(dt), f"channel {time_col!r}'s rate")
    else:
        incs = {chans[c]["increment"] for c in names}
        if None in incs:
            raise ValueError(f"{path}: channel {next(c for c in names if chans[c]['increment'] is None)!r} has no "
                             f"waveform increment (wf_increment); give --fs HZ or --time CHANNEL")
        if len(incs) != 1:
            raise ValueError(f"{path}: channels {', '.join(names)} differ in rate")
        inc = incs.pop()
        if not (np.isfinite(inc) and inc > 0):
            raise ValueError(f"{path}: waveform increment {inc} is not a time step; give --fs HZ")
        fs = check_rate(1.0 / inc, "the waveform increment's rate")
    return Columns({c: data[:, j] for j, c in enumerate(names)}, fs, str(path))


def read_samples(path: str | Path, *, time_col: str | None = None, fs_hz: float | None = None,
                 base: str = "base", tip1: str = "tip1", tip2: str = "tip2", fill: bool = True) -> Samples:
    """The three channels; a ``seq`` channel beside them (as ``replay export`` writes) marks the filled rows
    (-1), which are dropped with ``fill=False`` and not imported as samples."""
    c = read_columns(path, [base, tip1, tip2], time_col, fs_hz)
    v = c.matrix([base, tip1, tip2])
    seq = np.arange(len(v))
    chans = _channels(Path(path))
    marks = chans.get("seq", {}).get("data")
    if marks is not None and marks.size == len(v) and np.all(marks == np.rint(marks)):
        seq = marks.astype(np.int64)
    t = np.arange(len(v)) / c.fs_hz
    if not fill:
        keep = seq >= 0
        t, v, seq = t[keep], v[keep], seq[keep]
    return Samples(t, v, c.fs_hz, seq, str(path))


def write_samples(path: str | Path, samples: Samples, *, force: bool = False, inputs: Iterable = (),
                  label: str = "-o") -> Path:
    """Group ``rig``: base, tip1, tip2 as even waveforms in m/s^2, t and seq (see the module doc)."""
    values, seq = even_grid(samples)
    filled = int(np.count_nonzero(seq < 0))
    n = values.shape[0]
    cal = samples.metadata.get("calibration", {}) if samples.metadata else {}
    inc = 1.0 / samples.fs_hz
    objects = [RootObject({"name": Path(str(path)).stem, "description": f"shaker-ident replay export of "
                                                                          f"{Path(samples.source).name}"}),
               GroupObject("rig", {"lost_frames_filled": filled})]
    for j, ch in enumerate(CHANNELS):
        props = {"wf_increment": inc, "wf_start_offset": 0.0, "wf_samples": n, "unit_string": "m/s^2",
                 "NI_ChannelName": ch}
        for key in ("sensor_model", "serial_number", "sensitivity_counts_per_m_per_s2", "sensitivity_mv_per_g"):
            if cal.get(f"{ch}.{key}"):
                props[key] = cal[f"{ch}.{key}"]
        objects.append(ChannelObject("rig", ch, values[:, j].astype(np.float64), props))
    objects.append(ChannelObject("rig", "t", np.arange(n) * inc, {"unit_string": "s"}))
    objects.append(ChannelObject("rig", "seq", seq, {"description": "device sequence number; -1: filled"}))
    with safe_output(path, inputs=inputs, force=force, label=label) as tmp:
        with TdmsWriter(str(tmp)) as w:
            w.write_segment(objects)
    return Path(path)
