"""Discovery on a force-excited structure with a fitted linear modal baseline.

``ident discover DATA --baseline linear --excitation COL:force`` (an aircraft
in a ground vibration test, a frame on a shaker with a force cell). Response 1
is the driving point. Steps:

1. Baseline: a modal model (ident.modal) fitted on the baseline data (another
   recording at a low level, ``--fit-data``, or the training segment), run from
   rest with the measured force over the whole record; scored on the held-out
   segment (NRMSE of the accelerations, averaged over responses; not capped:
   above 1 the model does worse than predicting zero).
2. Physical coordinates: each response's displacement and velocity by
   band-limited integration (ident.physical, 1 Hz), and the relative motion of
   every pair of responses (an interface between them).
3. Catalogue: an internal force f(coordinate) acting on the structure at the
   response (grounded) or between the pair (+f on the first, -f on the
   second). It enters each mode through the gains reciprocity gives
   (ModalModel.input_gain), so its coefficient has physical units (N/m^3,
   N, ...). The coefficient is fitted by least squares to the residual
   (measured minus baseline accelerations, training segment) against the
   linear response to the term evaluated on the measured coordinate: SINDy on
   the discrepancy, one term at a time; a contact's gap and side are searched
   on a grid.
4. Every candidate runs closed loop (the force evaluated on the simulated
   coordinate) and is scored on the held-out segment. With separate baseline
   data, a candidate must also hold there (not spoil the baseline fit by more
   than the gain floor): an amplitude-dependent cause explains the high level
   without breaking the low one; an equivalent-linear change does not.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .discovery import lsq1, contact_shape, split
from .linear_discovery import T_CONTACT, T_COULOMB, T_CUBIC, T_LINEAR, T_QDAMP, T_QUAD, Term, term_values
from .modal import ModalModel, fit_modal, refine_poles, refit_residues, simulate
from .physical import edge_samples, integrate_band

MAX_MODES = 10
F_LO_HZ = 1.0


@dataclass(frozen=True)
class ModalCandidate:
    effect: str
    response: str  # a response name, or "A-B" for the relative motion of a pair
    parameters: dict
    term: tuple  # (code, coef, p1, p2) of the kernel
    b: np.ndarray  # modal input gains of the force
    wd: np.ndarray  # residues of the coordinate
    fit_r2: float
    test_nrmse: float = np.nan
    gain: float = np.nan
    fit_data_nrmse: float = np.nan  # on the baseline data (when given)
    holds_at_fit_level: bool = True
    model: ModalModel | None = None  # its own linear part (refitted jointly with the term), else the baseline


@dataclass(frozen=True)
class ModalDiscovery:
    model: ModalModel
    baseline_test_nrmse: float
    baseline_fit_nrmse: float  # the baseline on its own data (held-out part when fitted on DATA)
    extended_test_nrmse: float
    gain: float
    findings: list[ModalCandidate]
    candidates: list[ModalCandidate]
    train: slice
    test: slice
    residual_rms: dict
    baseline_sim: np.ndarray  # (n, k) accelerations of the baseline on DATA
    extended_sim: np.ndarray


def _nrmse(sim: np.ndarray, meas: np.ndarray) -> float:
    if not np.all(np.isfinite(sim)):
        return np.inf
    return float(np.mean(np.sqrt(np.mean((sim - meas) ** 2, axis=0)) / meas.std(axis=0)))


def _coordinates(Y: np.ndarray, fs: float, names: list[str]) -> dict[str, tuple[tuple[int, ...], np.ndarray, np.ndarray]]:
    """Each response and each pair 'A-B': (response indices, measured displacement, velocity)."""
    v, z = integrate_band(Y, fs, F_LO_HZ)
    k = Y.shape[1]
    out = {names[j]: ((j,), z[:, j], v[:, j]) for j in range(k)}
    for j in range(k):
        for i in range(j + 1, k):
            out[f"{names[j]}-{names[i]}"] = ((j, i), z[:, j] - z[:, i], v[:, j] - v[:, i])
    return out


def _gains(model: ModalModel, idx: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray]:
    """Modal input gains and displacement residues of a response (j,) or a pair (j, i)."""
    if len(idx) == 1:
        return model.input_gain(idx[0]), model.residues[idx[0]]
    return model.input_gain(*idx), model.residues[idx[0]] - model.residues[idx[1]]


def _shapes(zc: np.ndarray, vc: np.ndarray):
    """Catalogue shapes on a coordinate: (effect, code, p1, p2, values, parameter builder)."""
    eps = 0.01 * float(np.std(vc)) + 1e-12
    yield ("cubic_stiffness", T_CUBIC, 1.0, 0.0, zc**3, lambda c: {"coefficient_n_per_m3": -c})
    yield ("quadratic_stiffness", T_QUAD, 1.0, 0.0, zc * np.abs(zc), lambda c: {"coefficient_n_per_m2": -c})
    yield ("coulomb_friction", T_COULOMB, eps, 0.0, np.tanh(vc / eps), lambda c: {"force_n": -c})
    yield ("quadratic_damping", T_QDAMP, 1.0, 0.0, vc * np.abs(vc), lambda c: {"coefficient_n_s2_per_m2": -c})


def fit_order(F: np.ndarray, Y: np.ndarray, fs: float, seg: slice, max_modes: int = MAX_MODES) -> ModalModel:
    """The modal model of the lowest order after which two more modes no longer cut the simulation
    error on ``seg`` by 10 % (and 0.005): spare poles split a mode into a cluster whose driving-point
    residues are tiny, and an internal force entering through R_j / R_1 would blow up there."""
    nperseg = 2 ** int(np.log2(max(256, (seg.stop - seg.start) // 4)))
    kept, misses = None, 0
    for m in range(1, max_modes + 1):
        try:
            model, _ = fit_modal(F[seg], Y[seg], fs, m, nperseg=nperseg)
        except ValueError:
            break
        model = refine_poles(refit_residues(model, F, Y, fs, seg), F, Y, fs, seg, stride=4, max_nfev=12)
        err = _nrmse(simulate(model, F, fs)[seg], Y[seg])
        if kept is None or (err < 0.9 * kept[0] and kept[0] - err > 0.005):
            kept, misses = (err, model), 0
        else:
            misses += 1  # a mode can pair up with a neighbour first: look two orders further
            if misses == 2:
                break
    if kept is None:
        raise ValueError("too few excited frequency lines to fit a modal model")
    return kept[1]


def discover_modal(F: np.ndarray, Y: np.ndarray, names: list[str], fs: float, *, fit_data=None,
                   train: slice | None = None, test: slice | None = None, max_modes: int = MAX_MODES,
                   gain_floor: float = 0.05, joint_top: int = 3) -> ModalDiscovery:
    """F (n,) force, Y (n, k) accelerations (response 1 at the driving point); fit_data an optional
    (F, Y) at a low level to fit the linear baseline on."""
    F = np.asarray(F, float)
    Y = np.asarray(Y, float).reshape(len(F), -1)
    for arr in (F, Y) + (tuple(fit_data) if fit_data is not None else ()):
        if not np.all(np.isfinite(arr)):
            raise ValueError("data contain NaN or inf: repair or remove those samples first")
    n, k = Y.shape
    train, test = split(n, edge_samples(fs, F_LO_HZ), train, test)
    if fit_data is not None:
        Ff, Yf = np.asarray(fit_data[0], float), np.asarray(fit_data[1], float).reshape(len(fit_data[0]), -1)
        if Yf.shape[1] != k:
            raise ValueError(f"the baseline data have {Yf.shape[1]} responses, the data {k}")
        fit_seg = slice(edge_samples(fs, F_LO_HZ), len(Ff))
    else:
        Ff, Yf, fit_seg = F[:train.stop], Y[:train.stop], train
    model = fit_order(Ff, Yf, fs, fit_seg, max_modes)
    base_fit = _nrmse(simulate(model, Ff, fs)[fit_seg], Yf[fit_seg]) if fit_data is not None else np.nan
    base_sim = simulate(model, F, fs)
    base_err = _nrmse(base_sim[test], Y[test])
    d = Y - base_sim
    scale = Y[train].std(axis=0)
    resid = {names[j]: float(np.sqrt(np.mean(d[train, j] ** 2))) for j in range(k)}
    coords = _coordinates(Y, fs, names)
    bound = 50.0 * max(float(np.max(np.abs(zc))) for _, zc, _ in coords.values()) + 1e-12
    zero = np.zeros(n)

    def regress(b, g):
        """Least-squares coefficient of the force g (as a force on the structure) against the residual."""
        yg = simulate(model, zero, fs, b=b, g_ext=g)[train] / scale
        return lsq1(yg.ravel(), (d[train] / scale).ravel())

    cands = []
    for name, (idx, zc, vc) in coords.items():
        b, wd = _gains(model, idx)
        for effect, code, p1, p2, g, params in _shapes(zc, vc):
            c, r2 = regress(b, g)
            cands.append(ModalCandidate(effect, name, params(c), (code, c, p1, p2), b, wd, r2))
        # contact: gap and side on a grid, against the residual's force equivalent (the linear
        # response to a unit force is nearly proportional to the force over one coordinate)
        found = _best_contact(regress, b, zc)
        if found is not None:
            side, gap, c, r2 = found
            cands.append(ModalCandidate("contact", name, {"gap": gap, "side": side, "stiffness_n_per_m": -c},
                                        (T_CONTACT, c, gap, {"both": 0, "positive": 1, "negative": 2}[side]),
                                        b, wd, r2))
        # an interface spring and damper off nominal (equivalent linear)
        yz = simulate(model, zero, fs, b=b, g_ext=zc)[train] / scale
        yv = simulate(model, zero, fs, b=b, g_ext=vc)[train] / scale
        X = np.column_stack([yz.ravel(), yv.ravel()])
        dd = (d[train] / scale).ravel()
        ks, cs = np.linalg.lstsq(X, dd, rcond=None)[0]
        r2 = 1.0 - float(np.sum((dd - X @ [ks, cs]) ** 2)) / float(dd @ dd)
        cands.append(ModalCandidate("linear_mismatch", name, {"stiffness_n_per_m": -float(ks),
                                                               "damping_n_s_per_m": -float(cs)},
                                    (T_LINEAR, float(ks), 1.0, float(cs)), b, wd, r2))

    def score(c: ModalCandidate) -> ModalCandidate:
        mod = c.model or model
        sim = simulate(mod, F, fs, b=c.b, wd=c.wd, term=c.term, bound=bound)
        err = _nrmse(sim[test], Y[test])
        gain = 1.0 - err / base_err if np.isfinite(err) else -np.inf
        fit_err, holds = np.nan, True
        if fit_data is not None:
            fit_err = _nrmse(simulate(mod, Ff, fs, b=c.b, wd=c.wd, term=c.term, bound=bound)[fit_seg],
                             Yf[fit_seg])
            holds = bool(np.isfinite(fit_err) and fit_err <= base_fit * (1 + gain_floor))
        return replace(c, test_nrmse=err, gain=gain, fit_data_nrmse=fit_err, holds_at_fit_level=holds)

    scored = sorted((score(c) for c in cands), key=lambda c: -c.gain)
    if fit_data is not None:
        # the baseline data hold the effect too (weaker): refit the linear part with the term in place
        # for the leading nonlinear candidates, re-estimate the coefficient, score again
        coords_fit = _coordinates(Yf, fs, names)
        lead = [c for c in scored if c.effect != "linear_mismatch" and np.isfinite(c.gain)][:joint_top]
        scored = sorted([c for c in scored if all(c is not x for x in lead)]
                        + [score(_joint(c, model, Ff, Yf, fs, fit_seg, F, Y, train, scale, coords_fit, coords))
                           for c in lead], key=lambda c: -c.gain)
    # the best cause that also holds on the baseline data; if none does, the best by gain (flagged)
    above = [c for c in scored if c.gain > gain_floor]
    best = next((c for c in above if c.holds_at_fit_level), above[0] if above else None)
    findings = [best] if best is not None else []
    ext_sim = (simulate(best.model or model, F, fs, b=best.b, wd=best.wd, term=best.term, bound=bound)
               if best else base_sim)
    ext_err = best.test_nrmse if best else base_err
    return ModalDiscovery(model, base_err, base_fit, ext_err, 1.0 - ext_err / base_err, findings, scored, train,
                          test, resid, base_sim, ext_sim)


def _joint(c: ModalCandidate, model: ModalModel, Ff, Yf, fs, fit_seg, F, Y, train, scale, coords_fit,
           coords) -> ModalCandidate:
    """Refit the linear part on the baseline data driven by F and the candidate's force (evaluated on the
    measured coordinate there), then the coefficient on the data's residual with that linear part."""
    code, coef, p1, p2 = c.term
    shape = Term(c.effect, 0, code, 1.0, p1, p2)
    idx, zf, vf = coords_fit[c.response]
    g_fit = coef * term_values(shape, zf, vf)
    m2 = refit_residues(model, Ff, Yf, fs, fit_seg, c.b, g_fit)
    m2 = refine_poles(m2, Ff, Yf, fs, fit_seg, stride=4, max_nfev=15, b=c.b, g=g_fit)
    b, wd = _gains(m2, idx)
    _, z, v = coords[c.response]
    d = (Y - simulate(m2, F, fs))[train] / scale
    yg = simulate(m2, np.zeros(len(F)), fs, b=b, g_ext=term_values(shape, z, v))[train] / scale
    new = lsq1(yg.ravel(), d.ravel())[0]
    key = next(iter(c.parameters)) if c.effect != "contact" else "stiffness_n_per_m"
    return replace(c, term=(code, new, p1, p2), b=b, wd=wd, model=m2, parameters={**c.parameters, key: -new})


def _best_contact(regress, b, zc: np.ndarray, n_grid: int = 24):
    """Side and gap of a clearance on the coordinate by grid search, stiffness by regression."""
    best = None
    top = float(np.max(np.abs(zc)))
    for side in ("both", "positive", "negative"):
        for g in np.linspace(0.1, 0.9, n_grid) * top:
            h = contact_shape(zc, g, side)
            if not np.any(h):
                continue
            c, r2 = regress(b, h)
            if c < 0 and (best is None or r2 > best[3]):
                best = (side, float(g), c, r2)
    return best
