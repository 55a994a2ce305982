"""Ensemble SINDy by block bootstrap: each coefficient's spread and each term's inclusion probability.

Ensemble SINDy (Fasel, Kutz, Brunton & Brunton, Proc. R. Soc. A 478, 20210904, 2022; pysindy's
``EnsembleOptimizer``) fits the sparse regression on many bootstrap resamples of the rows
("bagging") and reads the spread of each coefficient over the ensemble as its uncertainty and the
share of models in which a term is non-zero as its inclusion probability. Rows of a time series
are not independent (neighbouring samples carry the same noise after filtering), so the rows are
resampled in contiguous blocks (the moving-block bootstrap of Kunsch, Ann. Stat. 17, 1989): the
window is cut into ``n_blocks`` blocks and each model draws ``n_blocks`` of them with
replacement.

Each model is sequentially thresholded least squares (``ident.sindy.stlsq``) at the given
threshold on unit-RMS columns; for the ensemble of an identified model, ``model_thresholds`` puts
it per equation at half the model's smallest active coefficient, so that every term of the model
is asked whether it survives resampling at the model's own sparsity. Since the blocks partition the rows, a resample's normal
equations are the count-weighted sum of the blocks' Gram matrices, so the whole ensemble is a
batch of small solves (library size squared), not a regression per model on the rows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Ensemble:
    mean: np.ndarray  # (K, n) mean coefficient over the models (zeros included)
    std: np.ndarray  # (K, n) standard deviation over the models (zeros included)
    inclusion: np.ndarray  # (K, n) share of models in which the term is non-zero
    coefficients: np.ndarray  # (B, K, n) every model


def block_counts(n_models: int, n_blocks: int, rng: np.random.Generator) -> np.ndarray:
    """(n_models, n_blocks) how often each block is drawn: n_blocks draws with replacement per model."""
    draws = rng.integers(0, n_blocks, size=(n_models, n_blocks))
    return np.stack([np.bincount(d, minlength=n_blocks) for d in draws]).astype(float)


def block_bootstrap(theta: np.ndarray, dxdt: np.ndarray, threshold: float | np.ndarray, *, n_models: int = 32,
                    n_blocks: int = 8, rng: np.random.Generator | None = None, max_iter: int = 20,
                    counts: np.ndarray | None = None) -> Ensemble:
    """STLSQ at ``threshold`` (unit-RMS columns, as the sweep's thresholds; one per equation if an array)
    on block-bootstrap resamples.

    theta: (N, K) library on the window's rows; dxdt: (N, n) derivatives. ``counts`` (B, n_blocks)
    fixes the resamples (else drawn from ``rng``).
    """
    theta = np.asarray(theta, float)
    dxdt = np.asarray(dxdt, float)
    if dxdt.ndim == 1:
        dxdt = dxdt[:, None]
    n, k = theta.shape
    if dxdt.shape[0] != n:
        raise ValueError(f"theta has {n} rows, derivatives {dxdt.shape[0]}")
    if n < 2 * n_blocks:
        raise ValueError(f"{n} rows are too few for {n_blocks} blocks")
    scale = np.sqrt(np.mean(theta**2, axis=0))
    scale[scale == 0] = 1.0
    tn = theta / scale
    edges = np.linspace(0, n, n_blocks + 1).astype(int)
    gram = np.stack([tn[a:b].T @ tn[a:b] for a, b in zip(edges[:-1], edges[1:])])  # (nb, K, K)
    cross = np.stack([tn[a:b].T @ dxdt[a:b] for a, b in zip(edges[:-1], edges[1:])])  # (nb, K, n)
    if counts is None:
        counts = block_counts(n_models, n_blocks, rng if rng is not None else np.random.default_rng(0))
    a = np.einsum("mb,bij->mij", counts, gram)
    c = np.einsum("mb,bij->mij", counts, cross)
    thr = np.broadcast_to(np.asarray(threshold, float), (dxdt.shape[1],))
    xi = _batched_stlsq(a, c, thr, max_iter)
    coefs = xi / scale[None, :, None]
    return Ensemble(coefs.mean(axis=0), coefs.std(axis=0), (coefs != 0).mean(axis=0), coefs)


def model_thresholds(theta: np.ndarray, coefficients: np.ndarray, fallback: float = 0.0) -> np.ndarray:
    """Per equation, half the smallest active coefficient on unit-RMS columns: the threshold at which the
    ensemble asks whether each of the model's terms survives resampling (``fallback`` for an empty
    equation)."""
    scale = np.sqrt(np.mean(np.asarray(theta, float) ** 2, axis=0))
    mags = np.abs(np.asarray(coefficients, float)) * scale[:, None]
    out = np.full(mags.shape[1], float(fallback))
    for e in range(mags.shape[1]):
        active = mags[:, e][mags[:, e] > 0]
        if active.size:
            out[e] = 0.5 * float(active.min())
    return out


def _batched_stlsq(a: np.ndarray, c: np.ndarray, threshold: np.ndarray, max_iter: int) -> np.ndarray:
    """STLSQ on normal equations a xi = c for a batch: a (B, K, K), c (B, K, n) -> xi (B, K, n).

    Every model and equation is one small system; inactive terms are pinned to zero by replacing their
    rows and columns with the identity, so each iteration is one batched solve.
    """
    bsz, k, n = c.shape
    eye = np.eye(k)
    # a tiny ridge against exactly collinear columns (a single tone makes z, v and F nearly so)
    a = a + 1e-12 * np.trace(a, axis1=1, axis2=2)[:, None, None] * eye
    aa = np.repeat(a[:, None], n, axis=1).reshape(bsz * n, k, k)  # (B n, K, K): model b, equation e
    cc = np.moveaxis(c, 2, 1).reshape(bsz * n, k)
    thr = np.tile(np.asarray(threshold, float), bsz)[:, None]
    active = np.ones((bsz * n, k), bool)
    xi = np.zeros((bsz * n, k))
    for _ in range(max_iter):
        mm = active[:, :, None] & active[:, None, :]
        sys = np.where(mm, aa, 0.0) + (~active)[:, :, None] * eye
        xi = np.linalg.solve(sys, np.where(active, cc, 0.0)[:, :, None])[:, :, 0]
        new = active & (np.abs(xi) >= thr)
        xi[~new] = 0.0
        if np.array_equal(new, active):
            break
        active = new
    return np.moveaxis(xi.reshape(bsz, n, k), 1, 2)
