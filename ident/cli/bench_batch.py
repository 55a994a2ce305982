"""``ident bench batch``: how ``ident batch`` scales on this machine, on a generated campaign.

The campaign (``--campaign DIR``, made there once and reused; a temporary folder otherwise) is a monitoring
campaign of the simulated rig (``daq.sim``: the rig model, shaker programme and sensors with their noise and
ADC): recording k of N has beam 1's natural frequency lowered from 11.2 Hz to 10.4 Hz across the campaign
(a stiffness loss of 14 %), beam 2's at 11.2 Hz. Most are broadband tests (random-phase multisine 3-40 Hz,
1.0-1.4 m/s^2 rms, beams free); every 10th is a louder one (2.5 m/s^2 rms: the beams reach their stoppers);
every 10th another is a 12.3 Hz sine with a blow on beam 1 at 3 s (the regime changes). One in five is
written as CSV (``t,seq,base,tip1,tip2``), the rest as MCAP, through replay's writers; plus a copy of the
first recording cut at 60 % of its bytes, as a kill -9 leaves one (a row with its error). ``campaign.json``
holds each recording's truth (its natural frequencies with the coupling spring, the test).

The benchmark runs the same batch in a plain loop in this process (no engine) and on local Dask clusters,
and checks that every way gives the same table (every column but the run time). First ``--regimes`` alone,
little work per task, in the loop and on 1 worker: the engine's overhead per recording, (T_1 worker -
T_loop) / N. Then ``--regimes --fit --start 2`` in the loop and on 1 and 2 workers: the speed-up 1 -> 2
workers (and the overhead with that work). The clusters are started and their workers warmed (one
recording each: imports and compiled kernels loaded) before the clock starts; their start-up is printed
apart. One worker (and the loop) keeps more than one core busy at times: the sweep integrates its
candidates in parallel threads; two workers get one such thread each. Also how far the trusted natural
frequencies fall from the truth. A benchmark, not a test.
"""

from __future__ import annotations

import json
import math
import shutil
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from daq.safeio import safe_folder
from daq.sim.excitation import Excitation, Kick
from daq.sim.rig import RigConfig, simulate_rig
from daq.sim.sensors import Sensor, from_counts, to_counts
from replay.formats import Samples, write_samples

from ..rig import RigParams
from .batch import Settings, analyse_job, expand
from .batch_report import trusted_frequency
from .engine import OneBlasThread, dask_client, run_unordered

FS_HZ = 1000.0
FN1_HZ = (11.2, 10.4)  # beam 1's natural frequency at the first and the last recording
CUT_SHARE = 0.6
NOOP_TASKS = 200


def recording_plan(k: int, n: int, seed: int) -> dict:
    """What recording k of n is: beam 1's natural frequency, the test, the file format."""
    rng = np.random.default_rng([seed, k])
    u = k / max(1, n - 1)
    fn1 = FN1_HZ[0] + (FN1_HZ[1] - FN1_HZ[0]) * u
    if k % 10 == 9:
        test = {"kind": "sine", "frequency_hz": 12.3, "amplitude_m_per_s2": 1.93, "blow_s": 3.0}
    elif k % 10 == 4:
        test = {"kind": "broadband", "rms_m_per_s2": 2.5}
    else:
        test = {"kind": "broadband", "rms_m_per_s2": round(float(rng.uniform(1.0, 1.4)), 3)}
    return {"name": f"rec-{k:04d}.{'csv' if k % 5 == 2 else 'mcap'}", "beam1_hz": round(fn1, 6),
            "beam2_hz": 11.2, "test": test, "seed": int(rng.integers(2**31))}


def coupled_hz(beam_hz: float, rig: RigParams) -> float:
    """A beam's natural frequency with the coupling spring to a still neighbour: sqrt((k + k_c) / m) / 2 pi."""
    m = rig.beam1.mass_kg
    return math.sqrt((2 * math.pi * beam_hz) ** 2 + rig.coupling_stiffness_n_per_m / m) / (2 * math.pi)


