"""``daq bench``: decoder throughput, bytes on disk per sample, CPU share of recording.

Benchmarks, not tests: each prints a ratio against a baseline measured in the
same run (the serial line's own rate; the simulated device serving alone),
which holds on a noisy machine where absolute times do not.
"""

from __future__ import annotations

import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

LINE_BAUD = 921_600
LINE_BYTES_PER_S = LINE_BAUD / 10  # 8N1: 10 bits per byte


def add_parser(sub) -> None:
    p = sub.add_parser("bench", help="benchmarks: decoder throughput, bytes per sample, CPU share")
    p.add_argument("--seconds", type=float, default=10.0, help="length of the recording runs (default 10)")
    p.set_defaults(func=run)


def _child_cpu() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def _timed(cmd: list[str]) -> tuple[float, float]:
    c0, t0 = _child_cpu(), time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return _child_cpu() - c0, time.perf_counter() - t0


def run(args) -> int:
    import numpy as np

    from .config import load_config
    from .device import SimulatedDevice
    from .protocol import Decoder

    data = SimulatedDevice(load_config(None)).frames(400_000)  # 9.6 MB, 200 s of the rig
    best = 0.0
    for _ in range(3):
        dec = Decoder()
        t0 = time.perf_counter()
        for i in range(0, len(data), 1 << 20):
            dec.feed(data[i:i + (1 << 20)])
        best = max(best, len(data) / (time.perf_counter() - t0))
    print(f"decoder      : {best / 1e6:8.1f} MB/s = {best / LINE_BYTES_PER_S:6.0f} x a {LINE_BAUD}-baud line "
          f"({dec.counters.frames} frames per pass)")

    py = [sys.executable, "-m", "daq"]
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "bench.mcap"
        # startup (imports, compiled kernels from cache) measured alone, then subtracted
        c_start, w_start = _timed([sys.executable, "-c", "import daq.cli, daq.driver, daq.recorder, "
                                   "daq.transport, ident.rig; from ident.rig import simulate_rig, RigConfig; "
                                   "simulate_rig(RigConfig(), 0.01)"])
        c_sim, w_sim = _timed(py + ["sim", "--duration", str(args.seconds)])
        c_rec, w_rec = _timed(py + ["record", "--sim", "--quiet", "--duration", str(args.seconds), "-o", str(out)])
        size = out.stat().st_size
        from replay.reader import read_recording

        n = len(read_recording(out, raw=False).seq)
    share_sim = (c_sim - c_start) / (w_sim - w_start)
    share_rec = (c_rec - c_start) / (w_rec - w_start)
    print(f"on disk      : {size / n:8.1f} bytes per 3-channel sample ({n} samples, {size} bytes, raw bytes "
          f"24/sample included)")
    print(f"CPU share    : record --sim {100 * share_rec:5.1f} % of one core; device alone (daq sim) "
          f"{100 * share_sim:5.1f} %; recording adds {100 * (share_rec - share_sim):5.1f} % "
          f"(ratio {share_rec / share_sim if share_sim > 0 else np.inf:4.1f}); start-up "
          f"{c_start:.2f} s CPU subtracted")
    return 0
