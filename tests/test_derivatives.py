import numpy as np
import pytest

from ident.derivatives import differentiate, noise_sigma, tvregdiff


@pytest.mark.parametrize("method,opts,tol", [
    ("tvregdiff", {}, 1e-3),
    ("savgol", {"window": 31, "order": 4}, 1e-4),
    ("spectral", {}, 1e-2),
    ("gradient", {}, 1e-3),
])
def test_smooth_signal_against_analytic_derivative(method, opts, tol):
    t = np.linspace(0, 10, 2001)
    f = np.sin(1.3 * t) + 0.5 * np.cos(0.4 * t)
    df = 1.3 * np.cos(1.3 * t) - 0.2 * np.sin(0.4 * t)
    u = differentiate(f, t[1] - t[0], method, **opts)
    inner = slice(20, -20)
    assert np.max(np.abs(u[inner] - df[inner])) < tol


def test_tvregdiff_recovers_the_step_derivative_of_a_kinked_signal():
    """|t - 1/2| has derivative sign(t - 1/2): TV keeps the jump, local polynomials smear it."""
    rng = np.random.default_rng(3)
    t = np.linspace(0, 1, 1001)
    dx = t[1] - t[0]
    f = np.abs(t - 0.5) + 0.01 * rng.standard_normal(t.size)
    truth = np.sign(t - 0.5)
    u_tv = tvregdiff(f, dx)
    u_sg = differentiate(f, dx, "savgol", window=51, order=2)
    away = (np.abs(t - 0.5) > 0.05) & (t > 0.02) & (t < 0.98)
    rms_tv = np.sqrt(np.mean((u_tv - truth)[away] ** 2))
    rms_sg = np.sqrt(np.mean((u_sg - truth)[away] ** 2))
    assert rms_tv < 0.01
    assert rms_tv < rms_sg / 5
    # the jump is sharp: within 20 samples of the kink the derivative has switched sign
    assert u_tv[480] < -0.8 and u_tv[520] > 0.8


def test_noise_estimate_matches_added_noise():
    rng = np.random.default_rng(1)
    t = np.linspace(0, 20, 5000)
    assert noise_sigma(np.sin(t) + 0.05 * rng.standard_normal(t.size)) == pytest.approx(0.05, rel=0.1)


def test_bad_input_is_a_clear_value_error():
    with pytest.raises(ValueError, match="unknown differentiation method 'bogus'"):
        differentiate(np.arange(10.0), 0.1, "bogus")
    with pytest.raises(ValueError, match="NaN"):
        tvregdiff(np.array([0, 1, np.nan, 3, 4, 5.0]), 0.1)
    with pytest.raises(ValueError, match="at least"):
        differentiate(np.arange(10.0), 0.1, "savgol", window=31)
    with pytest.raises(ValueError, match="spacing"):
        tvregdiff(np.arange(10.0), 0.0)
