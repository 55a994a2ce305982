"""Discovery on data this project's model did not make (the independent generator, importing nothing
from ``ident``), one generated case per test: the baseline and the linear part a cause is refitted with
(a cubic the linear fit mostly misses, a drag or a stopper the fitted linear part absorbed, a mode too
many, overdamped poles), and the responses' signs. The four cases the tests share are in
``test_discovery_independent.py``; records with a transient are in
``test_discovery_independent_transients.py``, the choice among candidates in
``test_discovery_independent_lookalikes.py``.

Seed 47 is a strongly hardening Duffing oscillator (26.2 Hz, 1 % damping, displacement out) under an odd
multisine; seed 140 another under a stepped sine that jumps.
"""

import sys

import numpy as np
import pytest
from scipy.signal import butter, sosfiltfilt
from threadpoolctl import threadpool_limits

from discovery_verdicts import named_right
from daq.sim.independent.cases import discovery_case
from ident.cli.bench_discovery import driving_sign, independent_case, judge
from ident.discovery import discover
from ident.discovery.baselines import modal
from ident.discovery.baselines.modal import ZETA_MAX, ModalBaseline, bounded
from ident.discovery.search import block_errors, simulation_bound
from ident.discovery.signals import prepare

D = sys.modules["ident.discovery.discover"]  # the module: the package exports its function by that name


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


def test_a_drag_the_fitted_linear_part_had_absorbed_is_found_with_its_coefficient():
    # independent seed 94: quadratic damping at tip 1 of a base-driven rig. The modal baseline fitted to
    # the record holds the drag's equivalent damping at the record's amplitude, so the drag regressed on
    # its residual was 0.1 /m, and refitting the linear part with it in place kept it there: "nothing
    # found" (gain 0.008). Refits that also start from drags worth a share of the mode's damping
    # (search._strong_starts) release that damping from the linear part and find the generator's drag
    generated, c, d, v = named_right(94)
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
    _, c, d, v = named_right(552)
    f = d.findings[0]
    assert f.parameters["gap"] == pytest.approx(c.truth["gap"], rel=0.05)  # 0.767 mm against 0.770 mm
    assert np.count_nonzero(d.baseline.drivable) == 1
    own = f.baseline
    assert own is not None and np.count_nonzero(own.drivable) == 2
    light = np.sort(own.model.frequencies_hz[own.drivable])
    modes = sorted(m["frequency_hz"] for m in c.truth["by_mode"])
    assert light == pytest.approx(modes, rel=0.03)


def test_a_baseline_with_fewer_modes_than_responses_gets_the_struck_beams_mode_for_a_second_search(monkeypatch):
    # independent seed 915 (first run at stop 88): a base-driven rig whose beams' first modes lie at 12.19 and
    # 13.85 Hz, a two-sided stopper on beam 1 (0.51 mm at the tip) that it strikes through the record, and a
    # blow at 15.9 s. The order search chooses on what the input alone makes on held-back blocks from rest,
    # where no linear model predicts the struck beam (one mode 1.17 times predicting zero at tip 1, two 1.45):
    # it stops at one mode, 13.4 Hz. One mode more, started from the training blocks' FRF once the blow's blocks
    # are left out (``discover._one_more_mode``), is the struck beam's. Discovery is stopped there
    seen = []
    one_more = D._one_more_mode

    class Seen(Exception):
        pass

    def spied(baseline, prep, split):
        seen.append((baseline, prep, split, one_more(baseline, prep, split)))
        raise Seen

    monkeypatch.setattr(D, "_one_more_mode", spied)
    # the split as it was when this was seen: the sweep's resonance block held out. Trained on
    # (``split.resonant_block``, stop 91), the two modes hold out worse than the one (1.35 against 0.62) and
    # the contact at tip 1 gains over them on the held-out blocks, its gap 13 % off
    monkeypatch.setattr(D, "resonant_block", lambda measured, split: None)
    generated = discovery_case(915)
    with pytest.raises(Seen):
        discover(independent_case(915, generated).measurement)
    ((base, prep, split, more),) = seen
    assert len(prep.names) == 2 and np.count_nonzero(base.drivable) == 1
    assert more is not None and np.count_nonzero(more.drivable) == 2
    beams = sorted(generated.truth["structure"]["system_modes_hz"][:2])
    light = np.sort(more.model.frequencies_hz[more.drivable])
    assert light[0] == pytest.approx(beams[0], rel=0.01)  # 12.18 Hz against 12.19
    assert more.fit_nrmse < 0.5 * base.fit_nrmse  # on the training blocks
    # held out, the two modes alone predict better than the one (the search's candidates must still beat them)
    rows = split.rows("test")
    scale = np.maximum(prep.measured[rows].std(axis=0), 1e-300)
    bound = simulation_bound(prep)
    with threadpool_limits(limits=1, user_api="blas"):
        held = [block_errors(b, b.model, prep, split.test, D._warm(b, prep), scale, (), bound)[1] for b in (base, more)]
        assert one_more(more, prep, split) is None  # as many modes as responses: no search more
    assert held[1] < 0.5 * held[0]


