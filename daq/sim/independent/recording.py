"""A generated record (`Case`: measured columns, their kinds and units, the truth) and its files.

`write_case` writes `case.csv` (a header row of column names, the time column `t` first), `truth.json`,
and `truth.csv` when the case has per-sample truth; each file is written under a temporary name beside
its target and then hard-linked to the target name, which fails if the target exists: nothing is ever
overwritten.

`seeded` marks a function that builds a Case from a seed: it runs with one BLAS thread, because the
generator's eigen-solutions and products round differently with two threads than with one, so a seed
would otherwise give other digits (and, near a threshold, another verdict) on a machine with another
core count or in a Dask worker.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

KINDS = ("time", "base_acceleration", "force", "voltage", "acceleration", "velocity", "displacement")


def seeded(build):
    """build, run with one BLAS thread (see the module docstring)."""
    return threadpool_limits.wrap(limits=1, user_api="blas")(build)


@dataclass
class Case:
    family: str
    fs_hz: float
    columns: dict[str, np.ndarray]  # "t" (s) first
    kinds: dict[str, str]
    units: dict[str, str]
    truth: dict
    # per-sample truth, "t" first: a regime case's contact flags and regimes; a discovery case's channels
    # before their sensor noise, range and quantisation ("clean:<column>")
    truth_series: dict[str, np.ndarray] = field(default_factory=dict)

    def __post_init__(self):
        names = list(self.columns)
        if not names or names[0] != "t":
            raise ValueError("the first column must be the time column t")
        for name in names:
            if self.kinds.get(name) not in KINDS:
                raise ValueError(f"column {name}: kind must be one of {KINDS}")


def jsonable(obj):
    """Numpy scalars and arrays to plain Python, recursively."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, np.bool_):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.floating):
        return float(obj)
    return obj


def _write_new(path: Path, text: str) -> None:
    if path.exists():
        raise FileExistsError(f"{path} exists; refusing to overwrite it")
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text)
    try:
        os.link(tmp, path)
    finally:
        tmp.unlink()


def _csv(columns: dict[str, np.ndarray]) -> str:
    names = list(columns)
    data = np.column_stack([np.asarray(columns[n], dtype=float) for n in names]) + 0.0  # no "-0"
    lines = [",".join(names)]
    lines += [",".join(f"{v:.10g}" for v in row) for row in data]
    return "\n".join(lines) + "\n"


def write_case(case: Case, folder: str | Path) -> Path:
    """Write the case's files into folder (created if missing); refuse to overwrite any file."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    targets = [folder / "case.csv", folder / "truth.json"] + ([folder / "truth.csv"] if case.truth_series else [])
    for t in targets:
        if t.exists():
            raise FileExistsError(f"{t} exists; refusing to overwrite it")
    truth = {"family": case.family, "fs_hz": case.fs_hz, "kinds": case.kinds, "units": case.units,
             **case.truth}
    _write_new(folder / "case.csv", _csv(case.columns))
    _write_new(folder / "truth.json", json.dumps(jsonable(truth), indent=1) + "\n")
    if case.truth_series:
        _write_new(folder / "truth.csv", _csv(case.truth_series))
    return folder
