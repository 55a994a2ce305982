"""Writes that cannot destroy: every writing command against an existing file and against its own input
(the same path, a hard link, a symlink), two outputs that are one file, and a failing port.

A case "clobbers" if any file it was pointed at changed (content or inode) without ``--force``; the
count must be 0. Every refusal is exit code 2 and one line. With ``--force`` an existing output is
replaced, an input never.
"""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from clitools import run_main
from daq import bench_regimes
from daq.cli import main as daq_main
from daq.safeio import Output, PartFile, check_outputs, safe_folder, safe_output, same_file
from ident.cli.main import main as ident_main
from replay.cli import main as replay_main

REC = Path(__file__).resolve().parents[1] / "recordings"
PRECIOUS = b"precious bytes that must survive\n" * 100


def snapshot(paths):
    return {p: (os.lstat(p).st_ino, Path(p).read_bytes() if not Path(p).is_dir() else None)
            for p in paths if os.path.lexists(p)}


@pytest.fixture()
def world(tmp_path):
    """A recording, a CSV, a config, and links to each."""
    rec = tmp_path / "rec.mcap"
    rec.write_bytes((REC / "linear.mcap").read_bytes())
    csv = tmp_path / "data.csv"
    code, _, err, tb = run_main(replay_main, ["export", rec, "--csv", csv])
    assert code == 0 and tb is None, err
    cfg = tmp_path / "rig.yaml"
    cfg.write_text("daq:\n  rate_hz: 2000\n")
    precious = tmp_path / "precious.mcap"
    precious.write_bytes(PRECIOUS)
    for name, target in (("rec", rec), ("data", csv), ("rig", cfg)):
        os.link(target, tmp_path / f"hard-{name}{target.suffix}")
        os.symlink(target, tmp_path / f"sym-{name}{target.suffix}")
    return tmp_path


