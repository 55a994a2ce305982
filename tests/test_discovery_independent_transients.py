"""Discovery on data this project's model did not make (the independent generator, importing nothing
from ``ident``), one generated case per test: records with a transient the measured input did not make
(unmeasured blows on a shaken rig) and records that are one (a hammer hit and its free decay). The other
cases with a test of their own are in ``test_discovery_independent_seeds.py`` (the baseline and its
linear part, the signs) and ``test_discovery_independent_lookalikes.py`` (which candidate is named); the
three files are one theme each and run on separate workers.

Seed 34 is a base-driven rig with nothing hidden and one unmeasured blow on beam 2 at 19.65 s; seed 12
another with two blows on beam 1, 3.5 s apart; seeds 31, 41, 64, 66, 93, 158, 197, 749 and 970 clamped-clamped
beams (membrane stretching) hit by a hammer, one velocity sensor each (and 925 in the long tier).
"""

from dataclasses import replace

import numpy as np
import pytest
from scipy.signal import butter, hilbert, sosfiltfilt

from discovery_verdicts import cubic_found
from daq.sim.independent.cases import discovery_case
from ident.cli.bench_discovery import independent_case, judge
from ident.discovery import discover, search
from ident.discovery.baselines.modal import ModalBaseline
from ident.discovery.search import block_errors
from ident.discovery.split import Split


def test_a_blow_is_left_out_and_the_baseline_fitted_with_its_free_response():
    # issue 10, point 5: a transient the measured input cannot make is found, the blocks it reaches are
    # left out of scoring, and a modal baseline fitted to the record is fitted again with a free response
    # from the blow on (it had fitted the blow's ringing as if the input had made it)
    generated = discovery_case(34)
    c = independent_case(34, generated)
    (blow,) = generated.truth["unmeasured_blows"]  # the generator's own record: 19.65 s, on beam 2
    d = discover(c.measurement)
    assert c.cause == "none" and not d.findings
    assert len(d.transients_s) == 1 and abs(d.transients_s[0] - blow["time_s"]) < 0.03  # 19.631 s
    assert d.prep.blows and any("free response from each blow on" in n for n in d.notes)
    assert d.split.excluded and all(k not in d.split.train for k in d.split.excluded)
    # the same blocks fitted without the blow's free response predict the held-out blocks worse (held-out
    # NRMSE 0.056 against 0.031)
    prep, split = d.prep, d.split
    fitted_on = Split(split.blocks, split.held_out).rows("train")
    plain = ModalBaseline.fit(replace(prep, blows=()), fitted_on, poles0=d.baseline.model.poles)
    scale = np.maximum(prep.measured[split.rows("test")].std(axis=0), 1e-300)
    _, e_plain = block_errors(plain, plain.model, prep, split.test, d.warm, scale)
    _, e_free = block_errors(d.baseline, d.baseline.model, prep, split.test, d.warm, scale)
    assert e_free == pytest.approx(d.baseline_test_nrmse)
    assert e_free < 0.75 * e_plain


def test_two_blows_on_a_linear_rig_are_found_and_nothing_else():
    # independent seed 12: nothing hidden, blows on beam 1 at 16.80 s and 20.32 s (the second within the
    # first's ringing). The earlier detector found neither (it asked a burst to be the largest for 10 s
    # after it and the error to be settled 10 to 20 s later) and the blows' ringing made an "ambiguous"
    # quadratic stiffness or damping (gain 0.05-0.09)
    generated = discovery_case(12)
    c = independent_case(12, generated)
    blows = sorted(b["time_s"] for b in generated.truth["unmeasured_blows"])
    d = discover(c.measurement)
    assert c.cause == "none" and not d.findings, d.verdict()
    assert len(d.transients_s) == 2
    assert np.all(np.abs(np.sort(d.transients_s) - blows) < 0.03)  # 16.786 and 20.315 s


def test_a_hammer_record_that_starts_at_the_hit_gets_a_baseline_and_its_cubic():
    # independent seed 197: a clamped-clamped beam hit 2.9 ms into a 7.5 s record at 10 kHz, one velocity
    # sensor, the force channel zero after the hit. The drive had the hit's mean and trend taken out, a
    # steady force each block's simulation met as a step: the baseline held out 7.8 times worse than
    # predicting zero and nothing was found. The coefficient was 8.7 % off; since the record's input gain is
    # fitted with the record at rest before its hit (stop 68), its first block is simulated through the hit,
    # the loudest part of the decay, and it was 16.7 % off. Its held-back blocks lie in the quiet after the
    # decay, so the first fit's order is chosen on the decay (stop 69): the beam's second mode (365.7 Hz)
    # joins the baseline, and the coefficient is 1.1 % off
    d, eq = cubic_found(197, rel=0.1)  # 1.1 %
    assert d.prep.transient and d.baseline_test_nrmse < 0.3
    f = np.sort(d.baseline.model.frequencies_hz)
    assert f.size == 2 and f[0] == pytest.approx(eq["natural_frequency_hz"], rel=0.02)


