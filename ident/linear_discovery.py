"""Discovery with a fitted linear baseline, for data from any rig (``ident discover --baseline linear``).

Responses may be accelerations, velocities or displacements; the excitation a
force or a base acceleration (then responses are taken relative to the base).
Physical coordinates z, v, a per response (band-limited integration or
differentiation, drift removed). The baseline is a linear model of the same
structure, a_j = sum_k A_jk z_k + B_jk v_k + c_j F + e_j, fitted by least
squares on the training segment and integrated over the held-out one from the
measured state. Causes from the catalogue are fitted to the residual force and
scored by simulation on the held-out segment with a compiled RK4 kernel that
integrates "linear plus one term" models.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .derivatives import differentiate
from .discovery import best_contact, lsq1, split
from .filters import lowpass_zero_phase
from .physical import edge_samples, integrate_band

KINDS_RESPONSE = ("acceleration", "velocity", "displacement")
KINDS_EXCITATION = ("base_acceleration", "force")
# term codes of the kernel
T_NONE, T_CUBIC, T_QUAD, T_COULOMB, T_QDAMP, T_CONTACT, T_LINEAR = 0, 1, 2, 3, 4, 5, 6


@dataclass(frozen=True)
class LinearModel:
    A: np.ndarray  # (k, k) on z
    B: np.ndarray  # (k, k) on v
    c: np.ndarray  # (k,) on F
    e: np.ndarray  # (k,) constant


@dataclass(frozen=True)
class Term:
    effect: str
    response: int
    code: int
    coef: float  # multiplies the term in a_j (negative = restoring)
    p1: float = 0.0  # gap, or velocity scale of the friction
    p2: float = 0.0  # contact side: 0 both, 1 positive, 2 negative
    parameters: dict | None = None


def coordinates(u: np.ndarray, Y: np.ndarray, kinds: list[str], excitation: str, fs: float, f_lo: float = 1.0):
    """(F (n,), z, v, a (n, k)) from excitation u and responses Y of the given kinds."""
    if excitation not in KINDS_EXCITATION:
        raise ValueError(f"unknown excitation kind {excitation!r}; use base_acceleration or force")
    k = Y.shape[1]
    cut = 0.45 * fs
    u = lowpass_zero_phase(u, fs, cut)
    Y = lowpass_zero_phase(Y, fs, cut)
    z, v, a = np.empty_like(Y), np.empty_like(Y), np.empty_like(Y)
    ub_v = ub_z = None
    if excitation == "base_acceleration":
        ub_v, ub_z = integrate_band(u, fs, f_lo)
    for j in range(k):
        kind = kinds[j]
        if kind not in KINDS_RESPONSE:
            raise ValueError(f"unknown response kind {kind!r}; use acceleration, velocity or displacement")
        y = Y[:, j]
        if kind == "acceleration":
            aj = y - (u if excitation == "base_acceleration" else 0.0)
            vj, zj = integrate_band(aj, fs, f_lo)
        elif kind == "velocity":
            vj = y - (ub_v if ub_v is not None else 0.0)
            zj = integrate_band(differentiate(vj, 1 / fs, "gradient"), fs, f_lo)[1]
            aj = differentiate(vj, 1 / fs, "gradient")
        else:
            zj = y - (ub_z if ub_z is not None else 0.0)
            vj = differentiate(zj, 1 / fs, "gradient")
            aj = differentiate(vj, 1 / fs, "gradient")
        z[:, j], v[:, j], a[:, j] = zj, vj, aj
    return u, z, v, a


def fit_linear(z, v, a, F, sl: slice, ridge: float = 1e-8) -> LinearModel:
    X = np.column_stack([z[sl], v[sl], F[sl], np.ones(sl.stop - sl.start)])
    scale = np.sqrt(np.mean(X**2, axis=0))
    scale[scale == 0] = 1.0
    Xn = X / scale
    G = Xn.T @ Xn + ridge * len(Xn) * np.eye(X.shape[1])
    W = np.linalg.solve(G, Xn.T @ a[sl]) / scale[:, None]
    k = z.shape[1]
    return LinearModel(W[:k].T, W[k:2 * k].T, W[2 * k], W[2 * k + 1])


def predict(m: LinearModel, z, v, F) -> np.ndarray:
    return z @ m.A.T + v @ m.B.T + F[:, None] * m.c + m.e


@njit(cache=True, nogil=True)
def _term(code, coef, p1, p2, zj, vj):  # pragma: no cover - compiled
    if code == 1:
        return coef * zj**3
    if code == 2:
        return coef * zj * abs(zj)
    if code == 3:
        return coef * np.tanh(vj / p1)
    if code == 4:
        return coef * vj * abs(vj)
    if code == 5:
        h = 0.0
        if p2 != 2 and zj > p1:
            h += zj - p1
        if p2 != 1 and zj < -p1:
            h += zj + p1
        return coef * h
    if code == 6:  # a linear spring (coef) and damper (p2)
        return coef * zj + p2 * vj
    return 0.0


@njit(cache=True, nogil=True)
def _acc(A, B, c, e, code, coef, p1, p2, zz, vv, f):  # pragma: no cover - compiled
    r = A @ zz + B @ vv + c * f + e
    for j in range(zz.shape[0]):
        if code[j] != 0:
            r[j] += _term(code[j], coef[j], p1[j], p2[j], zz[j], vv[j])
    return r


@njit(cache=True, nogil=True)
def _simulate(A, B, c, e, code, coef, p1, p2, F, z0, v0, dt, bound):  # pragma: no cover
    """RK4 of z' = v, v' = A z + B v + c F + e + one catalogue term per response (code[j])."""
    n = F.shape[0]
    k = z0.shape[0]
    out = np.full((n, k), np.nan)
    z = z0.copy()
    v = v0.copy()

    def acc(zz, vv, f):
        return _acc(A, B, c, e, code, coef, p1, p2, zz, vv, f)

    out[0] = acc(z, v, F[0])
    for i in range(n - 1):
        fm = 0.5 * (F[i] + F[i + 1])
        a1 = acc(z, v, F[i])
        z1 = v
        a2 = acc(z + 0.5 * dt * z1, v + 0.5 * dt * a1, fm)
        z2 = v + 0.5 * dt * a1
        a3 = acc(z + 0.5 * dt * z2, v + 0.5 * dt * a2, fm)
        z3 = v + 0.5 * dt * a2
        a4 = acc(z + dt * z3, v + dt * a3, F[i + 1])
        z4 = v + dt * a3
        z = z + dt / 6.0 * (z1 + 2 * z2 + 2 * z3 + z4)
        v = v + dt / 6.0 * (a1 + 2 * a2 + 2 * a3 + a4)
        if not np.all(np.abs(z) <= bound):
            break
        out[i + 1] = acc(z, v, F[i + 1])
    return out


def simulate_accel(m: LinearModel, terms: list[Term], F, z0, v0, fs: float, bound: float) -> np.ndarray:
    """Accelerations of the linear model plus the given terms (at most one per response)."""
    k = len(z0)
    code, coef, p1, p2 = np.zeros(k, np.int64), np.zeros(k), np.ones(k), np.zeros(k)
    for t in terms:
        code[t.response], coef[t.response], p1[t.response], p2[t.response] = t.code, t.coef, max(t.p1, 1e-12), t.p2
    return _simulate(np.ascontiguousarray(m.A), np.ascontiguousarray(m.B), m.c.astype(float), m.e.astype(float),
                     code, coef, p1, p2, np.ascontiguousarray(F, float), np.asarray(z0, float).copy(),
                     np.asarray(v0, float).copy(), 1.0 / fs, bound)


def term_values(t: Term, zj: np.ndarray, vj: np.ndarray) -> np.ndarray:
    """The term's shape (coefficient 1) on measured states, as the kernel evaluates it."""
    if t.code == T_CUBIC:
        return zj**3
    if t.code == T_QUAD:
        return zj * np.abs(zj)
    if t.code == T_COULOMB:
        return np.tanh(vj / t.p1)
    if t.code == T_QDAMP:
        return vj * np.abs(vj)
    h = np.zeros_like(zj)
    if t.p2 != 2:
        h += np.maximum(zj - t.p1, 0.0)
    if t.p2 != 1:
        h += np.minimum(zj + t.p1, 0.0)
    return h