@pytest.mark.long
@pytest.mark.parametrize("seed, rel", [(915, 0.15), (973, 0.08), (985, 0.12)])
def test_a_stopper_behind_a_baseline_that_lacks_the_struck_beams_mode_is_found_on_one_mode_more(seed, rel):
    # base-driven rigs whose beam strikes its stopper through the record, the fitted baseline one mode for two
    # beams: 915 (above; on one mode a quadratic stiffness at tip 1 was named), 973 (a one-sided stopper at tip
    # 1: nothing found) and 985 (one at tip 2, found at stop 88 by refining the contact at its next place, gap
    # 15 % off). Searched again on two modes (``discover._one_more_mode``), each stopper is found where it is:
    # gaps 0.5, 4.4 and 8.2 % off. 915's and 973's gains over their own linear part are in the training blocks,
    # where they strike (``search._own_gain_trained``: 0.57 and 0.58); held out, the second mode carries them.
    # Since stop 91 915's sweep resonance block is trained on (``split.resonant_block``): its contact gains
    # over its two modes on the held-out blocks (0.87), one-sided, the gap 13 % off
    _, c, d, v = named_right(seed)
    assert np.count_nonzero(d.baseline.drivable) == 1
    f = d.findings[0]
    assert f.baseline is not None and np.count_nonzero(f.baseline.drivable) == 2
    assert f.parameters["gap"] == pytest.approx(c.truth["gap"], rel=rel)
    assert any("linear part of 2 modes, where the linear fit to this record has 1" in n for n in d.notes)


@pytest.mark.long
def test_a_cubic_behind_a_baseline_with_a_mode_too_many_is_found_on_the_beams_two():
    # independent seed 697 (first run at stop 77, fresh): a base-driven rig whose beams' first modes lie at
    # 8.28 and 8.54 Hz, a cubic spring at tip 2. The modal fit follows the hardening with a third mode
    # (8.31, 9.04 and 9.08 Hz), every cause regressed against it found its residual taken, and the stopper
    # was named instead of the cubic. Searched again on the two modes the order search takes up to the
    # responses' count, the cubic with its own linear part (8.28 and 8.56 Hz) beats the three-mode baseline
    # on held-out blocks, its coefficient within 2.2 % of the generator's in the mode it acts in
    _, c, d, v = named_right(697)
    assert np.count_nonzero(d.baseline.drivable) == 3
    f = d.findings[0]
    own = f.baseline
    assert own is not None and np.count_nonzero(own.drivable) == 2
    modes = sorted(m["frequency_hz"] for m in c.truth["by_mode"])
    assert np.sort(own.model.frequencies_hz[own.drivable]) == pytest.approx(modes, rel=0.01)
    assert v.parameter_error < 0.05
    assert f.own_gain >= f.gain  # the two modes alone predict worse than the baseline: the gain is the cubic's
    assert any("linear part of 2 modes, where the linear fit to this record has 3" in n for n in d.notes)


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


@pytest.mark.long
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
