"""Fast time integration of identified models driven by a sampled forcing signal.

Classical fixed-step Runge-Kutta 4 on the sampling grid (optionally with
sub-steps), the forcing between samples taken from a cubic spline through the
samples. The integrator is a numba-compiled kernel over a batch of coefficient
matrices, so a sparsification sweep or a finite-difference gradient is one
call; a batch whose models share one sparsity pattern (a gradient's) is
integrated side by side, vectorised over the models, with the same numbers. A model that leaves ``bound`` or goes non-finite is flagged as diverged,
its remaining samples are NaN, and nothing is raised.

Accuracy: on the paper's Duffing case (dt = 0.01) this matches a solve_ivp
(DOP853, rtol = atol = 1e-12) reference to better than 1e-6 (tests/test_simulate.py).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numba import njit, prange
from scipy.interpolate import CubicSpline
from scipy.linalg.lapack import dgtsv as _gtsv

from .library import PolynomialForcingLibrary


@dataclass(frozen=True)
class Simulation:
    """Result of a batch integration.

    x: (B, N, n) states at the sample times (NaN after divergence).
    diverged: (B,) True where the trajectory left the bound or became non-finite.
    """

    x: np.ndarray
    diverged: np.ndarray


@lru_cache(maxsize=16)
def _chain(library: PolynomialForcingLibrary) -> tuple[np.ndarray, np.ndarray]:
    """Each monomial k > 0 as (parent monomial, state): theta[k] = theta[parent] * x[state].

    Cached per library (a frozen value): an SQP refinement integrates a few hundred times, and building
    this took as long as integrating a rig model over a window."""
    index = {tuple(p): k for k, p in enumerate(library.powers)}
    k_poly = library.powers.shape[0]
    parent = np.zeros(k_poly, dtype=np.int64)
    var = np.zeros(k_poly, dtype=np.int64)
    for k in range(1, k_poly):
        p = library.powers[k].copy()
        v = int(np.flatnonzero(p)[-1])
        p[v] -= 1
        parent[k], var[k] = index[tuple(p)], v
    return parent, var


@njit(cache=True, nogil=True, inline="always")
def _rhs(terms, values, starts, parent, var, k_top, forcing_at, x, f, theta, out):  # pragma: no cover - compiled
    """out = Theta(x, f) Xi with Xi given by its non-zero entries (see ``_sparse``): the monomials up to the
    highest one the model uses, then per equation the sum over its terms in term order. Inlined into the
    RK4 loop: called (four times a step, passing seven arrays each time) it made the integration 2.5 times slower."""
    theta[0] = 1.0
    for k in range(1, k_top):
        theta[k] = theta[parent[k]] * x[var[k]]
    if forcing_at >= 0:
        theta[forcing_at] = f
    for i in range(out.shape[0]):
        acc = 0.0
        for j in range(starts[i], starts[i + 1]):
            acc += values[j] * theta[terms[j]]
        out[i] = acc


@njit(cache=True, nogil=True)
def _sparse(c, k_poly):  # pragma: no cover - compiled
    """A model's non-zero coefficients per equation, in term order: (terms, values, starts, k_top), equation i
    holding entries starts[i] .. starts[i + 1]; k_top is one past the highest monomial used.

    Summing only these in term order adds the same products in the same order as the dense sum that skips
    zeros, so the result is bit for bit the same; a rig model holds 5-8 of the 22 entries, and skipping the
    rest makes the integration a quarter faster."""
    kk, n = c.shape
    terms = np.empty(kk * n, np.int64)
    values = np.empty(kk * n)
    starts = np.zeros(n + 1, np.int64)
    j = 0
    k_top = 1
    for i in range(n):
        for k in range(kk):
            if c[k, i] != 0.0:
                terms[j] = k
                values[j] = c[k, i]
                j += 1
                if k < k_poly:
                    k_top = max(k_top, k + 1)
        starts[i + 1] = j
    return terms, values, starts, k_top


@njit(cache=True, nogil=True)
def _rk4_model(c, parent, var, k_poly, forcing, x0, dt, f_stage, m, bound, out):  # pragma: no cover
    """Integrate one model into ``out`` (n_t, n), pre-filled with NaN; True if it diverged."""
    n = x0.shape[0]
    terms, values, starts, k_top = _sparse(c, k_poly)
    forcing_at = k_poly if forcing else -1
    theta = np.empty(c.shape[0])
    k1 = np.empty(n)
    k2 = np.empty(n)
    k3 = np.empty(n)
    k4 = np.empty(n)
    xs = np.empty(n)
    x = x0.copy()
    out[0] = x
    for i in range(dt.shape[0]):
        h = dt[i] / m
        for s in range(m):
            f0 = f_stage[i, 2 * s]
            fm = f_stage[i, 2 * s + 1]
            f1 = f_stage[i, 2 * s + 2]
            _rhs(terms, values, starts, parent, var, k_top, forcing_at, x, f0, theta, k1)
            for q in range(n):
                xs[q] = x[q] + 0.5 * h * k1[q]
            _rhs(terms, values, starts, parent, var, k_top, forcing_at, xs, fm, theta, k2)
            for q in range(n):
                xs[q] = x[q] + 0.5 * h * k2[q]
            _rhs(terms, values, starts, parent, var, k_top, forcing_at, xs, fm, theta, k3)
            for q in range(n):
                xs[q] = x[q] + h * k3[q]
            _rhs(terms, values, starts, parent, var, k_top, forcing_at, xs, f1, theta, k4)
            for q in range(n):
                x[q] = x[q] + (h / 6.0) * (k1[q] + 2.0 * k2[q] + 2.0 * k3[q] + k4[q])
        for q in range(n):
            if not (abs(x[q]) <= bound):  # also catches NaN
                return True
        out[i + 1] = x
    return False


@njit(cache=True, nogil=True)
def _rk4_serial(coefs, parent, var, k_poly, forcing, x0, dt, f_stage, m, bound):  # pragma: no cover
    b, _, n = coefs.shape
    out = np.full((b, dt.shape[0] + 1, n), np.nan)
    diverged = np.zeros(b, dtype=np.bool_)
    for j in range(b):
        diverged[j] = _rk4_model(coefs[j], parent, var, k_poly, forcing, x0[j], dt, f_stage, m, bound, out[j])
    return out, diverged


@njit(cache=True, parallel=True, nogil=True)
def _rk4_parallel(coefs, parent, var, k_poly, forcing, x0, dt, f_stage, m, bound):  # pragma: no cover
    b, _, n = coefs.shape
    out = np.full((b, dt.shape[0] + 1, n), np.nan)
    diverged = np.zeros(b, dtype=np.bool_)
    for j in prange(b):
        diverged[j] = _rk4_model(coefs[j], parent, var, k_poly, forcing, x0[j], dt, f_stage, m, bound, out[j])
    return out, diverged


@njit(cache=True, nogil=True, inline="always")
def _rhs_lockstep(terms, values, starts, parent, var, k_top, forcing_at, x, f, theta, out):  # pragma: no cover
    """``_rhs`` for a batch of models with one sparsity pattern, the models along the last axis (x, out (n, B),
    values (nnz, B)): each model's products and sums in the same order as ``_rhs``, so the same numbers."""
    b = x.shape[1]
    for j in range(b):
        theta[0, j] = 1.0
    for k in range(1, k_top):
        pk = parent[k]
        vk = var[k]
        for j in range(b):
            theta[k, j] = theta[pk, j] * x[vk, j]
    if forcing_at >= 0:
        for j in range(b):
            theta[forcing_at, j] = f
    for i in range(out.shape[0]):
        for j in range(b):
            out[i, j] = 0.0
        for e in range(starts[i], starts[i + 1]):
            k = terms[e]
            for j in range(b):
                out[i, j] += values[e, j] * theta[k, j]


