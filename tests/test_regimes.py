"""Regime monitor: on the project's rig (features against the simulation's states) and on the independent
generator's rigs (regimes against its per-sample truth); the streaming stage's block-split invariance."""

from dataclasses import replace
from types import SimpleNamespace as NS

import numpy as np
import pytest

from daq.bench_regimes import CaseData, at_the_gap
from daq.sim.excitation import Kick, Step
from daq.sim.rig import RigConfig, simulate_rig
from daq.sim.sensors import to_counts
from ident.live.pipeline import Pipeline, PipelineConfig
from ident.live.regimes import (CROSS_BAND, CROSS_MARGIN, CROSS_MIN_WINDOWS, CROSS_QUANTILE, LABELS, MIN_PERIODS,
                                PHASE_REFERENCE, PHASE_WINDOWS, PHASE_Z, SLOW_WINDOWS, Decision, RegimeConfig, RegimeMonitor, _cross_talk,
                                _clipping, _gap_evidence, _half_phasors, _in_phase, _leakage, _own_contact, decide,
                                label_of, regime_start, regime_step, spectral_features, starting)
from ident.live.scoring import score_regimes, true_changes

FS = 2000.0


def kick_time(t):
    """A kick at phase 0.55 of the 12.3 Hz cycle, where the tests' blows reliably capture."""
    return (np.floor(t * 12.3) + 0.55) / 12.3


def measured(cfg, seconds, seed=0):
    t, o = simulate_rig(cfg, seconds, FS)
    rng = np.random.default_rng(seed)
    sig = [to_counts(x, s, rng)[0] * s.lsb_m_per_s2 for x, s in zip((o.base, o.tip1, o.tip2), cfg.sensors)]
    return t, np.column_stack(sig), o


def run_monitor(x, seed=1, cfg=RegimeConfig(fs_hz=FS)):
    mon = RegimeMonitor(cfg)
    rng = np.random.default_rng(seed)
    windows, changes, pos = [], [], 0
    while pos < len(x):
        k = int(rng.integers(1, 1500))  # arbitrary block sizes, like serial reads
        w, c = mon.step(x[pos:pos + k])
        windows += w
        changes += c
        pos += k
    return windows, changes


def lock_in(y, fs, f):
    """Complex amplitude of y at frequency f (Hann-weighted, as the monitor), per column."""
    n = len(y)
    w = np.hanning(n)
    y = y - y.mean(axis=0)
    return 2 * ((y * w[:, None]).T @ np.exp(-2j * np.pi * f * np.arange(n) / fs)) / w.sum()


@pytest.fixture(scope="module")
def sequence():
    kicks = (Kick(kick_time(20), 1, 0.3), Kick(kick_time(60), 2, 0.3), Kick(kick_time(100), 1, 0.3),
             Kick(kick_time(100), 2, 0.3))
    steps = (Step(40, 0.6), Step(45, 1.93), Step(80, 0.6), Step(85, 1.93), Step(120, 0.6), Step(125, 1.93))
    cfg = RigConfig()
    cfg = replace(cfg, excitation=replace(cfg.excitation, kicks=kicks, steps=steps))
    t, x, o = measured(cfg, 140.0)
    contact = o.contact != 0
    # truth: a beam is hitting in a window if it touched its stopper within it
    windows, changes = run_monitor(x)
    truth = []
    for w in windows:
        i1 = int(round(w.t_s * FS))
        sl = slice(max(0, i1 - int(0.5 * FS)), i1)
        truth.append(label_of(contact[sl, 0].any(), contact[sl, 1].any()))
    true_ch = [(windows[i].t_s, truth[i]) for i in range(1, len(truth)) if truth[i] != truth[i - 1]]
    return windows, changes, truth, true_ch, x, o


def test_the_sequence_visits_all_four_regimes(sequence):
    _, _, truth, true_ch, _, _ = sequence
    assert set(truth) == {"linear", "localized-1", "localized-2", "impacting-both"}
    assert len(true_ch) == 6


def test_at_least_95_percent_of_windows_labelled_right(sequence):
    windows, _, truth, _, _, _ = sequence
    right = np.mean([w.label == tr for w, tr in zip(windows, truth)])
    assert right >= 0.95, right


def test_every_change_reported_within_one_second_and_nothing_else(sequence):
    _, changes, _, true_ch, _, _ = sequence
    assert len(changes) == len(true_ch)
    for (t_true, regime), ch in zip(true_ch, changes):
        assert ch.regime == regime
        assert 0 <= ch.t_s - t_true <= 1.0, (t_true, ch)


def test_features_against_the_simulated_states(sequence):
    """Displacement amplitude and phase per window against the simulation's own relative displacement and
    clean accelerations (the monitor sees only the noisy ADC counts); the impact band separates."""
    windows, _, truth, _, _, o = sequence
    n = int(0.5 * FS)
    steady = [w for w, tr in zip(windows, truth) if tr == w.label and w.t_s > 25 and int(w.t_s * 4) % 8 == 0]
    assert len(steady) > 30
    for w in steady:
        k = int(round(w.t_s * FS))
        sl = slice(k - n, k)
        z = lock_in(o.z[sl], FS, w.drive_frequency_hz)
        clean = lock_in(np.column_stack([o.base[sl], o.tip1[sl], o.tip2[sl]]), FS, w.drive_frequency_hz)
        for i, b in enumerate(w.beams):
            assert b.displacement_m == pytest.approx(abs(z[i]), rel=0.03)
            phase = np.degrees(np.angle(clean[1 + i] / clean[0]))
            assert abs((b.phase_deg - phase + 180) % 360 - 180) < 3.0
            assert b.sign == 1
        assert w.amplitude_ratio == pytest.approx(abs(z[0] / z[1]), rel=0.05)
    lin = [w for w, tr in zip(windows, truth) if tr == "linear" and w.label == "linear"]
    loc = [w for w, tr in zip(windows, truth) if tr == "localized-1" and w.label == "localized-1"]
    # tips lag the base by about 158 degrees in the linear regime (see ident.rig)
    assert abs(np.median([abs(w.phase_deg[0]) for w in lin]) - 158) < 10
    assert max(w.impact_rms[0] for w in lin) < 0.3 < min(w.impact_rms[0] for w in loc)


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


