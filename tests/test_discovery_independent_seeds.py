"""Discovery on data this project's model did not make (the independent generator, importing nothing
from ``ident``), one generated case per test; the four cases the tests share are in
``test_discovery_independent.py``.

Seed 34 is a base-driven rig with nothing hidden and one unmeasured blow on beam 2 at 19.65 s; seed 12
another with two blows on beam 1, 3.5 s apart; seed 47 a strongly hardening Duffing oscillator (26.2 Hz,
1 % damping, displacement out) under an odd multisine; seeds 31 and 66 clamped-clamped beams (membrane
stretching) hit by a hammer, one velocity sensor each.
"""

import sys
from dataclasses import replace

import numpy as np
import pytest
from scipy.signal import butter, hilbert, sosfiltfilt
from threadpoolctl import threadpool_limits

from discovery_fit import fitted_as_discover
from daq.sim.independent.cases import discovery_case
from ident.cli.bench_discovery import driving_sign, independent_case, judge
from ident.discovery import discover, search
from ident.discovery.baselines import modal
from ident.discovery.baselines.modal import ZETA_MAX, ModalBaseline, bounded
from ident.discovery.search import block_errors, compensation, simulation_bound
from ident.discovery.signals import prepare
from ident.discovery.split import Split

D = sys.modules["ident.discovery.discover"]  # the module: the package exports its function by that name


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


def test_a_strong_cubic_is_found_where_the_linear_fit_explains_a_fifth_of_the_motion():
    # independent seed 47: the modal baseline (28.6 Hz, 2.2 % damping) leaves a fit error of 0.81; refitted
    # from there together with the cubic force, the linear part stopped at 24.6 Hz with 10 % damping and
    # the cubic predicted worse than the baseline ("nothing found"). The refit now also starts from the
    # modes of the underlying linear FRF, the cubic force conditioned out (miso_frf)
    generated = discovery_case(47)
    c = independent_case(47, generated)
    eq = generated.truth["equivalent"]
    d = discover(c.measurement)
    v = judge(c, d, 0.0)
    assert v.right, d.verdict()
    f = d.findings[0]
    assert f.parameters["coefficient_per_mass"] == pytest.approx(eq["k3_per_mass"], rel=0.05)  # 1 %
    (pole,) = f.baseline.model.poles
    assert abs(pole) / (2 * np.pi) == pytest.approx(eq["natural_frequency_hz"], rel=0.02)  # 26.29 / 26.22
    assert -pole.real / abs(pole) == pytest.approx(eq["damping_ratio"], rel=0.15)  # 1.07 % / 1.05 %
    assert f.gain > 0.5


def test_a_cubic_that_acts_only_in_training_blocks_is_found_by_them():
    # independent seed 140: a hardening Duffing oscillator (33.39 Hz, 1.8 % damping, displacement out) under
    # a stepped sine that jumps in blocks 5 and 6 of 20, both training blocks. The baseline fitted through
    # the jump (36.4 Hz) holds out 0.78; the cubic, refitted with its linear part, gains 0.82 on held-out
    # blocks, all of it its linear part's there: the held-out rule alone named the quadratic stiffness
    # instead (0.77, most of it over its own, worse linear part). Over the training blocks the cubic's
    # linear part alone has several times its error (``search._own_gain_trained``)
    generated = discovery_case(140)
    c = independent_case(140, generated)
    eq = generated.truth["equivalent"]
    d = discover(c.measurement)
    scale = np.maximum(d.prep.measured[d.split.rows("test")].std(axis=0), 1e-300)
    base, _ = block_errors(d.baseline, d.baseline.model, d.prep, d.split.blocks, d.warm, scale)
    worst = np.argsort(base)[::-1][:2]  # the jump's two blocks (errors 4.8 and 2.5; the rest at most 2.0)
    assert sorted(worst) == [5, 6] and not set(worst) & set(d.split.held_out)
    v = judge(c, d, 0.0)
    assert v.right and v.extra == 0, d.verdict()
    f = d.findings[0]
    assert f.own_gain <= 0.03 and f.own_gain_trained > 0.5 and f.gain > 0.5
    assert f.parameters["coefficient_per_mass"] == pytest.approx(eq["k3_per_mass"], rel=0.10)  # 3.6 %
    (pole,) = f.baseline.model.poles
    assert abs(pole) / (2 * np.pi) == pytest.approx(eq["natural_frequency_hz"], rel=0.005)
    assert -pole.real / abs(pole) == pytest.approx(eq["damping_ratio"], rel=0.15)