@njit(cache=True, nogil=True)
def _rk4_lockstep(coefs, parent, var, k_poly, forcing, x0, dt, f_stage, m, bound):  # pragma: no cover
    """``_rk4_serial`` for a batch whose models share one sparsity pattern (an SQP refinement's gradient:
    every model perturbs one coefficient or initial state of the same model), integrated side by side so
    that each operation runs over the whole batch (vectorised) instead of one model at a time. A model
    that diverges keeps being stepped (its values are no longer used): its rows after divergence stay
    NaN, as in ``_rk4_model``."""
    b, kk, n = coefs.shape
    terms, _, starts, k_top = _sparse(coefs[0], k_poly)
    nnz = starts[n]
    values = np.empty((nnz, b))
    for j in range(b):
        values[:, j] = _sparse(coefs[j], k_poly)[1][:nnz]
    forcing_at = k_poly if forcing else -1
    out = np.full((b, dt.shape[0] + 1, n), np.nan)
    diverged = np.zeros(b, dtype=np.bool_)
    theta = np.empty((kk, b))
    k1 = np.empty((n, b))
    k2 = np.empty((n, b))
    k3 = np.empty((n, b))
    k4 = np.empty((n, b))
    xs = np.empty((n, b))
    x = np.empty((n, b))
    for j in range(b):
        for q in range(n):
            x[q, j] = x0[j, q]
            out[j, 0, q] = x0[j, q]
    alive = b
    for i in range(dt.shape[0]):
        h = dt[i] / m
        for s in range(m):
            f0 = f_stage[i, 2 * s]
            fm = f_stage[i, 2 * s + 1]
            f1 = f_stage[i, 2 * s + 2]
            _rhs_lockstep(terms, values, starts, parent, var, k_top, forcing_at, x, f0, theta, k1)
            for q in range(n):
                for j in range(b):
                    xs[q, j] = x[q, j] + 0.5 * h * k1[q, j]
            _rhs_lockstep(terms, values, starts, parent, var, k_top, forcing_at, xs, fm, theta, k2)
            for q in range(n):
                for j in range(b):
                    xs[q, j] = x[q, j] + 0.5 * h * k2[q, j]
            _rhs_lockstep(terms, values, starts, parent, var, k_top, forcing_at, xs, fm, theta, k3)
            for q in range(n):
                for j in range(b):
                    xs[q, j] = x[q, j] + h * k3[q, j]
            _rhs_lockstep(terms, values, starts, parent, var, k_top, forcing_at, xs, f1, theta, k4)
            for q in range(n):
                for j in range(b):
                    x[q, j] = x[q, j] + (h / 6.0) * (k1[q, j] + 2.0 * k2[q, j] + 2.0 * k3[q, j] + k4[q, j])
        for j in range(b):
            if diverged[j]:
                continue
            for q in range(n):
                if not (abs(x[q, j]) <= bound):  # also catches NaN
                    diverged[j] = True
                    alive -= 1
                    break
            if not diverged[j]:
                for q in range(n):
                    out[j, i + 1, q] = x[q, j]
        if alive == 0:
            break
    return out, diverged