def refit_with_term(m: LinearModel, t: Term, z, v, a, F, sl: slice) -> tuple[LinearModel, Term]:
    """Refit response t.response's linear row jointly with the term (the extended model)."""
    from dataclasses import replace as _replace

    j = t.response
    h = term_values(t, z[sl, j], v[sl, j])
    X = np.column_stack([z[sl], v[sl], F[sl], np.ones(sl.stop - sl.start), h])
    scale = np.sqrt(np.mean(X**2, axis=0))
    scale[scale == 0] = 1.0
    w = np.linalg.lstsq(X / scale, a[sl, j], rcond=None)[0] / scale
    k = z.shape[1]
    A, B, c, e = m.A.copy(), m.B.copy(), m.c.copy(), m.e.copy()
    A[j], B[j], c[j], e[j] = w[:k], w[k:2 * k], w[2 * k], w[2 * k + 1]
    params = dict(t.parameters or {})
    key = {"contact": "stiffness_per_mass", "coulomb_friction": "force_per_mass"}.get(t.effect, "coefficient_per_mass")
    params[key] = float(-w[-1])
    return LinearModel(A, B, c, e), _replace(t, coef=float(w[-1]), parameters=params)


def candidate_terms(j: int, z: np.ndarray, v: np.ndarray, d: np.ndarray) -> list[tuple[Term, float]]:
    """Catalogue terms for response j fitted to its residual d; returns (term, r2)."""
    zj, vj = z[:, j], v[:, j]
    out = []
    a, r2 = lsq1(zj**3, d)
    out.append((Term("cubic_stiffness", j, T_CUBIC, a, parameters={"coefficient_per_mass": -a}), r2))
    a, r2 = lsq1(zj * np.abs(zj), d)
    out.append((Term("quadratic_stiffness", j, T_QUAD, a, parameters={"coefficient_per_mass": -a}), r2))
    eps = 0.01 * float(np.std(vj)) + 1e-12
    a, r2 = lsq1(np.tanh(vj / eps), d)
    if a < 0:
        out.append((Term("coulomb_friction", j, T_COULOMB, a, eps, parameters={"force_per_mass": -a}), r2))
    a, r2 = lsq1(vj * np.abs(vj), d)
    if a < 0:
        out.append((Term("quadratic_damping", j, T_QDAMP, a, parameters={"coefficient_per_mass": -a}), r2))
    found = best_contact(zj, d, 60)
    if found is not None:
        side, g, k, r2 = found
        code = {"both": 0, "positive": 1, "negative": 2}[side]
        out.append((Term("contact", j, T_CONTACT, -k, g, code, {"gap": g, "side": side, "stiffness_per_mass": k}),
                    r2))
    return out


