"""Universal File Format, dataset 58 (function at nodal DOF): time histories as LMS Test.Lab, ME'scope and most
modal software read and write them; via ``pyuff``.

Reading: every dataset 58 of function type 1 (time response) with even abscissa spacing is a channel, ASCII or
binary (58b). Its name is ID line 1 (``id1``); where that is empty, ``NONE`` or taken by an earlier channel,
``ENTITY:NODE:DIR`` (response entity, node and direction, e.g. ``NONE:3:+Z``). The rate is 1 / the abscissa
increment; the file prints the increment with six significant digits, so a whole-number rate that prints as
the same increment is taken as it is (3000 Hz, not 3000.003 Hz). Units from the ordinate's axis-units label:
``g`` and ``mm/s^2`` are converted to m/s^2, ``m/s^2`` (``m/s2``, ``m/s**2``) and anything else kept as is
(a force in N stays in N). ``--fs`` overrides the rate; there is no time column.

Writing (``replay export --uff``, or ``-o NAME.uff``/``.unv``): one dataset 58 per channel (``base``, ``tip1``,
``tip2``), function type 1, ID line 1 the channel's name, 2 the source, 3 the date, 4 the sensor (model,
serial number, sensitivity) where the recording's calibration names it, 5 what was filled; response entity
the channel's name, node 1, 2, 3, direction +Z; abscissa time in s (specific data type 17), ordinate
acceleration (12) in m/s^2; ASCII, double precision (4E20.12, the form every reader takes). An even
abscissa has no holes: frames a recording lost are filled by linear interpolation, and ID line 5 says how
many.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import pyuff

from daq.safeio import safe_output

from .base import Columns, Samples, check_rate, even_grid, missing_refused

SUFFIXES = (".uff", ".unv")
MAX_BYTES = 4 << 30
CHANNELS = ("base", "tip1", "tip2")
DIRECTIONS = {0: "S", 1: "+X", -1: "-X", 2: "+Y", -2: "-Y", 3: "+Z", -3: "-Z", 4: "+RX", -4: "-RX", 5: "+RY",
              -5: "-RY", 6: "+RZ", -6: "-RZ"}
TO_M_PER_S2 = {"g": 9.80665, "mm/s^2": 1e-3, "mm/s2": 1e-3, "mm/s**2": 1e-3}


def unit_factor(label: str) -> float:
    """Factor to m/s^2 for an acceleration unit label (g, mm/s^2); 1 for m/s^2 and any other unit."""
    return TO_M_PER_S2.get(label.strip().lower().replace(" ", ""), 1.0)


def snap_rate(increment: float) -> float:
    """1 / increment, or the whole number that prints as the same increment at six significant digits."""
    fs = 1.0 / increment
    whole = round(fs)
    if whole > 0 and f"{1.0 / whole:.5e}" == f"{increment:.5e}":
        return float(whole)
    return fs


def _sets(path: Path) -> list[dict]:
    try:
        size = path.stat().st_size
    except FileNotFoundError:
        raise ValueError(f"{path}: no such file") from None
    if path.is_dir():
        raise ValueError(f"{path}: is a folder; give a UFF file")
    if size > MAX_BYTES:
        raise ValueError(f"{path}: larger than {MAX_BYTES >> 30} GiB")
    try:
        uff = pyuff.UFF(str(path))
        types = list(uff.get_set_types())
        picks = [i for i, t in enumerate(types) if int(t) == 58]
        sets = uff.read_sets(picks) if picks else []
    except Exception as exc:  # noqa: BLE001 - pyuff raises bare Exception for every kind of damage
        raise ValueError(f"{path}: not a readable UFF file ({' '.join(str(exc).split())[:80]})") from None
    if isinstance(sets, dict):
        sets = [sets]
    if not sets:
        kinds = ", ".join(sorted({str(int(t)) for t in types})) or "none"
        raise ValueError(f"{path}: no dataset 58 (time histories) in this UFF file (datasets found: {kinds})")
    return sets


def _channels(path: Path) -> dict[str, dict]:
    """Time histories by name: data (in m/s^2 where the unit is an acceleration), rate, start, unit."""
    out: dict[str, dict] = {}
    others = 0
    for d in _sets(path):
        data = d.get("data")
        if int(d.get("func_type", -1)) != 1 or int(d.get("abscissa_spacing", 0)) != 1 or data is None \
                or np.iscomplexobj(data):
            others += 1
            continue
        inc = float(d.get("abscissa_inc", 0.0))
        if not (np.isfinite(inc) and inc > 0):
            raise ValueError(f"{path}: dataset {d.get('id1', '?')!r} has abscissa increment {inc}; not a time history")
        unit = str(d.get("ordinate_axis_units_lab", "")).strip()
        unit = "" if unit.upper() == "NONE" else unit
        name = str(d.get("id1", "")).strip()
        if not name or name.upper() == "NONE" or name in out:
            name = f"{str(d.get('rsp_ent_name', 'NONE')).strip()}:{int(d.get('rsp_node', 0))}:" \
                   f"{DIRECTIONS.get(int(d.get('rsp_dir', 0)), d.get('rsp_dir'))}"
            k = 2
            while name in out:
                name, k = f"{name.rsplit('#', 1)[0]}#{k}", k + 1
        out[name] = {"data": np.asarray(data, np.float64) * unit_factor(unit), "fs": snap_rate(inc),
                     "start": float(d.get("abscissa_min", 0.0)), "unit": "m/s^2" if unit_factor(unit) != 1 else unit}
    if not out:
        raise ValueError(f"{path}: its {others} dataset(s) 58 are not time histories with even spacing (function "
                         f"type 1): spectra and FRFs are not samples")
    return out


def read_columns(path: str | Path, names: list[str], time_col: str | None = None,
                 fs_hz: float | None = None, gaps: bool = False) -> Columns:
    """Named time histories as floats and their rate (``fs_hz`` overrides the file's)."""
    path = Path(path)
    if time_col is not None:
        raise ValueError("--time is for CSV files; a UFF time history carries its own increment (or give --fs)")
    chans = _channels(path)
    missing = [c for c in names if c not in chans]
    if missing:
        raise ValueError(f"{path}: no channel {missing[0]!r}; channels are: {', '.join(chans)}")
    picked = [chans[c] for c in names]
    if len({p["data"].size for p in picked}) != 1:
        raise ValueError(f"{path}: channels {', '.join(names)} differ in length")
    if len({p["fs"] for p in picked}) != 1 or len({p["start"] for p in picked}) != 1:
        raise ValueError(f"{path}: channels {', '.join(names)} differ in rate or start time")
    data = np.column_stack([p["data"] for p in picked])
    data = missing_refused(path, data, gaps)
    fs = check_rate(fs_hz if fs_hz is not None else picked[0]["fs"],
                    "--fs" if fs_hz is not None else "the abscissa increment's rate")
    return Columns({c: data[:, j] for j, c in enumerate(names)}, fs, str(path))


def read_samples(path: str | Path, *, time_col: str | None = None, fs_hz: float | None = None,
                 base: str = "base", tip1: str = "tip1", tip2: str = "tip2", fill: bool = True) -> Samples:
    c = read_columns(path, [base, tip1, tip2], time_col, fs_hz)
    v = c.matrix([base, tip1, tip2])
    return Samples(np.arange(len(v)) / c.fs_hz, v, c.fs_hz, np.arange(len(v)), str(path))


def _sensor(samples: Samples, channel: str) -> str:
    cal = samples.metadata.get("calibration", {}) if samples.metadata else {}
    parts = [cal.get(f"{channel}.sensor_model", ""), cal.get(f"{channel}.serial_number", "") and
             f"SN {cal[f'{channel}.serial_number']}"]
    sens = cal.get(f"{channel}.sensitivity_counts_per_m_per_s2") or cal.get(f"{channel}.sensitivity_mv_per_g")
    if sens:
        unit = "counts/(m/s^2)" if f"{channel}.sensitivity_counts_per_m_per_s2" in cal else "mV/g"
        parts.append(f"{float(sens):.6g} {unit}")
    return ", ".join(p for p in parts if p) or "NONE"


def write_samples(path: str | Path, samples: Samples, *, force: bool = False, inputs: Iterable = (),
                  label: str = "--uff") -> Path:
    """Three datasets 58 (base, tip1, tip2) in m/s^2 on an even time grid (see the module doc)."""
    values, seq = even_grid(samples)
    filled = int(np.count_nonzero(seq < 0))
    t = np.arange(values.shape[0]) / samples.fs_hz
    date = time.strftime("%d-%b-%y %H:%M:%S")
    sets = []
    for j, ch in enumerate(CHANNELS):
        d = pyuff.prepare_58(
            binary=0, func_type=1, rsp_node=j + 1, rsp_dir=3, ref_node=0, ref_dir=0, data=values[:, j].copy(),
            x=t, id1=ch, id2=f"shaker-ident replay export of {Path(samples.source).name}"[:80], id3=date,
            id4=_sensor(samples, ch)[:80],
            id5=(f"{filled} lost frame(s) filled by linear interpolation" if filled else "no frame lost")[:80],
            rsp_ent_name=ch, abscissa_spacing=1, abscissa_spec_data_type=17, abscissa_axis_units_lab="s",
            ordinate_spec_data_type=12, ordinate_axis_units_lab="m/s^2", orddenom_spec_data_type=0,
            z_axis_spec_data_type=0)
        d["abscissa_axis_lab"], d["ordinate_axis_lab"] = "Time", f"{ch} acceleration"[:20]
        sets.append(d)
    with safe_output(path, inputs=inputs, force=force, label=label) as tmp:
        try:
            pyuff.UFF(str(tmp)).write_sets(sets, mode="overwrite")
        except Exception as exc:  # noqa: BLE001 - pyuff raises bare Exception
            raise ValueError(f"{path}: pyuff could not write the time histories ({' '.join(str(exc).split())[:80]})") \
                from None
    return Path(path)
