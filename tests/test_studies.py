"""The paper's experimental studies on the example recordings (ident.paper.studies, ident fit)."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ident.paper.studies import run_study
from replay.formats import read_samples as read_mcap

REC = Path(__file__).resolve().parents[1] / "recordings"


def steady(name, start=5.0):
    s = read_mcap(REC / f"{name}.mcap")
    return s.values[int(start * s.fs_hz):], s.fs_hz


def test_study1_rotation_rate_and_vanishing_quadratic_terms():
    """2-D embedding with a quarter-period delay of a sinusoid: x1' = -Omega x2, Omega = 2 pi 12.3 Hz."""
    v, fs = steady("linear")
    res = run_study(v, fs, 1)
    assert res.dimension == 2 and [f.degree for f in res.fits] == [1, 2]
    p1, p2 = res.fits
    c = p1.ident.model.as_dict()
    assert c["x1'"]["x2"] == pytest.approx(-2 * np.pi * 12.3, rel=0.03)
    assert p1.nrmse < 0.05
    quad = [t for eq in p2.ident.model.as_dict().values() for t in eq if "^2" in t or t.count("x") == 2]
    assert quad == []  # Table 5: the higher-order terms vanish


def test_study2_four_states_of_both_blades():
    v, fs = steady("localized-1")
    res = run_study(v, fs, 2)
    assert res.states.shape[1] == 4 and res.state_names == ("x1", "x2", "x3", "x4")
    fit = res.fits[0]
    assert np.isfinite(fit.nrmse) and fit.nrmse < 0.5
    assert fit.ident.refinement.error_after <= fit.ident.refinement.error_before


def test_ident_fit_command_writes_tables_and_figures(tmp_path):
    p = subprocess.run([sys.executable, "-m", "ident", "fit", str(REC / "impacting-both.mcap"), "--study", "3",
                        "--report", str(tmp_path / "rep"), "--json", str(tmp_path / "r.json")],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    js = json.loads((tmp_path / "r.json").read_text())
    assert js["study"] == 3 and js["fits"][0]["equations"]
    assert (tmp_path / "rep" / "fit_p2.png").read_bytes()[:4] == b"\x89PNG"
    assert (tmp_path / "rep" / "table_p2.csv").exists()
    bad = subprocess.run([sys.executable, "-m", "ident", "fit", str(REC / "linear.mcap"), "--start", "99"],
                         capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1
