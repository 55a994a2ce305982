"""A linear structure in modal coordinates plus nonlinear elements: what every baseline and every
extended model is, and the one integrator that simulates them.

The linear part (both baselines reduce to it) is diagonal: complex modal states w_r, one per
conjugate pole pair lambda_r (Im > 0),

    w_r' = lambda_r w_r + sum_q B_qr U_q - sum_e G_er f_e,          U the inputs (the excitation first),

and a response's displacement (relative to the frame when the frame is shaken) is
z_i = sum_r 2 Re(C_ir w_r); its velocity and acceleration follow by differentiating once or twice (a
feedthrough where an input acts directly). An element e is a catalogue law (``catalogue.law``) of its
location's coordinate z_e = sum_r 2 Re(LZ_er w_r), v_e = z_e', entering mode r with gain G_er.

Time stepping: within a step h the inputs and the element forces are taken linear in time, for which
the modal equation has an exact solution (first-order hold, e.g. Franklin, Powell & Workman, "Digital
Control of Dynamic Systems", sec. 6.3); the force at the step's end is predicted, then corrected
(Heun), so the loop is second-order accurate in the element forces and exact in the linear part.
``substeps`` divides each sample interval for stiff elements (``substeps_for``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numba import njit

from .catalogue import N_IWAN, law, slide, slope

KINDS = ("displacement", "velocity", "acceleration")
# what a fit or a simulation raises when the numbers fail (a singular system, a pole that underflowed to
# zero inside a compiled kernel, an optimiser given non-finite values): a failed candidate, never a crash
NUMERIC_FAILURES = (np.linalg.LinAlgError, ValueError, FloatingPointError, ZeroDivisionError)

OBSERVED = 0.03  # the nudging's cut-off: directions of the states observed 30 dB below the best one


@dataclass(frozen=True)
class Element:
    """A nonlinear force in the model: law ``code`` with parameters ``p`` at the coordinate with modal
    coefficients ``lz``, entering the modes with gains ``gain``."""

    code: int
    p: np.ndarray
    lz: np.ndarray
    gain: np.ndarray
    weights: np.ndarray | None = None  # the location as a combination of responses (for measured forces)


@dataclass(frozen=True)
class LinearModel:
    """poles (m,) with Im > 0; B (q, m) modal gains of the inputs; C (k, m) displacement coefficients of
    the responses."""

    poles: np.ndarray
    B: np.ndarray
    C: np.ndarray
    elements: tuple[Element, ...] = field(default=())  # the baseline's own (e.g. the rig's stoppers)

    @property
    def frequencies_hz(self) -> np.ndarray:
        return np.abs(self.poles) / (2 * np.pi)

    @property
    def damping_ratios(self) -> np.ndarray:
        return -self.poles.real / np.abs(self.poles)

    def with_elements(self, extra: tuple[Element, ...]) -> "LinearModel":
        return LinearModel(self.poles, self.B, self.C, self.elements + tuple(extra))


def without_feedthrough(lz: np.ndarray, gain: np.ndarray) -> np.ndarray:
    """The modal gains of a force at a coordinate with modal coefficients ``lz``, less the part by which
    the force would move that coordinate's velocity the instant it acts: per mode, the component of the
    gain that makes Re(lz_r gain_r) nonzero.

    A structure's coordinate answers a force through its mass, in acceleration; its velocity cannot
    jump. In a model with real modes (or complex ones scaled by a complex participation) each mode's
    lz_r gain_r is imaginary; a modal fit's complex residues break that, and a stiffness acting through
    such gains feeds its coordinate's velocity with its own displacement, a first-order loop of rate
    2 Re(lz . gain) x the stiffness that grows or damps by the sign of the residues' phase error, not by
    the physics (independent seed 60: a modal fit with an 18 Hz pseudo-mode at 24 % damping, a stopper
    found where it is, 41 % of the residual explained, and every simulation with it growing to 1e249 in
    a block). The physical gain of mode r is a real multiple of i conj(lz_r), whatever the excitation's
    complex participation; a gain of that form comes back as it was (to rounding; real residues exactly)."""
    lz = np.asarray(lz, complex)
    gain = np.asarray(gain, complex)
    with np.errstate(over="ignore", invalid="ignore"):  # a pseudo-mode's lz can be 1e160 (its gain is 0)
        mag = np.abs(lz) ** 2
        safe = np.where(mag > 0, mag, 1.0)
        return np.where(mag > 0, gain - np.real(lz * gain) * np.conj(lz) / safe, gain)


def output_coefficients(model: LinearModel, outputs):
    """Per output (response index, kind: 0 displacement, 1 velocity, 2 acceleration): modal coefficients
    of its state part, feedthrough of each input and of each element force."""
    lam = model.poles
    k = len(outputs)
    cs = np.zeros((k, lam.size), complex)
    cu = np.zeros((k, model.B.shape[0]))
    ce = np.zeros((k, len(model.elements)))
    for o, (i, kd) in enumerate(outputs):
        cs[o] = model.C[i] * lam ** int(kd)
        if kd >= 1:
            lead = model.C[i] * lam ** (int(kd) - 1)
            cu[o] = 2 * np.real(model.B @ lead)
            for e, el in enumerate(model.elements):
                ce[o, e] = -2 * np.real(el.gain @ lead)
    return cs, cu, ce


def _pack(model: LinearModel):
    m = model.poles.size
    ne = len(model.elements)
    codes = np.array([el.code for el in model.elements], np.int64)
    P = np.zeros((ne, 4))
    LZ = np.zeros((ne, m), complex)
    G = np.zeros((ne, m), complex)
    for e, el in enumerate(model.elements):
        P[e, :len(el.p)] = el.p
        LZ[e] = el.lz
        G[e] = el.gain
    return codes, P, LZ, G


@njit(cache=True, nogil=True)
def _foh(lam, h):  # pragma: no cover - compiled
    """w(t+h) = a w + c0 x(t) + c1 x(t+h) solves w' = lam w + x for x linear over the step."""
    a = np.exp(lam * h)
    c1 = (a - 1 - lam * h) / (lam * lam * h)
    return a, (a - 1) / lam - c1, c1