@dataclass(frozen=True)
class LinearDiscovery:
    baseline_test_nrmse: float
    extended_test_nrmse: float
    gain: float
    findings: list[dict]
    candidates: list[dict]
    train: slice
    test: slice
    residual_rms: dict


def discover_linear(u: np.ndarray, Y: np.ndarray, names: list[str], kinds: list[str], excitation: str, fs: float,
                    *, train: slice | None = None, test: slice | None = None, gain_floor: float = 0.05,
                    f_lo: float = 1.0) -> LinearDiscovery:
    u = np.asarray(u, float)
    Y = np.asarray(Y, float).reshape(len(u), -1)
    if not (np.all(np.isfinite(u)) and np.all(np.isfinite(Y))):
        raise ValueError("data contain NaN or inf: repair or remove those samples first")
    train, test = split(len(u), edge_samples(fs, f_lo), train, test)
    F, z, v, a = coordinates(u, Y, kinds, excitation, fs, f_lo)
    m = fit_linear(z, v, a, F, train)
    bound = 50.0 * float(np.max(np.abs(z))) + 1e-12
    meas = a[test]
    scale = meas.std(axis=0)

    def score(model, terms):
        sim = simulate_accel(model, terms, F[test], z[test.start], v[test.start], fs, bound)
        if not np.all(np.isfinite(sim)):
            return 1.0  # a diverged simulation is no better than predicting nothing (NRMSE 1)
        return min(1.0, float(np.mean(np.sqrt(np.mean((sim - meas) ** 2, axis=0)) / scale)))

    base_err = score(m, [])
    d_all = a[train] - predict(m, z[train], v[train], F[train])
    resid = {names[j]: float(np.sqrt(np.mean(d_all[:, j] ** 2))) for j in range(Y.shape[1])}
    cands = []
    for j in range(Y.shape[1]):
        for term, r2 in candidate_terms(j, z[train], v[train], d_all[:, j]):
            m_ext, term = refit_with_term(m, term, z, v, a, F, train)
            err = score(m_ext, [term])
            gain = 1.0 - err / base_err if base_err > 0 else 0.0
            cands.append({"effect": term.effect, "response": names[j], "parameters": term.parameters,
                          "gain": gain, "test_nrmse": err, "fit_r2": r2, "_term": term, "_model": m_ext})
    cands.sort(key=lambda c: -c["gain"])
    findings = [c for c in cands if c["gain"] > gain_floor]
    # one finding per response: the best
    seen, best = set(), []
    for c in findings:
        if c["response"] not in seen:
            seen.add(c["response"])
            best.append(c)
    ext_model = m
    for c in best:  # each finding's refitted row joins the extended model
        j = c["_term"].response
        A, B, cc, ee = ext_model.A.copy(), ext_model.B.copy(), ext_model.c.copy(), ext_model.e.copy()
        A[j], B[j], cc[j], ee[j] = c["_model"].A[j], c["_model"].B[j], c["_model"].c[j], c["_model"].e[j]
        ext_model = LinearModel(A, B, cc, ee)
    ext_err = score(ext_model, [c["_term"] for c in best]) if best else base_err

    def public(c):
        return {k: v for k, v in c.items() if not k.startswith("_")}

    return LinearDiscovery(base_err, ext_err, 1.0 - ext_err / base_err if base_err > 0 else 0.0,
                           [public(c) for c in best], [public(c) for c in cands], train, test, resid)
