"""UFF dataset 58 (replay.formats.uff): files written by pyuff itself read by ours, ours read by pyuff, and the
commands (replay export/import, ident fit, ident discover's reader) on them."""

import argparse
import json
import os
from pathlib import Path

import numpy as np
import pyuff
import pytest

from clitools import run_main
from daq.cli import main as daq_main
from ident.cli.discover import load_measurement
from ident.cli.main import main as ident_main
from replay.cli import main as replay_main
from replay.formats import read_columns, read_samples
from replay.formats.uff import snap_rate

REC = Path(__file__).resolve().parents[1] / "recordings"


def _dataset(data, fs, name, *, node=1, direction=3, unit="m/s^2", binary=0, func_type=1, x=None):
    return pyuff.prepare_58(binary=binary, func_type=func_type, rsp_node=node, rsp_dir=direction, ref_node=0,
                            ref_dir=0, data=data, x=np.arange(len(data)) / fs if x is None else x, id1=name,
                            rsp_ent_name="beam", abscissa_spacing=1, abscissa_spec_data_type=17,
                            abscissa_axis_units_lab="s", ordinate_spec_data_type=12, ordinate_axis_units_lab=unit,
                            orddenom_spec_data_type=0, z_axis_spec_data_type=0)


def _write(path, sets):
    for d in sets:  # one set per call: pyuff's binary writer truncates the file in 'overwrite' mode
        pyuff.UFF(str(path)).write_sets(d, mode="add")
    return path


@pytest.mark.parametrize("binary", [0, 1])
def test_files_written_by_pyuff_read_by_name_with_units(tmp_path, binary):
    """Three time histories at 3,000 Hz (an increment pyuff prints as 3.33333e-04), one in g, a frequency
    response among them, a channel without an ID line: values as written, g in m/s^2, the rate exact."""
    rng = np.random.default_rng(0)
    fs, n = 3000.0, 4500
    base, tip1, tip2 = rng.standard_normal((3, n)) * [[2.0], [30.0], [25.0]]
    frf = _dataset(rng.standard_normal(64) + 1j * rng.standard_normal(64), 1.0, "H11", func_type=4,
                   x=np.arange(64.0))
    path = _write(tmp_path / "lms.uff", [_dataset(base, fs, "Base acc", binary=binary), frf,
                                         _dataset(tip1 / 9.80665, fs, "Tip 1", node=2, unit="g", binary=binary),
                                         _dataset(tip2, fs, "NONE", node=3, direction=-2, binary=binary)])
    cols = read_columns(path, ["Base acc", "Tip 1", "beam:3:-Y"])
    assert cols.fs_hz == 3000.0 and snap_rate(float("3.33333e-04")) == 3000.0
    tol = 0 if binary else 1e-11  # ASCII keeps 12 significant digits (4E20.12)
    np.testing.assert_allclose(cols.data["Base acc"], base, rtol=tol, atol=1e-12)
    np.testing.assert_allclose(cols.data["Tip 1"], tip1, rtol=1e-11)  # g -> m/s^2
    np.testing.assert_allclose(cols.data["beam:3:-Y"], tip2, rtol=tol, atol=1e-12)
    s = read_samples(path, base="Base acc", tip1="Tip 1", tip2="beam:3:-Y")
    assert s.values.shape == (n, 3) and s.t[-1] == pytest.approx((n - 1) / fs)
    with pytest.raises(ValueError, match="no channel 'tip9'; channels are: Base acc, Tip 1, beam:3:-Y"):
        read_columns(path, ["tip9"])