def test_a_hammer_record_that_starts_at_the_hit_gets_a_baseline_and_its_cubic():
    # independent seed 197: a clamped-clamped beam hit 2.9 ms into a 7.5 s record at 10 kHz, one velocity
    # sensor, the force channel zero after the hit. The drive had the hit's mean and trend taken out, a
    # steady force each block's simulation met as a step: the baseline held out 7.8 times worse than
    # predicting zero and nothing was found. The coefficient was 8.7 % off; since the record's input gain is
    # fitted with the record at rest before its hit (stop 68), its first block is simulated through the hit,
    # the loudest part of the decay, and it was 16.7 % off. Its held-back blocks lie in the quiet after the
    # decay, so the first fit's order is chosen on the decay (stop 69): the beam's second mode (365.7 Hz)
    # joins the baseline, and the coefficient is 1.1 % off
    d, eq = _cubic_found(197, rel=0.1)  # 1.1 %
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
    d, _ = _cubic_found(12, rel=0.15, family="cc_beam")
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
    d, eq = _cubic_found(64, rel=0.15)  # 7.8 %
    (pole,) = d.baseline.model.poles
    assert abs(pole) / (2 * np.pi) == pytest.approx(eq["natural_frequency_hz"], rel=0.005)
    assert -pole.real / abs(pole) == pytest.approx(eq["damping_ratio"], rel=0.10)


def test_a_band_search_that_splits_a_gliding_decays_mode_is_not_taken():
    # independent seed 93: a clamped-clamped beam (166.3 Hz, 0.22 %) hit by a hammer, one velocity sensor.
    # The first fit finds the beam's mode; the order searched again in the modes' band came out as 167.2 Hz
    # undamped beside 168.6 and 169.5 Hz, one gliding mode split in three, and was taken: the undamped line
    # rang on through the record's quiet tail, the baseline held out 1.9 times worse than predicting zero,
    # and nothing was found. Not taken, the baseline is the beam's mode and its cubic is found (0.6 % off)
    d, eq = _cubic_found(93, rel=0.1)
    (pole,) = d.baseline.model.poles
    assert abs(pole) / (2 * np.pi) == pytest.approx(eq["natural_frequency_hz"], rel=0.005)
    assert d.baseline_test_nrmse < 1.0


def test_a_gliding_pair_in_the_first_fit_leaves_its_lighter_mode():
    # independent seed 41: a clamped-clamped beam (184.9 Hz, 0.35 %) hit by a hammer, one velocity sensor.
    # The first fit's last refinement made the beam's mode a pair, 185.5 Hz at 1.08 % (the decay's loud,
    # fast-fading start) and 184.9 Hz at 0.34 % (its tail); both went on to the band's fit, which kept a pair,
    # and the cubic's coefficient came out 90 % off. The lighter of a gliding pair is the mode at small
    # amplitude: with it alone the baseline's mode is within 1 % and the coefficient within 10 % (4.5 %)
    d, eq = _cubic_found(41, rel=0.1)
    f = np.sort(d.baseline.model.frequencies_hz)
    assert f.size == 2 and f[0] == pytest.approx(eq["natural_frequency_hz"], rel=0.01)  # and 511.8 Hz


