"""The paper's experimental studies (section 4, Tables 4-7, Figs. 9-12) on a recording of the rig.

Every study low-passes below 50 Hz (zero-phase), decimates to ``fs_hz``
(200 Hz), forms relative accelerations (tip minus base, as the paper's study 2
does), delay-embeds them with the core's ACF delay, differentiates, and runs
the sweep and the SQP refinement with the base acceleration as the forcing
column. The identified model is integrated over the segment and compared with
the embedded measurement.

- study 1: no impact, one blade, 2-D embedding, p = 1 and p = 2 (the quadratic
  terms should vanish): Tables 4-5;
- study 2: localized impact, relative motions of both blades, 2 delays each
  (4 embedded states), spectral derivatives (the paper's spectral filtering):
  Table 6;
- study 3: both impacting, one blade, dimension from false nearest
  neighbours (at most 3), p = 2: Table 7.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..derivatives import differentiate
from ..embedding import acf_delay, delay_embed, fnn_dimension
from ..filters import lowpass_zero_phase
from ..metrics import error_percent, nrmse
from ..sindy import Identification, identify

STUDIES = {
    1: {"title": "no impact, one blade, 2-D embedding", "signals": (0,), "dimension": 2, "degrees": (1, 2),
        "derivative": "tvregdiff"},
    2: {"title": "localized impact, relative motions of both blades, 4 embedded states", "signals": (0, 1),
        "dimension": 2, "degrees": (2,), "derivative": "spectral"},
    3: {"title": "both impacting, one blade", "signals": (0,), "dimension": None, "degrees": (2,),
        "derivative": "tvregdiff"},
}


@dataclass(frozen=True)
class StudyFit:
    degree: int
    ident: Identification
    reconstructed: np.ndarray  # (n, m) integrated model
    error_percent: float  # first coordinate, paper's metric
    nrmse: float  # first coordinate


@dataclass(frozen=True)
class StudyResult:
    study: int
    title: str
    fs_hz: float
    delay: int  # samples at fs_hz
    dimension: int  # per signal
    state_names: tuple[str, ...]
    t: np.ndarray
    states: np.ndarray  # (n, m_total) embedded measurement
    forcing: np.ndarray  # (n,) base acceleration
    fits: tuple[StudyFit, ...]


def prepare(values: np.ndarray, fs_in: float, fs_hz: float = 200.0) -> tuple[np.ndarray, np.ndarray, float]:
    """(base (n,), relative accelerations (n, 2), rate) below 50 Hz at about ``fs_hz``."""
    values = np.asarray(values, float)
    if values.ndim != 2 or values.shape[1] != 3:
        raise ValueError(f"expected samples of base, tip1, tip2 (n, 3), got {values.shape}")
    step = max(1, int(round(fs_in / fs_hz)))
    fs = fs_in / step
    lp = lowpass_zero_phase(values, fs_in, min(50.0, 0.45 * fs))[::step]
    return lp[:, 0], lp[:, 1:] - lp[:, :1], fs


RIDGE = 1e-2


def run_study(values: np.ndarray, fs_in: float, study: int, *, degrees: tuple[int, ...] | None = None,
              dimension: int | None = None, delay: int | None = None, derivative: str | None = None,
              fs_hz: float = 200.0, ridge: float = RIDGE) -> StudyResult:
    """One study on ``values`` (n, 3) sampled at ``fs_in``; give a steady segment of one regime.

    In a steady state driven by one tone, the forcing column lies in the span
    of the delay coordinates and least squares is ill-posed; ``ridge`` picks
    the small-norm solution, and the refinement by integration error then fits
    it to the measured orbit. The coefficients are one of many models that
    reproduce that orbit, as they are in the paper's Tables 4-7.
    """
    if study not in STUDIES:
        raise ValueError(f"unknown study {study}; choose 1, 2 or 3")
    spec = STUDIES[study]
    base, rel, fs = prepare(values, fs_in, fs_hz)
    sig = [rel[:, i] for i in spec["signals"]]
    d = int(delay) if delay is not None else acf_delay(sig[0])
    m = dimension or spec["dimension"]
    if m is None:
        m, _ = fnn_dimension(sig[0], d, max_dim=6)
        m = min(m, 3)
    deriv = derivative or spec["derivative"]
    span = (m - 1) * d
    states, dstates, names = [], [], []
    for k, s in enumerate(sig):
        ds = differentiate(s, 1.0 / fs, deriv)
        states.append(delay_embed(s, d, m))
        dstates.append(delay_embed(ds, d, m))
        names += [f"x{len(names) + j + 1}" for j in range(m)]
    x = np.concatenate(states, axis=1)
    dx = np.concatenate(dstates, axis=1)
    f = base[span:]
    t = np.arange(len(f)) / fs
    fits = []
    for p in degrees or spec["degrees"]:
        ident = identify(x, dx, t, f, degree=p, state_names=tuple(names), ridge=ridge)
        rec = ident.model.simulate(x[0], t, f, bound=20 * np.abs(x).max()).x
        fits.append(StudyFit(p, ident, rec, error_percent(x[:, :1], rec[:, :1]), nrmse(x[:, :1], rec[:, :1])))
    return StudyResult(study, spec["title"], fs, d, m, tuple(names), t, x, f, tuple(fits))