def _not_a_knot(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(knots, coefficients (4, n - 1)) of scipy's CubicSpline(x, y) (not-a-knot ends, n >= 4 ascending
    knots, y 1-D): its own expressions and LAPACK's tridiagonal solver (gtsv, as its solve_banded calls),
    so the same numbers; scipy's input validation around them cost five times the arithmetic, once per
    rolling window."""
    n = x.size
    dx = np.diff(x)
    slope = np.diff(y, axis=0) / dx
    a = np.zeros((3, n))  # banded: upper diagonal, diagonal, lower diagonal
    b = np.empty(n)
    a[1, 1:-1] = 2 * (dx[:-1] + dx[1:])
    a[0, 2:] = dx[:-1]
    a[-1, :-2] = dx[1:]
    b[1:-1] = 3 * (dx[1:] * slope[:-1] + dx[:-1] * slope[1:])
    a[1, 0] = dx[1]
    a[0, 1] = x[2] - x[0]
    d = x[2] - x[0]
    b[0] = ((dx[0] + 2 * d) * dx[1] * slope[0] + dx[0]**2 * slope[1]) / d
    a[1, -1] = dx[-2]
    a[-1, -2] = x[-1] - x[-3]
    d = x[-1] - x[-3]
    b[-1] = ((dx[-1]**2 * slope[-2] + (2 * d + dx[-1]) * dx[-2] * slope[-1]) / d)
    _, _, _, s, info = _gtsv(a[2, :-1], a[1, :], a[0, 1:], b.reshape(n, -1), True, True, True, True)
    if info != 0:
        raise np.linalg.LinAlgError(f"spline system singular (gtsv info {info})")
    s = s.reshape(n)
    t = (s[:-1] + s[1:] - 2 * slope) / dx  # scipy's CubicHermiteSpline from here
    return x, np.stack((t / dx, (slope - s[:-1]) / dx - t, s[:-1], y[:-1]))


@njit(cache=True, nogil=True)
def _spline_eval(x, c, xs):  # pragma: no cover - compiled
    """scipy's PPoly evaluation (scipy/interpolate/_ppoly.pyx: evaluate, find_interval_ascending,
    evaluate_poly1) of the cubic pieces c (4, n - 1) on knots x at the points xs: the interval by its binary
    search from the previous one (half-open, the last closed, extrapolated beyond the ends), the polynomial
    as sum_k c[3 - k] s^k with the powers built by products, in that order."""
    nx = x.shape[0]
    out = np.empty(xs.shape[0])
    interval = 0
    for ip in range(xs.shape[0]):
        xval = xs[ip]
        if not (x[0] <= xval <= x[nx - 1]):
            interval = 0 if xval < x[0] else nx - 2  # (NaN cannot reach here: checked by the caller)
        elif xval == x[nx - 1]:
            interval = nx - 2
        else:
            if xval >= x[interval]:
                low, high = interval, nx - 2
            else:
                low, high = 0, interval
            if xval < x[low + 1]:
                high = low
            while low < high:
                mid = (high + low) // 2
                if xval < x[mid]:
                    high = mid
                elif xval >= x[mid + 1]:
                    low = mid + 1
                else:
                    low = mid
                    break
            interval = low
        sv = xval - x[interval]
        res = 0.0
        z = 1.0
        for kp in range(4):
            res = res + c[3 - kp, interval] * z
            if kp < 3:
                z *= sv
        out[ip] = res
    return out


KERNELS = (_rk4_serial, _rk4_parallel, _rk4_lockstep, _spline_eval)  # the compiled integration kernels (see kernels_cached)


def kernels_cached(kernels=KERNELS) -> bool | None:
    """Whether numba's disk cache holds the given compiled kernels (default: the integration kernels), so
    they load in milliseconds instead of compiling for seconds; None where this numba keeps its cache
    elsewhere."""
    try:
        return all(os.path.exists(k._cache._cache_file._index_path) for k in kernels)
    except AttributeError:
        return None


# Below this many model-steps a batch runs on one thread: the pool's overhead would dominate.
PARALLEL_MIN_WORK = 200_000


_STAGE_CACHE: dict[tuple, np.ndarray] = {}


def _forcing_stages(t: np.ndarray, forcing: np.ndarray, m: int) -> np.ndarray:
    """Forcing at every RK4 stage time t_i + j h/2, j = 0 .. 2m, from a cubic spline of the samples.

    Cached by content (a sweep, an SQP run and a rolling fit integrate many
    models against the same forcing); the cache holds the last few.
    """
    key = (hash(t.tobytes()), hash(forcing.tobytes()), t.size, m)
    hit = _STAGE_CACHE.get(key)
    if hit is not None:
        return hit
    if not np.all(np.isfinite(forcing)):
        raise ValueError("forcing contains NaN or inf")
    dt = np.diff(t)
    frac = np.arange(2 * m) / (2 * m)
    t_stage = (t[:-1, None] + dt[:, None] * frac[None]).ravel()
    if t.size >= 4 and np.all(dt > 0):
        f_stage = _spline_eval(*_not_a_knot(t, forcing), t_stage).reshape(t.size - 1, 2 * m)
    else:
        f_stage = CubicSpline(t, forcing)(t_stage).reshape(t.size - 1, 2 * m)
    f_stage = np.ascontiguousarray(np.concatenate([f_stage, forcing[1:, None]], axis=1))
    if len(_STAGE_CACHE) >= 8:
        _STAGE_CACHE.pop(next(iter(_STAGE_CACHE)))
    _STAGE_CACHE[key] = f_stage
    return f_stage


def simulate(
    library: PolynomialForcingLibrary,
    coefs: np.ndarray,
    x0: np.ndarray,
    t: np.ndarray,
    forcing: np.ndarray | None = None,
    *,
    substeps: int = 1,
    bound: float = np.inf,
) -> Simulation:
    """Integrate dx/dt = Theta(x, F(t)) Xi from ``x0`` over the sample times ``t``.

    coefs: (K, n) for one model or (B, K, n) for a batch. x0: (n,) or (B, n).
    forcing: samples of F at ``t`` (required when the library has F).
    bound: a trajectory whose state exceeds this magnitude counts as diverged.
    """
    coefs = np.asarray(coefs, dtype=float)
    single = coefs.ndim == 2
    if single:
        coefs = coefs[None]
    b, k, n = coefs.shape
    if k != library.n_terms or n != library.n_states:
        raise ValueError(
            f"coefficients have shape {(k, n)}, library expects {(library.n_terms, library.n_states)}"
        )
    t = np.asarray(t, dtype=float)
    if t.ndim != 1 or t.size < 2:
        raise ValueError("t must be a 1-D array of at least 2 sample times")
    dt = np.diff(t)
    if not np.all(dt > 0):
        raise ValueError("t must be strictly increasing")
    # a writable copy: numba compiles a kernel apart for a read-only array (as a broadcast view is), and a
    # kernel compiled in the middle of a stream (the first refinement's) stalls it for seconds
    x0 = np.array(np.broadcast_to(np.asarray(x0, dtype=float), (b, n)), order="C")
    if not np.all(np.isfinite(x0)):
        raise ValueError("initial state contains NaN or inf")
    m = int(substeps)
    if m < 1:
        raise ValueError("substeps must be >= 1")

    n_t = t.size
    if library.forcing:
        if forcing is None:
            raise ValueError("this model has a forcing term F: pass the forcing samples")
        forcing = np.asarray(forcing, dtype=float)
        if forcing.shape != t.shape:
            raise ValueError(f"forcing has {forcing.shape[0]} samples, t has {t.size}")
        f_stage = _forcing_stages(t, forcing, m)
    else:
        f_stage = np.zeros((n_t - 1, 2 * m + 1))

    parent, var = _chain(library)
    if b * (n_t - 1) * m >= PARALLEL_MIN_WORK:
        kernel = _rk4_parallel
    elif b > 1 and np.array_equal(np.broadcast_to(coefs[:1] != 0, coefs.shape), coefs != 0):
        kernel = _rk4_lockstep  # one sparsity pattern: the models side by side (the same numbers)
    else:
        kernel = _rk4_serial
    coefs = np.require(coefs, requirements=("C", "W"))  # writable, as x0: one compiled signature per kernel
    res, diverged = kernel(coefs, parent, var, library.powers.shape[0], library.forcing, x0, dt,
                           np.ascontiguousarray(f_stage), m, float(bound))
    if single:
        return Simulation(res[0], diverged[:1])
    return Simulation(res, diverged)


def reference_solution(
    library: PolynomialForcingLibrary,
    coefs: np.ndarray,
    x0: np.ndarray,
    t: np.ndarray,
    forcing: np.ndarray | None = None,
    *,
    rtol: float = 1e-12,
    atol: float = 1e-12,
) -> np.ndarray:
    """Tight-tolerance scipy ``solve_ivp`` (DOP853) solution with the same spline forcing.

    Slow; the yardstick that :func:`simulate` is tested against.
    """
    from scipy.integrate import solve_ivp

    coefs = np.asarray(coefs, dtype=float)
    spline = CubicSpline(t, forcing) if library.forcing else None

    def rhs(tt, x):
        f = spline(tt) if spline is not None else None
        return library.transform(x, f) @ coefs

    sol = solve_ivp(rhs, (t[0], t[-1]), np.asarray(x0, float), t_eval=t,
                    method="DOP853", rtol=rtol, atol=atol)
    if not sol.success:
        raise RuntimeError(f"reference integration failed: {sol.message}")
    return sol.y.T
