"""Ensemble SINDy by block bootstrap: against a plain loop of STLSQ and against least-squares theory."""

import numpy as np
import pytest

from ident.ensemble import block_bootstrap, block_counts
from ident.library import PolynomialForcingLibrary
from ident.sindy import stlsq


def _system(n=800, noise=0.05, seed=0):
    """A linear oscillator's library on two tones and a random force, with known coefficients."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / 200.0
    z = np.sin(2 * np.pi * 3 * t) + 0.3 * np.sin(2 * np.pi * 7.1 * t)
    v = np.gradient(z, t)
    force = rng.normal(size=n)
    lib = PolynomialForcingLibrary(2, 3, True, ("z", "v"))
    theta = lib.transform(np.column_stack([z, v]), force)
    true = np.zeros((lib.n_terms, 2))
    true[lib.names.index("v"), 0] = 1.0
    true[lib.names.index("z"), 1] = -50.0
    true[lib.names.index("v"), 1] = -0.5
    true[-1, 1] = -1.0
    dx = theta @ true + noise * rng.normal(size=(n, 2))
    return lib, theta, dx, true


def test_every_model_is_stlsq_on_its_resampled_rows():
    """The batched normal-equation solve gives, model by model, what STLSQ gives on the stacked rows."""
    _, theta, dx, _ = _system()
    counts = block_counts(12, 8, np.random.default_rng(3))
    ens = block_bootstrap(theta, dx, 0.05, counts=counts)
    scale = np.sqrt(np.mean(theta**2, axis=0))
    edges = np.linspace(0, len(theta), 9).astype(int)
    for m in range(len(counts)):
        rows = np.concatenate([np.arange(edges[b], edges[b + 1]) for b in range(8) for _ in range(int(counts[m, b]))])
        xi = stlsq(theta[rows] / scale, dx[rows], 0.05) / scale[:, None]
        np.testing.assert_allclose(ens.coefficients[m], xi, rtol=1e-6, atol=1e-9)
    assert counts.sum(axis=1).tolist() == [8] * 12


def test_spread_matches_the_least_squares_standard_error():
    """Threshold 0 is least squares; with independent noise the bootstrap spread of a coefficient is its
    standard error sigma sqrt(diag((Theta' Theta)^-1)) (Efron & Tibshirani 1993, ch. 9)."""
    sigma = 0.05
    lib, theta, dx, true = _system(n=2000, noise=sigma, seed=1)
    cols = [lib.names.index("z"), lib.names.index("v"), lib.n_terms - 1]  # a well-posed regression
    th = theta[:, cols]
    ens = block_bootstrap(th, dx[:, 1], 0.0, n_models=600, n_blocks=40, rng=np.random.default_rng(2))
    se = sigma * np.sqrt(np.diag(np.linalg.inv(th.T @ th)))
    np.testing.assert_allclose(ens.std[:, 0], se, rtol=0.2)
    np.testing.assert_allclose(ens.mean[:, 0], true[cols, 1], atol=4 * se.max())


def test_inclusion_probability_separates_true_terms_from_noise():
    lib, theta, dx, true = _system(noise=0.05)
    ens = block_bootstrap(theta, dx, 0.05, n_models=64, rng=np.random.default_rng(4))
    assert np.all(ens.inclusion[true != 0] == 1.0)
    assert ens.inclusion[true == 0].max() < 0.2
    assert np.all(ens.std[true == 0][ens.inclusion[true == 0] == 0] == 0)


def test_bad_input():
    _, theta, dx, _ = _system(n=100)
    with pytest.raises(ValueError, match="rows"):
        block_bootstrap(theta, dx[:50], 0.1)
    with pytest.raises(ValueError, match="too few"):
        block_bootstrap(theta[:10], dx[:10], 0.1)