# --- the independent generator (daq.sim.independent: its own beams, stoppers, integrator, sensors) ---

@pytest.fixture(scope="module")
def generated():
    from daq.sim.independent.regimes import regime_case

    return {seed: regime_case(seed, segment_s=(10.0, 10.0)) for seed in GENERATED}


def columns(case):
    return np.column_stack([case.columns[k] for k in ("base", "tip1", "tip2")])


def scored(case, x=None, gaps=None):
    cfg = RegimeConfig(fs_hz=case.fs_hz, gap_m=gaps)
    windows, changes = run_monitor(columns(case) if x is None else x, cfg=cfg)
    t = np.array([w.t_s for w in windows])
    codes = np.array([LABELS.index(w.label) for w in windows])
    sc = score_regimes(t, codes, [(c.t_s, LABELS.index(c.regime)) for c in changes],
                       case.truth_series["achieved"], case.fs_hz)
    return sc, windows


# The three seeds that generate fastest (10 s segments), as measured: seed: (share of windows right,
# true changes, of them reported within 1 s, false changes). Seed 11 starts with beam 1 grazing a soft
# one-sided stopper (2 % beyond its gap, 5 x the beam's stiffness) while beam 2 hits hard: the monitor
# calls it localized-2 until the grazing beam hits properly (daq bench --regimes has the whole picture).
GENERATED = {4: (1.0, 5, 5, 1), 11: (0.81, 7, 6, 4), 2: (1.0, 7, 7, 0)}


@pytest.mark.parametrize("seed", list(GENERATED))
def test_regimes_on_the_independent_generator(generated, seed):
    case = generated[seed]
    share, changes, in_time, false = GENERATED[seed]
    sc, _ = scored(case)
    assert len(sc.true_changes) == changes  # the programme went through the regimes
    assert sc.share_right >= share, sc
    assert sc.changes_in_time >= in_time, sc
    assert sc.false_changes <= false, sc


def test_a_sensor_mounted_upside_down_changes_nothing(generated):
    """The tip's sign comes from the energy flow (a passive beam takes power from the base): flipping a
    tip's sign flips the sign the monitor reports, and nothing else."""
    case = generated[4]
    _, windows = scored(case)
    x = columns(case)
    x[:, 2] *= -1
    _, flipped = scored(case, x)
    assert [w.label for w in flipped] == [w.label for w in windows]
    late = [(w, f) for w, f in zip(windows, flipped) if w.t_s > 10]
    assert all(f.beams[1].sign == -w.beams[1].sign for w, f in late)
    for w, f in late:
        assert f.beams[1].displacement_m == pytest.approx(w.beams[1].displacement_m, rel=1e-9)


def test_no_false_change_on_a_steady_minute():
    from daq.sim.independent.regimes import steady_case

    case = steady_case(6, "beam2", minutes=1.0, fs_hz=500)
    assert case.truth["regime_share"]["beam2"] > 0.99
    sc, windows = scored(case)
    assert sc.reported_changes == 0
    assert sc.share_right == 1.0 and starting(windows).label == "localized-2"  # the starting regime too


def test_any_split_into_blocks_gives_the_same_output(generated):
    """The stage is a pure function of (state, block): one block, or random ones, the same windows."""
    x = columns(generated[2])
    cfg = RegimeConfig(fs_hz=generated[2].fs_hz)
    state, whole, ch_whole = regime_step(regime_start(cfg), x)
    rng = np.random.default_rng(5)
    state2, parts, ch_parts, pos = regime_start(cfg), [], [], 0
    while pos < len(x):
        k = int(rng.integers(1, 3000))
        state2, w, c = regime_step(state2, x[pos:pos + k])
        parts += w
        ch_parts += c
        pos += k
    assert repr(parts) == repr(whole) and repr(ch_parts) == repr(ch_whole)  # repr: exact floats, NaN equal
    assert state2.n_seen == state.n_seen == len(x)


def decided(probabilities, cfg=RegimeConfig()):
    """The decision stage alone on a synthetic sequence of the beams' probabilities of hitting: every
    window's reported label (None before the starting regime is decided) and the indices of the windows
    that report a change."""
    d, labels, changes = Decision(), [], []
    for k, p in enumerate(probabilities):
        d, changed = decide(d, p, cfg)
        labels.append(d.label if d.started else None)
        if changed:
            changes.append(k)
    return labels, changes


FREE, HIT, GRAZE = 0.1, 0.9, 0.6  # clear free, clear hitting, inside the hysteresis band [0.3, 0.7]
S = PHASE_WINDOWS - 1  # windows before the starting regime is decided