def cases(w: Path):
    """(name, main, argv, files that must not change): every writing command's output pointed at something
    that exists, at its input, at a hard link and a symlink of its input, and two outputs at one file."""
    rec, csv, cfg, precious = w / "rec.mcap", w / "data.csv", w / "rig.yaml", w / "precious.mcap"
    rig = "rig://?seed=1"
    out = []
    for what, target in (("existing", precious), ("input", cfg), ("hard link", w / "hard-rig.yaml"),
                         ("symlink", w / "sym-rig.yaml")):
        out.append((f"daq record -o {what}", daq_main,
                    ["record", "--port", rig, "--config", cfg, "--duration", "1", "-o", target, "--no-identify"],
                    [target, cfg]))
        out.append((f"daq record --events {what}", daq_main,
                    ["record", "--port", rig, "--config", cfg, "--duration", "1", "-o", w / "new.mcap",
                     "--events", target, "--no-identify"], [target, cfg]))
    out.append(("daq record -o a --events a", daq_main,
                ["record", "--port", rig, "--duration", "1", "-o", w / "a.mcap", "--events", w / "a.mcap"],
                [w / "a.mcap"]))
    out.append(("daq record bad port over an existing file", daq_main,
                ["record", "--port", w / "no-such-tty", "-o", precious, "--force", "--no-identify"], [precious]))
    out.append(("daq sim --link regular file", daq_main, ["sim", "--link", precious, "--duration", "1"], [precious]))
    out.append(("daq sim --link symlink to a recording", daq_main, ["sim", "--link", w / "sym-rec.mcap",
                                                                    "--duration", "1"], [w / "sym-rec.mcap", rec]))
    for what, target in (("existing", precious), ("input", csv), ("hard link", w / "hard-data.csv"),
                         ("symlink", w / "sym-data.csv")):
        t = target if target.suffix == ".mcap" else target.with_name(target.name + ".mcap")
        if what != "existing":  # an .mcap name that is the input: a link with the right suffix
            if not os.path.lexists(t):
                (os.link if what != "symlink" else os.symlink)(csv, t)
        out.append((f"replay import -o {what}", replay_main, ["import", csv, "-o", t], [t, csv]))
    for what, target in (("existing", precious), ("input", rec), ("hard link", w / "hard-rec.mcap"),
                         ("symlink", w / "sym-rec.mcap")):
        out.append((f"replay recover -o {what}", replay_main, ["recover", rec, "-o", target], [target, rec]))
        out.append((f"replay --events {what}", replay_main,
                    [rec, "--max", "--no-identify", "--viewer", "none", "--events", target], [target, rec]))
        out.append((f"replay --models {what}", replay_main,
                    ["--max", rec, "--viewer", "none", "--models", target], [target, rec]))
        out.append((f"ident fit --json {what}", ident_main, ["fit", rec, "--json", target], [target, rec]))
        out.append((f"ident fit --report {what}", ident_main, ["fit", rec, "--report", target], [target, rec]))
    for what, target in (("existing", precious), ("hard link", w / "hard-rec.mcap"), ("symlink", w / "sym-rec.mcap")):
        csv_name = target.with_name(target.name + ".csv")
        if what != "existing" and not os.path.lexists(csv_name):
            (os.link if what == "hard link" else os.symlink)(rec, csv_name)
        t = precious.with_suffix(".csv") if what == "existing" else csv_name
        if what == "existing":
            t.write_bytes(PRECIOUS)
        out.append((f"replay export --csv {what}", replay_main, ["export", rec, "--csv", t], [t, rec]))
    for what, target in (("existing", precious), ("hard link", w / "hard-rec.mcap"), ("symlink", w / "sym-rec.mcap")):
        for suffix, opt in ((".uff", "--uff"), (".tdms", "-o")):
            name = target.with_name(target.name + suffix)
            if what == "existing":
                name.write_bytes(PRECIOUS)
            elif not os.path.lexists(name):
                (os.link if what == "hard link" else os.symlink)(rec, name)
            out.append((f"replay export {opt} {suffix} {what}", replay_main, ["export", rec, opt, name], [name, rec]))
    cal = ["calibrate", "--port", "rig://?seed=1&calibrator=tip1", "--channel", "tip1", "--duration", "1"]
    for what, target in (("existing", precious), ("the config", cfg), ("hard link", w / "hard-rig.yaml"),
                         ("symlink", w / "sym-rig.yaml")):
        out.append((f"daq calibrate -o {what}", daq_main, cal + ["--config", cfg, "-o", target], [target, cfg]))
        out.append((f"daq calibrate --recording {what}", daq_main,
                    cal + ["--config", cfg, "-o", w / "new.yaml", "--recording", target], [target, cfg]))
    out.append(("daq calibrate in place without --force", daq_main, cal + ["--config", cfg], [cfg]))
    out.append(("daq calibrate -o a --recording a", daq_main, cal + ["-o", w / "c.yaml", "--recording", w / "c.yaml"],
                [w / "c.yaml"]))
    out.append(("replay recover garbage -o existing", replay_main, ["recover", w / "garbage.mcap", "-o", precious],
                [precious]))
    out.append(("replay recover garbage -o existing --force", replay_main,
                ["recover", w / "garbage.mcap", "-o", precious, "--force"], [precious]))
    out.append(("replay --events a --models a", replay_main,
                [rec, "--max", "--viewer", "none", "--events", w / "b.jsonl", "--models", w / "b.jsonl"],
                [w / "b.jsonl"]))
    out.append(("ident fit --json a --report a", ident_main, ["fit", rec, "--json", w / "r", "--report", w / "r"],
                [w / "r"]))
    out.append(("ident duffing --json existing", ident_main, ["duffing", "--quick", "--json", precious], [precious]))

    nonempty = w / "report"
    nonempty.mkdir(exist_ok=True)
    (nonempty / "README.md").write_bytes(PRECIOUS)
    out.append(("ident duffing --report non-empty", ident_main, ["duffing", "--quick", "--report", nonempty],
                [nonempty / "README.md"]))
    out.append(("ident fit --report non-empty", ident_main, ["fit", rec, "--report", nonempty],
                [nonempty / "README.md"]))
    return out


def test_no_writing_command_clobbers_anything(world):
    (world / "garbage.mcap").write_bytes(b"\x00not an mcap" * 100)
    clobbered, refused = [], 0
    all_cases = cases(world)
    for name, main, argv, guarded in all_cases:
        before = snapshot(guarded)
        listing = set(os.listdir(world))
        code, out, err, tb = run_main(main, argv)
        assert tb is None, (name, tb)
        if snapshot(guarded) != before:
            clobbered.append(name)
        assert code == 2, (name, code, out, err)
        assert len(err.strip().splitlines()) == 1, (name, err)
        refused += 1
        new = set(os.listdir(world)) - listing
        assert not new, (name, new)  # nothing created: checked before anything is opened for writing
    print(f"\nclobbering cases: {len(all_cases)} tried, {len(clobbered)} clobbered")
    assert clobbered == []
    assert refused == len(all_cases) >= 40


def test_an_output_under_a_file_is_refused_before_the_analysis(world):
    # the analysis had run for its minutes, printed its answer, then failed to write: "[Errno 17] File exists"
    precious = world / "precious.mcap"
    for argv in (["discover", world / "data.csv", "--report", precious / "x"],
                 ["fit", world / "rec.mcap", "--json", precious / "x" / "r.json"]):
        code, out, err, tb = run_main(ident_main, argv)
        assert code == 2 and tb is None and out == "", (argv, out)
        assert err.strip() == f"ident {argv[0]}: error: {argv[-2]} {argv[-1]}: {precious} is not a folder", err
        assert precious.read_bytes() == PRECIOUS