@njit(cache=True, nogil=True)
def _coords(w, lam, LZ, du, u, z, v):  # pragma: no cover - compiled
    """The elements' coordinates z, v (filled in place) at modal state w and inputs u."""
    for e in range(LZ.shape[0]):
        zz = 0.0
        vv = 0.0
        for r in range(w.shape[0]):
            t = LZ[e, r] * w[r]
            zz += 2 * t.real
            vv += 2 * (t * lam[r]).real
        for q in range(u.shape[0]):
            vv += du[e, q] * u[q]
        z[e] = zz
        v[e] = vv


@njit(cache=True, nogil=True)
def _forces(codes, P, z, v, S, f):  # pragma: no cover - compiled
    for e in range(codes.shape[0]):
        f[e] = law(codes[e], P[e], z[e], v[e], S[e])


@njit(cache=True, nogil=True)
def _simulate(lam, B, cs, cu, ce, codes, P, LZ, G, du, U, w0, dt, substeps, bound, Yo, Co, K):  # pragma: no cover
    n = U.shape[0]
    q_in = U.shape[1]
    n_obs = Yo.shape[0]
    m = lam.shape[0]
    k = cs.shape[0]
    ne = codes.shape[0]
    h = dt / substeps
    a, c0, c1 = _foh(lam, h)
    out = np.full((n, k), np.nan)
    w = w0.copy()
    wp = np.empty(m, np.complex128)
    x0 = np.empty(m, np.complex128)
    x1 = np.empty(m, np.complex128)
    S = np.zeros((ne, N_IWAN))
    z = np.zeros(ne)
    v = np.zeros(ne)
    f0 = np.zeros(ne)
    fp = np.zeros(ne)
    u0 = U[0].copy()
    u1 = U[0].copy()
    _coords(w, lam, LZ, du, u0, z, v)
    for e in range(ne):  # the joint's springs relaxed at equilibrium, its sliders dragged to where it is
        slide(codes[e], P[e], z[e], S[e])
    _forces(codes, P, z, v, S, f0)
    for kk in range(n):
        for i in range(k):  # outputs at sample kk
            acc = 0.0
            for r in range(m):
                acc += 2 * (cs[i, r] * w[r]).real
            for q in range(q_in):
                acc += cu[i, q] * U[kk, q]
            for e in range(ne):
                acc += ce[i, e] * f0[e]
            out[kk, i] = acc
        if kk == n - 1:
            break
        for j in range(substeps):
            frac1 = (j + 1) / substeps
            for q in range(q_in):
                u1[q] = U[kk, q] + (U[kk + 1, q] - U[kk, q]) * frac1
            for r in range(m):
                s0 = 0.0 + 0.0j
                s1 = 0.0 + 0.0j
                for q in range(q_in):
                    s0 += B[q, r] * u0[q]
                    s1 += B[q, r] * u1[q]
                for e in range(ne):
                    s0 -= G[e, r] * f0[e]
                x0[r] = s0
                x1[r] = s1
            if kk + 1 < n_obs:  # nudged towards the observations (held over the sub-step)
                frac = j / substeps
                for o in range(Yo.shape[1]):
                    err = Yo[kk, o] + (Yo[kk + 1, o] - Yo[kk, o]) * frac
                    for r in range(m):
                        err -= 2 * (Co[o, r] * w[r]).real
                    for r in range(m):
                        x0[r] += K[r, o] * err
                        x1[r] += K[r, o] * err
            for r in range(m):  # predictor: the element forces held at their start value
                t = a[r] * w[r] + c0[r] * x0[r] + c1[r] * x1[r]
                for e in range(ne):
                    t -= c1[r] * G[e, r] * f0[e]
                wp[r] = t
            if ne:
                _coords(wp, lam, LZ, du, u1, z, v)
                _forces(codes, P, z, v, S, fp)
            for r in range(m):  # corrector: the forces at the step's end from the predictor
                t = x1[r]
                for e in range(ne):
                    t -= G[e, r] * fp[e]
                w[r] = a[r] * w[r] + c0[r] * x0[r] + c1[r] * t
            if ne:
                _coords(w, lam, LZ, du, u1, z, v)
                for e in range(ne):
                    slide(codes[e], P[e], z[e], S[e])
                _forces(codes, P, z, v, S, f0)
            for q in range(q_in):
                u0[q] = u1[q]
        for e in range(ne):
            if not abs(z[e]) <= bound:
                return out
    return out


