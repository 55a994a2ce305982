"""Regime monitor on the simulated rig: a sequence through all four regimes, and 10 steady minutes."""

from dataclasses import replace

import numpy as np
import pytest

from daq.sim.excitation import Kick, Step
from ident.live.regimes import RegimeConfig, RegimeMonitor, label_of
from daq.sim.rig import RigConfig, simulate_rig
from daq.sim.sensors import to_counts

FS = 2000.0


def kick_time(t):
    """A kick at phase 0.55 of the 12.3 Hz cycle, where the tests' blows reliably capture."""
    return (np.floor(t * 12.3) + 0.55) / 12.3


def measured(cfg, seconds, seed=0):
    t, o = simulate_rig(cfg, seconds, FS)
    rng = np.random.default_rng(seed)
    sig = [to_counts(x, s, rng)[0] * s.lsb_m_per_s2 for x, s in zip((o.base, o.tip1, o.tip2), cfg.sensors)]
    return t, np.column_stack(sig), o.contact != 0


def run_monitor(x, seed=1):
    mon = RegimeMonitor(RegimeConfig(fs_hz=FS))
    rng = np.random.default_rng(seed)
    windows, changes, pos = [], [], 0
    while pos < len(x):
        k = int(rng.integers(1, 1500))  # arbitrary block sizes, like serial reads
        w, c = mon.step(x[pos:pos + k])
        windows += w
        changes += c
        pos += k
    return windows, changes


@pytest.fixture(scope="module")
def sequence():
    kicks = (Kick(kick_time(20), 1, 0.3), Kick(kick_time(60), 2, 0.3), Kick(kick_time(100), 1, 0.3),
             Kick(kick_time(100), 2, 0.3))
    steps = (Step(40, 0.6), Step(45, 1.93), Step(80, 0.6), Step(85, 1.93), Step(120, 0.6), Step(125, 1.93))
    cfg = RigConfig()
    cfg = replace(cfg, excitation=replace(cfg.excitation, kicks=kicks, steps=steps))
    t, x, contact = measured(cfg, 140.0)
    # truth: a beam is hitting in a window if it touched its stopper within it
    windows, changes = run_monitor(x)
    truth = []
    for w in windows:
        i1 = int(round(w.t_s * FS))
        sl = slice(max(0, i1 - int(0.5 * FS)), i1)
        truth.append(label_of(contact[sl, 0].any(), contact[sl, 1].any()))
    true_changes = [(windows[i].t_s, truth[i]) for i in range(1, len(truth)) if truth[i] != truth[i - 1]]
    return windows, changes, truth, true_changes


def test_the_sequence_visits_all_four_regimes(sequence):
    _, _, truth, true_changes = sequence
    assert set(truth) == {"linear", "localized-1", "localized-2", "impacting-both"}
    assert len(true_changes) == 6


def test_at_least_95_percent_of_windows_labelled_right(sequence):
    windows, _, truth, _ = sequence
    right = np.mean([w.label == tr for w, tr in zip(windows, truth)])
    assert right >= 0.95, right


def test_every_change_reported_within_one_second_and_nothing_else(sequence):
    _, changes, _, true_changes = sequence
    assert len(changes) == len(true_changes)
    for (t_true, regime), ch in zip(true_changes, changes):
        assert ch.regime == regime
        assert 0 <= ch.t_s - t_true <= 1.0, (t_true, ch)


def test_features_reported_with_every_window(sequence):
    windows, _, truth, _ = sequence
    lin = [w for w, tr in zip(windows, truth) if tr == "linear" and w.label == "linear"]
    loc = [w for w, tr in zip(windows, truth) if tr == "localized-1" and w.label == "localized-1"]
    assert np.median([w.amplitude_ratio for w in lin]) == pytest.approx(1.0, abs=0.05)  # equal tips
    assert np.median([w.amplitude_ratio for w in loc]) > 1.5  # beam 1 dominates (1.9 below 50 Hz)
    # tips lag the base by about 158 degrees in the linear regime (see ident.rig)
    assert abs(np.median([abs(w.phase_deg[0]) for w in lin]) - 158) < 10
    assert max(w.impact_rms[0] for w in lin) < 0.3 < 1.0 < min(w.impact_rms[0] for w in loc)


@pytest.mark.parametrize("kicks", [(), (Kick(kick_time(20), 1, 0.3),)], ids=["linear", "localized-1"])
def test_no_change_on_ten_minutes_of_steady_data(kicks):
    cfg = RigConfig()
    cfg = replace(cfg, excitation=replace(cfg.excitation, kicks=kicks))
    t, x, _ = measured(cfg, 600.0, seed=7)
    skip = int(25 * FS)  # from 25 s on, the regime is established
    mon = RegimeMonitor(RegimeConfig(fs_hz=FS))
    mon.step(x[:skip])
    windows, changes = mon.step(x[skip:])
    assert len(windows) > 2000
    assert changes == []


def test_bad_config_and_input():
    with pytest.raises(ValueError, match="hysteresis"):
        RegimeMonitor(RegimeConfig(on_m_per_s2=0.2, off_m_per_s2=0.5))
    with pytest.raises(ValueError, match="shape"):
        RegimeMonitor().step(np.zeros((10, 2)))