def test_force_replaces_an_output_but_never_an_input(world):
    rec, precious = world / "rec.mcap", world / "precious.mcap"
    code, out, err, tb = run_main(replay_main, ["recover", rec, "-o", precious, "--force"])
    assert code == 0 and tb is None, err
    assert precious.read_bytes() != PRECIOUS and precious.read_bytes()[:8] == b"\x89MCAP0\r\n"
    for target in (rec, world / "hard-rec.mcap", world / "sym-rec.mcap"):
        before = rec.read_bytes()
        code, _, err, _ = run_main(replay_main, ["recover", rec, "-o", target, "--force"])
        assert code == 2 and "is the input" in err and rec.read_bytes() == before
    # daq record --force: the recording replaces the old file only when it is complete
    target = world / "old.mcap"
    target.write_bytes(PRECIOUS)
    code, out, err, tb = run_main(daq_main, ["record", "--port", "rig://?seed=2", "--duration", "1", "-o", target,
                                             "--no-identify", "--force", "--quiet"])
    assert code == 0 and tb is None, err
    assert target.read_bytes()[:8] == b"\x89MCAP0\r\n" and not (world / "old.mcap.part").exists()


def test_a_wrong_port_creates_nothing(tmp_path):
    """The issue's first case, as a real process: a mistyped port must not create (or replace) the output."""
    p = subprocess.run([sys.executable, "-m", "daq", "record", "--port", "/dev/nonexistent", "-o",
                        str(tmp_path / "X.mcap")], capture_output=True, text=True, timeout=60)
    assert p.returncode == 2 and "cannot open port /dev/nonexistent" in p.stderr
    assert os.listdir(tmp_path) == []