@njit(cache=True, nogil=True)
def mode_states(poles, x, dt):  # pragma: no cover - compiled
    """w_r (n, m) of w_r' = lambda_r w_r + x(t) from rest, x linear between samples (exact)."""
    n = x.shape[0]
    m = poles.shape[0]
    out = np.empty((n, m), np.complex128)
    for r in range(m):
        lam = poles[r]
        a = np.exp(lam * dt)
        c1 = (a - 1 - lam * dt) / (lam * lam * dt)
        c0 = (a - 1) / lam - c1
        w = 0.0 + 0.0j
        out[0, r] = w
        for k in range(n - 1):
            w = a * w + c0 * x[k] + c1 * x[k + 1]
            out[k + 1, r] = w
    return out


def simulate(model: LinearModel, U: np.ndarray, fs_hz: float, outputs, w0: np.ndarray | None = None,
             substeps: int = 1, bound: float = np.inf, nudge: tuple | None = None) -> np.ndarray:
    """Outputs (n, len(outputs)), each a (response index, kind) pair (kind 0 displacement, 1 velocity,
    2 acceleration, relative to the frame), under inputs U (n, q), from modal state ``w0`` (rest if None)
    at the first sample. NaN from where an element's coordinate leaves ``bound``.

    ``nudge`` = (Y (n_obs, o), C_obs (o, m), K (m, o)): over the first n_obs samples the states are pulled
    towards observations, w' += K (Y - 2 Re(C_obs w)) (Newtonian relaxation, as data assimilation
    synchronises a model with measurements), so a simulation enters the scored part on the measured
    trajectory, whichever of several coexisting states the structure is in."""
    U = np.asarray(U, float)
    if U.ndim == 1:
        U = U[:, None]
    cs, cu, ce = output_coefficients(model, outputs)
    codes, P, LZ, G = _pack(model)
    # a coordinate's velocity picks up the inputs that act on it directly (none, for a consistent model)
    du = np.zeros((len(model.elements), model.B.shape[0]))
    for e, el in enumerate(model.elements):
        du[e] = 2 * np.real(model.B @ el.lz)
    m = model.poles.size
    w = np.zeros(m, complex) if w0 is None else np.asarray(w0, complex)
    if nudge is None:
        nudge = (np.zeros((0, 1)), np.zeros((1, m), complex), np.zeros((m, 1), complex))
    Yo, Co, K = (np.ascontiguousarray(nudge[0], float), np.ascontiguousarray(nudge[1], complex),
                 np.ascontiguousarray(nudge[2], complex))
    return _simulate(model.poles.astype(complex), np.ascontiguousarray(model.B, complex), cs, cu, ce, codes, P,
                     LZ, G, du, np.ascontiguousarray(U), w, 1.0 / fs_hz, int(substeps), float(bound), Yo, Co, K)