def test_a_hammer_decay_inside_the_first_bands_edge_keeps_its_beams_first_mode():
    # independent seed 158: a clamped-clamped beam (174.3 and 480.6 Hz) hit 4.5 ms into a 5.4-s record at
    # 10 kHz, one velocity sensor at the hit. The first fit's preliminary band has a band-pass edge of 0.54 s,
    # by when the decay is gone: it saw the quiet alone, every order predicted its held-back blocks as well
    # as zero, and it kept 480.5 Hz; the band was set above the first mode, and the cubic came out on the
    # second, 7.2 times the generator's one-mode equivalent. The decay from the hit on gives both modes; the
    # cubic is per mass of the first, 32 % off (the target is 10 %)
    d, eq = _cubic_found(158, rel=0.4)
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


def _named_right(seed: int, family: str | None = None):
    """Discovery on the generator's case ``seed`` (of ``family``, if given), asserted to name its cause at the
    right place with no false extra finding; the generated case, the case as measured, the discovery and its
    verdict."""
    generated = discovery_case(seed, family)
    c = independent_case(seed, generated)
    d = discover(c.measurement)
    v = judge(c, d, 0.0)
    assert v.right and v.extra == 0, d.verdict()
    return generated, c, d, v


def _cubic_found(seed: int, rel: float, family: str | None = None):
    """``_named_right`` for a cubic, its coefficient per modal mass asserted within ``rel`` of the generator's
    one-mode equivalent; the discovery and that equivalent."""
    generated, _, d, _ = _named_right(seed, family)
    eq = generated.truth["equivalent"]
    assert d.findings[0].parameters["coefficient_per_mass"] == pytest.approx(eq["k3_per_mass"], rel=rel)
    return d, eq


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


def test_a_drag_the_fitted_linear_part_had_absorbed_is_found_with_its_coefficient():
    # independent seed 94: quadratic damping at tip 1 of a base-driven rig. The modal baseline fitted to
    # the record holds the drag's equivalent damping at the record's amplitude, so the drag regressed on
    # its residual was 0.1 /m, and refitting the linear part with it in place kept it there: "nothing
    # found" (gain 0.008). Refits that also start from drags worth a share of the mode's damping
    # (search._strong_starts) release that damping from the linear part and find the generator's drag
    generated, c, d, v = _named_right(94)
    f = d.findings[0]
    # 43.5 /m found, 43.6 /m in the generator (its one-mode equivalent at the tip)
    assert f.parameters["coefficient_per_mass"] == pytest.approx(c.truth["coefficient_per_mass"], rel=0.1)
    assert f.gain > 0.05 and f.own_gain > 0.5  # its linear part alone, less damped, predicts far worse

    def damping(model):
        p = model.poles[np.argmin(np.abs(model.poles))]
        return -p.real / abs(p)

    # the beam's mode (14.8 Hz) in the generator is 1.17 % damped; the baseline holds 2.27 %, the linear
    # part refitted with the drag 1.44 %
    eq = generated.truth["equivalent"]
    assert damping(d.baseline.model) > 1.5 * eq["damping_ratio"]
    assert damping(f.baseline.model) == pytest.approx(eq["damping_ratio"], rel=0.3)


def test_a_stopper_struck_throughout_is_found_with_the_beam_mode_its_linearisation_hid():
    # independent seed 552: a base-driven rig whose beams' first modes lie at 12.26 and 12.61 Hz, a stopper
    # on beam 1 at 0.77 mm that it strikes through the record. The order search fits one mode (12.3 Hz):
    # the struck beam's resonance is smeared, and every cause refitted with that one mode gained nothing
    # ("nothing found"; the stopper at its true gap too). With the stopper's force as an input the joint
    # fit finds the second mode (its fit error 0.20 -> 0.08), and the stopper is found where it is
    _, c, d, v = _named_right(552)
    f = d.findings[0]
    assert f.parameters["gap"] == pytest.approx(c.truth["gap"], rel=0.05)  # 0.767 mm against 0.770 mm
    assert np.count_nonzero(d.baseline.drivable) == 1
    own = f.baseline
    assert own is not None and np.count_nonzero(own.drivable) == 2
    light = np.sort(own.model.frequencies_hz[own.drivable])
    modes = sorted(m["frequency_hz"] for m in c.truth["by_mode"])
    assert light == pytest.approx(modes, rel=0.03)