def simulate_recording(plan: dict, duration_s: float) -> Samples:
    """The rig of ``plan`` through its test, read by the default accelerometers and ADC."""
    p = RigParams()
    p = replace(p, beam1=replace(p.beam1, natural_frequency_hz=plan["beam1_hz"]),
                beam2=replace(p.beam2, natural_frequency_hz=plan["beam2_hz"]))
    t = plan["test"]
    if t["kind"] == "sine":
        exc = Excitation(frequency_hz=t["frequency_hz"], amplitude_m_per_s2=t["amplitude_m_per_s2"], ramp_s=1.0,
                         kicks=(Kick(t["blow_s"], 1, 0.3),))
    else:
        exc = Excitation(amplitude_m_per_s2=0.0, ramp_s=1.0, noise_rms_m_per_s2=t["rms_m_per_s2"],
                         noise_band_hz=(3.0, 40.0), seed=plan["seed"])
    _, out = simulate_rig(RigConfig(rig=p, excitation=exc), duration_s, FS_HZ)
    rng = np.random.default_rng(plan["seed"])
    sensor = Sensor()
    values = np.column_stack([from_counts(to_counts(v, sensor, rng)[0], sensor.lsb_m_per_s2)
                              for v in (out.base, out.tip1, out.tip2)])
    n = len(values)
    return Samples(np.arange(n) / FS_HZ, values, FS_HZ, np.arange(n), source=plan["name"])


def make_campaign(folder: Path, n: int, duration_s: float, seed: int) -> dict:
    """Write the campaign into ``folder`` (a new folder, built beside and renamed whole); its manifest."""
    rig = RigParams()
    plans = [recording_plan(k, n, seed) for k in range(n)]
    for p in plans:
        p["beam1_coupled_hz"] = coupled_hz(p["beam1_hz"], rig)
        p["beam2_coupled_hz"] = coupled_hz(p["beam2_hz"], rig)
    manifest = {"recordings": n, "duration_s": duration_s, "seed": seed, "fs_hz": FS_HZ, "plans": plans,
                "cut": f"cut-{plans[0]['name'].rsplit('.', 1)[0]}.mcap"}
    with safe_folder(folder, label="--campaign") as tmp:
        for p in plans:
            write_samples(tmp / p["name"], simulate_recording(p, duration_s))
        first = next(p for p in plans if p["name"].endswith(".mcap"))
        data = (tmp / first["name"]).read_bytes()
        (tmp / manifest["cut"]).write_bytes(data[:int(CUT_SHARE * len(data))])
        (tmp / "campaign.json").write_text(json.dumps(manifest, indent=1))
    return manifest


def campaign(folder: Path, n: int, duration_s: float, seed: int) -> dict:
    """The campaign in ``folder``: reused when its manifest matches, made when the folder is missing or empty."""
    man = folder / "campaign.json"
    if man.exists():
        old = json.loads(man.read_text())
        if (old.get("recordings"), old.get("duration_s"), old.get("seed")) != (n, duration_s, seed):
            raise ValueError(f"--campaign {folder} holds another campaign ({old.get('recordings')} recordings of "
                             f"{old.get('duration_s')} s, seed {old.get('seed')}); give another folder")
        return old
    if folder.exists() and any(folder.iterdir()):
        raise ValueError(f"--campaign {folder} exists and holds no campaign.json; give a new or empty folder")
    t0 = time.perf_counter()
    out = make_campaign(folder, n, duration_s, seed)
    print(f"campaign: {n} recordings of {duration_s:g} s at {FS_HZ:g} Hz and one cut copy written to {folder} "
          f"in {time.perf_counter() - t0:.0f} s")
    return out


def _key(row: dict) -> tuple:
    return tuple(sorted((k, v) for k, v in row.items() if k != "seconds"))


def _noop(job):
    return job


def _warm(job) -> None:
    """Run one recording on a worker (imports, compiled kernels from their cache) before the clock starts."""
    OneBlasThread(analyse_job)(job)


def _same(a: dict, b: dict) -> bool:
    return {_key(r) for r in a.values()} == {_key(r) for r in b.values()}