@pytest.mark.parametrize("dwell", [1, 2, 3, 5])
def test_a_sustained_change_is_reported_after_exactly_the_dwell(dwell):
    cfg = RegimeConfig(dwell=dwell)
    labels, changes = decided([(FREE, FREE)] * 10 + [(HIT, FREE)] * 10, cfg)
    assert labels[:S] == [None] * S and labels[S] == "linear" and changes == [10 + dwell - 1]
    assert labels[S:10 + dwell - 1] == ["linear"] * (10 + dwell - 1 - S)
    assert labels[10 + dwell - 1:] == ["localized-1"] * (10 - dwell + 1)


def test_flicker_shorter_than_the_dwell_is_no_change():
    cfg = RegimeConfig(dwell=3)
    # clear flicker: the other regime for 1 and 2 windows at a time (< 3), ten times over
    seq = [(FREE, FREE)] * 4 + ([(HIT, FREE)] + [(FREE, FREE)] * 2 + [(FREE, HIT)] * 2 + [(FREE, FREE)]) * 10
    labels, changes = decided(seq, cfg)
    assert changes == [] and set(labels[S:]) == {"linear"}
    # the starting regime is the PHASE_WINDOWS-th window's, whatever the windows before it guessed
    labels, changes = decided([(FREE, FREE), (HIT, FREE), (HIT, HIT)] + [(HIT, FREE), (HIT, HIT)] * 5,
                              RegimeConfig(dwell=2))
    assert changes == [] and set(labels[S:]) == {"impacting-both"}


def test_the_start_waits_for_the_windows_the_phase_rules_sum():
    """Independent regime seed 6015, held in "both": beam 2's p rose 0.27, 0.62, 0.97 over the first three
    windows (its harmonics taken for the coupling's before the coupling was measured, the phase rules not
    yet summed). Decided at the first window, the stream started "beam 1 hitting" and reported "both" at
    the fourth: a false change. Decided at the third, it starts "both"; the windows before say nothing."""
    seq = [(HIT, 0.27), (HIT, 0.62), (HIT, 0.97)] + [(HIT, HIT)] * 10
    labels, changes = decided(seq, RegimeConfig(dwell=2))
    assert S == 2 and labels[:S] == [None, None]
    assert changes == [] and set(labels[S:]) == {"impacting-both"}


def test_the_starting_regime_is_each_beams_likelier_state_and_then_held_by_the_hysteresis():
    """A beam at p = 0.6 in the window that decides the start starts hitting (the likelier state; the hysteresis has no
    state yet to hold) and is held there while p stays above 0.5 - h; the same p after a free start does
    not make it hitting."""
    cfg = RegimeConfig(dwell=2, hysteresis=0.2)
    labels, changes = decided([(GRAZE, HIT)] + [(0.45, HIT), (GRAZE, HIT)] * 10, cfg)  # the third window: GRAZE
    assert changes == [] and set(labels[S:]) == {"impacting-both"}
    labels, changes = decided([(0.45, HIT)] * (S + 1) + [(GRAZE, HIT)] * 10, cfg)
    assert changes == [] and set(labels[S:]) == {"localized-2"}
    labels, changes = decided([(0.5, 0.51)] * (S + 1), cfg)  # at exactly 0.5 a beam is not the likelier hitting
    assert labels[S:] == ["localized-2"]


def test_windows_inside_the_hysteresis_band_neither_count_nor_break_the_dwell():
    cfg = RegimeConfig(dwell=2, max_dwell=8, hysteresis=0.2)
    start = [(HIT, FREE)] * 4  # localized-1
    # beam 2 crosses 0.7 once, then stays in the band (hitting by hysteresis, unclear) for 5 windows, then
    # leaves: the label impacting-both for 6 windows, but only 1 clear one: no change (the plain two-window
    # dwell reported it, and its return, as two changes)
    labels, changes = decided(start + [(HIT, 0.75)] + [(HIT, GRAZE)] * 5 + [(HIT, FREE)] * 4, cfg)
    assert changes == [] and set(labels[S:]) == {"localized-1"}
    # unclear windows in between do not break the run: the second clear window reports the change
    labels, changes = decided(start + [(HIT, 0.75)] + [(HIT, GRAZE)] * 3 + [(HIT, HIT)] * 3, cfg)
    assert changes == [4 + 4] and labels[8] == "impacting-both"
    # a regime that stays unclear is reported after max_dwell windows of it
    labels, changes = decided(start + [(HIT, 0.75)] + [(HIT, GRAZE)] * 10, cfg)
    assert changes == [4 + 8 - 1] and labels[-1] == "impacting-both"
    # without hysteresis every window is clear: the plain dwell
    labels, changes = decided(start + [(HIT, 0.75)] + [(HIT, GRAZE)] * 3, RegimeConfig(dwell=2, hysteresis=0.0))
    assert changes == [4 + 1]


def test_a_beam_that_leaves_clearly_is_a_change_while_the_other_grazes():
    cfg = RegimeConfig(dwell=2, max_dwell=8, hysteresis=0.2)
    start = [(HIT, HIT)] * 4  # impacting-both
    # beam 1 leaves its stopper clearly; beam 2 stays hitting by hysteresis with p inside the band. Only
    # beam 1 changes, and its windows are clear: reported at the dwell's second window, not at max_dwell
    # (independent regime seed 1012 reported such a change 31 s late)
    labels, changes = decided(start + [(FREE, GRAZE)] * 6, cfg)
    assert changes == [4 + 1] and labels[-1] == "localized-2"
    # the beam that changes lingering inside the band is still no evidence: free after one clear window,
    # then p = 0.4 (free by hysteresis, unclear), so the change waits for max_dwell as before
    labels, changes = decided(start + [(0.25, HIT)] + [(0.4, HIT)] * 8, cfg)
    assert changes == [4 + 8 - 1] and labels[-1] == "localized-2"


