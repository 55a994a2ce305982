"""The long benchmarks as Dask tasks (ident.cli.engine): the same output as the serial run, digit for digit,
on small case sets; results in the order of the cases however the tasks finish."""

import json
import os
import re
import time

import dask
import numpy as np

from clitools import run_main
from ident.cli.bench_discovery import rig_case
from ident.cli.engine import dask_client, mapper, run_ordered
from ident.cli.main import main as ident_main
from ident.discovery import discover, to_json
from ident.paper.duffing import DuffingParams, duffing_data, noise_sweeps


def _without_times(text: str) -> str:
    """The bench's lines less its run times ("[3 s]" per case, the closing run-time line)."""
    text = re.sub(r"\[\d+ s\]", "[- s]", text)
    return "\n".join(line for line in text.splitlines() if not line.startswith("run time per case"))


def test_bench_discovery_on_dask_prints_what_the_serial_run_prints(dask_scheduler):
    argv = ["bench", "discovery", "--generator", "rig", "--cases", "2", "--seed", "10", "--duration", "3"]
    code, serial, err, tb = run_main(ident_main, argv)
    assert code == 0 and tb is None, err
    code, on_dask, err, tb = run_main(ident_main, [*argv, "--scheduler", dask_scheduler])
    assert code == 0 and tb is None, err
    assert _without_times(on_dask) == _without_times(serial)
    assert [int(m) for m in re.findall(r"^case +(\d+)", serial, re.M)] == [10, 11]
    assert "confusion (rows true, columns named first), 2 cases:" in serial
    assert serial.startswith(f"numpy {np.__version__}, scipy ")  # what the figures were computed with
    # both cases name their cause (Coulomb friction, a sensor gain): their parameter errors are compared too
    assert "coulomb_friction    parameter error median" in serial
    assert "sensor_gain         parameter error median" in serial


def _gains(js: dict) -> list[float]:
    """The candidates' held-out gains of a discover JSON (a diverged candidate's is written as null)."""
    return [np.nan if c["gain"] is None else c["gain"] for c in js["candidates"]]


def test_bench_discovery_saves_each_case_as_discover_answers_it(dask_scheduler, tmp_path):
    """--save on Dask workers: one JSON line per case, read back with the standard json module, holding the
    generator's truth, the verdict the bench printed, and every candidate as ``discover`` answers the same
    case run here (cause, place, held-out gain); an existing file is refused and left as it was."""
    out = tmp_path / "cases.jsonl"
    argv = ["bench", "discovery", "--generator", "rig", "--cases", "2", "--seed", "10", "--duration", "3",
            "--save", str(out), "--scheduler", dask_scheduler]
    code, printed, err, tb = run_main(ident_main, argv)
    assert code == 0 and tb is None, err
    records = [json.loads(line) for line in out.read_text().splitlines()]
    assert [r["seed"] for r in records] == [10, 11] and not (tmp_path / "cases.jsonl.part").exists()
    for r in records:
        case = rig_case(r["seed"], 3.0)
        assert r["truth"]["cause"] == case.cause and r["truth"]["location"] == case.location
        line = next(x for x in printed.splitlines() if re.match(rf"case +{r['seed']} ", x))
        assert line.split("->")[1].split()[0] == r["verdict"]["named"]
        here = to_json(discover(case.measurement, rig=case.rig))
        assert [(c["effect"], c["response"]) for c in r["discovery"]["candidates"]] == \
            [(c["effect"], c["response"]) for c in here["candidates"]]
        np.testing.assert_allclose(_gains(r["discovery"]), _gains(here), rtol=1e-9)
    before = out.read_bytes()
    code, _, err, tb = run_main(ident_main, argv)
    assert code == 2 and tb is None and "exists" in err and out.read_bytes() == before


def test_bench_discovery_save_leaves_no_part_when_nothing_ran_and_keeps_a_cut_one(tmp_path):
    """A run that fails before its first case (both --scheduler and --workers) leaves no OUT.jsonl.part to block
    the corrected command; a part left by a run cut short is refused, not overwritten."""
    out = tmp_path / "cases.jsonl"
    argv = ["bench", "discovery", "--generator", "rig", "--cases", "1", "--duration", "3", "--save", str(out)]
    code, _, err, tb = run_main(ident_main, [*argv, "--scheduler", "tcp://127.0.0.1:1", "--workers", "2"])
    assert code == 2 and tb is None and "not both" in err
    assert sorted(tmp_path.iterdir()) == []
    part = tmp_path / "cases.jsonl.part"
    part.write_text('{"seed": 0}\n')
    code, _, err, tb = run_main(ident_main, argv)
    assert code == 2 and tb is None and "cut short" in err
    assert part.read_text() == '{"seed": 0}\n' and not out.exists()


