"""Discovery on data this project's model did not make: the independent generator (``daq.sim.independent``,
finite-element beams with their own integrator, importing nothing from ``ident``) hides an effect, and
``ident discover`` with a modal baseline fitted to the same record must name it, where it is, with its
size; where nothing is hidden it must find nothing.

The seeds are fixed; ``ident bench discovery`` runs many more (its figures are in the README). Four cases
are discovered once and shared by the tests here: seed 2 is a two-sided contact near the tip of beam 1
under base excitation at 2 kHz; seed 63 a force-driven rig with nothing hidden at 1 kHz (its tip-1
accelerometer clips); seed 23 a force-driven Duffing oscillator with displacement output under an odd
multisine at 610 Hz (26.8 Hz, 3.6 % damping, hardening); seed 3 a two-sided contact at beam 1 under base
excitation at 1 kHz with two unmeasured blows, whose one-mode baseline predicts worse than zero. Cases
with a test of their own are in ``test_discovery_independent_seeds.py``,
``test_discovery_independent_transients.py`` and ``test_discovery_independent_lookalikes.py`` (separate
files, one theme each, so that they run on separate workers).
"""

import importlib

import numpy as np
import pytest
from scipy.signal import butter, sosfiltfilt
from scipy.stats import wilcoxon
from threadpoolctl import threadpool_limits

from daq.sim.independent.cases import discovery_case
from ident.cli.bench_discovery import independent_case, judge
from ident.discovery import Settings, discover
from ident.discovery.discover import PIECE_PERIODS, noise_floor
from ident.discovery.search import block_errors, simulation_bound


@pytest.fixture(scope="module")
def cases():
    out = {}
    for seed in (2, 3, 23, 63):
        generated = discovery_case(seed)
        c = independent_case(seed, generated)
        out[seed] = (c, discover(c.measurement), generated.truth)
    return out


def test_a_hidden_contact_is_named_at_its_beam_with_its_gap(cases):
    c, d, _ = cases[2]
    assert (c.cause, c.location) == ("contact", "tip1")  # what the generator hid (its own record of it)
    v = judge(c, d, 0.0)
    assert v.right, d.verdict()
    f = d.findings[0]
    # the generator's gap at the sensor is a first-mode equivalent (the stopper's gap over the mode-shape
    # ratio of stopper point to tip), exact only while the first mode alone moves the beam; with the
    # baseline chosen on held-out blocks the gap comes out 12.7 % small (the extended model predicts the
    # held-out blocks with NRMSE 0.20); a baseline worse than predicting zero (held-out NRMSE 1.87) had
    # put it within 2 % (NRMSE 0.33). The target is 5 %: see the README's discovery figures
    assert f.parameters["gap"] == pytest.approx(c.truth["gap"], rel=0.15)
    assert f.parameters["side"] == c.truth["side"]
    assert f.p_value < 0.05 and d.gain > 0.3 and d.gain_vs_zero > 0


def test_nothing_is_found_where_nothing_is_hidden(cases):
    c, d, _ = cases[63]
    assert c.cause == "none"
    assert d.findings == [] and d.verdict().startswith("nothing found")


def test_a_duffing_gets_one_mode_and_its_cubic_with_the_physical_coefficient(cases):
    # a periodic record once gave seven modes, four of them undamped, where the generator has one: their
    # free response fitted the steady nonlinear response line by line (held-out NRMSE 0.41 against a fit
    # error of 0.03) and nothing was found; the order is now chosen on what the input alone makes on
    # training blocks the fit did not see
    c, d, truth = cases[23]
    structure = truth["structure"]
    assert d.baseline.model.poles.size == 1
    assert d.baseline.model.frequencies_hz[0] == pytest.approx(structure["natural_frequency_hz"], rel=0.05)
    v = judge(c, d, 0.0)
    assert v.right, d.verdict()
    f = d.findings[0]
    assert f.parameters["coefficient_per_mass"] == pytest.approx(c.truth["coefficient_per_mass"], rel=0.10)
    # force in, displacement out at the same point: the coefficient in N/m^3 through the driving point
    assert f.physical["coefficient_n_per_m3"] == pytest.approx(truth["effect"]["k3_n_per_m3"],
                                                              rel=0.10)
    assert d.gain > 0.5 and d.gain_vs_zero > 0.9


def test_a_gain_that_is_only_the_refitted_linear_parts_is_not_a_finding(cases):
    # refitting the linear part with a force on the measured motion as an extra input improves it
    # whatever the force (the force takes up the blows' ringing and the missing mode): a Coulomb
    # friction gained 0.63 over the baseline that way and was reported beside the true contact. Since the
    # strong starts (43fcfe8) the quadratic damping that was found here has 0.016 over its own linear part
    # too, and the answer is "nothing" (the contact itself is a known miss, below)
    c, d, _ = cases[3]
    assert (c.cause, c.location) == ("contact", "tip1")
    assert d.baseline_test_nrmse > 1.0  # the one-mode baseline: worse than predicting zero
    refitted = [x for x in d.candidates if x.baseline is not None and np.isfinite(x.own_gain)]
    borrowed = [x for x in refitted if x.gain > 0.5 and x.own_gain < 0.03]  # gains that are the linear part's
    assert borrowed  # and none is a finding: every finding gains over its own linear part
    assert all(x.own_gain > 0.03 for x in d.findings if x.baseline is not None), d.verdict()
    # the signed-rank test against that linear part alone (``search.over_own_part`` selects on it for every
    # cause but a stopper), recomputed here with scipy from the linear part's own free runs
    k = max(borrowed, key=lambda x: x.gain)
    prep, split = d.prep, d.split
    scale = np.maximum(prep.measured[split.rows("test")].std(axis=0), 1e-300)
    piece = max(16, int(PIECE_PERIODS * prep.fs_hz / (prep.band[0] / 0.4)))
    with threadpool_limits(limits=1, user_api="blas"):
        alone, _ = block_errors(k.baseline, k.baseline.model, prep, split.test, d.warm, scale, (),
                                simulation_bound(prep), piece)
    assert alone.shape == k.block_errors.shape
    assert k.own_p == pytest.approx(wilcoxon(alone - k.block_errors, alternative="greater").pvalue, rel=1e-9)


