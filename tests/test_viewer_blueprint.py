"""The live view as laid out: a short simulated ``daq record --viewer save`` fills every panel of the
blueprint (every entity a panel shows holds data on the ``time`` timeline), the .rrd is written beside the
output and verifies, the command says where it is; the spectra it draws are the H1 estimate and the
coherence (checked against their analytic values)."""

import os
import subprocess
import sys
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from rerun.chunk import RrdReader

from daq.tools import screenshot_view
from daq.viewer import PANELS, nice_ticks, transfer_estimates
from ident.cli.fit import cycles_window

ROOT = Path(__file__).resolve().parents[1]


def rerun_cli(*args):
    exe = os.path.join(os.path.dirname(sys.executable), "rerun")
    return subprocess.run([exe, *args], capture_output=True, text=True, timeout=120)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    folder = tmp_path_factory.mktemp("view")
    out = folder / "run.mcap"
    env = dict(os.environ, PYTHONPATH=str(ROOT), RERUN_ANALYTICS="0")
    p = subprocess.run([sys.executable, "-m", "daq", "record", "-o", str(out), "--duration", "8", "--viewer", "save"],
                       capture_output=True, text=True, timeout=180, cwd=folder, env=env)
    assert p.returncode == 0, p.stderr
    return out, p


def test_save_writes_beside_the_output_and_says_where(recorded):
    out, p = recorded
    rrd = out.with_suffix(".rrd")
    assert rrd.is_file()
    assert f"viewer: saving to {rrd}" in p.stderr
    assert rerun_cli("rrd", "verify", str(rrd)).returncode == 0


def test_every_panel_of_the_blueprint_holds_data(recorded):
    out, _ = recorded
    reader = RrdReader(out.with_suffix(".rrd"))
    assert len(reader.blueprints()) == 1  # the layout travels with the data
    rows: Counter = Counter()
    for chunk in reader.stream():
        if not chunk.is_static and "time" in chunk.timeline_names:
            rows[chunk.entity_path.lstrip("/")] += chunk.num_rows
    empty = [(title, e) for _, title, entities in PANELS for e in entities if rows[e] == 0]
    assert not empty, empty
    fs, seconds = 2000, 8
    for c in ("base", "tip1", "tip2"):  # the kHz traces: every sample, once
        assert rows[f"accel/raw/{c}"] == rows[f"accel/filtered/{c}"] == fs * seconds
    # measured and predicted z: each identification sample once (the windows overlap, the newest hop is sent)
    assert rows["model/beam1/z"] == rows["model/beam1/z_pred"]
    assert rows["model/beam1/z"] <= 200 * seconds


def test_h1_and_coherence_against_their_analytic_values():
    """tip1 = 3 base + noise uncorrelated with the base: H1 = 3 whatever the output noise (H1 is unbiased by
    output noise), coherence = 9 s_b^2 / (9 s_b^2 + s_n^2) = 9 / 13 for s_n = 2 s_b; tip2 independent:
    coherence near 0."""
    rng = np.random.default_rng(1)
    fs, n = 2000.0, 2000 * 60
    base = rng.standard_normal(n)
    tip1 = 3 * base + 2 * rng.standard_normal(n)
    tip2 = rng.standard_normal(n)
    f, h1, coh, pxx = transfer_estimates(np.column_stack([base, tip1, tip2]), fs, 2000)
    band = (f > 5) & (f < 500)
    assert np.median(np.abs(h1[band, 0])) == pytest.approx(3.0, rel=0.02)
    assert np.median(coh[band, 0]) == pytest.approx(9 / 13, abs=0.02)
    assert np.median(coh[band, 1]) < 0.05
    assert np.median(pxx[band, 0]) == pytest.approx(2 / fs, rel=0.05)  # one-sided PSD of unit white noise


def test_nice_ticks():
    assert np.allclose(nice_ticks(0.0, 1.1), [0, 0.5, 1.0])
    assert np.allclose(nice_ticks(9.8, 11.6), [10, 10.5, 11, 11.5])


def test_replay_saves_the_view_beside_its_output_not_beside_the_input(tmp_path):
    rec = ROOT / "recordings" / "linear.mcap"
    env = dict(os.environ, PYTHONPATH=str(ROOT), RERUN_ANALYTICS="0")
    before = set((ROOT / "recordings").iterdir())
    run = [sys.executable, "-m", "replay", str(rec), "--max", "--no-identify", "--duration", "2", "--viewer", "save"]
    p = subprocess.run(run, capture_output=True, text=True, timeout=120, cwd=tmp_path, env=env)
    assert p.returncode == 0, p.stderr
    assert (tmp_path / "linear.rrd").is_file() and f"saving to {tmp_path / 'linear.rrd'}" in p.stderr
    events = tmp_path / "out" / "ev.jsonl"
    events.parent.mkdir()
    p = subprocess.run(run + ["--events", str(events)], capture_output=True, text=True, timeout=120, cwd=tmp_path,
                       env=env)
    assert p.returncode == 0, p.stderr
    assert events.with_suffix(".rrd").is_file()
    assert set((ROOT / "recordings").iterdir()) == before


def test_fit_figure_shows_four_cycles_of_the_strongest_frequency():
    t = np.arange(0, 20, 1 / 200)
    x = np.sin(2 * np.pi * 12.5 * t) + 0.3 * np.sin(2 * np.pi * 37.5 * t)
    assert cycles_window(x, 200.0) == pytest.approx(4 / 12.5, rel=0.01)
    assert cycles_window(x[:40], 200.0) == pytest.approx(0.2)  # shorter than 4 cycles: all of it


def test_screenshot_script_never_replaces_a_file_without_force(tmp_path, capsys):
    png = tmp_path / "view.png"
    png.write_bytes(b"precious")
    assert screenshot_view.main(["-o", str(png), "--duration", "1"]) == 2
    assert png.read_bytes() == b"precious"
    assert "exists; give --force" in capsys.readouterr().err
    src = tmp_path / "rec.mcap"
    src.write_bytes(b"mcap")
    assert screenshot_view.main(["-o", str(src), "--source", str(src), "--force"]) == 2
    assert src.read_bytes() == b"mcap" and "is the input" in capsys.readouterr().err