def test_bench_discovery_resumes_a_run_cut_short_and_ends_as_the_whole_run(tmp_path):
    """--resume keeps the whole lines of a part a run cut short left (a line cut off mid-way is dropped),
    runs only the cases it lacks, and ends with the file and the report of a run that never stopped; a
    part from another run, a missing part, or --resume without --save is refused with one line, and the
    part is left as it was."""
    argv = ["bench", "discovery", "--generator", "rig", "--cases", "2", "--seed", "10", "--duration", "3"]
    whole = tmp_path / "whole.jsonl"
    code, printed_whole, err, tb = run_main(ident_main, [*argv, "--save", str(whole)])
    assert code == 0 and tb is None, err
    first, second = whole.read_bytes().splitlines(keepends=True)
    out = tmp_path / "cut.jsonl"
    part = tmp_path / "cut.jsonl.part"
    part.write_bytes(first + second[:40])  # cut short while writing seed 11's line

    other = [*argv[:-4], "--seed", "11", "--duration", "3", "--save", str(out), "--resume"]
    code, _, err, tb = run_main(ident_main, other)
    assert code == 2 and tb is None and "line 1" in err and "seed 10" in err and "seed 11" in err
    assert part.read_bytes() == first + second[:40] and not out.exists()
    for bad, says in (([*argv, "--resume"], "--save"),
                      ([*argv, "--save", str(tmp_path / "none.jsonl"), "--resume"], "nothing to resume")):
        code, _, err, tb = run_main(ident_main, bad)
        assert code == 2 and tb is None and says in err, err

    code, printed, err, tb = run_main(ident_main, [*argv, "--save", str(out), "--resume"])
    assert code == 0 and tb is None, err
    assert not part.exists()
    lines = out.read_bytes().splitlines(keepends=True)
    assert lines[0] == first  # the first run's line, as it was
    again, before = json.loads(lines[1]), json.loads(second)
    assert again["seed"] == 11 and again["discovery"] == before["discovery"]
    assert {k: v for k, v in again["verdict"].items() if k != "seconds"} == \
        {k: v for k, v in before["verdict"].items() if k != "seconds"}
    # the report over both: the resumed case's line as the first run printed it, the summary the same
    assert "resumed 1 records from" in printed

    def same(text: str) -> str:
        return _without_times("\n".join(line for line in text.splitlines()
                                         if not line.startswith(("resumed ", "saved "))))
    assert same(printed) == same(printed_whole)


def test_duffing_noise_sweep_on_dask_equals_the_serial_sweep(dask_scheduler):
    data = duffing_data(DuffingParams(t_end=20.0))  # a short record keeps the four fits quick
    args = (data, (0.25,), 2, ("paper", "realistic"), 7)
    serial = noise_sweeps(*args, mapper=mapper(None))
    with dask_client(dask_scheduler, None) as client:
        on_dask = noise_sweeps(*args, mapper=mapper(client, "duffing"))
    assert on_dask == serial  # every float equal
    assert [len(serial[p][0]["error_percent"]) for p in ("paper", "realistic")] == [2, 2]
    # the same draws as noise_sweep's serial loop: repetition r of level i from default_rng([seed, i, r])
    assert serial["paper"][0]["error_percent"][0] != serial["paper"][0]["error_percent"][1]


def _sleep_then_return(x):
    time.sleep(0.1 * (3 - x))
    return x


def test_results_come_in_the_order_of_the_cases_however_they_finish(dask_scheduler):
    with dask_client(dask_scheduler, None) as client:
        assert list(run_ordered(client, _sleep_then_return, [0, 1, 2, 3])) == [0, 1, 2, 3]


def test_local_workers_allocate_memory_as_glibc_does_by_itself(dask_scheduler):
    # distributed starts its workers with MALLOC_TRIM_THRESHOLD_=65536, which also turns off glibc's
    # dynamic mmap threshold: a discovery case ran 2.6-3 x slower on a worker than in a plain process
    # (README, Campaigns). The local cluster's workers start without it, as this process did.
    # (distributed also writes its value into the environment of the process that starts the workers, so
    # the workers are compared with distributed's value, not with this process's environment)
    theirs = str(dask.config.get("distributed.nanny.pre-spawn-environ")["MALLOC_TRIM_THRESHOLD_"])
    with dask_client(dask_scheduler, None) as client:
        seen = client.run(os.environ.get, "MALLOC_TRIM_THRESHOLD_")
    assert len(seen) == 2 and theirs not in set(seen.values())
