"""Rolling SINDy in physical coordinates against the rig's known parameters."""

from dataclasses import replace

import numpy as np
import pytest

from daq.sim.excitation import Excitation
from scipy.signal import sosfiltfilt

from ident.filters import design_highpass
from ident.physical import integrate_band
from daq.sim.rig import RigConfig, simulate_rig
from ident.rig import RigParams
from ident.live.pipeline import IDENTIFY_KERNELS, MONITOR_KERNELS, warm_up
from ident.live.regimes import RegimeConfig, RegimeMonitor
from ident.live.rolling import RollingConfig, RollingIdentifier
from daq.sim.sensors import to_counts


def test_band_limited_integration_of_a_sine():
    fs = 2000.0
    t = np.arange(0, 4, 1 / fs)
    w = 2 * np.pi * 12.3
    a = -(w**2) * 1e-3 * np.sin(w * t) + 0.05  # with an offset that plain integration would blow up
    v, z = integrate_band(a, fs)
    mid = slice(2000, -2000)
    np.testing.assert_allclose(z[mid], 1e-3 * np.sin(w * t)[mid], atol=2e-5)
    np.testing.assert_allclose(v[mid], w * 1e-3 * np.cos(w * t)[mid], atol=0.01 * w * 1e-3)


@pytest.fixture(scope="module")
def linear_rig_fits():
    """Linear rig (no stoppers, no coupling) under broadband base noise: parameters are identifiable."""
    p = RigParams().with_beams(gap_pos_m=np.inf, gap_neg_m=np.inf)
    p = replace(p, coupling_stiffness_n_per_m=0.0, beam2=replace(p.beam2, natural_frequency_hz=10.5))
    cfg = RigConfig(rig=p, excitation=Excitation(amplitude_m_per_s2=0.0, noise_rms_m_per_s2=2.0,
                                                 noise_band_hz=(2.0, 40.0), ramp_s=0.5))
    t, o = simulate_rig(cfg, 14.0)
    rng = np.random.default_rng(0)
    x = np.column_stack([to_counts(s, se, rng)[0] * se.lsb_m_per_s2
                         for s, se in zip((o.base, o.tip1, o.tip2), cfg.sensors)])
    ri = RollingIdentifier(RollingConfig(degree=1))
    fits = []
    for k in range(0, len(x), 333):  # serial-read-sized blocks
        fits += ri.step(x[k:k + 333])
    fits += ri.finish()
    return p, fits, x, o.z


def test_identified_stiffness_and_damping_match_the_rig(linear_rig_fits):
    p, fits, _, _ = linear_rig_fits
    assert len(fits) >= 9
    for beam, fit in zip((p.beam1, p.beam2), fits[-1].beams):
        w = 2 * np.pi * beam.natural_frequency_hz
        c = fit.model.as_dict()["v'"]
        assert fit.stiffness_per_mass == pytest.approx(w**2, rel=0.02)
        assert fit.natural_frequency_hz == pytest.approx(beam.natural_frequency_hz, rel=0.01)
        assert -c["v"] == pytest.approx(2 * beam.damping_ratio * w, rel=0.15)
        assert c["F"] == pytest.approx(-1.0, abs=0.05)  # the base drives the tip with -m a_b
        assert set(c) <= {"1", "z", "v", "F"}
        assert fit.error < 0.1


def test_steady_data_gives_no_model_change_after_warm_up(linear_rig_fits):
    _, fits, _, _ = linear_rig_fits
    assert not any(b.changed for f in fits[3:] for b in f.beams)


def test_fits_do_not_depend_on_how_the_stream_is_cut(linear_rig_fits):
    """Windows end on the hop grid (1 s) whatever the block sizes: the same fits for random blocks."""
    _, fits, x, _ = linear_rig_fits
    final = [f for f in fits if f.final]
    assert np.allclose(np.diff([f.t_s for f in final]), 1.0, rtol=0, atol=1e-12)
    assert not fits[0].final and fits[1].final and fits[1].t_s == fits[0].t_s  # the first window is refined
    ri = RollingIdentifier(RollingConfig(degree=1))
    rng = np.random.default_rng(1)
    other, k = [], 0
    while k < len(x):
        n = int(rng.integers(1, 2500))
        other += ri.step(x[k:k + n])
        k += n
    other += ri.finish()
    assert [(f.t_s, f.final) for f in other] == [(f.t_s, f.final) for f in fits]
    for a, b in zip(fits, other):
        for ba, bb in zip(a.beams, b.beams):
            assert ba.model.as_dict() == bb.model.as_dict()
            assert np.array_equal(ba.coefficient_std, bb.coefficient_std)


def test_uncertainty_and_backbone(linear_rig_fits):
    """Each window carries its ensemble: the true terms always in, the natural frequency's spread far
    below its error bound, and the amplitude is the simulated relative displacement's (sqrt 2 RMS)."""
    p, fits, _, z_true = linear_rig_fits
    fs = 2000.0
    for fit in [f for f in fits if f.final][3:]:
        for i, (beam, b) in enumerate(zip((p.beam1, p.beam2), fit.beams)):
            names = b.model.library.names
            assert b.inclusion[names.index("z"), 1] == 1.0 and b.inclusion[names.index("F"), 1] == 1.0
            assert b.inclusion[names.index("v"), 0] == 1.0
            assert 0 < b.natural_frequency_std_hz < 0.01 * beam.natural_frequency_hz
            assert b.coefficient_std[names.index("z"), 1] > 0
            # the simulated displacement in the integration's band (above 2 Hz), over the window's span
            sl = slice(int(round((fit.t[0]) * fs)), int(round(fit.t[-1] * fs)) + 1)
            zb = sosfiltfilt(design_highpass(fs, 2.0, 2), z_true[:, i])[sl]
            assert b.amplitude_m == pytest.approx(np.sqrt(2) * np.sqrt(np.mean(zb**2)), rel=0.03)
            # the terms' RMS over the window: the constant 1, z's is the amplitude's over sqrt 2, F's the base's
            assert b.term_rms[names.index("1")] == 1.0
            assert b.term_rms[names.index("z")] == pytest.approx(b.amplitude_m / np.sqrt(2), rel=1e-12)
            assert b.term_rms[names.index("F")] == pytest.approx(np.sqrt(np.mean(fit.base**2)), rel=1e-12)


def test_warm_up_compiles_the_kernels_the_fits_run(linear_rig_fits):
    """One compiled signature per kernel, the one warm_up compiles: the fits (filters, integration, sweeps,
    refinements, ensembles) ran before, and a second signature (a read-only array is one) would have been
    compiled in mid-stream, stalling the first refinement for seconds. The regime monitor's kernels too:
    warm_up compiles them whether or not the identification runs."""
    RegimeMonitor(RegimeConfig()).step(linear_rig_fits[2][:4000])
    warm_up()
    kernels = MONITOR_KERNELS + IDENTIFY_KERNELS
    assert {k.__name__: len(k.signatures) for k in kernels} == {k.__name__: 1 for k in kernels}