def test_a_twin_without_its_effect_gets_no_finding_from_a_linear_refit():
    # independent seed 48's twin: the base-driven rig of a Coulomb friction case, run without the friction,
    # so a linear record. Its first modal fit (in the preliminary band, 2.7-16 Hz) keeps an overdamped
    # pseudo-mode (5.5 Hz, damping ratio 1) and with that order the baseline held out at NRMSE 0.31, where
    # the same fit on the case holds out at 0.05; a cubic between the tips, refitted with its own linear
    # part, then held out at 0.047 and was named (a gain of 0.85, nearly all of it the refit's). The order
    # chosen again in the modes' band predicts the left-out training blocks better (0.039 and 0.054 against
    # 0.052 and 0.068): the baseline holds out at 0.05 and nothing is found
    c = independent_case(48, twin=True)
    assert c.cause == "none" and "twin of coulomb_friction" in c.info
    d = discover(c.measurement)
    assert d.findings == [], d.verdict()
    assert d.baseline_test_nrmse < 0.1


def test_a_cause_no_better_than_its_own_linear_part_in_most_pieces_is_no_look_alike():
    # independent seed 389 (a base-driven rig, a joint at tip 2, 1 kHz; first run at stop 75): the joint at
    # tip 2 holds out 0.40 better than the baseline. A cubic at tip 2, refitted with its own linear part,
    # holds out 0.38 better than the baseline and 15 % better than that linear part alone on average, over
    # the 3 % floor, so it stood as a look-alike and the answer was "ambiguous: cubic or joint". Piece by
    # piece the cubic is no better than its own linear part (signed rank p ~ 0.8): the refit's gain, not
    # the cubic's. The joint is named alone
    c = independent_case(389)
    d = discover(c.measurement)
    assert [(f.cause, f.location) for f in d.findings] == [("hysteretic_joint", "tip2")], d.verdict()
    assert not any(d.ambiguous), d.verdict()
    settings = search.Settings()
    cubics = [k for k in d.candidates if k.cause == "cubic_stiffness" and k.location == "tip2" and k.gain > 0.3
              and np.isfinite(k.own_p)]
    assert cubics
    for k in cubics:  # the floor alone let it through; the test over the pieces does not
        assert k.own_gain > settings.gain_floor and k.p_value < settings.alpha
        assert k.own_p >= settings.alpha and not search.significant(k, settings)
        assert search.significant(replace(k, own_p=0.0), settings)


def test_a_cause_riding_on_a_correction_of_the_fitted_linear_part_is_not_a_finding():
    # the softening Duffing family's seed 17: a linear one-mode oscillator (53.5 Hz, 0.8 % damping, 500 Hz,
    # a log sweep), nothing hidden. The modal baseline fitted to it is a little off (5.9 x the noise floor);
    # with nothing found, the compensated second step regressed a Coulomb friction with a spring and a
    # damper at x1 and named it (held-out gain 0.12, p = 6e-39). Its spring and damper alone already predict
    # better than the baseline: a correction of the fitted linear part, and the friction rides on top of it
    generated = discovery_case(17, family="duffing_softening")
    c = independent_case(17, generated)
    d = discover(c.measurement)
    assert c.cause == "none" and d.findings == [], d.verdict()
    assert any("correction of the fitted linear part" in n for n in d.notes), d.notes
    comp = [k for k in d.candidates if compensation(k) and np.isfinite(k.gain) and k.gain > 0.03]
    assert comp
    f = max(comp, key=lambda k: k.gain)
    # its spring and damper alone, simulated here on the held-out blocks: better than the baseline
    scale = np.maximum(d.prep.measured[d.split.rows("test")].std(axis=0), 1e-300)
    with threadpool_limits(limits=1, user_api="blas"):
        _, alone = block_errors(d.baseline, d.baseline.model.with_elements(compensation(f)), d.prep, d.split.test,
                                d.warm, scale, (), simulation_bound(d.prep))
    assert f.test_nrmse < alone < d.baseline_test_nrmse  # 0.0485 < 0.0512 < 0.0549


