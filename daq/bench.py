"""``daq bench``: decoder throughput, bytes on disk per sample, CPU share of recording.

Benchmarks, not tests: each prints a ratio against a baseline measured in the
same run (the serial line's own rate; the simulated device serving alone),
which holds on a noisy machine where absolute times do not.
"""

from __future__ import annotations

import os
import re
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from ident.cli import number
from replay.formats.mcap import read_recording

from . import bench_regimes
from .config import load_config
from .protocol import Decoder
from .sim.device import SimulatedDevice

LINE_BAUD = 921_600
LINE_BYTES_PER_S = LINE_BAUD / 10  # 8N1: 10 bits per byte


def add_parser(sub) -> None:
    p = sub.add_parser("bench", help="benchmarks: decoder throughput, bytes per sample, CPU share")
    p.add_argument("--seconds", type=number(0.0, 3600.0, gt=True, unit="s"), default=10.0,
                   help="length of the recording runs (default 10)")
    p.add_argument("--live", action="store_true",
                   help="also the live pipeline: replay --max speed, latency, CPU share of identification")
    bench_regimes.add_arguments(p)
    p.set_defaults(func=run)


def _child_cpu() -> float:
    ru = resource.getrusage(resource.RUSAGE_CHILDREN)
    return ru.ru_utime + ru.ru_stime


def _timed(cmd: list[str]) -> tuple[float, float]:
    c0, t0 = _child_cpu(), time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return _child_cpu() - c0, time.perf_counter() - t0


def run(args) -> int:
    if args.regimes:
        return bench_regimes.run(args)
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
                                   "daq.transport, daq.sim.rig; from daq.sim.rig import simulate_rig, RigConfig; "
                                   "simulate_rig(RigConfig(), 0.01)"])
        c_sim, w_sim = _timed(py + ["sim", "--duration", str(args.seconds)])
        c_rec, w_rec = _timed(py + ["record", "--sim", "--quiet", "--duration", str(args.seconds), "-o", str(out)])
        size = out.stat().st_size
        n = len(read_recording(out, raw=False).seq)
    share_sim = (c_sim - c_start) / (w_sim - w_start)
    share_rec = (c_rec - c_start) / (w_rec - w_start)
    print(f"on disk      : {size / n:8.1f} bytes per 3-channel sample ({n} samples, {size} bytes: the serial bytes, "
          f"events, status and models; {size / n / 40:.2f} x the 40-byte target)")
    print(f"CPU share    : record --sim {100 * share_rec:5.1f} % of one core; device alone (daq sim) "
          f"{100 * share_sim:5.1f} %; recording adds {100 * (share_rec - share_sim):5.1f} % "
          f"(ratio {share_rec / share_sim if share_sim > 0 else np.inf:4.1f}); start-up "
          f"{c_start:.2f} s CPU subtracted")
    if args.live:
        _live(args, py, c_start, w_start)
    return 0


def _live(args, py, c_start, w_start) -> None:
    """Live pipeline: replay --max with and without identification; latency and CPU of daq record, warm
    (numba's cache filled) and as the first run after an install (an empty numba cache)."""
    with tempfile.TemporaryDirectory() as tmp:
        cfg = Path(tmp) / "kick.yaml"
        cfg.write_text("excitation:\n  ramp_s: 1.0\n  kicks:\n    - {t_s: 20.0447, beam: 1, velocity_m_per_s: 0.3}\n")
        rec = Path(tmp) / "rec60.mcap"
        subprocess.run(py + ["record", "--port", f"rig://?config={cfg}", "--config", str(cfg), "--duration", "60",
                             "-o", str(rec), "--quiet", "--no-identify"], check=True, stdout=subprocess.DEVNULL)
        replay = [sys.executable, "-m", "replay", str(rec), "--max"]

        def speed(extra):
            out = subprocess.run(replay + extra, check=True, capture_output=True, text=True).stdout
            m = re.search(r"\(([\d.]+) x real time; CPU [\d.]+ s, ([\d.]+) x[;)]", out)
            return float(m.group(1)), float(m.group(2)), "identification in a second process" in out

        # interleaved, so that a load that comes and goes touches every variant alike
        runs = [(speed([]), speed(["--one-process"]), speed(["--no-identify"])) for _ in range(3)]
        with_id, one, without = (np.array([r[k][:2] for r in runs]) for k in range(3))
        where = "in a second process" if runs[0][0][2] else "in one process (one core)"  # as replay said
        print(f"replay --max : {np.median(with_id[:, 0]):6.0f} x real time with identification "
              f"({np.median(with_id[:, 1]):.0f} x in CPU time; {where}), "
              f"{np.median(one[:, 0]):6.0f} x with it in one process ({np.median(one[:, 1]):.0f} x in CPU time), "
              f"{np.median(without[:, 0]):6.0f} x without ({np.median(without[:, 1]):.0f} x in CPU time); 60 s "
              f"recording with a regime change, medians of 3 interleaved; target 200 x")
        out = Path(tmp) / "live.mcap"
        c0, t0 = _child_cpu(), time.perf_counter()
        res = subprocess.run(py + ["record", "--sim", "--config", str(cfg), "--duration", "30", "-o", str(out),
                                   "--quiet"], check=True, capture_output=True, text=True)
        c_live, w_live = _child_cpu() - c0, time.perf_counter() - t0
        c_rec, w_rec = _timed(py + ["record", "--sim", "--config", str(cfg), "--duration", "30", "-o",
                                    str(Path(tmp) / "plain.mcap"), "--quiet", "--no-identify"])
        share_live = (c_live - c_start) / (w_live - w_start)
        share_rec = (c_rec - c_start) / (w_rec - w_start)
        print(f"live record  : CPU {100 * share_live:5.1f} % of one core with the pipeline, {100 * share_rec:5.1f} % "
              f"with --no-identify (filters and regime monitor); identification adds "
              f"{100 * (share_live - share_rec):5.1f} %")
        _latency("latency warm ", res.stdout)
        # the first run after an install: numba's cache empty (a fresh folder), so the kernels compile
        env = {**os.environ, "NUMBA_CACHE_DIR": str(Path(tmp) / "numba-cache")}
        first = subprocess.run(py + ["record", "--sim", "--config", str(cfg), "--duration", "30", "-o",
                                     str(Path(tmp) / "first.mcap"), "--quiet"], check=True, capture_output=True,
                               text=True, env=env)
        _latency("latency first", first.stdout)


def _latency(label: str, stdout: str) -> None:
    lat = re.search(r"p50 (\d+) ms, p95 (\d+) ms", stdout)
    comp = re.search(r"kernels compiled in ([\d.]+) s", stdout)
    if lat:
        print(f"{label}: sample arrival -> the first model update that includes it: p50 {lat.group(1)} ms, "
              f"p95 {lat.group(2)} ms (hop 1 s, window 4 s; target p95 50 ms)"
              + (f"; kernels compiled in {comp.group(1)} s before the first sample" if comp else ""))
    else:
        print(f"{label}: no model update")