def test_true_changes_ignore_flicker():
    codes = np.array([0] * 300 + [2, 0] * 20 + [2] * 300 + [3] * 50 + [2] * 300)
    tc = true_changes(codes, fs_hz=100.0, min_run_s=1.0)
    assert [(c.code, c.previous) for c in tc] == [(2, 0)]
    assert tc[0].t_departure_s == pytest.approx(2.99) and tc[0].t_s == pytest.approx(3.40)


def test_false_changes_are_split_by_whether_the_rig_held_the_regime():
    """At 100 Hz: free for 3 s, beam 1 alone for 0.5 s (samples 300-349: flicker, shorter than the 1 s a
    regime must last), then both for 5 s: one true change, free -> both at 3.5 s (departing at 2.99 s), reported
    at 4.0 s (0.5 s late). Six false reports, each judged on the samples its window's end covers, [t - 1 s, t):
    beam 1 at 3.0 s (samples 200-299: never held, the rig got there one sample later), at 3.2 s (held), at
    4.49 s (samples 349-448: held by sample 349 alone), at 5.0 s (400-499: never held, though the record holds
    it elsewhere); beam 2 at 6.0 s (never anywhere); both at 7.0 s (held: a return to the rig's regime)."""
    codes = np.array([0] * 300 + [1] * 50 + [3] * 500)
    windows = np.arange(1, 35) * 0.25
    labels = np.where(windows < 4.0, 0, 3)
    reports = [(3.0, 1), (3.2, 1), (4.0, 3), (4.49, 1), (5.0, 1), (6.0, 2), (7.0, 3)]
    sc = score_regimes(windows, labels, reports, codes, 100.0)
    assert [(c.previous, c.code) for c in sc.true_changes] == [(0, 3)]
    assert sc.latencies_s == (pytest.approx(0.5),)
    assert (sc.false_changes, sc.false_never_held, sc.reported_changes) == (6, 3, 7)


def test_the_wrong_beams_at_their_gap_are_counted_over_the_scored_windows_only():
    """At 100 Hz, free for 3 s then both beams hitting: the true change at 3 s opens [2.99 s, 4.0 s), whose
    windows are not scored. Windows every 0.5 s report free throughout, so from 4.0 s both beams are wrong in
    each (4.0-6.5 s: 6 windows, 12 beam-windows); beam 1's peak lies at 1.02 gaps (at its gap), beam 2's at
    1.2 (clearly beyond). The window at 3.5 s (inside the transition) is wrong too, and at its gap, but
    not scored; the windows before are right."""
    codes = np.array([0] * 300 + [3] * 400)
    truth = {"stoppers": [{"gap_eq_m": 1e-3}, {"gap_eq_m": 2e-3}]}
    beams = (NS(peak_displacement_m=1.02e-3), NS(peak_displacement_m=2.4e-3))
    windows = [NS(t_s=t, label="linear", beams=beams) for t in np.arange(1, 14) * 0.5]
    assert at_the_gap(CaseData(100.0, np.zeros((700, 3)), codes, truth), windows) == (12, 6)


def test_bad_config_and_input():
    with pytest.raises(ValueError, match="gap_m"):
        regime_start(RegimeConfig(gap_m=(1e-3, -1.0)))
    with pytest.raises(ValueError, match="window_s"):
        regime_start(RegimeConfig(window_s=0.1, hop_s=0.25))
    with pytest.raises(ValueError, match="shape"):
        RegimeMonitor().step(np.zeros((10, 2)))
    with pytest.raises(ValueError, match="NaN"):
        RegimeMonitor().step(np.full((10, 3), np.nan))


# --- the coupling's share of the other beam's distortion, learned from the stream ---

def test_the_coupling_share_is_the_streams_low_quantile_within_the_bound():
    cfg = RegimeConfig()
    rng = np.random.default_rng(3)
    n = CROSS_MIN_WINDOWS + 10
    ratios = rng.uniform(1e-3, 3e-3, n)
    near = np.column_stack([np.full(n, 10.0), ratios, np.full(n, np.nan)])  # no impact rows: the bound stays
    far = np.column_stack([np.full(n, 10.0 * np.exp(2 * CROSS_BAND)), np.full(n, 1e-6), np.full(n, 1e-6)])
    k = int(CROSS_QUANTILE * (n - 1))
    expected = CROSS_MARGIN[0] * np.sort(ratios)[k]
    assert _cross_talk(np.vstack([near, far]), 10.0, cfg) == (pytest.approx(expected, rel=1e-12),
                                                              cfg.cross_talk_impact)
    assert _cross_talk(near[:CROSS_MIN_WINDOWS - 1], 10.0, cfg) == (cfg.cross_talk, cfg.cross_talk_impact)
    # never above the configured bound, whatever the stream shows
    assert _cross_talk(np.column_stack([near[:, :1], near[:, 1:2] * 100, near[:, 2:]]), 10.0, cfg)[0] == cfg.cross_talk


