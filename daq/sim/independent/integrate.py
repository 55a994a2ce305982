"""Fixed-step integration of the reduced equations with nonlinear elements, compiled with numba.

State: modal coordinates q, velocities q', the coil current i of an electrodynamic shaker, and the slider
positions z of the Jenkins elements. The equations (mass-normalised modes, see modal.py):

    q'' = -diag(omega^2) q - C_m q' + B s(t) + sum_e a_e f_e(a_e . q, a_e . q', z_e)
          - gamma (q^T G q) G q + a_coil Bl i
    L i' = V(t) - R i - Bl a_coil . q'

are advanced by the classical 4th-order Runge-Kutta method (Hairer, Norsett and Wanner, Solving Ordinary
Differential Equations I, 1993, sec. II.1) with the loads s(t) sampled at the half steps. Within a step
the Jenkins sliders are frozen (each stage uses the trial force of the elastic predictor, clipped at the
slip force); after the step they are updated by return mapping with the new displacement (exact for a
displacement that is monotonic within the step). The step is chosen so that omega_max dt <= 0.5 for the
stiffest linearised state (all contacts closed), where RK4's numerical damping is below 1e-3 of
critical and its phase error below 1e-4 per period.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from .elements import CONTACT, CUBIC, DRAG, HYSTERETIC, Element, Membrane, pack, stiffening
from .modal import ModalModel

MAX_OMEGA_DT = 0.5


@dataclass
class Load:
    """A force distribution (physical vector, force per unit signal) and its signal on the half-step grid."""

    vector: np.ndarray
    samples: np.ndarray  # length 2 n_steps + 1, at t = k dt / 2


@dataclass
class Output:
    """A recorded quantity: sum of b . x^(order) terms plus multiples of load signals (feed-through)."""

    terms: list[tuple[np.ndarray, int]]
    feed: list[tuple[int, float]] = field(default_factory=list)


@dataclass
class Coil:
    """Electrodynamic shaker coil: L i' + R i + Bl v_armature = V(t), force Bl i on the armature."""

    inductance_h: float
    resistance_ohm: float
    force_factor_n_per_a: float
    armature: np.ndarray  # physical vector of the armature displacement
    voltage_load: int  # index of the load whose samples are the voltage (its vector is zero)


@dataclass
class State:
    q: np.ndarray
    qd: np.ndarray
    current_a: float = 0.0
    sliders: np.ndarray | None = None  # (n_elements, n_jenkins)


@dataclass
class Response:
    rate_hz: float
    outputs: np.ndarray  # (n_steps + 1, n_outputs)
    element_u: np.ndarray  # (n_steps + 1, n_elements [+ 1 membrane: q_1])
    element_v: np.ndarray
    element_f: np.ndarray  # force on the coordinate [membrane: generalised force on mode 1]
    final: State
    modal_q: np.ndarray | None = None  # every record_every steps
    modal_qd: np.ndarray | None = None

    @property
    def time_s(self) -> np.ndarray:
        return np.arange(self.outputs.shape[0]) / self.rate_hz


@njit(cache=True)
def _derivative(k2, q, qd, cur, w2, cm, bm, loads, kinds, rows, par, jk, jf, jz, voff, gm, gamma,
                coil, coil_a, volt, qdd, fe, ue, ve, g):
    m = q.shape[0]
    for i in range(m):
        s = -w2[i] * q[i]
        for j in range(m):
            s -= cm[i, j] * qd[j]
        for l in range(loads.shape[1]):
            s += bm[i, l] * loads[k2, l]
        qdd[i] = s
    for e in range(kinds.shape[0]):
        u = 0.0
        v = 0.0
        for i in range(m):
            u += rows[e, i] * q[i]
            v += rows[e, i] * qd[i]
        kind = kinds[e]
        f = 0.0
        if kind == CONTACT:
            gap = par[e, 0]
            side = par[e, 3]
            if side >= 0.0 and u > gap:
                f = -(par[e, 1] * (u - gap) + par[e, 2] * v)
                if f > 0.0:
                    f = 0.0
            elif side <= 0.0 and u < -gap:
                f = par[e, 1] * (-u - gap) - par[e, 2] * v
                if f < 0.0:
                    f = 0.0
        elif kind == CUBIC:
            f = -par[e, 0] * u * u * u
        elif kind == HYSTERETIC:
            f = par[e, 0] * u
            for j in range(jk.shape[1]):
                fj = jk[e, j] * (u - jz[e, j])
                if fj > jf[e, j]:
                    fj = jf[e, j]
                elif fj < -jf[e, j]:
                    fj = -jf[e, j]
                f -= fj
        elif kind == DRAG:
            va = v + par[e, 1] * voff[k2]
            f = -par[e, 0] * abs(va) * va
        fe[e] = f
        ue[e] = u
        ve[e] = v
        for i in range(m):
            qdd[i] += rows[e, i] * f
    if gamma != 0.0:
        s = 0.0
        for i in range(m):
            g[i] = 0.0
            for j in range(m):
                g[i] += gm[i, j] * q[j]
            s += q[i] * g[i]
        for i in range(m):
            qdd[i] -= gamma * s * g[i]
        ne = kinds.shape[0]
        fe[ne] = -gamma * s * g[0]
        ue[ne] = q[0]
        ve[ne] = qd[0]
    dcur = 0.0
    if coil[0] > 0.0:
        va = 0.0
        for i in range(m):
            va += coil_a[i] * qd[i]
            qdd[i] += coil_a[i] * coil[2] * cur
        dcur = (loads[k2, volt] - coil[1] * cur - coil[2] * va) / coil[0]
    return dcur


