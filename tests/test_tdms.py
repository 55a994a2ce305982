"""NI TDMS (replay.formats.tdms): files written by npTDMS itself read by ours, ours read by npTDMS, and the
commands on them (replay import keeps the holes our export marks, ident discover's reader)."""

import argparse
import os

import numpy as np
import pytest
from nptdms import ChannelObject, GroupObject, RootObject, TdmsFile, TdmsWriter

from clitools import run_main
from daq.cli import main as daq_main
from ident.cli.discover import load_measurement
from replay.cli import main as replay_main
from replay.formats import read_columns, read_samples


def test_files_written_by_nptdms_read_by_name_with_units(tmp_path):
    """A LabVIEW-like file: group 'Rig' with waveforms (one in g), a second group sharing a channel name, a
    string channel; and a file whose rate is only in a time channel."""
    rng = np.random.default_rng(1)
    fs, n = 5120.0, 6000
    a = rng.standard_normal((3, n)) * [[1.0], [20.0], [15.0]]
    wf = {"wf_increment": 1 / fs, "wf_start_offset": 0.0}
    path = tmp_path / "labview.tdms"
    with TdmsWriter(str(path)) as w:
        w.write_segment([RootObject({"name": "run 7"}), GroupObject("Rig"),
                         ChannelObject("Rig", "Base", a[0], {**wf, "unit_string": "m/s^2"}),
                         ChannelObject("Rig", "Tip1", a[1] / 9.80665, {**wf, "unit_string": "g"}),
                         ChannelObject("Rig", "Tip2", a[2], wf),
                         ChannelObject("Other", "Base", np.zeros(10), wf),
                         ChannelObject("Rig", "Note", ["x"] * 3)])
    cols = read_columns(path, ["Rig/Base", "Tip1", "Tip2"])
    assert cols.fs_hz == pytest.approx(5120.0, rel=1e-12)
    np.testing.assert_array_equal(cols.data["Rig/Base"], a[0])
    np.testing.assert_allclose(cols.data["Tip1"], a[1], rtol=1e-14)  # g -> m/s^2
    np.testing.assert_array_equal(cols.data["Tip2"], a[2])
    with pytest.raises(ValueError, match="no channel 'Base'; channels are: .*Rig/Base.*Other/Base"):
        read_columns(path, ["Base"])  # two groups hold one: give the group
    timed = tmp_path / "timed.tdms"
    t = np.arange(n) / 1000.0
    with TdmsWriter(str(timed)) as w:
        w.write_segment([ChannelObject("g", c, v) for c, v in (("time", t), ("b", a[0]), ("t1", a[1]), ("t2", a[2]))])
    s = read_samples(timed, time_col="time", base="b", tip1="t1", tip2="t2")
    assert s.fs_hz == pytest.approx(1000.0) and np.array_equal(s.values, a.T)
    with pytest.raises(ValueError, match="has no waveform increment"):
        read_samples(timed, base="b", tip1="t1", tip2="t2")


def test_our_export_read_by_nptdms_and_imported_back_with_its_holes(tmp_path):
    cfg = tmp_path / "drops.yaml"
    cfg.write_text("daq:\n  faults: {drop_frame_rate: 0.01}\n  calibration:\n    tip2: {serial_number: S-9}\n")
    rec = tmp_path / "drops.mcap"
    code, _, err, _ = run_main(daq_main, ["record", "--port", f"rig://?config={cfg}", "--config", cfg, "--duration",
                                          "2", "-o", rec, "--quiet", "--no-identify"])
    assert code == 0, err
    out = tmp_path / "drops.tdms"
    code, text, err, tb = run_main(replay_main, ["export", rec, "-o", out])
    assert code == 0 and tb is None, err
    want = read_samples(rec)
    f = TdmsFile.read(str(out))
    g = f["rig"]
    assert [c.name for c in g.channels()] == ["base", "tip1", "tip2", "t", "seq"]
    for j, ch in enumerate(("base", "tip1", "tip2")):
        props = g[ch].properties
        assert (props["unit_string"], props["wf_increment"], props["wf_samples"]) == ("m/s^2", 0.0005, len(want.t))
        np.testing.assert_array_equal(g[ch][:], want.values[:, j])
    assert g["tip2"].properties["serial_number"] == "S-9"
    np.testing.assert_array_equal(g["seq"][:], np.where(want.filled, -1, want.seq))
    assert g.properties["lost_frames_filled"] == int(np.count_nonzero(want.filled)) > 10
    back = tmp_path / "back.mcap"
    code, _, err, _ = run_main(replay_main, ["import", out, "-o", back])
    assert code == 0, err
    got = read_samples(back)
    assert np.array_equal(got.filled, want.filled)  # the lost frames are holes again, not samples
    np.testing.assert_allclose(got.values, want.values, rtol=1e-5, atol=1e-5)
    ns = argparse.Namespace(excitation="base", response=["tip1"], time_col=None, fs_hz=None)
    m = load_measurement(out, ns)
    assert m.fs_hz == 2000.0 and np.array_equal(m.excitation.values, want.values[:, 0])


def test_what_is_not_tdms_is_refused_in_one_line(tmp_path):
    junk = tmp_path / "junk.tdms"
    junk.write_bytes(os.urandom(2000))
    empty = tmp_path / "strings.tdms"
    with TdmsWriter(str(empty)) as w:
        w.write_segment([ChannelObject("g", "note", ["a", "b"])])
    for path, match in ((junk, "not a readable TDMS file"), (empty, "no channel with numeric data"),
                        (tmp_path / "missing.tdms", "no such file")):
        code, out, err, tb = run_main(replay_main, ["import", path, "-o", tmp_path / "x.mcap"])
        assert code == 2 and tb is None and len(err.strip().splitlines()) == 1 and match in err, err