def test_a_hammer_record_at_rest_gets_its_input_gain_from_the_hit_and_its_cubic():
    # the clamped-clamped family's seed 12 (``--family cc_beam``): a beam at 120.4 Hz hit 9.5 ms into its
    # record, one velocity sensor. The hit lies before the fit's first row; with an initial state fitted, the
    # modal model's input gain was not: its first training block, simulated from rest through the hit, made
    # 268 times the measured response and nothing was found. The record is still before its hit, so it has
    # no initial state: that block 0.91 times (the linear part under a hardening decay), the cubic found,
    # its coefficient 9.1 % off the generator's one-mode equivalent
    d, _ = cubic_found(12, rel=0.15, family="cc_beam")
    assert d.prep.rest_until is not None
    first = d.split.blocks[0]
    y = search.predict(d.baseline, d.baseline.model, d.prep, first, d.warm)
    ratio = np.sqrt(np.mean(y**2)) / np.sqrt(np.mean(d.prep.measured[first] ** 2))
    assert 0.7 < ratio < 1.3


def test_a_hardening_hammer_decay_on_one_sensor_gets_one_mode_and_its_cubic():
    # independent seed 31: a clamped-clamped beam (membrane stretching) hit by a hammer, one velocity
    # sensor. Its decay glides in frequency with amplitude (3 % at the hit); without the rule that two modes
    # closer than their bandwidths on one response are one gliding mode, the order search keeps four modes
    # and a Coulomb friction is named (gain 0.50)
    generated = discovery_case(31)
    c = independent_case(31, generated)
    eq = generated.truth["equivalent"]
    d = discover(c.measurement)
    assert d.baseline.model.poles.size == 1
    v = judge(c, d, 0.0)
    assert v.right and v.extra == 0, d.verdict()
    f = d.findings[0]
    # the linear part refitted with the cubic force in place is the beam's first mode: 167.72 / 167.74 Hz,
    # 0.222 / 0.213 % damping
    (pole,) = f.baseline.model.poles
    f0 = eq["natural_frequency_hz"]
    assert abs(pole) / (2 * np.pi) == pytest.approx(f0, rel=0.005)
    assert -pole.real / abs(pole) == pytest.approx(eq["damping_ratio"], rel=0.10)
    # 0.77 over a baseline no longer driven by the force channel's noise between hits (0.94 before the force
    # window, stop 67)
    assert f.gain > 0.7 and f.own_gain > 0.5
    # the record's own backbone (the frequency at the first mode's amplitude A over the decay,
    # f = f0 (1 + 3/8 k3 A^2 / w0^2), read off the analytic signal of the band-passed velocity) is the
    # generator's one-mode equivalent (6.65e11 against 6.67e11 per kg); the coefficient found is 7.22e11
    k3 = _backbone_k3(c.measurement.responses[0].values, c.measurement.fs_hz, f0,
                      generated.truth["structure"]["hit_time_s"])
    assert k3 == pytest.approx(eq["k3_per_mass"], rel=0.05)
    assert f.parameters["coefficient_per_mass"] == pytest.approx(eq["k3_per_mass"], rel=0.15)


def test_a_gliding_decays_baseline_keeps_the_mode_its_first_fit_resolved():
    # independent seed 64: a clamped-clamped beam hit by a hammer, one velocity sensor. The first fit finds
    # the beam's mode (185.96 Hz at 0.229 %; the beam's 185.84 Hz at 0.229 %); refined on the training
    # blocks' glide (195 -> 186 Hz) it went to 191.5 Hz at zeta 5e-27, a sinusoid the record cannot resolve,
    # the baseline held out 11.5 times worse than predicting zero and a stopper was named (gain 0.96)
    d, eq = cubic_found(64, rel=0.15)  # 7.8 %
    (pole,) = d.baseline.model.poles
    assert abs(pole) / (2 * np.pi) == pytest.approx(eq["natural_frequency_hz"], rel=0.005)
    assert -pole.real / abs(pole) == pytest.approx(eq["damping_ratio"], rel=0.10)