def test_a_baseline_worse_than_predicting_zero_is_said(cases):
    # a one-mode baseline cannot describe a record with a stopper and blows: the answer says so, with the
    # number the JSON holds (checked on the project's own transitions recording through the command line
    # until stop 58; that a note reaches stdout is test_discovery.py's). Until stop 76 the answer was
    # "nothing found"; since the joint fit may add the mode the struck stopper hid (stop 77), the stopper
    # is named at its beam (its gap 35 % small: 0.55 mm where the generator's first-mode equivalent is 0.84)
    _, d, _ = cases[3]
    n0 = d.baseline_test_nrmse
    assert n0 > 1.0 and np.count_nonzero(d.baseline.drivable) == 1
    assert any(f"worse than predicting zero (NRMSE {n0:.3g})" in note for note in d.notes), d.notes
    assert np.count_nonzero(d.findings[0].baseline.drivable) == 2


def test_a_hidden_contact_comes_without_a_false_second_finding(cases):
    # a quadratic stiffness between the tips added 0.03 on top of the contact at p = 0.020 over 40
    # pieces, and 0.18 over the 8 blocks they come from: a second finding is tested over blocks
    c, d, _ = cases[2]
    v = judge(c, d, 0.0)
    assert v.right and v.extra == 0, d.verdict()


def test_a_linear_mismatch_is_scored_but_not_refined_against_a_baseline_fitted_to_the_record(cases):
    # it cannot be a finding there (``discover.findable``), and its refinement was the dearest of all: a
    # spring stiff enough that the integrator took its cap of 64 sub-steps a sample, 98 of the 163 s of
    # seed 2's run. It keeps its place among the leaders, so the causes refined beside it are the same
    c, d, _ = cases[2]
    mismatch = [x for x in d.candidates if x.cause == "linear_mismatch"]
    assert mismatch and all(x.block_errors is not None for x in mismatch)  # scored on the held-out blocks
    assert not any(x.refined for x in mismatch)
    # seed 2 had four leaders (``max_refined``), the mismatch among them: three are refined
    assert len({x.cause for x in d.candidates if x.refined}) == Settings().max_refined - 1


def test_a_contact_behind_a_baseline_worse_than_zero_is_named(cases):
    # an expected failure from `21ca610` to stop 76 (nothing found; the refined contact gained 0.39 over the
    # baseline and -0.001 over its own linear part): named since the joint fit may add the hidden mode
    c, d, _ = cases[3]
    v = judge(c, d, 0.0)
    assert v.right and v.extra == 0, d.verdict()


def test_a_linear_algebra_failure_in_the_search_is_a_failed_candidate_not_a_crash(monkeypatch):
    # issue 10: an optimiser or linear-algebra failure is a failed candidate in the report, never a crash
    # (discover's except clauses named a tuple it had not imported: the first failure raised NameError)
    def failing(*args, **kwargs):
        raise np.linalg.LinAlgError("SVD did not converge")

    monkeypatch.setattr(importlib.import_module("ident.discovery.discover"), "regressions", failing)
    c = independent_case(15)  # a Duffing oscillator with nothing hidden
    d = discover(c.measurement)
    assert not d.findings
    assert any("regression failed (SVD did not converge)" in n for n in d.notes)


def test_the_noise_floor_is_the_instruments_noise_band_passed_on_the_scored_blocks(cases):
    # the floor (``ident bench discovery`` prints each baseline against it) recomputed apart: the generator's
    # noise (recorded minus its noise-free channels), band-passed in the time domain by scipy with the
    # Butterworth pair whose zero-phase magnitude the discovery's FFT filter uses (high-pass order 2, low-pass
    # order 4, each forward and backward), its RMS over the held-out blocks over each response's held-out std
    c, d, _ = cases[63]
    floor = noise_floor(d, c.measurement, c.reference)
    p, rows = d.prep, d.split.rows("test")
    lo, hi = p.band
    hp, lp = butter(2, lo, "highpass", fs=p.fs_hz, output="sos"), butter(4, hi, "lowpass", fs=p.fs_hz, output="sos")
    apart = []
    for i, (ch, ref) in enumerate(zip(c.measurement.responses, c.reference.responses)):
        noise = sosfiltfilt(lp, sosfiltfilt(hp, np.asarray(ch.values) - np.asarray(ref.values)))
        apart.append(np.sqrt(np.mean(noise[rows] ** 2)) / p.measured[rows, i].std())
    assert floor == pytest.approx(np.mean(apart), rel=0.005)  # 0.11 % apart on seed 63 (6e-5 on seed 1)
    # the noise is real and small: the record's SNR was drawn at 20-40 dB, and a model cannot beat it
    assert 0 < floor < d.baseline_test_nrmse