@njit(cache=True)
def _integrate(dt, n_steps, q0, qd0, cur0, w2, cm, bm, loads, kinds, rows, par, jk, jf, jz, voff, gm,
               gamma, coil, coil_a, volt, out_q, out_v, out_a, out_d, rec_every):
    m = q0.shape[0]
    n_rec = kinds.shape[0] + (1 if gamma != 0.0 else 0)
    n_out = out_q.shape[0]
    y = np.zeros((n_steps + 1, n_out))
    eu = np.zeros((n_steps + 1, n_rec))
    ev = np.zeros((n_steps + 1, n_rec))
    ef = np.zeros((n_steps + 1, n_rec))
    n_hist = n_steps // rec_every + 1 if rec_every > 0 else 0
    hq = np.zeros((n_hist, m))
    hv = np.zeros((n_hist, m))
    q = q0.copy()
    qd = qd0.copy()
    cur = cur0
    k1q = np.zeros(m)
    k1v = np.zeros(m)
    k2q = np.zeros(m)
    k2v = np.zeros(m)
    k3q = np.zeros(m)
    k3v = np.zeros(m)
    k4v = np.zeros(m)
    qs = np.zeros(m)
    vs = np.zeros(m)
    fe = np.zeros(n_rec)
    ue = np.zeros(n_rec)
    ve = np.zeros(n_rec)
    gw = np.zeros(m)
    for n in range(n_steps + 1):
        k = 2 * n
        c1 = _derivative(k, q, qd, cur, w2, cm, bm, loads, kinds, rows, par, jk, jf, jz, voff, gm, gamma,
                         coil, coil_a, volt, k1v, fe, ue, ve, gw)
        for o in range(n_out):
            s = 0.0
            for i in range(m):
                s += out_q[o, i] * q[i] + out_v[o, i] * qd[i] + out_a[o, i] * k1v[i]
            for l in range(loads.shape[1]):
                s += out_d[o, l] * loads[k, l]
            y[n, o] = s
        for e in range(n_rec):
            eu[n, e] = ue[e]
            ev[n, e] = ve[e]
            ef[n, e] = fe[e]
        if rec_every > 0 and n % rec_every == 0:
            hq[n // rec_every] = q
            hv[n // rec_every] = qd
        if n == n_steps:
            break
        for i in range(m):
            k1q[i] = qd[i]
            qs[i] = q[i] + 0.5 * dt * k1q[i]
            vs[i] = qd[i] + 0.5 * dt * k1v[i]
        c2 = _derivative(k + 1, qs, vs, cur + 0.5 * dt * c1, w2, cm, bm, loads, kinds, rows, par, jk, jf,
                         jz, voff, gm, gamma, coil, coil_a, volt, k2v, fe, ue, ve, gw)
        for i in range(m):
            k2q[i] = vs[i]
            qs[i] = q[i] + 0.5 * dt * k2q[i]
            vs[i] = qd[i] + 0.5 * dt * k2v[i]
        c3 = _derivative(k + 1, qs, vs, cur + 0.5 * dt * c2, w2, cm, bm, loads, kinds, rows, par, jk, jf,
                         jz, voff, gm, gamma, coil, coil_a, volt, k3v, fe, ue, ve, gw)
        for i in range(m):
            k3q[i] = vs[i]
            qs[i] = q[i] + dt * k3q[i]
            vs[i] = qd[i] + dt * k3v[i]
        c4 = _derivative(k + 2, qs, vs, cur + dt * c3, w2, cm, bm, loads, kinds, rows, par, jk, jf, jz,
                         voff, gm, gamma, coil, coil_a, volt, k4v, fe, ue, ve, gw)
        for i in range(m):
            q[i] += dt / 6.0 * (k1q[i] + 2.0 * k2q[i] + 2.0 * k3q[i] + vs[i])
            qd[i] += dt / 6.0 * (k1v[i] + 2.0 * k2v[i] + 2.0 * k3v[i] + k4v[i])
        cur += dt / 6.0 * (c1 + 2.0 * c2 + 2.0 * c3 + c4)
        for e in range(kinds.shape[0]):
            if kinds[e] == HYSTERETIC:
                u = 0.0
                for i in range(m):
                    u += rows[e, i] * q[i]
                for j in range(jk.shape[1]):
                    if jk[e, j] > 0.0:
                        fj = jk[e, j] * (u - jz[e, j])
                        if fj > jf[e, j]:
                            jz[e, j] = u - jf[e, j] / jk[e, j]
                        elif fj < -jf[e, j]:
                            jz[e, j] = u + jf[e, j] / jk[e, j]
    return y, eu, ev, ef, q, qd, cur, hq, hv


def stable_rate_hz(model: ModalModel, elements: list[Element] = ()) -> float:
    """Smallest rate with omega_max dt <= MAX_OMEGA_DT, omega_max of the stiffest linearised state."""
    k = np.diag(model.omega_rad_s**2)
    for e in elements:
        a = model.project(e.coordinate)
        k = k + stiffening(e) * np.outer(a, a)
    omega_max = math.sqrt(max(np.linalg.eigvalsh(k).max(), 0.0))
    return omega_max / MAX_OMEGA_DT


def internal_rate(fs_hz: int, model: ModalModel, elements: list[Element] = (), min_rate_hz: float = 20e3,
                  min_factor: int = 10) -> int:
    """The internal rate: an integer multiple of fs_hz, >= min_rate_hz, >= min_factor fs, and stable."""
    need = max(min_rate_hz, min_factor * fs_hz, stable_rate_hz(model, elements))
    return int(math.ceil(need / fs_hz - 1e-9)) * int(fs_hz)


def simulate(model: ModalModel, rate_hz: float, n_steps: int, loads: list[Load],
             elements: list[Element] = (), outputs: list[Output] = (), membrane: Membrane | None = None,
             coil: Coil | None = None, initial: State | None = None,
             velocity_offset: np.ndarray | None = None, record_every: int = 0) -> Response:
    """Integrate n_steps steps of 1 / rate_hz from the initial state (rest by default)."""
    m = model.n_modes
    n_fine = 2 * n_steps + 1
    elements = list(elements)
    if loads:
        for ld in loads:
            if len(ld.samples) != n_fine:
                raise ValueError(f"load samples must have 2 n_steps + 1 = {n_fine} values")
        load_arr = np.ascontiguousarray(np.column_stack([ld.samples for ld in loads]), dtype=float)
        bm = np.column_stack([model.project(ld.vector) for ld in loads])
    else:
        load_arr = np.zeros((n_fine, 0))
        bm = np.zeros((m, 0))
    kinds, rows, par, jk, jf = pack(elements, model.project)
    rows = rows.reshape(len(elements), m) if elements else np.zeros((0, m))
    if initial is None:
        initial = State(q=np.zeros(m), qd=np.zeros(m))
    jz = np.zeros_like(jk) if initial.sliders is None else np.array(initial.sliders, dtype=float)
    if velocity_offset is None:
        voff = np.zeros(n_fine)
    else:
        voff = np.asarray(velocity_offset, dtype=float)
        if len(voff) != n_fine:
            raise ValueError("velocity_offset must be on the half-step grid")
    if membrane is not None:
        gm = model.shapes.T @ membrane.matrix @ model.shapes
        gamma = membrane.coefficient_n
    else:
        gm = np.zeros((m, m))
        gamma = 0.0
    if coil is not None:
        coil_par = np.array([coil.inductance_h, coil.resistance_ohm, coil.force_factor_n_per_a])
        coil_a = model.project(coil.armature)
        volt = coil.voltage_load
    else:
        coil_par = np.zeros(3)
        coil_a = np.zeros(m)
        volt = 0
    n_out = len(outputs)
    out_mats = [np.zeros((n_out, m)) for _ in range(3)]
    out_d = np.zeros((n_out, load_arr.shape[1]))
    for o, spec in enumerate(outputs):
        for b, order in spec.terms:
            out_mats[order][o] += model.project(b)
        for li, coef in spec.feed:
            out_d[o, li] += coef
    y, eu, ev, ef, q, qd, cur, hq, hv = _integrate(
        1.0 / rate_hz, int(n_steps), np.asarray(initial.q, float).copy(), np.asarray(initial.qd, float).copy(),
        float(initial.current_a), model.omega_rad_s**2, np.ascontiguousarray(model.damping), bm, load_arr,
        kinds, np.ascontiguousarray(rows), par, jk, jf, jz, voff, gm, gamma, coil_par, coil_a, volt,
        out_mats[0], out_mats[1], out_mats[2], out_d, int(record_every))
    return Response(rate_hz=rate_hz, outputs=y, element_u=eu, element_v=ev, element_f=ef,
                    final=State(q=q, qd=qd, current_a=cur, sliders=jz),
                    modal_q=hq if record_every else None, modal_qd=hv if record_every else None)