def test_safeio_rules(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    a.write_text("A")
    os.link(a, b)
    (tmp_path / "s").symlink_to(a)
    assert same_file(a, b) and same_file(a, tmp_path / "s") and not same_file(a, tmp_path / "c")
    (tmp_path / "dangling").symlink_to(tmp_path / "c")
    assert same_file(tmp_path / "dangling", tmp_path / "c")  # not there yet, but resolves to it
    with pytest.raises(ValueError, match="is the input"):
        check_outputs([Output("-o", tmp_path / "dangling")], [tmp_path / "c"], force=True)
    with pytest.raises(ValueError, match="are the same file"):
        check_outputs([Output("-o", tmp_path / "x"), Output("--events", tmp_path / "sub" / ".." / "x")])
    # an exception inside the block leaves the target untouched and no temporary file behind
    with pytest.raises(RuntimeError), safe_output(a, force=True) as tmp:
        tmp.write_text("half")
        raise RuntimeError("disk full")
    assert a.read_text() == "A" and sorted(os.listdir(tmp_path)) == ["a", "b", "dangling", "s"]
    with safe_output(tmp_path / "new.txt") as tmp:
        tmp.write_text("whole")
    assert (tmp_path / "new.txt").read_text() == "whole"
    assert oct((tmp_path / "new.txt").stat().st_mode & 0o777) == oct(0o666 & ~_umask())
    # where an output cannot be written is said before anything is read: a folder under a file, a read-only folder
    with pytest.raises(ValueError, match=f"--report {a}/x: {a} is not a folder"):
        check_outputs([Output("--report", a / "x", folder=True)])
    locked = tmp_path / "locked"
    locked.mkdir(mode=0o555)
    # a folder no one may write in: one made read-only (root may write in it all the same), and /proc/sys, which
    # the kernel keeps so for root too
    for ro in [p for p in (locked, Path("/proc/sys")) if p.is_dir() and not os.access(p, os.W_OK)]:
        for out in (Output("--json", ro / "r.json"), Output("--report", ro / "rep", folder=True)):
            with pytest.raises(ValueError, match=f"cannot write in {ro} "):
                check_outputs([out])
    if not os.access(locked, os.W_OK):  # an existing report folder is written in too: it must be writable
        with pytest.raises(ValueError, match=f"cannot write in {locked} "):
            check_outputs([Output("--report", locked, folder=True)])
    locked.rmdir()
    # a folder: new ones appear whole; into an existing one only the report's files are replaced
    with safe_folder(tmp_path / "rep") as d:
        (d / "README.md").write_text("one")
    (tmp_path / "rep" / "keep.txt").write_text("mine")
    with safe_folder(tmp_path / "rep", force=True) as d:
        (d / "README.md").write_text("two")
    assert (tmp_path / "rep" / "README.md").read_text() == "two" and (tmp_path / "rep" / "keep.txt").exists()
    # a streamed output lives as NAME.part; an existing .part is never overwritten
    pf = PartFile(tmp_path / "rec.mcap")
    pf.file.write(b"data")
    assert (tmp_path / "rec.mcap.part").exists() and not (tmp_path / "rec.mcap").exists()
    pf.commit()
    assert (tmp_path / "rec.mcap").read_bytes() == b"data" and not (tmp_path / "rec.mcap.part").exists()
    (tmp_path / "crashed.mcap.part").write_bytes(b"unrecovered")
    with pytest.raises(ValueError, match="replay recover"):
        PartFile(tmp_path / "crashed.mcap", force=True)
    assert (tmp_path / "crashed.mcap.part").read_bytes() == b"unrecovered"


def test_a_resumed_part_keeps_its_whole_lines_and_never_replaces_a_finished_file(tmp_path):
    """PartFile.resumed: a part cut short mid-line goes on after its last whole line and is renamed as any
    other; a part with its target already there, or no part at all, is refused and nothing changes."""
    part = tmp_path / "runs.jsonl.part"
    part.write_text('{"seed": 0}\n{"seed": 1}\n{"se')
    pf = PartFile.resumed(tmp_path / "runs.jsonl", keep=len('{"seed": 0}\n{"seed": 1}\n'), label="--save")
    pf.file.write('{"seed": 2}\n')
    pf.commit()
    assert (tmp_path / "runs.jsonl").read_text() == '{"seed": 0}\n{"seed": 1}\n{"seed": 2}\n'
    assert not part.exists()
    part.write_text('{"seed": 9}\n')
    with pytest.raises(ValueError, match="exists"):
        PartFile.resumed(tmp_path / "runs.jsonl", keep=0)
    assert part.read_text() == '{"seed": 9}\n'
    assert (tmp_path / "runs.jsonl").read_text().endswith('{"seed": 2}\n')
    with pytest.raises(ValueError, match="nothing to resume"):
        PartFile.resumed(tmp_path / "other.jsonl", keep=0)
    assert not (tmp_path / "other.jsonl.part").exists()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_daq_sim_link_is_its_own_and_survives_nothing_else(tmp_path):
    """--link over a symlink to a file replaces the link only with --force, and the file is kept."""
    target = tmp_path / "keep.mcap"
    target.write_bytes(PRECIOUS)
    link = tmp_path / "rig"
    link.symlink_to(target)
    code, out, err, tb = run_main(daq_main, ["sim", "--link", link, "--duration", "0.2", "--force"])
    assert code == 0 and tb is None, err
    assert target.read_bytes() == PRECIOUS
    assert not os.path.lexists(link)  # removed at the end: it was ours
    stale = tmp_path / "stale"
    stale.symlink_to("/dev/pts/999999")  # a stale link of an earlier run is fine to replace
    code, out, err, tb = run_main(daq_main, ["sim", "--link", stale, "--duration", "0.2"])
    assert code == 0, err
    assert not os.path.lexists(stale)


def test_the_regime_benchmark_cache_is_written_whole_and_never_rewritten(tmp_path, monkeypatch):
    """daq bench --regimes --cache DIR: a generated case is written as one file, beside and renamed; a case
    found there is read, not generated again; a file there that is not a case is refused, not replaced."""
    made = []

    def generate(kind, seed, regime, minutes, fs_hz, first):
        made.append(seed)
        return bench_regimes.CaseData(500.0, np.arange(30.0).reshape(10, 3), np.zeros(10, int), {"seed": seed})

    monkeypatch.setattr(bench_regimes, "_generate", generate)
    a = bench_regimes.load_case("regimes", 7, cache=tmp_path)
    b = bench_regimes.load_case("regimes", 7, cache=tmp_path)
    assert made == [7] and os.listdir(tmp_path) == ["regimes_7.npz"]
    assert b.truth == {"seed": 7} and np.array_equal(a.x, b.x) and b.fs_hz == 500.0
    (tmp_path / "regimes_8.npz").write_bytes(PRECIOUS)
    with pytest.raises(ValueError, match="not a case this benchmark wrote"):
        bench_regimes.load_case("regimes", 8, cache=tmp_path)
    assert (tmp_path / "regimes_8.npz").read_bytes() == PRECIOUS and made == [7]
    # a slow rig (--first-hz) is another case under another name, never the default draw's file
    bench_regimes.load_case("regimes", 7, cache=tmp_path, first=(3.5, 6.0))
    assert made == [7, 7] and (tmp_path / "regimes_7_first3.5-6Hz.npz").is_file()