def test_the_gap_says_nothing_between_the_free_and_the_hitting_amplitudes():
    cfg = RegimeConfig()
    free, hit = np.full(10, 1.0e-3), np.full(10, 2.0e-3)
    spread = 0.5 * np.log(2.0)
    assert _gap_evidence(1.5e-3, free, hit, cfg) == (pytest.approx(np.sqrt(2) * 1e-3), 0.0)
    assert _gap_evidence(0.9e-3, free, hit, cfg)[1] == pytest.approx(np.log(0.9) / spread)
    assert _gap_evidence(2.2e-3, free, hit, cfg)[1] == pytest.approx(np.log(1.1) / spread)
    assert _gap_evidence(0.3e-3, free, hit, cfg)[1] == -1.5  # clipped
    # no free amplitude learned yet: below the hitting ones free (down to -3), above them hitting (up to 1)
    nothing = np.zeros(0)
    assert _gap_evidence(1.8e-3, nothing, hit, cfg)[1] == pytest.approx(np.log(0.9) / 0.15)
    assert _gap_evidence(2.2e-3, nothing, hit, cfg)[1] == pytest.approx(np.log(1.1) / 0.15)
    assert _gap_evidence(3.0e-3, nothing, hit, cfg)[1] == 1.0
    # free amplitudes above the hitting ones: the learned sets disagree, no evidence above them
    assert _gap_evidence(3.0e-3, np.full(10, 2.5e-3), hit, cfg)[1] == 0.0


def two_tips(seconds, own1, c=4e-3, f=40.0, fs=FS, seed=0, own=9.0, own_deg=90.0, hit_deg=0.0):
    """Base, tip 1, tip 2 [m/s^2]: a sine drive; tip 2 hits (its odd harmonics a tenth of its fundamental's
    power, in the phase a stopper gives them: -sin 3 theta + sin 5 theta on a fundamental sin theta, the
    series of pulses at the acceleration's extremes); tip 1 carries the coupling's share c of tip 2's harmonic
    power in anti-phase (a free beam pulled through a spring above its first mode answers as a mass) and, from
    own1 on, harmonics of its own of ``own`` c of that power, ``own_deg`` degrees from tip 2's (90: the phase
    says nothing; 0: a contact). ``hit_deg`` turns tip 2's harmonics from the stopper's phase (0) to one that no
    stopper gives."""
    t = np.arange(int(seconds * fs)) / fs
    w = 2 * np.pi * f
    base = np.sin(w * t)
    theta = w * t - np.radians(100)  # lags the base: a passive beam above resonance
    fund = 20 * np.sin(theta)

    def harm(deg):  # two harmonics: 0.1 of the fundamental's power
        d = np.radians(deg)
        return np.sqrt(0.1 / 2) * 20 * (-np.sin(3 * theta + d) + np.sin(5 * theta + d))

    tip1 = fund - np.sqrt(c) * harm(hit_deg) + np.where(t < own1, 0.0, np.sqrt(own * c)) * harm(hit_deg + own_deg)
    noise = np.random.default_rng(seed).normal(0, 1e-3, (len(t), 3))
    return np.column_stack([base, tip1, fund + harm(hit_deg)]) + noise


def test_a_grazing_beam_beside_a_hitting_one_is_found_once_the_coupling_is_measured():
    """Tip 1 first carries 0.4 % of tip 2's harmonic power (the coupling), then 4 % (its own harmonics in
    quadrature with tip 2's, where their phase tells nothing): within the configured bound (5 %), so without
    the stream's measure of the coupling it is called free throughout; with it, the share removed is twice the
    measured 0.4 % and the excess (3.2 % of tip 2's harmonics, 3.2e-3 of tip 1's fundamental) calls beam 1
    hitting."""
    c = 4e-3
    x = two_tips(60.0, own1=30.0, c=c)
    windows, _ = run_monitor(x)
    early = [w for w in windows if 10 < w.t_s < 29]
    late = [w for w in windows if w.t_s > 32]
    assert all(w.label == "localized-2" for w in early)
    # the measured share: c (at 40 Hz the fundamental's leakage into the harmonic band is below 1e-6 of it)
    assert all(w.beams[0].cross_talk == pytest.approx(CROSS_MARGIN[0] * c, rel=0.01) for w in early + late)
    assert all(w.beams[0].distortion == pytest.approx((10 - CROSS_MARGIN[0]) * c * 0.1, rel=0.01) for w in late)
    assert all(w.label == "impacting-both" for w in late)
    # the same data from the second half on: nothing measured yet, the bound removes it all
    fresh, _ = run_monitor(two_tips(60.0, own1=0.0, c=c)[: int(10 * FS)])
    assert all(w.beams[0].cross_talk == RegimeConfig().cross_talk for w in fresh)
    assert all(w.label == "localized-2" for w in fresh if w.t_s > 1)


