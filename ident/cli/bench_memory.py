"""``ident bench memory``: what ``discover``'s memory budget saves and what it costs, in one run.

One long record of a linear two-mode structure (a random force low-passed at 100 Hz; two accelerations
from scipy's ``lfilter`` of two second-order modes at 12 and 31 Hz; 1 % noise) goes through ``discover``
twice, each run in a process of its own so its peak resident memory is its own: once within a budget
(``--max-samples``, default a quarter of the record's samples x responses: decimated where the rate
allows, else cut) and once with a budget that holds the whole record, as recorded. Prints each run's
peak memory (and what the process held before discovery started: its modules and the record), its
time, the ratios, the modes each baseline found (the structure's are 12 and 31 Hz) and both answers (a
linear record: "nothing found" is right).

A benchmark, not a test: run it alone (each run is one process on one BLAS thread).
"""

from __future__ import annotations

import json
import resource
import subprocess
import sys
import time

import numpy as np
from scipy import signal

from ..discovery import Channel, Measurement, Settings, discover

MODES = ((12.0, 0.02, (1.0, 0.6)), (31.0, 0.015, (0.5, -0.8)))  # Hz, damping ratio, the two sensors' shares


def record(seconds: float, fs_hz: float, seed: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The force and the two accelerations."""
    n = int(seconds * fs_hz)
    rng = np.random.default_rng(seed)
    b, a = signal.butter(4, min(100.0, 0.4 * fs_hz) / (fs_hz / 2))
    u = signal.lfilter(b, a, rng.standard_normal(n))
    y = np.zeros((2, n))
    for f0, zeta, shares in MODES:
        w = 2 * np.pi * f0
        num, den, _ = signal.cont2discrete(([w * w, 0.0, 0.0], [1.0, 2 * zeta * w, w * w]), 1 / fs_hz,
                                           method="bilinear")
        mode = signal.lfilter(np.ravel(num), den, u)
        y += np.outer(shares, mode)
    y += 0.01 * y.std(axis=1, keepdims=True) * rng.standard_normal(y.shape)
    return u, y[0], y[1]


def _peak_gb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9  # kB on Linux


def child(seconds: float, fs_hz: float, max_samples: int) -> dict:
    """One run (in its own process): the record made, then discovered within ``max_samples``."""
    u, y1, y2 = record(seconds, fs_hz)
    m = Measurement(fs_hz, Channel("force", "force", u),
                    (Channel("a1", "acceleration", y1), Channel("a2", "acceleration", y2)))
    held = _peak_gb()
    t0 = time.perf_counter()
    d = discover(m, settings=Settings(max_samples=max_samples))
    return {"seconds": time.perf_counter() - t0, "peak_gb": _peak_gb(), "record_gb": held,
            "modes_hz": sorted(float(f) for f, z in zip(d.baseline.model.frequencies_hz,
                                                        d.baseline.model.damping_ratios) if z < 0.2),
            "analysed_hz": d.prep.fs_hz, "analysed_samples": d.prep.n, "verdict": d.verdict()}


def _run_child(seconds: float, fs_hz: float, max_samples: int) -> dict:
    proc = subprocess.run([sys.executable, "-m", "ident.cli.bench_memory", str(seconds), str(fs_hz), str(max_samples)],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        raise RuntimeError(f"the run with --max-samples {max_samples} failed: {tail}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


def run_bench(seconds: float, fs_hz: float, max_samples: int | None) -> int:
    n = int(seconds * fs_hz)
    whole = 2 * n
    budget = max_samples or whole // 4
    print(f"record: {seconds:g} s at {fs_hz:g} Hz, two accelerations ({whole:,} samples x responses); modes "
          + ", ".join(f"{f:g} Hz" for f, _, _ in MODES))
    runs = {}
    for label, b in (("within the budget", budget), ("as recorded", whole)):
        r = runs[label] = _run_child(seconds, fs_hz, b)
        print(f"{label:18s} --max-samples {b:>12,}: {r['analysed_samples']:,} samples at {r['analysed_hz']:.6g} Hz; "
              f"peak {r['peak_gb']:.2f} GB ({r['record_gb']:.2f} GB before discovery); {r['seconds']:.0f} s; modes "
              + ", ".join(f"{f:.3f}" for f in r["modes_hz"]) + f" Hz; {r['verdict']}")
    a, b = runs["within the budget"], runs["as recorded"]
    own = (a["peak_gb"] - a["record_gb"]) / max(b["peak_gb"] - b["record_gb"], 1e-9)
    print(f"ratios, within the budget / as recorded: peak memory {a['peak_gb'] / b['peak_gb']:.2f}, discovery's own "
          f"(peak less the memory before it) {own:.2f}, time {a['seconds'] / b['seconds']:.2f}")
    return 0


if __name__ == "__main__":
    print(json.dumps(child(float(sys.argv[1]), float(sys.argv[2]), int(sys.argv[3]))))
