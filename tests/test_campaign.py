"""One recording's analyses for a campaign table (ident.campaign): regimes as spans against the example
recording's programme, each beam's natural frequency against the simulated rig's, one-tone excitation
flagged."""

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from daq.sim.excitation import Excitation
from daq.sim.rig import RigConfig, simulate_rig
from ident.campaign import fit_beams, one_tone, regime_durations, regime_record
from ident.live.regimes import MIN_PERIODS, SLOW_WINDOWS
from ident.rig import RigParams
from replay.formats import read_samples

REC = Path(__file__).resolve().parents[1] / "recordings"


def test_regime_spans_follow_the_transitions_programme():
    """transitions.mcap (recordings/README.md): a blow on beam 1 at 4 s, amplitude down at 8 s, beam 2's blow at
    12 s, down at 16 s, both at 20 s; each change is reported within a second after its cause (0.5 s windows
    every 0.25 s, two windows of dwell), and the spans tile the 26 s."""
    s = read_samples(REC / "transitions.mcap")
    r = regime_record(s.values, s.fs_hz)
    spans = r.spans
    assert r.slow_drive is None  # a 12-14 Hz drive makes 6-7 periods in a 0.5 s window
    assert [x.regime for x in spans] == ["linear", "localized-1", "linear", "localized-2", "linear",
                                         "impacting-both"]
    for span, cause in zip(spans[1:], (4.0, 8.0, 12.0, 16.0, 20.0)):
        assert cause < span.start_s <= cause + 1.0, (span, cause)
    assert spans[0].start_s == 0.0 and spans[-1].end_s == pytest.approx(26.0)
    assert all(a.end_s == b.start_s for a, b in zip(spans, spans[1:]))
    assert sum(regime_durations(spans).values()) == pytest.approx(26.0)
    assert regime_durations(spans)["localized-1"] == pytest.approx(spans[1].end_s - spans[1].start_s)


def test_regime_spans_of_a_slow_drive_need_a_longer_window():
    """A linear rig driven by a 6.5 Hz sine (3.25 periods in a 0.5 s window, fewer than MIN_PERIODS: the
    window's leakage reads as distortion): with the default window the spans call a beam hitting; with the 1 s
    window that ``ident batch --regime-window 1`` gives, it is linear throughout."""
    fs = 1000.0
    t = np.arange(int(20 * fs)) / fs
    x = np.column_stack([np.sin(2 * np.pi * 6.5 * t), 10 * np.sin(2 * np.pi * 6.5 * t - np.pi / 2),
                         8 * np.sin(2 * np.pi * 6.5 * t - 1.2)]) + np.random.default_rng(0).normal(0, 0.01, (len(t), 3))
    short = regime_record(x, fs)
    assert set(span.regime for span in short.spans) - {"linear"}  # a free beam read as hitting
    slow = short.slow_drive
    assert slow.drive_frequency_hz == pytest.approx(6.5, abs=0.1) and slow.periods == pytest.approx(3.25, abs=0.05)
    assert slow.t_s == pytest.approx(SLOW_WINDOWS * 0.25 + 0.25)  # windows end every 0.25 s from 0.5 s
    assert slow.window_needed_s == 1.0 and 1.0 * 6.5 >= MIN_PERIODS > 0.5 * 6.5
    assert "--regime-window 1 or more" in slow.message
    long = regime_record(x, fs, window_s=1.0)
    assert [(span.regime, span.start_s, span.end_s) for span in long.spans] == [("linear", 0.0, pytest.approx(20.0))]
    assert long.slow_drive is None


def _broadband(fn1_hz: float, fn2_hz: float, fs_hz: float = 500.0, duration_s: float = 7.0) -> np.ndarray:
    p = RigParams()
    p = replace(p, beam1=replace(p.beam1, natural_frequency_hz=fn1_hz),
                beam2=replace(p.beam2, natural_frequency_hz=fn2_hz))
    exc = Excitation(amplitude_m_per_s2=0.0, ramp_s=1.0, noise_rms_m_per_s2=1.2, noise_band_hz=(3.0, 40.0), seed=5)
    _, o = simulate_rig(RigConfig(rig=p, excitation=exc), duration_s, fs_hz)
    v = np.column_stack([o.base, o.tip1, o.tip2])
    return v + 0.02 * np.random.default_rng(1).standard_normal(v.shape)  # the default sensors' noise


def test_fit_beams_finds_each_beams_natural_frequency_under_broadband_excitation():
    """Free beams (no stopper reached) under a 3-40 Hz multisine: the coefficient of z in v' is -(k + k_c) / m,
    each beam's stiffness with the coupling spring, so the identified frequency is sqrt((k + k_c) / m) / 2 pi."""
    p = RigParams()
    fit = fit_beams(_broadband(10.6, 11.2), 500.0, start_s=2.0)
    for b, fn in zip(fit.beams, (10.6, 11.2)):
        truth = math.sqrt((2 * math.pi * fn) ** 2 + p.coupling_stiffness_n_per_m / p.beam1.mass_kg) / (2 * math.pi)
        assert b.natural_frequency_hz == pytest.approx(truth, rel=0.005), (b.beam, b.natural_frequency_hz, truth)
        assert b.nrmse < 0.05
        assert b.equations[1].startswith("v' = ") and " z" in b.equations[1]
    assert fit.one_tone_hz is None
    assert fit.start_s == 2.0 and fit.duration_s == pytest.approx(5.0)


def test_one_tone_is_flagged_and_broadband_is_not():
    fs = 200.0
    t = np.arange(2000) / fs
    rng = np.random.default_rng(0)
    sine = 1.93 * np.sin(2 * np.pi * 12.3 * t) + 0.02 * rng.standard_normal(t.size)
    assert one_tone(sine, fs) == pytest.approx(12.3, abs=fs / t.size)  # within a bin of the tone
    assert one_tone(_broadband(11.2, 11.2)[:, 0], 500.0) is None
    two = sine + 1.0 * np.sin(2 * np.pi * 17.0 * t)
    assert one_tone(two, fs) is None


def test_fit_refuses_a_segment_too_short_in_one_line():
    v = _broadband(11.2, 11.2, duration_s=4.0)
    with pytest.raises(ValueError, match=r"--start 3 s leaves 1.00 s of the 4.00 s recording; the fit needs at "
                                         r"least 2 s"):
        fit_beams(v, 500.0, start_s=3.0)
    with pytest.raises(ValueError, match="outside the recording"):
        fit_beams(v, 500.0, start_s=4.0)