def test_a_grazing_beam_is_told_from_the_coupling_by_the_phase_of_its_third_harmonic():
    """From the start, nothing measured: tip 1's harmonics in phase with tip 2's are its own contact
    (none removed as the coupling's: its distortion is all of its 1.6 % of tip 2's harmonic power, 1.6e-3 of
    its fundamental's, within the bound of 5 % that would otherwise hide it) and beam 1 is called hitting;
    harmonics in anti-phase (0.4 %) are what the coupling carries into a free beam, and the bound removes
    them."""
    c = 4e-3
    carried = two_tips(10.0, own1=0.0, c=c, own=0.0)  # 0.4 % of tip 2's power in anti-phase
    windows, _ = run_monitor(carried)
    assert all(w.label == "localized-2" for w in windows)
    # removed as the coupling's: the bound, then (from 20 windows on) twice the share the stream measured
    assert all(w.beams[0].cross_talk in (RegimeConfig().cross_talk, pytest.approx(CROSS_MARGIN[0] * c, rel=0.01))
               for w in windows)
    # in phase: the carried -sqrt(c) and the own 3 sqrt(c) make (3 - 1)^2 c = 4 c of tip 2's harmonic power
    contact = two_tips(10.0, own1=0.0, c=c, own=9.0, own_deg=0.0)
    windows, _ = run_monitor(contact)
    assert starting(windows).label == "impacting-both"  # the starting regime
    # (a single window's phase counts for at most PHASE_Z deviations: the rule needs two, so the first
    # window, provisional, still has the bound removed)
    decided = [w for w in windows if not w.provisional]
    assert all(w.label == "impacting-both" and w.beams[0].cross_talk == 0.0 for w in decided)
    assert all(w.beams[0].distortion == pytest.approx(4 * c * 0.1, rel=0.01) for w in decided)


def test_the_in_phase_component_and_its_noise():
    """_in_phase against hand-computed numbers: beam 1's third harmonic 2 at 60 degrees from beam 2's (whose
    sign is flipped), less the base's 0.1; the noise variance half the phasor's noise power; nothing where
    beam 2's third harmonic does not stand PHASE_REFERENCE times above its noise."""
    h = np.zeros((3, 3), complex)
    h[2] = [0.1j, 2 * np.exp(1j * np.radians(60)), -5.0]  # base, tip 1, tip 2 (tip 2 mounted the other way up)
    floor = [1e-6, 1e-6, 1e-6]
    c, v = _in_phase(h, (1, -1), 0, floor, 4.0)
    assert c == pytest.approx(2 * np.cos(np.radians(60)) - 0.1, rel=1e-12)
    assert v == pytest.approx(0.5 * 4.0 * 1e-6, rel=1e-12)
    assert _in_phase(h, (1, -1), 0, [1e-6, 1e-6, 25.0 / (PHASE_REFERENCE * 4.0)], 4.0) == (0.0, 0.0)
    # the sum over recent windows against PHASE_Z deviations of its noise
    assert PHASE_Z * np.sqrt(0.02) < 2.0 and _own_contact(((1.0, 0.01), (1.0, 0.01)))  # 2 against 4 x 0.14
    assert not _own_contact(((0.1, 0.01), (0.1, 0.01), (0.1, 0.01)))
    assert not _own_contact(((0.0, 0.0),))


def test_one_windows_burst_alone_is_no_own_contact():
    """Each window counts for at most PHASE_Z deviations, so three windows (PHASE_Z sqrt(3) = 6.9 needed)
    need evidence in two of them. Independent regime seed 6008 at the onset of beam 1's contact: beam 2's
    in-phase component at -0.2, 53.2 and 1.3 deviations in three windows, a sum of 54 that made it "hitting"
    for three windows; capped 5.3."""
    sd = 0.1
    onset = tuple((z * sd, sd**2) for z in (-0.2, 53.2, 1.3))
    assert sum(c for c, _ in onset) > PHASE_Z * np.sqrt(3 * sd**2)  # the plain sum would call it contact
    assert not _own_contact(onset)
    assert _own_contact(tuple((z * sd, sd**2) for z in (2.5, 2.5, 2.5)))  # a grazing beam: 7.5 deviations
    assert _own_contact(tuple((z * sd, sd**2) for z in (40.0, 30.0, 0.0)))  # two windows of a contact: 8
    assert not _own_contact(tuple((z * sd, sd**2) for z in (40.0, -1.5, 0.0)))  # one: 2.5


@pytest.mark.parametrize("sides", ["both", "one"])
def test_a_stoppers_third_harmonic_lies_in_the_clipping_phase_of_the_fundamental(sides):
    """_clipping on a beam's relative acceleration on a stiff stopper (the spring's force k (z - g) beyond the gap on
    one side or both, z = cos theta): the component is the waveform's third Fourier coefficient in the direction of
    the fundamental's cube, computed here by quadrature on the unshifted waveform, whatever phase the motion has
    against the window (the phasors from the monitor's own spectral features); a third harmonic in anti-phase (a
    free beam answering the coupling as a mass) is negative; a fundamental alone gives nothing."""
    fs, f, k, g = 2000.0, 10.0, 40.0, 0.8
    theta = np.linspace(0.0, 2 * np.pi, 4096, endpoint=False)

    def rel_acc(th):  # z = cos th: a = -z w^2 - k (z - g)+ [- k (z + g)- on both sides], per w^2
        z = np.cos(th)
        push = np.where(z > g, z - g, 0.0) + (np.where(z < -g, z + g, 0.0) if sides == "both" else 0.0)
        return -z - k * push

    a = rel_acc(theta)
    a1 = 2 * np.mean(a * np.cos(theta))  # both negative: the fundamental and the stopper's pulses at the peaks
    a3 = 2 * np.mean(a * np.cos(3 * theta))
    assert a1 < 0 and a3 < 0  # even in theta: no sine terms
    assert np.allclose([np.mean(a * np.sin(theta)), np.mean(a * np.sin(3 * theta))], 0, atol=1e-12)
    t = np.arange(int(2.0 * fs)) / fs
    for phase in (0.0, 1.0, 2.5):
        tip = rel_acc(2 * np.pi * f * t + phase)
        x = np.column_stack([np.zeros_like(t), tip, np.zeros_like(t)])
        x[:, 0] = 1e-3 * np.sin(2 * np.pi * f * t)  # a base that sets the drive frequency, far below the tip
        sp = spectral_features(x, fs)
        h = sp.harmonics.copy()
        h[:, 0] = 0.0  # the base's own phasors removed: the tip's relative motion is the tip's here
        c, v = _clipping(h, (1, 1), 0, [1.0, 1.0, 1.0], sp.phasor_scale)
        scale = abs(h[0, 1]) / abs(a1)  # the phasors' normalisation
        assert c == pytest.approx(abs(a3) * scale, rel=1e-3)
        assert v == pytest.approx(0.5 * sp.phasor_scale, rel=1e-12)
        h[2, 1] = -h[2, 1]  # the same harmonic in anti-phase
        assert _clipping(h, (1, 1), 0, [1.0, 1.0, 1.0], sp.phasor_scale)[0] == pytest.approx(-c, rel=1e-12)
        h[2, 1] = 0.0
        assert _clipping(h, (1, 1), 0, [1.0, 1.0, 1.0], sp.phasor_scale)[0] == 0.0


