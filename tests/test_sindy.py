import numpy as np
import pytest

from ident.paper.duffing import DuffingParams, coefficient_errors
from ident.library import PolynomialForcingLibrary
from ident.sindy import identify, integration_errors, refine, sweep


def test_table1_clean_duffing_coefficients_within_1e6(duffing):
    res = identify(duffing.x, duffing.xdot, duffing.t, duffing.forcing, degree=3)
    err = coefficient_errors(res.model, DuffingParams().true_coefficients())
    assert err["active_set_exact"]
    assert err["max_abs_error"] < 1e-6
    # the Pareto curve runs from every term to none
    assert res.sweep.n_nonzero.max() == 2 * 11 and res.sweep.n_nonzero.min() == 0


def test_lorenz_recovery(lorenz):
    t, x, dx = lorenz
    res = identify(x[:5000], dx[:5000], t[:5000], None, degree=2, do_refine=False)
    c = res.model.as_dict()
    expected = {"x1'": {"x1": -10.0, "x2": 10.0},
                "x2'": {"x1": 28.0, "x2": -1.0, "x1 x3": -1.0},
                "x3'": {"x3": -8 / 3, "x1 x2": 1.0}}
    assert {k: set(v) for k, v in c.items()} == {k: set(v) for k, v in expected.items()}
    for eq, terms in expected.items():
        for term, value in terms.items():
            assert c[eq][term] == pytest.approx(value, rel=1e-6)


def test_sweep_survives_diverging_candidates(duffing):
    """Noisy derivatives of a softening system: some candidates blow up; the sweep scores them."""
    rng = np.random.default_rng(1)
    lib = PolynomialForcingLibrary(2, 3)
    xd = duffing.xdot + 2.0 * rng.standard_normal(duffing.x.shape)  # SNR of the derivative ~ -3 dB
    sw = sweep(lib, duffing.x, xd, duffing.t, duffing.forcing)
    assert sw.diverged.any()
    assert np.all(np.isinf(sw.errors[sw.diverged]))
    assert np.isfinite(sw.errors[sw.chosen])


def test_refinement_lowers_the_integration_error(duffing):
    lib = PolynomialForcingLibrary(2, 3)
    rng = np.random.default_rng(0)
    x = duffing.x + 0.05 * rng.standard_normal(duffing.x.shape)
    sw = sweep(lib, x, duffing.xdot + 0.3 * rng.standard_normal(x.shape), duffing.t, duffing.forcing)
    ref = refine(lib, sw.coefficients[sw.chosen], x, duffing.t, duffing.forcing)
    assert ref.error_before == pytest.approx(sw.errors[sw.chosen], rel=1e-6, abs=1e-3)
    assert ref.error_after < ref.error_before
    # bounds hold: every refined coefficient within +-50 % of its regression value
    c0 = sw.coefficients[sw.chosen]
    assert np.all(np.abs(ref.coefficients - c0) <= 0.5 * np.abs(c0) + 1e-12)


@pytest.mark.parametrize("mutate,match", [
    (lambda x, d, t, f: (np.where(np.arange(x.size).reshape(x.shape) == 7, np.nan, x), d, t, f), "NaN"),
    (lambda x, d, t, f: (x, d, t, f[:-1]), "samples"),
    (lambda x, d, t, f: (x[:15], d[:15], t[:15], f[:15]), "too few"),
    (lambda x, d, t, f: (np.column_stack([x[:, 0], np.ones(len(x))]), d, t, f), "constant"),
])
def test_bad_input_raises_a_clear_value_error(duffing, mutate, match):
    x, d, t, f = mutate(duffing.x, duffing.xdot, duffing.t, duffing.forcing)
    with pytest.raises(ValueError, match=match):
        identify(x, d, t, f)


@pytest.mark.parametrize("n_states", [1, 2, 3, 9])
def test_integration_errors_of_offset_trajectories(n_states):
    """A trajectory off by a constant c_j in each state has NRMSE mean_j(|c_j| / std_j) exactly in real
    numbers; a diverged one (NaN) has inf. Both the compiled path (two to seven states) and numpy's."""
    rng = np.random.default_rng(n_states)
    x = rng.normal(size=(500, n_states)) * rng.uniform(0.1, 10.0, size=n_states)
    c = rng.normal(size=(4, n_states))
    sim = x[None] + c[:, None, :]
    sim[3, 200:] = np.nan
    err = integration_errors(sim, x)
    expected = np.mean(np.abs(c) / x.std(axis=0), axis=1)
    np.testing.assert_allclose(err[:3], expected[:3], rtol=1e-12)
    assert err[3] == np.inf
    np.testing.assert_array_equal(integration_errors(sim, x, x.std(axis=0)), err)
