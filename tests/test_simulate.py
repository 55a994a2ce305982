import numpy as np
import pytest

from ident.paper.duffing import DuffingParams
from ident.library import PolynomialForcingLibrary
from ident.model import SindyModel
from ident.simulate import reference_solution, simulate


def eq8() -> SindyModel:
    return SindyModel.from_dict({"states": ["x1", "x2"], "degree": 3, "forcing": True,
                                 "equations": DuffingParams().true_coefficients()})


def test_matches_tight_solve_ivp_reference_on_duffing_to_1e6(duffing):
    m = eq8()
    ours = m.simulate(duffing.x[0], duffing.t, duffing.forcing).x
    ref = reference_solution(m.library, m.coefficients, duffing.x[0], duffing.t, duffing.forcing)
    assert np.max(np.abs(ours - ref)) < 1e-6
    # and the spline forcing is not a shortcut: against the analytic-cosine solution too
    assert np.max(np.abs(ours - duffing.x)) < 1e-6


def test_batch_equals_one_by_one_and_divergence_is_flagged(duffing):
    m = eq8()
    lib = m.library
    bad = m.coefficients.copy()
    bad[lib.names.index("x1^3"), 1] = +3.0  # softening cubic: escapes to infinity
    batch = np.stack([m.coefficients, bad, 0.5 * m.coefficients])
    sim = simulate(lib, batch, [0.0, 0.0], duffing.t, duffing.forcing, bound=100.0)
    assert sim.diverged.tolist() == [False, True, False]
    assert np.isnan(sim.x[1, -1]).all() and np.isfinite(sim.x[[0, 2]]).all()
    one = simulate(lib, batch[2], [0.0, 0.0], duffing.t, duffing.forcing, bound=100.0)
    np.testing.assert_array_equal(one.x, sim.x[2])


def test_unforced_linear_oscillator_has_the_analytic_solution():
    lib = PolynomialForcingLibrary(2, 1, forcing=False)
    c = np.zeros((3, 2))
    c[2, 0] = 1.0  # x1' = x2
    c[1, 1] = -4.0  # x2' = -4 x1  -> x1 = cos(2 t)
    t = np.linspace(0, 10, 2001)
    x = simulate(lib, c, [1.0, 0.0], t).x
    assert np.max(np.abs(x[:, 0] - np.cos(2 * t))) < 1e-7


def test_bad_arguments():
    lib = PolynomialForcingLibrary(2, 1)
    c = np.zeros((4, 2))
    t = np.linspace(0, 1, 11)
    with pytest.raises(ValueError, match="forcing"):
        simulate(lib, c, [0, 0], t)
    with pytest.raises(ValueError, match="increasing"):
        simulate(lib, c, [0, 0], t[::-1], np.zeros(11))
    with pytest.raises(ValueError, match="NaN"):
        simulate(lib, c, [np.nan, 0], t, np.zeros(11))
    with pytest.raises(ValueError, match="shape"):
        simulate(lib, np.zeros((3, 2)), [0, 0], t, np.zeros(11))


def test_forcing_stages_are_scipys_cubic_spline():
    """The forcing at the RK4 stages is scipy's not-a-knot CubicSpline through the samples, bit for bit
    (uneven spacing, two and three sub-steps, points beyond the ends extrapolated as scipy does)."""
    from scipy.interpolate import CubicSpline

    from ident.simulate import _forcing_stages, _not_a_knot, _spline_eval

    rng = np.random.default_rng(5)
    t = np.cumsum(rng.uniform(0.002, 0.01, size=300))
    f = np.sin(40 * t) + 0.1 * rng.normal(size=t.size)
    for m in (1, 2, 3):
        frac = np.arange(2 * m) / (2 * m)
        ts = (t[:-1, None] + np.diff(t)[:, None] * frac[None]).ravel()
        stages = _forcing_stages(t, f, m)
        np.testing.assert_array_equal(stages[:, :-1].ravel(), CubicSpline(t, f)(ts))
        np.testing.assert_array_equal(stages[:, -1], f[1:])
    beyond = np.array([t[0] - 0.05, t[-1], t[-1] + 0.05])
    np.testing.assert_array_equal(_spline_eval(*_not_a_knot(t, f), beyond), CubicSpline(t, f)(beyond))