@pytest.mark.parametrize("hit_deg", [0.0, 90.0, 180.0])
def test_only_a_window_in_the_clipping_phase_is_learned_as_a_hitting_amplitude(hit_deg):
    """The learning gate: tip 2 distorts strongly (its harmonics a tenth of its fundamental's power) in steady
    windows, but its amplitude is learned as a hitting one only where its third harmonic lies in the phase a
    stopper gives it (0 degrees); in quadrature (90) or anti-phase (180) it is ringing or the coupling, which no
    stopper makes, and nothing is learned (fresh seed 6012: a start's ringing learned as hitting held a free beam
    "hitting" for 6 s). What is learned is the relative amplitude |tip - base| / omega^2 of the drive's
    fundamental: 20 at 100 degrees behind a base of 1, at 40 Hz."""
    mon = RegimeMonitor(RegimeConfig(fs_hz=FS))
    windows, _ = mon.step(two_tips(20.0, own1=99.0, hit_deg=hit_deg))
    assert all(w.beams[1].significant for w in windows)  # tip 2 distorts clearly in every window
    assert len(mon.state.hit_z[0]) == 0  # tip 1 is free
    learned = mon.state.hit_z[1]
    if hit_deg == 0.0:
        expected = abs(20 * np.exp(-1j * np.radians(100)) - 1) / (2 * np.pi * 40.0) ** 2
        assert len(learned) > 0.9 * len(windows)
        assert learned == pytest.approx(np.full(len(learned), expected), rel=1e-3)
    else:
        assert len(learned) == 0


def test_the_envelope_is_the_change_of_amplitude_between_the_window_halves():
    """A 40 Hz sine whose amplitude steps from 1 to 1.5 at the middle of a half-second window (ten periods in
    either half): the envelope is log 1.5; a steady sine's is zero."""
    t = np.arange(int(0.5 * FS)) / FS
    sine = np.sin(2 * np.pi * 40.0 * t)
    step = np.where(t < 0.25, 1.0, 1.5) * sine
    assert spectral_features(np.column_stack([step] * 3), FS).envelope == pytest.approx(np.log(1.5), rel=1e-6)
    assert spectral_features(np.column_stack([sine] * 3), FS).envelope == pytest.approx(0.0, abs=1e-9)


@pytest.mark.parametrize("n_windows, n", [(1, 1000), (2, 1000), (3, 251), (40, 500)])
def test_the_halves_phasors_are_numpys_bit_for_bit(n_windows, n):
    """The compiled phasors of the window halves give the numpy expression they replace, bit for bit (the
    envelope compares them against a threshold): the halves' Hann windows on the fundamental's basis,
    einsum's products and sums, the mean removed as numpy's."""
    rng = np.random.default_rng(n_windows)
    xs = rng.standard_normal((n_windows, n, 3)) * [1.0, 30.0, 0.01] + [5.0, -2.0, 0.3]
    f = rng.uniform(5.0, 40.0, n_windows)
    basis = np.exp(-2j * np.pi * f[:, None, None] * np.arange(1, 4)[:, None] * np.arange(n) / FS)  # (W, 3, n)
    m = n // 2
    centred = xs - xs.mean(axis=1, keepdims=True)
    want = [np.einsum("wt,wtc->wc", basis[:, 0, k:k + m] * np.hanning(m), centred[:, k:k + m]) for k in (0, m)]
    got = _half_phasors(xs, basis, np.hanning(m))
    for h in (0, 1):
        np.testing.assert_array_equal(got[h].view(float), want[h].view(float))


def test_a_free_beam_beside_a_hitting_one_is_free_where_the_harmonics_reach_the_second_modes():
    """Independent regime seed 3022 (coupling 7.9 %, beam 2 on a stiff one-sided stopper, beam 1 free), the
    drive at 7.6 Hz: its tenth harmonic sits on the beams' second modes (74 and 76 Hz), which are alike and
    carry 10 % of beam 2's power in [1.5 f, 10.5 f] into beam 1; counted as harmonics, beyond the 5 % the
    coupling may carry there, it called beam 1 hitting in every window. From the fifth harmonic on the
    bands belong to the higher modes (see the module's docstring): beam 1 is free throughout."""
    from daq.sim.independent.regimes import steady_case

    case = steady_case(3022, "beam2", minutes=0.5, fs_hz=1000)
    assert case.truth["regime_share"]["beam2"] == 1.0
    sc, windows = scored(case)
    assert sc.reported_changes == 0 and sc.share_right == 1.0
    assert all(w.label == "localized-2" for w in windows)