def test_a_friction_three_times_better_at_its_own_beam_is_named_there_not_ambiguous():
    # independent seed 90: Coulomb friction at tip 1 of a base-driven rig. The friction at tip 1 holds out
    # at a gain of 0.76 over the baseline, the same law at tip 2 at 0.24 (significant) and 0.31 (not), and
    # the first beats the second over the held-out pieces at p = 0.08 on the stop-35 install: at a level of
    # 0.05 that was "ambiguous: friction at tip 1 or tip 2", at the search's 0.1 it is the friction at tip 1
    c = independent_case(90)
    d = discover(c.measurement)
    v = judge(c, d, 0.0)
    assert v.right and v.extra == 0 and d.ambiguous == [[]], d.verdict()
    f = d.findings[0]
    other = [k for k in d.candidates if k.cause == "coulomb_friction" and k.location == "tip2"]
    assert other and f.gain > 2 * max(k.gain for k in other)
    # the slip force per unit modal mass: 0.038 found, 0.066 in the generator (its one-mode equivalent)
    assert f.parameters["force_per_mass"] == pytest.approx(c.truth["force_per_mass"], rel=0.5)


def test_an_overdamped_pole_above_the_band_is_dropped_where_it_lets_the_free_runs_wander(monkeypatch):
    # seed 45, a joint at tip 1 (1 kHz): the fit in the modes' band (5.2-65 Hz) keeps a pole above it at
    # zeta > 0.5 (490 Hz). The fit follows round-off and the record's padding, and so does what that pole does
    # to a free run: with numpy's AVX2 kernels (daq/__init__.py) it cuts the fit's error and makes the
    # held-out free runs err 0.23 (0.056 without it), and the rule drops it; with its AVX-512 kernels (stop 64's
    # host before numpy was held to AVX2) the same pole's free runs do not wander (the training blocks' 0.042
    # with it, 0.055 without), and the rule keeps it. (Seed 53 was this test's case
    # until the band-pass's FFT length changed; a check on a refit of two thirds of the training blocks had
    # kept such a pole on another host.) So the test holds the rule to its contract on whatever the host fits:
    # the baseline it leaves predicts the held-out blocks, and a pole it keeps is one that does not wander
    c = independent_case(45)
    m = c.measurement
    with threadpool_limits(limits=1, user_api="blas"):  # as discover fits (its docstring says why)
        band, poles0 = D._fit_modal(m, None, None, None)
        prep = prepare(m, band)
        split = D._split(prep)
        base = D._fit_in_band(prep, split, poles0)
        monkeypatch.setattr(D, "_without_devices", lambda fitted, prep, split: fitted)
        kept = D._fit_in_band(prep, split, poles0)
    p, q = base.model.poles, kept.model.poles
    device = (-q.real / np.abs(q) > 0.5) & (np.abs(q) / (2 * np.pi) > band[1])
    assert device.sum() == 1 and band[1] < abs(q[device][0]) / (2 * np.pi) < m.fs_hz / 2
    scale = np.maximum(prep.measured[split.rows("test")].std(axis=0), 1e-300)
    bound = simulation_bound(prep)
    errors = [block_errors(b, b.model, prep, split.test, D._warm(b, prep), scale, (), bound)[1] for b in (base, kept)]
    assert errors[0] < 0.15
    if len(p) == len(q) and np.allclose(p, q):  # kept: its free runs did not wander
        assert errors[1] < 0.15
    else:  # dropped: every pole left is a lightly damped mode of the band, and the pole had made them wander
        assert np.all(-p.real / np.abs(p) < 0.3) and np.all(np.abs(p) / (2 * np.pi) < band[1])
        assert errors[1] > 2 * errors[0]


