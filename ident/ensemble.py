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
from numba import njit


@dataclass(frozen=True)
class Ensemble:
    mean: np.ndarray  # (K, n) mean coefficient over the models (zeros included)
    std: np.ndarray  # (K, n) standard deviation over the models (zeros included)
    inclusion: np.ndarray  # (K, n) share of models in which the term is non-zero
    coefficients: np.ndarray  # (B, K, n) every model


def block_counts(n_models: int, n_blocks: int, rng: np.random.Generator) -> np.ndarray:
    """(n_models, n_blocks) how often each block is drawn: n_blocks draws with replacement per model."""
    draws = rng.integers(0, n_blocks, size=(n_models, n_blocks))
    cells = (draws + n_blocks * np.arange(n_models)[:, None]).ravel()  # model m's draw of block j: cell m n_blocks + j
    return np.bincount(cells, minlength=n_models * n_blocks).reshape(n_models, n_blocks).astype(float)


def column_rms(theta: np.ndarray) -> np.ndarray:
    """(K,) the RMS of each library column over the rows: the scale on which thresholds are set (a
    coefficient times its column's RMS is its term's contribution)."""
    return np.sqrt(np.mean(np.asarray(theta, float) ** 2, axis=0))


def block_bootstrap(theta: np.ndarray, dxdt: np.ndarray, threshold: float | np.ndarray, *, n_models: int = 32,
                    n_blocks: int = 8, rng: np.random.Generator | None = None, max_iter: int = 20,
                    counts: np.ndarray | None = None, rms: np.ndarray | None = None) -> Ensemble:
    """STLSQ at ``threshold`` (unit-RMS columns, as the sweep's thresholds; one per equation if an array)
    on block-bootstrap resamples.

    theta: (N, K) library on the window's rows; dxdt: (N, n) derivatives. ``counts`` (B, n_blocks)
    fixes the resamples (else drawn from ``rng``). ``rms``: ``column_rms(theta)`` where the caller has it.
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
    scale = np.array(column_rms(theta) if rms is None else rms, float)
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
    if k * dxdt.shape[1] > 1:
        return Ensemble(*_ensemble_stats(xi, scale))
    coefs = xi / scale[None, :, None]  # a single coefficient: numpy sums its models pairwise, the kernel in order
    return Ensemble(coefs.mean(axis=0), coefs.std(axis=0), (coefs != 0).mean(axis=0), coefs)


@njit(cache=True, nogil=True)
def _ensemble_stats(xi, scale):  # pragma: no cover - compiled
    """(mean, std, inclusion, coefficients) of the models xi (B, K, n), K n > 1, on unit-RMS columns, the coefficients
    xi / scale: numpy's coefs.mean(axis=0), coefs.std(axis=0) and (coefs != 0).mean(axis=0) bit for bit (an
    axis-0 reduction of a C-contiguous array adds the models in order; std is the square root of the mean
    squared deviation from that mean), without five numpy calls on a (32, 11, 2) array."""
    b_n, k, n = xi.shape
    coefs = np.empty((b_n, k, n))
    mean = np.zeros((k, n))
    var = np.zeros((k, n))
    inclusion = np.zeros((k, n))
    for b in range(b_n):
        for i in range(k):
            for e in range(n):
                v = xi[b, i, e] / scale[i]
                coefs[b, i, e] = v
                mean[i, e] += v
                inclusion[i, e] += v != 0.0
    for i in range(k):
        for e in range(n):
            mean[i, e] = mean[i, e] / b_n
            inclusion[i, e] = inclusion[i, e] / b_n
    for b in range(b_n):
        for i in range(k):
            for e in range(n):
                d = coefs[b, i, e] - mean[i, e]
                var[i, e] += d * d
    std = np.sqrt(var / b_n)
    return mean, std, inclusion, coefs


def model_thresholds(theta: np.ndarray, coefficients: np.ndarray, fallback: float = 0.0, *,
                     rms: np.ndarray | None = None) -> np.ndarray:
    """Per equation, half the smallest active coefficient on unit-RMS columns: the threshold at which the
    ensemble asks whether each of the model's terms survives resampling (``fallback`` for an empty
    equation). ``rms``: ``column_rms(theta)`` where the caller has it."""
    scale = column_rms(theta) if rms is None else rms
    mags = np.abs(np.asarray(coefficients, float)) * scale[:, None]
    out = np.full(mags.shape[1], float(fallback))
    for e in range(mags.shape[1]):
        active = mags[:, e][mags[:, e] > 0]
        if active.size:
            out[e] = 0.5 * float(active.min())
    return out


def _batched_stlsq(a: np.ndarray, c: np.ndarray, threshold: np.ndarray, max_iter: int) -> np.ndarray:
    """STLSQ on normal equations a xi = c for a batch: a (B, K, K), c (B, K, n) -> xi (B, K, n).

    Every model and equation is one small system, solved on its active terms until they stop changing
    (``_stlsq_normal``, compiled: a rolling window's ensemble is 64 systems of 11 terms, for which numpy's
    batched solve spent most of its time building masked arrays).
    """
    k = a.shape[1]
    # a tiny ridge against exactly collinear columns (a single tone makes z, v and F nearly so)
    a = a + 1e-12 * np.trace(a, axis1=1, axis2=2)[:, None, None] * np.eye(k)
    xi, singular = _stlsq_normal(np.ascontiguousarray(a), np.ascontiguousarray(c),
                                 np.array(threshold, dtype=float), int(max_iter))  # writable: one compiled signature
    if singular:
        raise np.linalg.LinAlgError("singular normal equations in the ensemble: a library column is all zero")
    return xi


@njit(cache=True, nogil=True)
def _stlsq_normal(a, c, threshold, max_iter):  # pragma: no cover - compiled
    """(xi (B, K, n), singular) for ``_batched_stlsq``: per model b and equation e, solve the normal
    equations restricted to the active terms (Gaussian elimination with partial pivoting), drop the terms
    below threshold[e], repeat until none drops or ``max_iter`` solves."""
    bsz, k, n = c.shape
    xi = np.zeros((bsz, k, n))
    idx = np.empty(k, np.int64)
    m = np.empty((k, k))
    r = np.empty(k)
    active = np.empty(k, np.bool_)
    for b in range(bsz):
        for e in range(n):
            active[:] = True
            for _ in range(max_iter):
                na = 0
                for j in range(k):
                    if active[j]:
                        idx[na] = j
                        na += 1
                for p in range(na):
                    r[p] = c[b, idx[p], e]
                    for q in range(na):
                        m[p, q] = a[b, idx[p], idx[q]]
                if not _solve_in_place(m, r, na):
                    return xi, True
                dropped = False
                for j in range(k):
                    xi[b, j, e] = 0.0
                for p in range(na):
                    if abs(r[p]) >= threshold[e]:
                        xi[b, idx[p], e] = r[p]
                    else:
                        active[idx[p]] = False
                        dropped = True
                if not dropped:
                    break
    return xi, False


@njit(cache=True, nogil=True, inline="always")
def _solve_in_place(m, r, na):  # pragma: no cover - compiled
    """Solve m[:na, :na] x = r[:na] into r by Gaussian elimination with partial pivoting (as LAPACK's
    gesv); False if a pivot is exactly zero."""
    for col in range(na):
        piv = col
        for row in range(col + 1, na):
            if abs(m[row, col]) > abs(m[piv, col]):
                piv = row
        if m[piv, col] == 0.0:
            return False
        if piv != col:
            for q in range(col, na):
                m[col, q], m[piv, q] = m[piv, q], m[col, q]
            r[col], r[piv] = r[piv], r[col]
        for row in range(col + 1, na):
            f = m[row, col] / m[col, col]
            if f != 0.0:
                for q in range(col + 1, na):
                    m[row, q] -= f * m[col, q]
                r[row] -= f * r[col]
    for row in range(na - 1, -1, -1):
        acc = r[row]
        for q in range(row + 1, na):
            acc -= m[row, q] * r[q]
        r[row] = acc / m[row, row]
    return True


KERNELS = (_stlsq_normal, _ensemble_stats)  # the compiled kernels (ident.simulate.kernels_cached)