def test_a_band_search_that_splits_a_gliding_decays_mode_is_not_taken():
    # independent seed 93: a clamped-clamped beam (166.3 Hz, 0.22 %) hit by a hammer, one velocity sensor.
    # The first fit finds the beam's mode; the order searched again in the modes' band came out as 167.2 Hz
    # undamped beside 168.6 and 169.5 Hz, one gliding mode split in three, and was taken: the undamped line
    # rang on through the record's quiet tail, the baseline held out 1.9 times worse than predicting zero,
    # and nothing was found. Not taken, the baseline is the beam's mode and its cubic is found (0.6 % off)
    d, eq = cubic_found(93, rel=0.1)
    (pole,) = d.baseline.model.poles
    assert abs(pole) / (2 * np.pi) == pytest.approx(eq["natural_frequency_hz"], rel=0.005)
    assert d.baseline_test_nrmse < 1.0


def test_a_gliding_pair_in_the_first_fit_leaves_its_lighter_mode():
    # independent seed 41: a clamped-clamped beam (184.9 Hz, 0.35 %) hit by a hammer, one velocity sensor.
    # The first fit's last refinement made the beam's mode a pair, 185.5 Hz at 1.08 % (the decay's loud,
    # fast-fading start) and 184.9 Hz at 0.34 % (its tail); both went on to the band's fit, which kept a pair,
    # and the cubic's coefficient came out 90 % off. The lighter of a gliding pair is the mode at small
    # amplitude: with it alone the baseline's mode is within 1 % and the coefficient within 10 % (4.5 %)
    d, eq = cubic_found(41, rel=0.1)
    f = np.sort(d.baseline.model.frequencies_hz)
    assert f.size == 2 and f[0] == pytest.approx(eq["natural_frequency_hz"], rel=0.01)  # and 511.8 Hz


def test_a_hammer_decay_inside_the_first_bands_edge_keeps_its_beams_first_mode():
    # independent seed 158: a clamped-clamped beam (174.3 and 480.6 Hz) hit 4.5 ms into a 5.4-s record at
    # 10 kHz, one velocity sensor at the hit. The first fit's preliminary band has a band-pass edge of 0.54 s,
    # by when the decay is gone: it saw the quiet alone, every order predicted its held-back blocks as well
    # as zero, and it kept 480.5 Hz; the band was set above the first mode, and the cubic came out on the
    # second, 7.2 times the generator's one-mode equivalent. The decay from the hit on gives both modes; the
    # cubic is per mass of the first, 32 % off (the target is 10 %)
    d, eq = cubic_found(158, rel=0.4)
    f = np.sort(d.baseline.model.frequencies_hz)
    assert f.size == 2 and f[0] == pytest.approx(eq["natural_frequency_hz"], rel=0.01)
    second = discovery_case(158).truth["structure"]["natural_frequencies_hz"][1]  # 480.6 Hz
    assert f[1] == pytest.approx(second, rel=0.01)
    assert d.per_mass_mode_hz(d.findings[0]) == pytest.approx(eq["natural_frequency_hz"], rel=0.01)


def test_a_weaker_hardening_decay_gets_its_cubic_and_its_coefficient():
    # independent seed 66: a clamped-clamped beam hit by a hammer, one velocity sensor, 0.78 % damping:
    # the cubic leads (held-out gain 0.94) a quadratic stiffness (0.82) by more than the paired test's
    # spread, and its coefficient is the generator's one-mode equivalent within 11 % (4.54e11 against
    # 4.08e11 per kg; the record's own backbone says 4.18e11)
    generated = discovery_case(66)
    c = independent_case(66, generated)
    d = discover(c.measurement)
    v = judge(c, d, 0.0)
    assert v.right and v.extra == 0 and d.ambiguous == [[]], d.verdict()
    f = d.findings[0]
    assert f.parameters["coefficient_per_mass"] == pytest.approx(generated.truth["equivalent"]["k3_per_mass"],
                                                                 rel=0.15)
    quadratic = [x for x in d.candidates if x.cause == "quadratic_stiffness"]
    assert quadratic and max(x.gain for x in quadratic) < f.gain