def test_damping_ratios_are_capped_below_critical():
    # analytic: -s + i w has zeta = s / sqrt(s^2 + w^2); brought to ZETA_MAX where above it, s kept
    p = np.array([-1.0 + 100j, -1.0 + 1j, -5.0 + 1e-12j, -2.0 + 0j])
    q = bounded(p)
    zeta = -q.real / np.abs(q)
    raw = -p.real / np.abs(p)
    assert np.allclose(zeta, np.minimum(raw, ZETA_MAX), rtol=1e-12)
    assert np.array_equal(q.real, p.real) and q[0] == p[0] and q[1] == p[1]


def test_an_overdamped_pair_in_the_first_fit_is_brought_below_critical_and_its_residues_fitted_again(monkeypatch):
    # seed 28 hides nothing: a chain of masses, band 1.9-90 Hz. The first modal fit ends with two poles at
    # zeta = 1 (30.1 and 26.6 Hz): each pair one real pole twice, the two columns of the design nearly the
    # same and the residues that tell them apart 4e10. Every block's state read through them starts the
    # free runs off (held-out 0.34); ``modal.undegenerate`` brings the pair to ``ZETA_MAX`` and fits the
    # residues again (0.12), and the baseline the search then fits in the band predicts the held-out blocks
    # near the instruments' noise floor. (Seed 58 was the witness until stop 79: its pole came from wrongly
    # signed tips, which the sign rule now reads right.)
    calls = []
    undegenerate = modal.undegenerate

    def recorded(model, prep, rows):
        calls.append((model, undegenerate(model, prep, rows)))
        return calls[-1][1]

    monkeypatch.setattr(modal, "undegenerate", recorded)
    c = independent_case(28)
    m = c.measurement
    with threadpool_limits(limits=1, user_api="blas"):
        band, poles0 = D._fit_modal(m, None, None, None)
        first = [(model, fixed[0]) for model, fixed in calls if fixed is not None]
        assert len(first) == 1, "the first fit is the one repaired"
        raw, fixed = first[0]
        zeta = -raw.poles.real / np.abs(raw.poles)
        assert zeta.max() > ZETA_MAX and np.abs(raw.C).max() > 1e6
        zeta = -fixed.poles.real / np.abs(fixed.poles)
        assert zeta.max() <= ZETA_MAX * (1 + 1e-12) and np.abs(fixed.C).max() < 1e3
        prep = prepare(m, band)
        split = D._split(prep)
        base = D._fit_in_band(prep, split, poles0)
    rows = split.rows("test")
    scale = np.maximum(prep.measured[rows].std(axis=0), 1e-300)

    def held_out(model):
        b = ModalBaseline(model, base.driving_point)
        return block_errors(b, model, prep, split.test, D._warm(b, prep), scale, (), simulation_bound(prep))[1]

    assert held_out(fixed) < 0.5 * held_out(raw)
    # the floor apart: the generator's own noise (recorded minus noise-free), band-passed as the data are
    lo, hi = prep.band
    hp = butter(2, lo, "highpass", fs=prep.fs_hz, output="sos")
    lp = butter(4, hi, "lowpass", fs=prep.fs_hz, output="sos")
    floor = np.mean([np.sqrt(np.mean(sosfiltfilt(lp, sosfiltfilt(hp, np.asarray(ch.values) - np.asarray(ref.values)))[rows]
                                      ** 2)) / prep.measured[rows, i].std()
                     for i, (ch, ref) in enumerate(zip(m.responses, c.reference.responses))])
    err = held_out(base.model)
    assert 0 < floor < err < 3 * floor, (err, floor)


