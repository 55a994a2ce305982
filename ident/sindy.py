"""Sparse identification: STLSQ regression, the sparsification sweep, SQP refinement.

- Regression (Brunton et al. 2016, PNAS 113, 3932): sequentially thresholded
  least squares dX = Theta(X, F) Xi (paper eqs. 5-7).
- Sweep (Stender et al. 2019, Vibration 2, 25-46): the threshold lambda runs
  from 0 (every term active) to above the largest coefficient (none active);
  each distinct candidate is integrated with the measured forcing and scored
  by its integration error against the measured states. The sparsest candidate
  whose error is within a factor (1 + ``tolerance``) of the smallest is chosen
  (default 0.5: before refinement, candidates on the plateau differ by
  regression noise of tens of percent, while a missing true term costs
  orders of magnitude); the whole Pareto curve (non-zero count vs error) is
  returned.
- Refinement (Stender et al. 2019): the non-zero coefficients are optimised by
  SQP (scipy SLSQP) within bounds around their regression values, minimising
  the same integration error; gradients by central differences, all
  perturbed models integrated in one batch.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.optimize import minimize

from .library import PolynomialForcingLibrary
from .model import SindyModel
from .simulate import simulate


@dataclass(frozen=True)
class SweepResult:
    """Candidates of the sparsification sweep, one row each, sorted by non-zero count."""

    thresholds: np.ndarray  # (C,) lambda that produced each candidate
    n_nonzero: np.ndarray  # (C,)
    errors: np.ndarray  # (C,) integration NRMSE; inf where diverged
    diverged: np.ndarray  # (C,)
    coefficients: np.ndarray  # (C, K, n)
    chosen: int


@dataclass(frozen=True)
class Refinement:
    error_before: float
    error_after: float
    coefficients: np.ndarray
    iterations: int
    success: bool
    message: str


@dataclass(frozen=True)
class Identification:
    sparse: SindyModel  # chosen by the sweep
    model: SindyModel  # after refinement (== sparse when refinement is off)
    sweep: SweepResult
    refinement: Refinement | None


def _check_data(x: np.ndarray, dxdt: np.ndarray | None, t: np.ndarray, forcing: np.ndarray | None,
                library: PolynomialForcingLibrary) -> None:
    if x.ndim != 2:
        raise ValueError(f"states must be a 2-D array (samples, states), got shape {x.shape}")
    n_samples = x.shape[0]
    arrays = {"states": x, "t": t}
    if dxdt is not None:
        arrays["derivatives"] = dxdt
    if forcing is not None:
        arrays["forcing"] = forcing
    for name, a in arrays.items():
        if a.shape[0] != n_samples:
            raise ValueError(f"{name} has {a.shape[0]} samples but states have {n_samples}: "
                             "pass arrays of equal length")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} contain NaN or inf: remove or interpolate those samples first")
    if dxdt is not None and dxdt.shape != x.shape:
        raise ValueError(f"derivatives have shape {dxdt.shape}, states {x.shape}")
    if n_samples < 2 * library.n_terms:
        raise ValueError(f"{n_samples} samples are too few for a library of {library.n_terms} terms; "
                         f"need at least {2 * library.n_terms}: record longer or lower the degree")
    if np.any(x.std(axis=0) == 0):
        raise ValueError("a state is constant: a constant signal carries no dynamics to identify")
    if library.forcing and forcing is None:
        raise ValueError("the library has a forcing column F: pass the forcing signal")


def _lstsq(theta: np.ndarray, y: np.ndarray, ridge: float) -> np.ndarray:
    """Least squares, with ridge ``ridge * N`` on unit-RMS columns when ridge > 0."""
    if ridge <= 0:
        return np.linalg.lstsq(theta, y, rcond=None)[0]
    k = theta.shape[1]
    aug = np.vstack([theta, np.sqrt(ridge * theta.shape[0]) * np.eye(k)])
    pad = np.zeros((k,) + y.shape[1:])
    return np.linalg.lstsq(aug, np.concatenate([y, pad]), rcond=None)[0]


def stlsq(theta: np.ndarray, dxdt: np.ndarray, threshold: float, max_iter: int = 20,
          initial: np.ndarray | None = None, ridge: float = 0.0) -> np.ndarray:
    """Sequentially thresholded least squares (Brunton et al. 2016, Algorithm in SI).

    Coefficients with magnitude below ``threshold`` are zeroed and the rest re-fitted,
    until the active set stops changing. ``initial`` warm-starts the active set.
    ``ridge`` > 0 adds Tikhonov regularisation (as pysindy's STLSQ ``alpha``),
    for libraries whose columns are nearly collinear (single-tone steady states).
    """
    xi = _lstsq(theta, dxdt, ridge) if initial is None else np.array(initial, float)
    return _stlsq(xi, threshold, max_iter, lambda big, i: _lstsq(theta[:, big], dxdt[:, i], ridge))


def _stlsq(xi: np.ndarray, threshold: float, max_iter: int, solve) -> np.ndarray:
    """STLSQ's iterations from the coefficients ``xi`` (changed in place); ``solve(big, i)`` is the least-squares
    fit of equation i on the terms where ``big`` is true (the sweep memoises it across thresholds)."""
    for _ in range(max_iter):
        small = np.abs(xi) < threshold
        xi[small] = 0.0
        changed = False
        for i in range(xi.shape[1]):
            big = ~small[:, i]
            if not big.any():
                continue
            new = solve(big, i)
            if np.any(np.abs(new) < threshold):
                changed = True
            xi[big, i] = new
        if not changed:
            break
    xi[np.abs(xi) < threshold] = 0.0
    return xi


def integration_errors(sim_x: np.ndarray, x: np.ndarray, scale: np.ndarray | None = None) -> np.ndarray:
    """NRMSE of each simulated trajectory (B, N, n) against measured states (N, n); inf if NaN.

    ``scale``: the states' standard deviations, x.std(axis=0), where the caller has them (an SQP
    refinement asks for the errors of hundreds of trajectories against the same x). Per trajectory the
    mean over the states of RMS(sim - x) / scale, computed in a compiled kernel (``_nrmse``) in numpy's
    order for these arrays: this runs as often as the integrator, and numpy's per-call overhead on the
    small arrays made it cost as much as integrating one model.
    """
    if scale is None:
        scale = x.std(axis=0)
    sim_x = np.asarray(sim_x, float)
    if not 2 <= sim_x.shape[2] < 8:  # numpy's orders of summation differ there (pairwise over a single state's
        # rows, over eight or more states); the kernel's are those of two to seven states
        d = sim_x - x[None]
        rms = np.sqrt(np.add.reduce(d * d, axis=1) / x.shape[0])  # (B, n)
        err = np.add.reduce(rms / scale, axis=1) / x.shape[1]
        err[~np.isfinite(err)] = np.inf
        return err
    return _nrmse(np.require(sim_x, float, "CW"), np.require(x, float, "CW"), np.require(scale, float, "CW"))


@njit(cache=True, nogil=True, error_model="numpy")  # x / 0 is inf or nan, as in numpy, not an exception
def _nrmse(sim_x, x, scale):  # pragma: no cover - compiled
    """``integration_errors`` for two to seven states, bit for bit numpy's
    mean(sqrt(add.reduce((sim - x)**2, axis=1) / N) / scale): the rows' squares added in order (a reduction
    over the middle axis of a C-contiguous array), then the states' ratios in order (numpy's pairwise sum
    of fewer than eight terms is sequential); inf where the result is not finite (a diverged trajectory)."""
    b_n, n_t, n = sim_x.shape
    err = np.empty(b_n)
    acc = np.empty(n)
    for b in range(b_n):
        acc[:] = 0.0
        for i in range(n_t):
            for j in range(n):
                d = sim_x[b, i, j] - x[i, j]
                acc[j] += d * d
        e = 0.0
        for j in range(n):
            e += np.sqrt(acc[j] / n_t) / scale[j]
        e = e / n
        err[b] = e if np.isfinite(e) else np.inf
    return err


KERNELS = (_nrmse,)  # the compiled kernels (ident.live.pipeline.warm_up)


def sweep(library: PolynomialForcingLibrary, x: np.ndarray, dxdt: np.ndarray, t: np.ndarray,
          forcing: np.ndarray | None = None, *, tolerance: float = 0.5, bound_factor: float = 20.0,
          max_candidates: int = 200, ridge: float = 0.0) -> SweepResult:
    """Sparsification sweep chosen by integration error (Stender et al. 2019)."""
    x = np.asarray(x, float)
    dxdt = np.asarray(dxdt, float)
    t = np.asarray(t, float)
    forcing = None if forcing is None else np.asarray(forcing, float)
    _check_data(x, dxdt, t, forcing, library)
    theta = library.transform(x, forcing)
    # Threshold in normalised units: each column scaled to unit RMS, so a
    # coefficient's size is its term's contribution (pysindy's normalize_columns).
    scale = np.sqrt(np.mean(theta**2, axis=0))
    scale[scale == 0] = 1.0
    theta_n = theta / scale
    xi0 = _lstsq(theta_n, dxdt, ridge)
    mags = np.unique(np.abs(xi0[xi0 != 0]))
    # Thresholds between consecutive magnitudes give every count from all to none.
    lambdas = np.concatenate([[0.0], 0.5 * (mags[:-1] + mags[1:]), [mags[-1] * 1.01 if mags.size else 1.0]])
    if lambdas.size > max_candidates:
        lambdas = np.quantile(lambdas, np.linspace(0, 1, max_candidates))
    # Every threshold's STLSQ starts from xi0 and refits subsets of terms; different thresholds refit the
    # same subsets again and again (a rolling window's sweep asked for about 100 fits, 30 of them distinct), so each
    # subset is fitted once. The same numbers as a plain stlsq per threshold.
    fits: dict[tuple[int, bytes], np.ndarray] = {}

    def solve(big: np.ndarray, i: int) -> np.ndarray:
        key = (i, big.tobytes())
        if key not in fits:
            fits[key] = _lstsq(theta_n[:, big], dxdt[:, i], ridge)
        return fits[key]

    cands: dict[bytes, tuple[float, np.ndarray]] = {}
    for lam in lambdas:
        xi = _stlsq(xi0.copy(), lam, 20, solve) / scale[:, None]
        key = (xi != 0).tobytes()
        cands.setdefault(key, (float(lam), xi))
    lams = np.array([v[0] for v in cands.values()])
    coefs = np.stack([v[1] for v in cands.values()])
    nnz = np.count_nonzero(coefs.reshape(len(coefs), -1), axis=1)
    order = np.argsort(-nnz, kind="stable")
    lams, coefs, nnz = lams[order], coefs[order], nnz[order]
    bound = bound_factor * float(np.max(np.abs(x)))
    sim = simulate(library, coefs, x[0], t, forcing, bound=bound)
    err = integration_errors(sim.x, x)
    err[sim.diverged] = np.inf
    chosen = _choose(err, nnz, tolerance)
    return SweepResult(lams, nnz, err, sim.diverged, coefs, chosen)


def _choose(err: np.ndarray, nnz: np.ndarray, tolerance: float) -> int:
    finite = np.isfinite(err) & (nnz > 0)
    if not finite.any():
        raise ValueError("every candidate model diverged or was empty: the data may not be "
                         "described by this library; try another degree, embedding or derivative method")
    best = np.min(err[finite])
    ok = np.flatnonzero(finite & (err <= best * (1.0 + tolerance)))
    return int(ok[np.argmin(nnz[ok])])


def refine(library: PolynomialForcingLibrary, coefs: np.ndarray, x: np.ndarray, t: np.ndarray,
           forcing: np.ndarray | None = None, *, rel_bound: float = 0.5, maxiter: int = 100,
           bound_factor: float = 20.0, fit_initial: bool = True, gradient: str = "central") -> Refinement:
    """SQP (SLSQP) on the non-zero coefficients within +-rel_bound of their values.

    Minimises the squared integration NRMSE; reports the error before and after.
    With ``fit_initial`` the initial state is optimised too (within half a
    standard deviation of the first sample): a noisy first sample otherwise
    biases the whole trajectory fit. ``gradient``: "central" differences
    (2p integrations per gradient) or "forward" (p, for live use), beside
    the one integration per point at which the objective is asked.
    """
    if gradient not in ("central", "forward"):
        raise ValueError(f"unknown gradient scheme {gradient!r}; choose central or forward")
    x = np.asarray(x, float)
    t = np.asarray(t, float)
    coefs = np.asarray(coefs, float)
    active = coefs != 0
    n_c = int(active.sum())
    if n_c == 0:
        raise ValueError("nothing to refine: the model has no non-zero coefficient")
    x0 = x[0].copy()
    n_x = x.shape[1] if fit_initial else 0
    p0 = np.concatenate([coefs[active], x0[:n_x]])
    bound = bound_factor * float(np.max(np.abs(x)))
    scale = x.std(axis=0)

    def batch(ps: np.ndarray) -> np.ndarray:
        cs = np.repeat(coefs[None], ps.shape[0], axis=0)
        cs[:, active] = ps[:, :n_c]
        starts = np.repeat(x0[None], ps.shape[0], axis=0)
        starts[:, :n_x] = ps[:, n_c:]
        sim = simulate(library, cs, starts, t, forcing, bound=bound)
        e = integration_errors(sim.x, x, scale)
        e[sim.diverged] = np.inf
        return e**2

    # SLSQP asks for the objective at every line-search point and for the gradient only at the accepted
    # ones (about half as often): the p perturbed integrations run only when a gradient is asked for, and
    # the objective at a point is integrated once (a gradient reuses it). The numbers are the ones a batch
    # of the point and its perturbations gives: every model is integrated on its own.
    errors: dict[bytes, float] = {}  # squared error (inf where diverged) per point

    def error(p: np.ndarray) -> float:
        key = p.tobytes()
        if key not in errors:
            errors[key] = float(batch(p[None])[0])
        return errors[key]

    def fun(p: np.ndarray) -> float:
        e = error(p)
        return e if np.isfinite(e) else 1e10

    def jac(p: np.ndarray) -> np.ndarray:
        h = 1e-6 * np.maximum(np.abs(p), 1e-3)
        with np.errstate(invalid="ignore"):  # inf - inf where a perturbation diverged
            if gradient == "central":
                e = batch(np.vstack([p + np.diag(h), p - np.diag(h)]))
                g = (e[:p.size] - e[p.size:]) / (2 * h)
            else:
                g = (batch(p + np.diag(h)) - error(p)) / h
        return np.where(np.isfinite(g), g, 0.0)

    widths = np.concatenate([rel_bound * np.abs(p0[:n_c]), 0.5 * x.std(axis=0)[:n_x]])
    res = minimize(fun, p0, jac=jac, method="SLSQP", bounds=list(zip(p0 - widths, p0 + widths)),
                   options={"maxiter": maxiter, "ftol": 1e-12})
    e0 = fun(p0)
    p = res.x if fun(res.x) <= e0 else p0
    e1 = fun(p)
    out = coefs.copy()
    out[active] = p[:n_c]
    return Refinement(float(np.sqrt(e0)), float(np.sqrt(e1)), out, int(res.nit), bool(res.success),
                      str(res.message))


def identify(x: np.ndarray, dxdt: np.ndarray, t: np.ndarray, forcing: np.ndarray | None = None, *,
             degree: int = 3, state_names: tuple[str, ...] | None = None, do_refine: bool = True,
             tolerance: float = 0.5, rel_bound: float = 0.5, ridge: float = 0.0) -> Identification:
    """The paper's pipeline on given states and derivatives: library, sweep, refinement."""
    x = np.asarray(x, float)
    if x.ndim == 1:
        x = x[:, None]
    dxdt = np.asarray(dxdt, float).reshape(x.shape[0], -1)
    lib = PolynomialForcingLibrary(x.shape[1], degree, forcing is not None, state_names)
    sw = sweep(lib, x, dxdt, t, forcing, tolerance=tolerance, ridge=ridge)
    sparse = SindyModel(lib, sw.coefficients[sw.chosen])
    if not do_refine:
        return Identification(sparse, sparse, sw, None)
    ref = refine(lib, sparse.coefficients, x, t, forcing, rel_bound=rel_bound)
    return Identification(sparse, SindyModel(lib, ref.coefficients), sw, ref)
