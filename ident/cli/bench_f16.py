"""``ident bench f16``: discovery on the F-16 ground vibration test, and what its answer does to the resonance.

The F-16 benchmark's records (Noel & Schoukens 2017, "F-16 aircraft benchmark based on ground vibration test
data"; ``--data``, default ``../shared/data/f16_gvt``) as recorded: the level-1 multisine fits the baseline, the
level-7 one is analysed (the command the README gives). Then, independently of the method, the H1 estimate
(Welch cross-spectrum over auto-spectrum, scipy) of each acceleration against the force near the 7.3 Hz mode,
whose peak softens and drops as the level grows (the damping growth at the wing-payload interface): measured
at level 1 and level 7, and simulated under the measured level-7 force by the baseline and by the extended
model (free run over the record after the usual warm-up). A model that captures the softening and the damping
growth puts its level-7 peak where the measured one is, not where level 1's is.

A benchmark, not a test (two minutes on one core).
"""

from __future__ import annotations

import time
from argparse import Namespace
from pathlib import Path

import numpy as np

from ..discovery import discover
from ..discovery.search import predict
from ..discovery.signals import frf, prepare
from .discover import load_measurement

FILES = ("F16Data_FullMSine_Level7.mat", "F16Data_FullMSine_Level1.mat")
RESPONSES = ("Acceleration1", "Acceleration2", "Acceleration3")
MODE_HZ = (6.9, 7.6)  # the interface's mode, 7.32 Hz at level 1
SEGMENT = 8192  # Welch segment: 0.05 Hz at 400 Hz


def h1_peak(u: np.ndarray, y: np.ndarray, fs_hz: float, band: tuple[float, float] = MODE_HZ,
            nperseg: int = SEGMENT) -> tuple[float, float]:
    """(frequency, |H1|) of the largest |H1| = |S_uy / S_uu| within ``band`` (``signals.frf``: Hann-windowed
    Welch estimates, segments of ``nperseg``)."""
    f, H, _ = frf(u, y, fs_hz, nperseg)
    h = np.abs(H[0])
    k = np.flatnonzero((f >= band[0]) & (f <= band[1]))
    if k.size == 0:
        raise ValueError(f"no frequency line in {band[0]:g}-{band[1]:g} Hz at {fs_hz:g} Hz")
    j = k[np.argmax(h[k])]
    return float(f[j]), float(h[j])


def run_bench(data: Path) -> int:
    paths = [data / name for name in FILES]
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        raise ValueError(f"--data {data}: not the F-16 benchmark's folder (missing {', '.join(missing)})")
    args = Namespace(excitation="Force:force", response=list(RESPONSES), time_col=None, fs_hz=None)
    high, low = (load_measurement(p, args) for p in paths)
    t0 = time.perf_counter()
    d = discover(high, fit_data=low)
    seconds = time.perf_counter() - t0
    print(f"ident discover {FILES[0]} --fit-data {FILES[1]}: {d.verdict()} ({seconds:.0f} s)")
    print(f"baseline held out at {d.baseline_test_nrmse:.3f}, extended model at {d.extended_test_nrmse:.3f}")
    prep = d.prep
    seg = slice(prep.edge + d.warm, prep.n - prep.edge)
    first = d.findings[0] if d.findings else None
    own = first.baseline if first is not None and first.baseline is not None else d.baseline
    simulated = {"baseline": predict(d.baseline, d.baseline.model, prep, seg, d.warm),
                 "extended": predict(own, d.extended, prep, seg, d.warm, d.extended_output)}
    prep_low = prepare(low, prep.band)
    seg_low = slice(prep_low.edge + d.warm, prep_low.n - prep_low.edge)
    print(f"H1 peak near the interface's mode ({MODE_HZ[0]:g}-{MODE_HZ[1]:g} Hz), Hz and (m/s^2)/N:")
    print(f"{'sensor':15s} {'level 1 measured':>20s} {'level 7 measured':>20s} {'baseline at 7':>20s} "
          f"{'extended at 7':>20s}   share of the drop captured")
    for i, name in enumerate(prep.names):
        lo = h1_peak(prep_low.u[seg_low], prep_low.measured[seg_low, i], prep_low.fs_hz)
        hi = h1_peak(prep.u[seg], prep.measured[seg, i], prep.fs_hz)
        base = h1_peak(prep.u[seg], simulated["baseline"][:, i], prep.fs_hz)
        ext = h1_peak(prep.u[seg], simulated["extended"][:, i], prep.fs_hz)
        drop = (base[1] - ext[1]) / (base[1] - hi[1]) if base[1] != hi[1] else float("nan")
        cells = " ".join(f"{fr:8.3f} Hz {h:8.4f}" for fr, h in (lo, hi, base, ext))
        print(f"{name:15s} {cells}   {drop:6.0%}")
    return 0