def test_our_export_read_by_pyuff(tmp_path):
    """A recording with lost frames exported as UFF 58: pyuff finds three time histories named base, tip1, tip2
    in m/s^2 at 0.5 ms, their samples those of the recording with the lost frames interpolated."""
    rec = tmp_path / "drops.mcap"
    cfg = tmp_path / "drops.yaml"
    cfg.write_text("daq:\n  faults: {drop_frame_rate: 0.01}\n  calibration:\n"
                   "    tip1: {sensitivity_mv_per_g: 100.0, adc_mv_per_count: 0.0805664, sensor_model: PCB 352C33, "
                   "serial_number: LW123}\n")
    code, _, err, _ = run_main(daq_main, ["record", "--port", f"rig://?config={cfg}", "--config", cfg, "--duration",
                                          "2", "-o", rec, "--quiet", "--no-identify"])
    assert code == 0, err
    out = tmp_path / "drops.uff"
    code, text, err, tb = run_main(replay_main, ["export", rec, "--uff", out])
    assert code == 0 and tb is None, err
    want = read_samples(rec)  # on the grid, holes filled
    filled = int(np.count_nonzero(want.filled))
    assert filled > 10 and f"({filled} lost frame(s) filled" in text
    sets = pyuff.UFF(str(out)).read_sets()
    assert [d["id1"] for d in sets] == ["base", "tip1", "tip2"]
    for j, d in enumerate(sets):
        assert (d["func_type"], d["abscissa_spacing"], d["abscissa_inc"], d["ordinate_axis_units_lab"]) == \
            (1, 1, 0.0005, "m/s^2")
        assert (d["abscissa_spec_data_type"], d["ordinate_spec_data_type"], d["rsp_node"], d["rsp_dir"]) == \
            (17, 12, j + 1, 3)
        np.testing.assert_allclose(d["data"], want.values[:, j], rtol=1e-11, atol=1e-14)
        assert d["id5"] == f"{filled} lost frame(s) filled by linear interpolation"
    assert sets[1]["id4"].startswith("PCB 352C33, SN LW123, 100 mV/g")
    back = tmp_path / "back.mcap"
    code, _, err, _ = run_main(replay_main, ["import", out, "-o", back])
    assert code == 0, err
    np.testing.assert_allclose(read_samples(back).values, want.values, rtol=1e-5, atol=1e-5)  # JSON keeps 6 digits
    code, _, err, tb = run_main(replay_main, ["export", rec, "--uff", out])
    assert code == 2 and "exists; give --force" in err  # never replaced by accident


def test_ident_fit_and_discover_read_uff(tmp_path):
    """The example recording exported to UFF identifies to the same model as the recording itself."""
    out = tmp_path / "linear.uff"
    assert run_main(replay_main, ["export", REC / "linear.mcap", "--uff", out])[0] == 0
    fits = []
    for src in (REC / "linear.mcap", out):
        js = tmp_path / f"{src.suffix[1:]}.json"
        code, text, err, tb = run_main(ident_main, ["fit", src, "--json", js])
        assert code == 0 and tb is None, err
        fits.append([f["equations"] for f in json.loads(js.read_text())["fits"]])
    assert fits[0] == fits[1]
    ns = argparse.Namespace(excitation="base", response=["tip1", "tip2"], time_col=None, fs_hz=None)
    m = load_measurement(out, ns)
    np.testing.assert_allclose(m.responses[0].values, read_samples(REC / "linear.mcap").values[:, 1], rtol=1e-11,
                               atol=1e-12)
    assert m.fs_hz == 2000.0


def test_what_is_not_a_uff_time_history_is_refused_in_one_line(tmp_path):
    junk = tmp_path / "junk.uff"
    junk.write_bytes(os.urandom(3000))
    frf = _write(tmp_path / "frf.uff", [_dataset(np.ones(8) + 1j, 1.0, "H", func_type=4, x=np.arange(8.0))])
    csv = tmp_path / "renamed.unv"
    csv.write_text("t,base,tip1,tip2\n0,1,2,3\n")
    for path, match in ((junk, "no dataset 58"), (frf, "not time histories"), (csv, "no dataset 58"),
                        (tmp_path / "missing.uff", "no such file")):
        code, out, err, tb = run_main(replay_main, ["import", path, "-o", tmp_path / "x.mcap"])
        assert code == 2 and tb is None and len(err.strip().splitlines()) == 1 and match in err, err
