"""Discovery on data this project's model did not make (the independent generator, importing nothing
from ``ident``), one generated case per test: which candidate is named where several predict better than
the baseline (a refit's gain that is not the cause's, a look-alike, a cause at the other beam, the
response a chain's reciprocity is taken through, a refinement's end). The other cases with a test of
their own are in ``test_discovery_independent_seeds.py`` and ``test_discovery_independent_transients.py``.
"""

import sys
from dataclasses import replace

import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from discovery_fit import fitted_as_discover
from discovery_verdicts import named_right
from daq.sim.independent.cases import discovery_case
from ident.cli.bench_discovery import independent_case, judge
from ident.discovery import discover, search
from ident.discovery.search import block_errors, compensation, simulation_bound

D = sys.modules["ident.discovery.discover"]  # the module: the package exports its function by that name


@pytest.mark.long
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


@pytest.mark.long
def test_reciprocity_through_the_response_that_explains_most_finds_a_chains_drag():
    # seed 50: a chain of six masses pushed at its second, a drag between its third and fourth, driven about
    # its lowest modes: five masses read as the driving point, the signs take the sixth, and through it the
    # drag was "ambiguous" beside a false cubic. Through the second mass, the driven one, a force surface
    # explains the most of the training residual, and the drag is found where it is. The answer is settled
    # before any refinement by simulation (measured at stop 83: the same finding, gain 0.39 and coefficient
    # 6 % off with the four refinements or without), so none is run here: 44 s -> 33 s alone
    case = independent_case(50)
    d = discover(case.measurement, settings=search.Settings(max_refined=0))
    v = judge(case, d, 0.0)
    assert d.prep.names[d.prep.driving_point] != case.driven
    assert d.prep.names[d.baseline.driving_point] == case.driven
    assert any(n.startswith(f"the modal baseline's reciprocity taken through {case.driven}") for n in d.notes)
    assert v.right and v.extra == 0, d.verdict()
    # the drag's coefficient, in N s^2/m^2 through the chain's masses: 6 % off the generator's element
    # (stop 83, with or without refinements; the test was written at 41 %, at `7a2daba`)
    assert v.parameter_error < 0.15


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


def test_fewer_modes_that_alone_predict_better_than_the_baseline_make_no_look_alike():
    # independent seed 42: a chain of masses (5 modes, 4 responses, all five modes the chain's own) with a weak
    # cubic between masses 3 and 4. The search on four modes finds that four modes alone predict the held-out
    # blocks better than the fitted five do; a contact on them gained 0.10 on the baseline and 0.04 on its own
    # linear part, and, taken as a look-alike, it made the true cubic "ambiguous". Such candidates are held
    # back (``FEWER_ALONE``), and the cubic is named
    _, c, d, v = named_right(42)
    assert not d.ambiguous[0], d.verdict()
    assert np.count_nonzero(d.baseline.drivable) == 5 and len(d.prep.names) == 4
    held = [k for k in d.candidates if k.note.startswith(D.FEWER_ALONE)]
    assert held and all(k.own_gain < k.gain and k.p_value == 1.0 for k in held)
    assert all(k.baseline.model.poles.size == 4 for k in held)