def test_the_driving_points_sign_on_a_hammer_record_and_a_chain_where_the_record_cannot_tell():
    # seed 4: a clamped-clamped beam hit from rest, its laser facing the force, its decay gliding (Im of its
    # receptance negative on 33 % of its power, neither side of the 10-90 % rule): its first motion flips it
    case = independent_case(4)
    assert case.driven == "v1" and case.signs == {"v1": -1}
    prep = prepare(case.measurement)
    assert driving_sign(case, prep) == "right" and prep.signs.tolist() == [-1]
    # seed 72: a chain pushed at its second mass, driven about its first mode, where all four masses move in
    # phase: the first is taken for the driving point, and the report names the driven one among the others
    case = independent_case(72)
    prep = prepare(case.measurement)
    assert case.driven == "a2" and driving_sign(case, prep) == "another"
    assert "taken for it, but a2, a3, a4 read as one too" in prep.sign_notes[0]


@pytest.mark.parametrize("seed, flipped_below", [(789, "tip2"), (737, "tip2"), (44, "tip2")])
def test_a_struck_tips_sign_under_a_shaken_frame_is_read_below_its_resonance(seed, flipped_below):
    # base-driven rigs whose sensors the generator mounted against each other (its own record of the signs):
    # the struck beam's tip shows no resonance whose phase says its sign, and it had been kept as recorded,
    # its relative motion then the frame's plus its own (seed 737: 10-21 times the stopper's gap, the
    # baseline held out worse than predicting zero). Below its lowest resonance a tip moves with the frame
    generated = discovery_case(seed)
    case = independent_case(seed, generated)
    m = case.measurement
    assert m.base_excited and case.cause == "contact"
    frame = generated.truth["signs"][m.excitation.name]
    prep = prepare(m)
    assert prep.signs.tolist() == [generated.truth["signs"][ch.name] * frame for ch in m.responses]
    assert any(n.startswith(f"{flipped_below}: flipped (Re of its transmissibility is negative below")
               for n in prep.sign_notes), prep.sign_notes


def test_no_tip_is_flipped_by_the_lines_below_its_resonance_in_a_band_above_the_first_mode():
    # seed 726: base-driven beams whose first modes lie near 14 Hz, analysed in the band the modal fit chose
    # (75-849 Hz). Below tip 2's lowest resonance there (166 Hz) the lines lie between modes, where Re T < 0
    # and |T| is 0.09: taken for "below every mode", they had flipped a tip the generator mounted right
    generated = discovery_case(726)
    m = independent_case(726, generated).measurement
    prep = prepare(m, band=(75.5, 849.1))
    assert prep.signs[1] == generated.truth["signs"]["tip2"] * generated.truth["signs"][m.excitation.name] == 1
    assert not any(n.startswith("tip2") for n in prep.sign_notes), prep.sign_notes


def test_reciprocity_through_the_response_that_explains_most_finds_a_chains_drag():
    # seed 50: a chain of six masses pushed at its second, a drag between its third and fourth, driven about
    # its lowest modes: five masses read as the driving point, the signs take the sixth, and through it the
    # drag was "ambiguous" beside a false cubic. Through the second mass, the driven one, a force surface
    # explains the most of the training residual, and the drag is found where it is
    case = independent_case(50)
    d = discover(case.measurement)
    v = judge(case, d, 0.0)
    assert d.prep.names[d.prep.driving_point] != case.driven
    assert d.prep.names[d.baseline.driving_point] == case.driven
    assert any(n.startswith(f"the modal baseline's reciprocity taken through {case.driven}") for n in d.notes)
    assert v.right and v.extra == 0, d.verdict()
    # the drag's coefficient, in N s^2/m^2 through the chain's masses: 41 % off the generator's element
    assert v.parameter_error < 0.5