def sine_rig(f_hz, seconds=20.0, fs=1000.0):
    """Base and two free tips driven by one sine (a linear rig: the sine alone, with 1 % sensor noise)."""
    t = np.arange(int(seconds * fs)) / fs
    x = np.column_stack([np.sin(2 * np.pi * f_hz * t), 10 * np.sin(2 * np.pi * f_hz * t - np.pi / 2),
                         8 * np.sin(2 * np.pi * f_hz * t - 1.2)])
    return x + np.random.default_rng(0).normal(0, 0.01, x.shape)


@pytest.mark.parametrize("f_hz", [5.3, 6.5, 7.6, 9.2])
def test_a_window_too_short_for_the_drive_is_said_and_a_longer_one_sees_a_linear_rig(f_hz):
    """A sine-driven linear rig. In a 0.5 s window a pure sine's Hann leakage puts into the harmonic band more
    than the distortion threshold below 3.6 periods (numpy's FFT of the window, computed here): a free beam at
    5.3 or 6.5 Hz reads as hitting. The pipeline says so once, after 2 s, with the window that holds 3.6
    periods; in that window the rig is linear throughout."""
    n = 500
    t = np.arange(n) / 1000.0
    x = np.sin(2 * np.pi * f_hz * t + 0.3)
    p = np.abs(np.fft.rfft((x - x.mean()) * np.hanning(n), 4 * n)) ** 2
    nu = np.fft.rfftfreq(4 * n, 1e-3)
    leak = p[(nu >= 1.5 * f_hz) & (nu < 5.5 * f_hz)].sum() / p[(nu >= 0.5 * f_hz) & (nu < 1.5 * f_hz)].sum()
    short = f_hz * 0.5 < MIN_PERIODS
    assert (leak > RegimeConfig().distortion_on) == short
    pipe = Pipeline(PipelineConfig(fs_hz=1000.0, identify=False, regime=RegimeConfig(fs_hz=1000.0)))
    out = pipe.step(sine_rig(f_hz))
    assert all(w.periods == pytest.approx(f_hz * 0.5, rel=0.02) for w in out.windows[2:])
    notes = [e for e in out.events if e["kind"] == "regime_note"]
    if not short:
        assert notes == [] and all(w.label == "linear" for w in out.windows)
        return
    assert len(notes) == 1 and notes[0]["t"] == pytest.approx(SLOW_WINDOWS * 0.25 + 0.25)
    assert "--regime-window 1 or more" in notes[0]["message"]
    # what the note warns of: a free beam reads as hitting (at 6.5 Hz one of the two since the fundamental's
    # leakage is taken out of the third harmonic's phasor; the band powers still hold it)
    assert out.windows[-1].label != "linear"
    windows, changes = RegimeMonitor(RegimeConfig(fs_hz=1000.0, window_s=1.0)).step(sine_rig(f_hz))
    assert changes == [] and all(w.label == "linear" for w in windows)


@pytest.mark.parametrize("periods", [3.8, 4.3, 6.1])
def test_a_pure_sine_leaves_no_third_harmonic_phasor_once_its_leakage_is_taken_out(periods):
    """A pure sine's projection on its third harmonic through a Hann window of a few periods is not zero (the
    window's transform 2 and 4 harmonics away); the phasor at 3 f comes out without that leakage, while a
    true third harmonic is kept. Computed here from the definition: the projection of the windowed sine,
    its mean removed, on exp(-2 pi i n f t). What is left of the leakage (about 2 %) comes from the drive
    frequency, which the monitor reads off the spectrum's peak."""
    fs, n = 1000.0, 500
    f = periods / (n / fs)
    t = np.arange(n) / fs
    sine = np.sin(2 * np.pi * f * t + 0.7)
    w = np.hanning(n)
    raw = 2 * np.sum(w * (sine - sine.mean()) * np.exp(-2j * np.pi * 3 * f * t)) / w.sum()
    assert abs(raw) > 1e-4  # the leakage the monitor took for a third harmonic
    c = np.array([1.0 + 2.0j, -0.5j])  # the closed form against the projection of the windowed sinusoids
    s = (c[None, :] * np.exp(2j * np.pi * f * t)[:, None]).real
    direct = 2 * (np.exp(-6j * np.pi * f * t) @ ((s - s.mean(axis=0)) * w[:, None])) / w.sum()
    assert _leakage(c, 2 * np.pi * f / fs, n, w.sum()) == pytest.approx(direct, rel=1e-9)
    x = np.column_stack([sine, 10 * sine, 10 * sine + 0.05 * np.sin(2 * np.pi * 3 * f * t + 0.2)])
    sp = spectral_features(x, fs)
    assert sp.f_hz == pytest.approx(f, rel=1e-3)
    assert np.max(np.abs(sp.harmonics[2, :2] / sp.harmonics[0, :2])) < 0.05 * abs(raw)
    # the true third harmonic of tip 2, 0.05 at phase 0.2 - pi/2 (a sine's phasor), within 2 % (its own image and
    # the drive frequency read off the peak; it was measured within 1.1 %)
    assert sp.harmonics[2, 2] == pytest.approx(0.05 * np.exp(1j * (0.2 - np.pi / 2)), abs=0.02 * 0.05)