def _loop(jobs: list) -> tuple[dict, float]:
    """The rows of a plain loop in this process and its wall time (printed with the CPU it used)."""
    t0, c0 = time.perf_counter(), time.process_time()
    rows = {r["file"]: r for r in map(OneBlasThread(analyse_job), jobs)}
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    what = "+".join(jobs[0][1].analyses)
    print(f"{'plain loop, ' + what:<27s}: {wall:7.1f} s ({wall / len(jobs):.3f} s per recording; {cpu / wall:.2f} cores "
          f"busy)")
    return rows, wall


def _on_dask(client, jobs: list) -> tuple[dict, float]:
    t0 = time.perf_counter()
    rows = {r["file"]: r for _, r in run_unordered(client, analyse_job, jobs, "bench")}
    return rows, time.perf_counter() - t0


def run_bench(args) -> int:
    folder = args.campaign
    scratch = None
    if folder is None:
        scratch = Path(tempfile.mkdtemp(prefix="ident-bench-batch-"))
        folder = scratch / "campaign"
    try:
        man = campaign(folder, args.recordings, args.duration, args.seed)
        files = expand([str(folder)])
        settings = Settings(("regimes", "fit"), start_s=2.0)
        jobs = [(f, settings) for f in files]
        n = len(jobs)
        light = [(f, Settings(("regimes",))) for f in files]
        print(f"batch: {n} files; the engine's overhead with --regimes alone (little work per task), the scaling "
              f"with --regimes --fit --start 2")
        _warm(jobs[0])
        (loop_light, t_light), (loop, t_loop) = _loop(light), _loop(jobs)
        times, tables, light_1 = {}, {}, None
        for workers in (1, 2):
            t0 = time.perf_counter()
            with dask_client(None, workers) as client:
                client.run(_warm, jobs[0])
                t_start = time.perf_counter() - t0
                if workers == 1:
                    t0 = time.perf_counter()
                    list(run_unordered(client, _noop, list(range(NOOP_TASKS)), "noop"))
                    t_noop = (time.perf_counter() - t0) / NOOP_TASKS
                    light_1, t_light_1 = _on_dask(client, light)
                tables[workers], times[workers] = _on_dask(client, jobs)
            print(f"{f'Dask, {workers} local worker' + ('s' if workers > 1 else ''):<27s}: {times[workers]:7.1f} s "
                  f"(cluster start and warm-up {t_start:.1f} s, apart)")
        same = all(_same(loop, t) for t in tables.values()) and _same(loop_light, light_1)
        print(f"speed-up 1 -> 2 workers    : {times[1] / times[2]:.2f} x")
        print(f"engine overhead            : {1e3 * (t_light_1 - t_light) / n:+.1f} ms per recording with --regimes "
              f"({t_light:.1f} s in the loop, {t_light_1:.1f} s on 1 worker); {1e3 * (times[1] - t_loop) / n:+.1f} ms "
              f"with --fit too; {1e3 * t_noop:.1f} ms per task that does nothing")
        print(f"same table every way       : {same} (every column but the run time)")
        errors = [r for r in loop.values() if r["error"]]
        print(f"rows: {n}, with an error: {len(errors)}" + "".join(f"\n  {Path(r['file']).name}: {r['error']}"
                                                               for r in errors))
        truth = {p["name"]: p for p in man["plans"]}
        for beam in (1, 2):
            err = [trusted_frequency(r, beam) / truth[Path(r["file"]).name][f"beam{beam}_coupled_hz"] - 1
                   for r in loop.values() if Path(r["file"]).name in truth]
            err = np.abs([e for e in err if math.isfinite(e)])
            if err.size:
                print(f"beam {beam} natural frequency against the simulated rig's: median error "
                      f"{100 * np.median(err):.2f} %, max {100 * np.max(err):.2f} % ({err.size} trusted fits)")
        if scratch is None:
            print(f"the campaign stays in {folder}: ident batch {folder} --regimes --fit --start 2 -o RESULTS.csv")
    finally:
        if scratch is not None:
            shutil.rmtree(scratch, ignore_errors=True)
    return 0