def test_a_refinement_ends_no_worse_than_the_cause_as_regressed():
    # independent seed 164: a hardening cubic at tip 1 of a base-driven rig (2,500 Hz, the beams' modes at
    # 8.34 and 8.57 Hz). Its regression on the fitted baseline's residual simulates the busiest training
    # blocks better than the baseline; the linear part refitted with it in place (``joint_refit``, which fits
    # the cubic's force on the measured coordinate, not its simulation) simulates them worse than the
    # baseline, and the refinement, which starts from that refit, ends worse still: an expected failure
    # until a fix that costs no verdict (refining from both starts, stop 71, gave seed 26 a false joint and
    # gained none)
    c = independent_case(164)
    assert (c.cause, c.location) == ("cubic_stiffness", "tip1")
    with threadpool_limits(limits=1, user_api="blas"):
        f = fitted_as_discover(c.measurement)
        loc = next(loc for loc in f.base.locations(f.prep) if loc.name == "tip1")
        plain = search.regress(f.base, f.prep, f.rows, f.residual, loc, "cubic_stiffness", f.scale)
        bound = simulation_bound(f.prep)
        segs = search.busiest(f.prep, f.split, loc.weights, search.Settings().refine_blocks)

        def error(cand):
            return search.train_error(f.base, cand, f.prep, segs, f.warm, f.scale, bound)

        e_base = error(search.Candidate("none", "tip1", {}))
        e_plain = error(plain)
        e_refit = error(search.joint_refit(plain, f.base, loc, f.prep, f.split, f.warm, f.scale))
        ref = search.refine(plain, f.base, loc, f.prep, f.split, f.warm, f.scale, bound, search.Settings())
    assert e_plain < e_base < e_refit  # measured: 0.094 < 0.110 < 0.111
    assert ref.refined
    if not ref.train_nrmse <= e_plain:  # measured: 0.137
        pytest.xfail(f"a refinement from the joint refit alone ended at {ref.train_nrmse:.3f}, worse than the cause "
                     f"as regressed ({e_plain:.3f})")


def test_a_cubic_behind_a_baseline_with_a_mode_too_many_is_found_on_the_beams_two():
    # independent seed 697 (first run at stop 77, fresh): a base-driven rig whose beams' first modes lie at
    # 8.28 and 8.54 Hz, a cubic spring at tip 2. The modal fit follows the hardening with a third mode
    # (8.31, 9.04 and 9.08 Hz), every cause regressed against it found its residual taken, and the stopper
    # was named instead of the cubic. Searched again on the two modes the order search takes up to the
    # responses' count, the cubic with its own linear part (8.28 and 8.56 Hz) beats the three-mode baseline
    # on held-out blocks, its coefficient within 2.2 % of the generator's in the mode it acts in
    _, c, d, v = _named_right(697)
    assert np.count_nonzero(d.baseline.drivable) == 3
    f = d.findings[0]
    own = f.baseline
    assert own is not None and np.count_nonzero(own.drivable) == 2
    modes = sorted(m["frequency_hz"] for m in c.truth["by_mode"])
    assert np.sort(own.model.frequencies_hz[own.drivable]) == pytest.approx(modes, rel=0.01)
    assert v.parameter_error < 0.05
    assert f.own_gain >= f.gain  # the two modes alone predict worse than the baseline: the gain is the cubic's
    assert any("linear part of 2 modes, where the linear fit to this record has 3" in n for n in d.notes)


def test_fewer_modes_that_alone_predict_better_than_the_baseline_make_no_look_alike():
    # independent seed 42: a chain of masses (5 modes, 4 responses, all five modes the chain's own) with a weak
    # cubic between masses 3 and 4. The search on four modes finds that four modes alone predict the held-out
    # blocks better than the fitted five do; a contact on them gained 0.10 on the baseline and 0.04 on its own
    # linear part, and, taken as a look-alike, it made the true cubic "ambiguous". Such candidates are held
    # back (``FEWER_ALONE``), and the cubic is named
    _, c, d, v = _named_right(42)
    assert not d.ambiguous[0], d.verdict()
    assert np.count_nonzero(d.baseline.drivable) == 5 and len(d.prep.names) == 4
    held = [k for k in d.candidates if k.note.startswith(D.FEWER_ALONE)]
    assert held and all(k.own_gain < k.gain and k.p_value == 1.0 for k in held)
    assert all(k.baseline.model.poles.size == 4 for k in held)