def _backbone_k3(velocity: np.ndarray, fs: float, f0: float, hit_s: float) -> float:
    """A hardening cubic per unit mass from a free decay's backbone (first-order Duffing), at 0.05, 0.1
    and 0.2 s after the hit."""
    sos = butter(4, [0.6 * f0, 1.6 * f0], "bandpass", fs=fs, output="sos")
    a = hilbert(sosfiltfilt(sos, velocity))
    f = np.gradient(np.unwrap(np.angle(a))) * fs / (2 * np.pi)
    amp = np.abs(a) / (2 * np.pi * f)
    w0 = 2 * np.pi * f0
    out = []
    for t in (0.05, 0.1, 0.2):
        w = slice(int((hit_s + t) * fs), int((hit_s + t + 0.01) * fs))
        out.append((np.median(f[w]) / f0 - 1) * w0**2 * 8 / (3 * np.median(amp[w]) ** 2))
    return float(np.median(out))


def test_a_hammer_decays_backbone_weighs_a_cubic_that_beats_the_baseline_but_not_its_own_linear_part():
    # independent seed 749: a clamped-clamped beam hit by a hammer, one velocity sensor at 10 kHz. The cubic
    # beats the baseline (0.067 at p = 1e-4 over the blocks) but not its own refitted linear part in the
    # typical piece (p = 0.16), so the quadratic stiffness (0.049) was the one significant stiffness law and
    # the answer "ambiguous: quadratic stiffness or contact" (stop 84). The decay's backbone follows the
    # cubic's shape (0.03 Hz RMS off its best line) and neither the quadratic's (0.16 Hz) nor the stopper's
    # (0.19 Hz): a law that passes the paired test against the baseline is now weighed by it
    generated = discovery_case(749)
    c = independent_case(749, generated)
    d = discover(c.measurement)
    v = judge(c, d, 0.0)
    assert v.right and v.extra == 0, d.verdict()
    f = d.findings[0]
    settings = search.Settings()
    assert f.p_value < settings.alpha and not search.significant(f, settings)
    quadratic = [x for x in d.candidates if x.cause == "quadratic_stiffness" and search.significant(x, settings)]
    assert quadratic
    assert any("backbone" in n and "contact, quadratic_stiffness set aside" in n for n in d.notes), d.notes
    # the generator's one-mode equivalent within 20 % (17 % off: the issue asks for 10 %)
    assert f.parameters["coefficient_per_mass"] == pytest.approx(generated.truth["equivalent"]["k3_per_mass"],
                                                                 rel=0.20)


def test_a_decays_backbone_sets_a_law_aside_by_a_test_that_counts_its_points():
    # independent seed 970: a clamped-clamped beam (126.2 Hz) hit by a hammer, one velocity sensor. The cubic
    # beats the baseline (0.27 at p = 6e-13), and a quadratic stiffness (0.18) is significant in every test.
    # The decay's backbone (14 points) follows the cubic's shape at 0.11 Hz RMS and the quadratic's at
    # 0.25 Hz: 2.3 times, under the fixed ratio of 3 asked before stop 92, so the quadratic stiffness was
    # named; F(12, 12) at 95 % asks 1.64 times. Over all held-out pieces the cubic did not beat its own linear
    # part (p = 0.62); over the pieces that move above the noise (stop 93) it does (gain 0.07, p = 0.008)
    d, _ = cubic_found(970, rel=0.10)  # 3.0 %
    (note,) = [n for n in d.notes if "backbone" in n]
    assert "quadratic_stiffness set aside" in note, note
    bb = d.characterisation["v1"]["backbone"]
    assert len(bb["frequency_hz"]) == 14
    settings = search.Settings()
    assert any(x.cause == "quadratic_stiffness" and search.significant(x, settings) for x in d.candidates)
    f = d.findings[0]
    assert search.significant(f, settings) and f.own_p < settings.alpha


@pytest.mark.long
def test_a_decays_pieces_of_noise_alone_do_not_outvote_the_pieces_that_move():
    # independent seed 925: a clamped-clamped beam hit by a hammer, one velocity sensor, a membrane cubic. 196
    # of its 235 held-out pieces hold the sensor's noise alone; over all of them the cubic's signed-rank p
    # against the baseline was 0.14 (the t-test's 2e-4), and a quadratic stiffness (0.38, p = 0.09) was
    # named. Over the 39 pieces that move (``search.moving_pieces``) the cubic is significant, and the
    # decay's backbone names it
    d, _ = cubic_found(925, rel=0.10)  # 4.3 %
    f = d.findings[0]
    assert d.baseline_block_errors.size > 200
    assert search.signed_rank_p(d.baseline_block_errors, f.block_errors) > search.Settings().alpha > f.p_value