def nudging_gain(model: LinearModel, rate: float) -> tuple[np.ndarray, np.ndarray]:
    """C_obs (k, m) of the responses' relative velocities and the gain K (m, k) that relaxes them towards
    observed ones at ``rate`` [1/s]: K = rate x the least-squares map from a velocity error to the modal
    states that would remove it, over the directions of the states the velocities observe at least
    ``OBSERVED`` as well as the best observed one.

    With several responses and mode shapes that are real (as a structure's are, up to the fit's error),
    a velocity at one instant sees each mode's velocity, not its displacement: the map has directions
    observed next to nothing, and a pseudo-inverse that keeps them maps whatever part of a velocity error
    the model cannot produce (a mode it lacks, noise) into states thousands of times too large. The
    dynamics carry a displacement into a velocity a quarter period later, where it is observed."""
    lam = model.poles
    Co = model.C * lam[None, :]
    m = lam.size
    # real map from (Re w, Im w) to the velocities: v = 2 Re(Co w)
    Mr = np.hstack([2 * Co.real, -2 * Co.imag])
    pinv = np.linalg.pinv(Mr, rcond=OBSERVED)
    K = rate * (pinv[:m] + 1j * pinv[m:])
    return Co, K


def substeps_for(model: LinearModel, fs_hz: float, z_max: float, v_max: float, limit: int = 64,
                 accuracy: float = 0.1) -> int:
    """Sub-steps per sample for the elements: the linear part is stepped exactly, an element's force
    to second order, so the step must resolve the loop each element closes on its own coordinate at
    its largest slope within the motion: a pole of about sqrt(k / m) + c / m, 1 / m being the
    coordinate's acceleration per unit force. ``accuracy``: that pole times the step (0.1: about 1 %
    error in a strongly nonlinear response)."""
    fast = 0.0
    for el in model.elements:
        k, c = slope(el.code, el.p, z_max, v_max)
        if k == 0 and c == 0:
            continue
        inv_m = abs(float(2 * np.real(np.sum(el.lz * model.poles * el.gain))))
        fast = max(fast, np.sqrt(k * inv_m) + c * inv_m)
    return int(min(limit, max(1, np.ceil(fast / fs_hz / accuracy))))


def force_response(model: LinearModel, h: np.ndarray, gains: list[np.ndarray], outputs, fs_hz: float) -> np.ndarray:
    """Outputs (n, len(outputs), len(gains)) of the linear part from rest under a force series h entering
    the modes with each gain vector (w' += -gain h): the modal states of h computed once, then combined."""
    h = np.ascontiguousarray(h, float)
    st = mode_states(model.poles.astype(complex), h.astype(complex), 1.0 / fs_hz)
    sr, si = np.ascontiguousarray(st.real), np.ascontiguousarray(st.imag)
    lam = model.poles
    coef = np.array([[model.C[i] * lam ** int(kd) * -g for g in gains] for i, kd in outputs])  # (k, gains, m)
    flat = coef.reshape(-1, lam.size).T  # (m, k gains): one matrix product (einsum was 5 x slower here)
    out = (2 * (sr @ flat.real - si @ flat.imag)).reshape(h.size, len(outputs), len(gains))
    for o, (i, kd) in enumerate(outputs):
        if kd >= 1:
            for j, g in enumerate(gains):
                out[:, o, j] += 2 * np.real(np.sum(model.C[i] * lam ** (int(kd) - 1) * -g)) * h
    return out


class LeastSquares:
    """Least squares for tall, narrow systems: the normal equations of the column-scaled matrix by
    Cholesky (the columns of modal responses differ in scale by orders), a ridge of 1e-12 of the
    diagonal keeping them definite; falls back to SVD when they are not. Many times faster than SVD on
    the 10^4 x 10^1 systems that pole fitting solves thousands of times. The factorisation is made once
    and kept for every right-hand side of the same matrix (the responses of one kinematic order share
    their design matrix); each solve is the very arithmetic of a fresh one."""

    def __init__(self, X: np.ndarray):
        norms = np.sqrt(np.einsum("ij,ij->j", X, X))
        self.norms = np.where(norms > 0, norms, 1.0)
        self.Xs = X / self.norms
        A = self.Xs.T @ self.Xs
        A[np.diag_indices_from(A)] += 1e-12
        try:
            self.c = np.linalg.cholesky(A)
        except np.linalg.LinAlgError:
            self.c = None

    def solve(self, y: np.ndarray) -> np.ndarray:
        sol = None
        if self.c is not None:
            try:
                sol = np.linalg.solve(self.c.T, np.linalg.solve(self.c, self.Xs.T @ y))
            except np.linalg.LinAlgError:
                sol = None
        if sol is None:
            sol = np.linalg.lstsq(self.Xs, y, rcond=None)[0]
        return sol / self.norms


def lstsq(X: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``LeastSquares(X).solve(y)``: one right-hand side."""
    return LeastSquares(X).solve(y)
