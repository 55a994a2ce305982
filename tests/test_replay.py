"""replay: the live pipeline on recordings and CSVs, pacing, info/export/import, the rerun viewer."""

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from clitools import run_main
from daq.viewer import ENTITIES
from ident.live.regimes import PHASE_WINDOWS, RegimeConfig
from replay.cli import main as replay_main
from ident.live.pipeline import Pipeline, PipelineConfig, rolling_config
from ident.live.rolling import RollingConfig, RollingIdentifier
from replay.play import LAG_BLOCKS, RemoteIdentifier, play
from replay.formats.mcap import read_recording
from replay.formats import read_samples as read_mcap
from replay.formats.csv import read_samples as read_csv

REC = Path(__file__).resolve().parents[1] / "recordings"


def cli(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", *args], capture_output=True, text=True, timeout=timeout)


def rerun_cli(*args):
    exe = os.path.join(os.path.dirname(sys.executable), "rerun")
    return subprocess.run([exe, *args], capture_output=True, text=True, timeout=120)


def test_example_recordings_are_small_and_complete():
    files = sorted(REC.glob("*.mcap"))
    assert {f.stem for f in files} == {"linear", "localized-1", "localized-2", "impacting-both", "transitions"}
    for f in files:
        assert f.stat().st_size < 2 * 1024 * 1024, f
        rec = read_recording(f, raw=False)
        assert np.all(np.diff(rec.seq) == 1)
        # in today's layout, a chunk a second: damage costs its second, not the file (the examples of
        # 2026-11-22 held everything in one chunk, and `replay recover` found none intact after one flipped byte)
        from mcap.reader import make_reader

        with open(f, "rb") as fh:
            chunks = len(make_reader(fh).get_summary().chunk_indexes)
        assert chunks >= int(rec.t_device[-1] - rec.t_device[0]) >= 9, (f, chunks)


# a recording from before the compact layout (the example localized-1 as made on 2026-11-22: one chunk, a JSON
# message per sample beside the serial bytes); the examples are made again in today's layout (``make.sh``)
BEFORE_COMPACT = Path(__file__).resolve().parent / "data" / "localized-1-before-compact.mcap"


def test_fast_raw_path_equals_the_json_samples():
    f = BEFORE_COMPACT
    s = read_mcap(f)
    rec = read_recording(f, raw=False)
    assert np.array_equal(s.seq, rec.seq)
    np.testing.assert_allclose(s.values, rec.values, atol=1e-5, rtol=1e-5)  # JSON keeps 6 digits
    assert s.fs_hz == pytest.approx(2000.0)
    assert read_mcap(REC / "transitions.mcap").fs_hz == pytest.approx(1000.0)


def test_old_recordings_json_samples_equal_their_raw_bytes_decoded():
    """Recordings before the compact layout carry one JSON message per sample beside the serial bytes; the
    raw decode (the only record in new recordings) gives the same samples, flags and log times."""
    from mcap.reader import make_reader

    from replay.formats.mcap import decode_raw, scan

    f = BEFORE_COMPACT
    rec = read_recording(f, raw=False)
    assert rec.samples_topic == "/rig/accel"
    with open(f, "rb") as fh:
        raws = [(m.data, m.log_time) for _, _, m in make_reader(fh).iter_messages(topics=["/rig/raw"])]
    d = decode_raw(scan(f), raws, rec.events)
    seq, t_dev, values, clipped, log_ns, pub_ns = (d.seq, d.t_device, d.values, d.clipped, d.log_time_ns,
                                                   d.publish_time_ns)
    assert np.array_equal(seq, rec.seq) and len(seq) == 20000
    np.testing.assert_allclose(t_dev, rec.t_device, atol=1e-6)  # JSON keeps microseconds
    np.testing.assert_allclose(values, rec.values, atol=1e-5, rtol=1e-5)  # JSON keeps 6 digits
    assert np.array_equal(clipped, rec.clipped)
    assert np.array_equal(log_ns, rec.log_time_ns) and np.array_equal(pub_ns, rec.publish_time_ns)


def test_a_compact_recording_cut_short_decodes_after_recover_as_recorded(tmp_path):
    """A recording killed before it was closed has no ``samples`` metadata (range, anchor); after recover the
    reader still decodes its serial bytes to the samples the recorder wrote, at the same log and publish times
    (anchored as the recorder anchors). test_damage covers damage in the middle."""
    from mcap.reader import make_reader

    from replay.formats.mcap import decode_raw, scan

    out = tmp_path / "whole.mcap"
    p = cli("daq", "record", "--port", "rig://?seed=3", "--duration", "4", "-o", str(out), "--quiet", "--no-identify",
            "--accel-json")
    assert p.returncode == 0, p.stderr
    data = out.read_bytes()
    cut = tmp_path / "cut.mcap.part"
    cut.write_bytes(data[:len(data) * 3 // 5])  # as kill -9 leaves it: no summary, no footer, no metadata at close
    fixed = tmp_path / "fixed.mcap"
    assert cli("replay", "recover", str(cut), "-o", str(fixed)).returncode == 0
    with open(fixed, "rb") as fh:
        msgs = list(make_reader(fh).iter_messages(topics=["/rig/raw", "/rig/accel"], log_time_order=False))
    accel = [(m.log_time, m.publish_time, json.loads(m.data)) for _, ch, m in msgs if ch.topic == "/rig/accel"]
    raws = [(m.data, m.publish_time) for _, ch, m in msgs if ch.topic == "/rig/raw"]
    s = scan(fixed)
    assert not s.meta("samples") and s.meta("recovery")
    d = decode_raw(s, raws, [])
    n = len(accel)  # the raw bytes may hold a few frames more than the last chunk's /rig/accel messages
    assert 2 * 2000 <= n <= len(d.seq) <= n + 50
    assert np.array_equal(d.seq[:n], [a[2]["seq"] for a in accel])
    assert np.array_equal(d.log_time_ns[:n], [a[0] for a in accel])
    assert np.array_equal(d.publish_time_ns[:n], [a[1] for a in accel])


@pytest.mark.parametrize("name,regime", [("linear", None), ("localized-1", "localized-1"),
                                         ("localized-2", "localized-2"),
                                         ("impacting-both", "impacting-both")])
def test_each_example_shows_its_regime(name, regime):
    changes = []
    play(read_mcap(REC / f"{name}.mcap"), rate=None, identify=False,
         on_step=lambda out: changes.extend(out.changes))
    assert [c.regime for c in changes] == ([regime] if regime else [])
    if regime:
        assert 3.0 <= changes[0].t_s <= 4.0  # the blow came at 3 s


def test_transitions_events_file_and_viewer(tmp_path):
    ev, rrd = tmp_path / "ev.jsonl", tmp_path / "tr.rrd"
    p = cli("replay", str(REC / "transitions.mcap"), "--max", "--events", str(ev), "--viewer", "save",
            "--rrd", str(rrd))
    assert p.returncode == 0, p.stderr
    events = [json.loads(line) for line in ev.read_text().splitlines()]
    assert all("t" in e and "kind" in e for e in events)
    regimes = [e["regime"] for e in events if e["kind"] == "regime"]
    assert regimes == ["localized-1", "linear", "localized-2", "linear", "impacting-both"]
    times = [e["t"] for e in events if e["kind"] == "regime"]
    for t_true, t in zip([4.03, 8.0, 12.0, 16.0, 20.04], times):
        assert 0 <= t - t_true <= 1.5, (t_true, t)  # amplitude drops take a few cycles to stop the impacts
    assert rerun_cli("rrd", "verify", str(rrd)).returncode == 0
    stats = rerun_cli("rrd", "stats", str(rrd)).stdout
    for entity in ENTITIES:
        assert f"/{entity}:" in stats, entity


def _same_fit(a, b) -> bool:
    return (a.t_s == b.t_s and a.final == b.final and np.array_equal(a.predicted, b.predicted)
            and all(np.array_equal(x.model.coefficients, y.model.coefficients) and x.error == y.error
                    and np.array_equal(x.coefficient_std, y.coefficient_std) for x, y in zip(a.beams, b.beams)))


@pytest.mark.parametrize("lag", [1, LAG_BLOCKS])
def test_the_identification_in_a_second_process_gives_the_same_fits_lag_blocks_behind(lag):
    """The same fits bit for bit and in the same order; each step carries what the step ``lag`` before
    carried in one process, and the end carries the last ``lag`` blocks' with what the end carried."""
    s = read_mcap(REC / "transitions.mcap")
    local, remote = [], []
    play(s, rate=None, on_step=lambda out: local.append(out.fits))
    with RemoteIdentifier(rolling_config(s.fs_hz), lag=lag) as ident:
        play(s, rate=None, on_step=lambda out: remote.append(out.fits), identifier=ident)
    assert sum(map(len, local)) >= 8 and len(remote) == len(local) > lag + 1
    expected = [[]] * lag + local[:-lag - 1] + [sum(local[-lag - 1:], [])]  # steps, then what finish() gave
    assert [len(f) for f in remote] == [len(f) for f in expected]
    assert all(_same_fit(a, b) for got, want in zip(remote, expected) for a, b in zip(got, want))


def test_an_identifier_built_for_another_config_is_refused():
    cfg = PipelineConfig(fs_hz=2000.0, rolling=rolling_config(2000.0))
    Pipeline(cfg, identifier=RollingIdentifier(rolling_config(2000.0)))
    with pytest.raises(ValueError, match="not the pipeline's"):
        Pipeline(cfg, identifier=RollingIdentifier(rolling_config(2000.0, window_s=6.0)))


@pytest.mark.parametrize("extra", [[], ["--max"], ["--max", "--one-process"]])
def test_a_refused_window_leaves_no_output_behind(tmp_path, extra):
    events = tmp_path / "ev.jsonl"
    code, out, err, tb = run_main(replay_main, [str(REC / "linear.mcap"), "--window", "2", "--viewer", "none",
                                                "--events", str(events), *extra])
    assert tb is None and code == 2 and "needs more than 2 s" in err
    assert list(tmp_path.iterdir()) == []


def test_an_error_in_the_identifications_process_is_raised_here():
    with RemoteIdentifier(rolling_config(2000.0)) as ident:
        assert ident.step(np.zeros((10, 2))) == []  # its error comes back with the next call
        with pytest.raises(ValueError, match="shape"):
            ident.finish()
    with RemoteIdentifier(RollingConfig(fs_hz=2000.0, window_s=2.0)) as ident:  # refused as it starts
        with pytest.raises(ValueError, match="too short for integration"):
            ident.ready()


def test_replay_max_identifies_in_a_second_process_with_the_same_models_and_events(tmp_path):
    runs = {}
    for name, extra in (("two", []), ("one", ["--one-process"])):
        models, events = tmp_path / f"{name}.models.jsonl", tmp_path / f"{name}.events.jsonl"
        p = cli("replay", str(REC / "transitions.mcap"), "--max", "--viewer", "none", "--models", str(models),
                "--events", str(events), *extra)
        assert p.returncode == 0, p.stderr
        assert ("identification in a second process" in p.stdout) == (name == "two"), p.stdout
        runs[name] = (models.read_bytes(), sorted(events.read_text().splitlines()))
    assert runs["two"][0] and runs["two"] == runs["one"]  # the model lines in order; events as a set


def test_pacing_holds_recorded_time_without_drift():
    s = read_mcap(REC / "linear.mcap")  # 10 s
    for rate in (1.0, 4.0):
        t0 = time.monotonic()
        rep = play(s, rate=rate)
        wall = time.monotonic() - t0
        # paced by the recorded clock: never ahead of it (within 1 %); behind it only by what a busy
        # runner's scheduling costs (the suite runs two processes on two cores)
        assert 0.99 * 10.0 / rate <= wall <= 1.15 * 10.0 / rate, (rate, wall)
        assert rep.stream_s == pytest.approx(10.0)


def test_start_duration_and_loop():
    s = read_mcap(REC / "linear.mcap")
    rep = play(s, rate=None, start_s=2.0, duration_s=3.0, identify=False)
    assert rep.samples == 6000
    rep = play(s, rate=None, duration_s=1.0, loop=True, max_loops=3, identify=False)
    assert rep.samples == 3 * 2000 and rep.stream_s == pytest.approx(3.0)


def test_info_reports_drops(tmp_path):
    cfg = tmp_path / "drops.yaml"
    cfg.write_text("daq:\n  faults:\n    drop_frame_rate: 0.01\n")
    out = tmp_path / "drops.mcap"
    p = cli("daq", "record", "--port", f"rig://?config={cfg}", "--config", str(cfg), "--duration", "5", "-o",
            str(out), "--quiet", "--no-identify")
    assert p.returncode == 0, p.stderr
    rec = read_recording(out, raw=False)
    lost = int(np.sum(np.diff(rec.seq) - 1))
    assert 50 < lost < 150  # 1 % of 10,000 frames
    info = cli("replay", "info", str(out))
    assert info.returncode == 0
    assert f"drops      {lost} frame(s)" in info.stdout
    assert "rate       2000.000 Hz" in info.stdout
    # replay fills the holes so the pipeline's clock stays right
    s = read_mcap(out)
    assert len(s.t) == len(rec.seq) + lost


def test_export_import_round_trip(tmp_path):
    csv_path, back = tmp_path / "x.csv", tmp_path / "back.mcap"
    assert cli("replay", "export", str(REC / "localized-2.mcap"), "--csv", str(csv_path)).returncode == 0
    p = cli("replay", "import", str(csv_path), "-o", str(back), "--time", "t")
    assert p.returncode == 0, p.stderr
    a = read_recording(REC / "localized-2.mcap", raw=False)
    b = read_recording(back, raw=False)
    np.testing.assert_allclose(b.values, a.values, rtol=1e-5, atol=1e-5)
    assert read_mcap(back).fs_hz == pytest.approx(2000.0, rel=1e-6)  # JSON path (no raw bytes)


def test_csv_from_another_daq_with_other_column_names(tmp_path):
    s = read_mcap(REC / "localized-1.mcap")
    path = tmp_path / "other.csv"
    np.savetxt(path, s.values[:8000], delimiter=",", header="shaker,bladeA,bladeB", comments="")
    p = cli("replay", str(path), "--fs", "2000", "--base", "shaker", "--tip1", "bladeA", "--tip2", "bladeB",
            "--max", "--no-identify")
    assert p.returncode == 0, p.stderr
    assert "regime localized-1" in p.stdout
    c = read_csv(path, fs_hz=2000.0, base="shaker", tip1="bladeA", tip2="bladeB")
    np.testing.assert_allclose(c.values, s.values[:8000], rtol=1e-6, atol=1e-9)


def test_a_time_column_written_with_too_few_digits_reads_at_its_rate(tmp_path):
    # a 2560 Hz analyser's stamps written to 10 us: steps of 0.00039 and 0.00040 s, 2.5 % off their median,
    # had been refused as "not uniformly sampled". Read at the slope of the stamps' least-squares line; a
    # sample missing among them moves every later stamp a whole step off that line and is still refused
    n = 3000
    t = np.arange(n) / 2560.0
    x = np.sin(2 * np.pi * 50.0 * t)
    rows = [f"{t[i]:.5f},{x[i]:.6f},0,0" for i in range(n)]
    path = tmp_path / "rounded.csv"
    path.write_text("t,base,tip1,tip2\n" + "\n".join(rows) + "\n")
    steps = np.diff(np.round(t, 5))
    assert steps.min() == pytest.approx(0.00039) and steps.max() == pytest.approx(0.00040)
    c = read_csv(path, time_col="t")
    assert c.fs_hz == pytest.approx(2560.0, rel=1e-5) and len(c.t) == n
    np.testing.assert_allclose(c.values[:, 0], np.round(x, 6))
    holed = tmp_path / "holed.csv"
    holed.write_text("t,base,tip1,tip2\n" + "\n".join(rows[:1500] + rows[1501:]) + "\n")
    with pytest.raises(ValueError, match="not uniformly sampled"):
        read_csv(holed, time_col="t")


def test_a_table_separated_by_semicolons_tabs_or_blanks_reads_as_its_comma_separated_twin(tmp_path):
    # a European spreadsheet's export (semicolons, decimal commas), a LabVIEW text export (tabs), an
    # analyser's aligned columns and its export with settings and units around the header had been refused
    # as "no column 't'; columns are: t;base;tip1;tip2" (or "line 2 has a missing or non-numeric value")
    n = 400
    t = np.arange(n) / 1000.0
    v = np.column_stack([np.sin(2 * np.pi * 30 * t), 1e-4 * np.cos(2 * np.pi * 30 * t), -2.5e3 * t])
    cells = [[f"{t[i]:.3f}"] + [f"{x:.6g}" for x in v[i]] for i in range(n)]
    header = ["t", "base", "tip1", "tip2"]
    forms = {"comma.csv": (",", "."), "semicolon.csv": (";", ","), "tab.txt": ("\t", "."),
             "blanks.txt": ("   ", ".")}
    for name, (sep, dec) in forms.items():
        (tmp_path / name).write_text("\n".join(sep.join(c.replace(".", dec) for c in row)
                                              for row in [header] + cells) + "\n")
    # an analyser's export: its settings before the header, a row of units after it
    (tmp_path / "preamble.txt").write_text("Analyser export\nSample rate;1000;Hz\nChannels;3\n\n"
                                           + "\n".join(";".join(c.replace(".", ",") for c in row)
                                                       for row in [header, ["s", "m/s^2", "m/s^2", "m/s^2"]] + cells)
                                           + "\n")
    forms["preamble.txt"] = (";", ",")
    # Excel's "CSV UTF-8" (a byte-order mark before the header, CRLF) and a logger that ends with blank lines
    # or a row of empty cells (the F-16 benchmark's CSVs end with a blank line): each had been refused, the
    # first as "no column 't'", the second as "line N has a missing or non-numeric value"
    comma = (tmp_path / "comma.csv").read_text()
    (tmp_path / "excel.csv").write_bytes(b"\xef\xbb\xbf" + comma.replace("\n", "\r\n").encode())
    (tmp_path / "trailing.csv").write_text(comma + "\n,,,\n\n")
    forms.update({"excel.csv": (",", "."), "trailing.csv": (",", ".")})
    want = read_csv(tmp_path / "comma.csv", time_col="t")
    assert want.fs_hz == pytest.approx(1000.0)
    np.testing.assert_allclose(want.values, v, rtol=1e-5)
    for name in forms:
        got = read_csv(tmp_path / name, time_col="t")
        assert got.fs_hz == want.fs_hz and np.array_equal(got.values, want.values), name


def test_a_comma_table_keeps_its_commas_and_a_preamble_naming_the_channels_is_no_header(tmp_path):
    # a comma-separated file with semicolons in a text column is read as before; a semicolon file whose
    # first rows are integers still reads its decimal commas; a preamble line that names the channels is
    # not the header (the header is the last such line before the numbers)
    notes = tmp_path / "notes.csv"
    notes.write_text("t,base,tip1,tip2,comment\n0.000,1,2,3,ok; fine\n0.001,1.5,2,3,ok\n0.002,2,2,3,x\n")
    got = read_csv(notes, time_col="t")
    np.testing.assert_array_equal(got.values[:, 0], [1.0, 1.5, 2.0])
    late = tmp_path / "late.csv"
    late.write_text("t;base;tip1;tip2\n0;0;0;0\n0,001;0;0;0\n0,002;0,52;1,5;2,5\n")
    np.testing.assert_array_equal(read_csv(late, time_col="t").values[2], [0.52, 1.5, 2.5])
    one = tmp_path / "one.csv"
    one.write_text("x\n0,1429\n-2,5\n")
    got = read_csv(one, fs_hz=10.0, base="x", tip1="x", tip2="x")
    np.testing.assert_array_equal(got.values[:, 0], [0.1429, -2.5])
    trailing = tmp_path / "trailing.csv"  # a logger that ends every line with its delimiter
    trailing.write_text("t,base,tip1,tip2,\n0,1,2,3,\n0.5,4,5,6,,bad hit\n")  # and an unheaded remark
    np.testing.assert_array_equal(read_csv(trailing, time_col="t").values, [[1, 2, 3], [4, 5, 6]])
    named = tmp_path / "named.csv"
    named.write_text("Channels,base,tip1,tip2\nt,base,tip1,tip2\ns,m/s^2,m/s^2,m/s^2\n0,1,2,3\n0.5,4,5,6\n")
    got = read_csv(named, time_col="t")
    assert got.fs_hz == 2.0
    np.testing.assert_array_equal(got.values, [[1, 2, 3], [4, 5, 6]])


@pytest.mark.parametrize("content,args,match", [
    ("a,b,c\n1,2,3\n", ["--fs", "100"], "no column 'base'"),
    ("base,tip1,tip2\n1,2,3\n1,nan,3\n1,2,3\n", ["--fs", "100"], "line 3 holds NaN"),
    ("base,tip1,tip2\n1,2,3\n1,x,3\n", ["--fs", "100"], "line 3 has a missing or non-numeric value"),
    # a comma table written with decimal commas: every number in two cells (read as 0, 5, 1 before)
    ("base,tip1,tip2\n0,5,1,25,2,0\n0,6,1,5,2,1\n", ["--fs", "100"],
     "line 2 holds 6 cells where the header names 3 columns (decimal commas in a comma-separated table?)"),
    ("t,base,tip1,tip2\n0,1,2,3\n0.1,1,2,3\n0.5,1,2,3\n", ["--time", "t"], "not uniformly sampled"),
    ("base,tip1,tip2\n1,2,3\n1,2,3\n", [], "no time column (t, time, time_s, t_s); give --time COL or --fs HZ"),
    ("t,base,tip1,tip2\n0,1,2,3\n0.1,1,2,3\n", ["--time", "t", "--fs", "10"], "exactly one of --time COL or --fs"),
    # a time column in milliseconds or sample numbers (it had been read at 1 Hz, and refused later for other reasons)
    ("time_ms,base,tip1,tip2\n0,1,2,3\n1,1,2,3\n2,1,2,3\n", ["--time", "time_ms"],
     "column 'time_ms' counts in whole steps of 1 (sample numbers, or milliseconds?), which would be 1 Hz in seconds"),
    # a rate given against the table's own time column (it had been read at 400 Hz, silently); a column of
    # sample numbers with the rate given is read at that rate (test_replay's rate test below)
    ("t,base,tip1,tip2\n0,1,2,3\n0.001,1,2,3\n0.002,1,2,3\n", ["--fs", "400"],
     "--fs 400 Hz, but column 't' steps at 1000 Hz (read as seconds): leave --fs out"),
])
def test_bad_csv_is_one_line_exit_2(tmp_path, content, args, match):
    path = tmp_path / "bad.csv"
    path.write_text(content)
    code, _, err, tb = run_main(replay_main, [path, "--max", *args])  # in-process: the entry point is below
    lines = err.strip().splitlines()
    assert tb is None and code == 2 and len(lines) == 1 and match in lines[0], (code, err, tb)


def test_bad_files_are_one_line_exit_2(tmp_path):
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap at all")
    # the console entry point once, in a process of its own; the other cases through main() in this one
    p = cli("replay", str(junk), "--max")
    assert p.returncode == 2 and len(p.stderr.strip().splitlines()) == 1 and "Traceback" not in p.stderr, p.stderr
    for args in (["info", junk], [tmp_path / "missing.mcap"], [tmp_path / "x.wav"],
                 [REC / "linear.mcap", "--start", "99"]):
        code, _, err, tb = run_main(replay_main, args)
        assert tb is None and code == 2 and len(err.strip().splitlines()) == 1, (args, code, err, tb)


def test_record_no_identify_still_monitors_regimes(tmp_path):
    """--no-identify leaves out the rolling SINDy only (its help: "filters and regimes only"): the regime
    monitor runs and its events reach the recording and --events; no model is written."""
    cfg = tmp_path / "kick.yaml"
    cfg.write_text("excitation:\n  ramp_s: 1.0\n  kicks:\n    - {t_s: 3.0285, beam: 2, velocity_m_per_s: 0.3}\n")
    out, ev = tmp_path / "plain.mcap", tmp_path / "plain.jsonl"
    p = cli("daq", "record", "--sim", "--config", str(cfg), "--duration", "8", "-o", str(out), "--events", str(ev),
            "--quiet", "--no-identify")
    assert p.returncode == 0, p.stderr
    rec = read_recording(out, raw=False)
    assert [e["regime"] for e in rec.events if e["kind"] == "regime"] == ["localized-2"]
    assert rec.models == [] and not any(e["kind"] == "model" for e in rec.events)
    lines = [json.loads(x) for x in ev.read_text().splitlines()]
    assert [e["regime"] for e in lines if e["kind"] == "regime"] == ["localized-2"]
    # the regime the stream starts in (free: the kick comes at 3 s), once, at the window that decides it: the
    # PHASE_WINDOWS-th (window 0.5 s, hop 0.25 s), the windows before it provisional
    for events in (rec.events, lines):
        start = [e for e in events if e["kind"] == "regime_start"]
        assert [e["regime"] for e in start] == ["linear"]
        assert start[0]["t"] == pytest.approx(RegimeConfig.window_s + (PHASE_WINDOWS - 1) * RegimeConfig.hop_s)
        assert 0.0 < start[0]["confidence"] <= 1.0
    assert {"start", "stop"} <= {e["kind"] for e in lines}  # the acquisition's events as before
    assert "1 regime changes" in p.stdout and "no identification" in p.stdout, p.stdout


def test_live_record_writes_regime_events_to_mcap_and_jsonl(tmp_path):
    cfg = tmp_path / "kick.yaml"
    cfg.write_text("excitation:\n  ramp_s: 1.0\n  kicks:\n    - {t_s: 3.0285, beam: 2, velocity_m_per_s: 0.3}\n")
    out, ev = tmp_path / "live.mcap", tmp_path / "live.jsonl"
    p = cli("daq", "record", "--sim", "--config", str(cfg), "--duration", "8", "-o", str(out), "--events", str(ev),
            "--viewer", "save", "--quiet")
    assert p.returncode == 0, p.stderr
    assert "model updates" in p.stdout and "latency" in p.stdout
    rec = read_recording(out, raw=False)
    reg = [e for e in rec.events if e["kind"] == "regime"]
    assert [e["regime"] for e in reg] == ["localized-2"]
    lines = [json.loads(x) for x in ev.read_text().splitlines()]
    assert any(e["kind"] == "regime" and e["regime"] == "localized-2" for e in lines)
    assert rerun_cli("rrd", "verify", str(out.with_suffix(".rrd"))).returncode == 0
    # every rolling window's model per beam is kept as a time series in the recording
    assert len(rec.models) >= 2 * 4 and {m["beam"] for m in rec.models} == {1, 2}
    t = [m["t"] for m in rec.models if m["beam"] == 1 and m["final"]]
    assert np.allclose(np.diff(t), 1.0)  # hop 1 s (a window that needed a new model also has its first fit)
    assert all("integration_nrmse" in m and m["equations"] for m in rec.models)


def test_a_rate_whose_step_is_no_whole_tick_is_read_from_every_step_not_the_median(tmp_path):
    # 3 kHz stamped to the microsecond steps 333 and 334 us: 1 / median had read 3003.003 Hz (0.1 % off),
    # in the CSV reader, in `replay info` and in a recording's own rate; 7 kHz (142/143 us) the same
    from replay.formats.base import typical_step

    for fs in (3000.0, 7000.0):
        t = np.round(np.arange(4 * int(fs)) / fs, 6)  # the stamps a microsecond clock writes
        assert 1 / typical_step(np.diff(t)) == pytest.approx(fs, rel=2e-7)
        assert 1 / np.median(np.diff(t)) != pytest.approx(fs, rel=5e-4)  # (what the median gave: 0.1 % off)
        x = np.sin(2 * np.pi * 30 * t)
        path = tmp_path / f"r{fs:g}.csv"
        np.savetxt(path, np.column_stack([t, x, x, x]), delimiter=",", header="t,base,tip1,tip2", comments="",
                   fmt="%.6f")
        assert read_csv(path).fs_hz == pytest.approx(fs, rel=1e-6)
        rec = tmp_path / f"r{fs:g}.mcap"
        assert run_main(replay_main, ["import", path, "-o", rec])[0] == 0
        code, out, err, _ = run_main(replay_main, ["info", rec])
        assert code == 0 and f"rate       {fs:.3f} Hz" in out, out
        assert read_mcap(rec).fs_hz == pytest.approx(fs, rel=1e-6)
    # a rate given for a table whose time column agrees with it through rounding (1.5 kHz written to 4 decimals:
    # steps of 0.0007 and 0.0006 s), or counts samples, is taken; the median of the first had refused it
    t = np.arange(3000) / 1500.0
    (tmp_path / "r4.csv").write_text("t,base,tip1,tip2\n" + "".join(f"{x:.4f},0,0,0\n" for x in t))
    (tmp_path / "n.csv").write_text("t,base,tip1,tip2\n" + "".join(f"{i},0,0,0\n" for i in range(3000)))
    assert read_csv(tmp_path / "r4.csv", fs_hz=1500.0).fs_hz == 1500.0
    assert read_csv(tmp_path / "n.csv", fs_hz=1500.0).fs_hz == 1500.0
    (tmp_path / "broken.csv").write_text("t,base,tip1,tip2\n0,0,0,0\nnan,0,0,0\n0,0,0,0\n")  # (what --fs is for)
    assert read_csv(tmp_path / "broken.csv", fs_hz=1000.0).fs_hz == 1000.0  # (had divided by zero)
    # a lost frame's step (two) and a doubled stamp's (none) are left out of the mean
    assert typical_step(np.array([1.0, 1.0, 2.0, 1.0, 0.0, 1.0])) == 1.0
