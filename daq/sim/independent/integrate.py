"""Fixed-step integration of the reduced equations with nonlinear elements, compiled with numba.

State: modal coordinates q, velocities q', the coil current i of an electrodynamic shaker, and the slider
positions z of the Jenkins elements. The equations (mass-normalised modes, see modal.py):

    q'' = -diag(omega^2) q - C_m q' + B s(t) + sum_e a_e f_e(a_e . q, a_e . q', z_e)
          - gamma (q^T G q) G q + a_coil Bl i
    L i' = V(t) - R i - Bl a_coil . q'

are advanced by the classical 4th-order Runge-Kutta method (Hairer, Norsett and Wanner, Solving Ordinary
Differential Equations I, 1993, sec. II.1) with the loads s(t) sampled at the half steps (quadratic
interpolation between them inside a step). The step is chosen so that omega dt <= 0.5 for the highest
kept mode, where RK4's amplitude and phase errors per step, (omega dt)^6 / 144 and (omega dt)^5 / 120,
amount to a numerical damping ratio of 2e-4 (against 5e-3 to 3e-2 of the structure) and a phase
error of 3e-3 rad per period, and omega dt <= 0.2 for a stiff element (a stopper) acting alone on the
effective mass of its coordinate.

A stopper's force law changes when it starts or stops pushing; a step that straddles such an instant is
split there (event location on the cubic Hermite interpolant of the stopper coordinate over the step,
by bisection), so that each piece integrates a smooth right-hand side. Within a step the Jenkins sliders
are frozen (each stage uses the trial force of the elastic predictor, clipped at the slip force); after
the step they are updated by return mapping with the new displacement (exact for a displacement that is
monotonic within the step).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from .elements import CONTACT, CUBIC, DRAG, HYSTERETIC, Element, Membrane, pack, stiffening
from .modal import ModalModel

MAX_OMEGA_DT = 0.5
MAX_CONTACT_OMEGA_DT = 0.2
MAX_EVENTS = 4  # contact events located within one step


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
def _derivative(q, qd, cur, lv, vo, model, jz, qdd, fe, ue, ve, g):
    """q'' into qdd and the coil's di/dt (returned); element coordinates and forces into ue, ve, fe."""
    w2, cm, bm, kinds, rows, par, jk, jf, gm, gamma, coil, coil_a, volt = model
    m = q.shape[0]
    for i in range(m):
        s = -w2[i] * q[i]
        for j in range(m):
            s -= cm[i, j] * qd[j]
        for l in range(lv.shape[0]):
            s += bm[i, l] * lv[l]
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
                f = -(u - gap) * (par[e, 1] + par[e, 2] * v)
                if f > 0.0:
                    f = 0.0
            elif side <= 0.0 and u < -gap:
                f = (-u - gap) * (par[e, 1] - par[e, 2] * v)
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
            va = v + par[e, 1] * vo
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
        dcur = (lv[volt] - coil[1] * cur - coil[2] * va) / coil[0]
    return dcur


@njit(cache=True)
def _rk4(q, qd, cur, h, l0, lm, l1, v0, vm, v1, k1v, c1, model, jz, ws, q_out, qd_out):
    """One RK4 step of length h from (q, qd, cur) with loads l0, lm, l1 at 0, h/2, h; k1 given."""
    k2v, k3v, k4v, qs, vs, vs2, vs3, fe, ue, ve, g = ws
    m = q.shape[0]
    for i in range(m):
        qs[i] = q[i] + 0.5 * h * qd[i]
        vs[i] = qd[i] + 0.5 * h * k1v[i]
    c2 = _derivative(qs, vs, cur + 0.5 * h * c1, lm, vm, model, jz, k2v, fe, ue, ve, g)
    for i in range(m):
        vs2[i] = vs[i]
        qs[i] = q[i] + 0.5 * h * vs2[i]
        vs[i] = qd[i] + 0.5 * h * k2v[i]
    c3 = _derivative(qs, vs, cur + 0.5 * h * c2, lm, vm, model, jz, k3v, fe, ue, ve, g)
    for i in range(m):
        vs3[i] = vs[i]
        qs[i] = q[i] + h * vs3[i]
        vs[i] = qd[i] + h * k3v[i]
    c4 = _derivative(qs, vs, cur + h * c3, l1, v1, model, jz, k4v, fe, ue, ve, g)
    for i in range(m):
        q_out[i] = q[i] + h / 6.0 * (qd[i] + 2.0 * vs2[i] + 2.0 * vs3[i] + vs[i])
        qd_out[i] = qd[i] + h / 6.0 * (k1v[i] + 2.0 * k2v[i] + 2.0 * k3v[i] + k4v[i])
    return cur + h / 6.0 * (c1 + 2.0 * c2 + 2.0 * c3 + c4)


@njit(cache=True)
def _loads_at(loads, voff, k, s, out):
    """Loads at fraction s of the step starting at half-step index k (quadratic through k, k+1, k+2)."""
    a = 2.0 * s * s - 3.0 * s + 1.0
    b = -4.0 * s * s + 4.0 * s
    c = 2.0 * s * s - s
    for l in range(out.shape[0]):
        out[l] = a * loads[k, l] + b * loads[k + 1, l] + c * loads[k + 2, l]
    return a * voff[k] + b * voff[k + 1] + c * voff[k + 2]


@njit(cache=True)
def _pushing(sgn, u, v, gap, k, lam):
    """Whether a stopper on side sgn pushes: penetration p = sgn u - gap > 0 and k + lambda p' > 0."""
    return sgn * u - gap > 0.0 and k + lam * sgn * v > 0.0


@njit(cache=True)
def _hermite(s, h, u0, v0, u1, v1):
    """Cubic Hermite interpolant of a coordinate over a step of length h: (u, u') at fraction s."""
    s2 = s * s
    s3 = s2 * s
    u = (2 * s3 - 3 * s2 + 1) * u0 + (s3 - 2 * s2 + s) * h * v0 + (-2 * s3 + 3 * s2) * u1 + (s3 - s2) * h * v1
    v = (6 * s2 - 6 * s) * u0 / h + (3 * s2 - 4 * s + 1) * v0 + (-6 * s2 + 6 * s) * u1 / h + (3 * s2 - 2 * s) * v1
    return u, v


@njit(cache=True)
def _first_contact_event(q0, qd0, q1, qd1, h, kinds, rows, par):
    """Fraction s in (0, 1] of the step, just past the instant, at which a stopper first starts or stops
    pushing, on the cubic Hermite interpolant of its coordinate over the step (checked at quarters of the
    step, so that a brief touch inside one step is found too); -1 if none."""
    first = -1.0
    m = q0.shape[0]
    for e in range(kinds.shape[0]):
        if kinds[e] != CONTACT:
            continue
        gap, k, lam, side = par[e, 0], par[e, 1], par[e, 2], par[e, 3]
        u0 = 0.0
        v0 = 0.0
        u1 = 0.0
        v1 = 0.0
        for i in range(m):
            u0 += rows[e, i] * q0[i]
            v0 += rows[e, i] * qd0[i]
            u1 += rows[e, i] * q1[i]
            v1 += rows[e, i] * qd1[i]
        for sgn in (1.0, -1.0):
            if side * sgn < 0.0:
                continue
            start = _pushing(sgn, u0, v0, gap, k, lam)
            lo = 0.0
            hi = -1.0
            for quarter in range(1, 5):
                s = 0.25 * quarter
                u, v = _hermite(s, h, u0, v0, u1, v1)
                if _pushing(sgn, u, v, gap, k, lam) != start:
                    hi = s
                    break
                lo = s
            if hi < 0.0:
                continue
            for _ in range(40):
                s = 0.5 * (lo + hi)
                u, v = _hermite(s, h, u0, v0, u1, v1)
                if _pushing(sgn, u, v, gap, k, lam) == start:
                    lo = s
                else:
                    hi = s
            if first < 0.0 or hi < first:
                first = hi
    return first


@njit(cache=True)
def _slide(q, kinds, rows, jk, jf, jz):
    """Return mapping of the Jenkins sliders to the displacement of the state q."""
    m = q.shape[0]
    for e in range(kinds.shape[0]):
        if kinds[e] != HYSTERETIC:
            continue
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


@njit(cache=True)
def _integrate(dt, n_steps, q0, qd0, cur0, model, jz, loads, voff, out_q, out_v, out_a, out_d, rec_every):
    kinds = model[3]
    rows = model[4]
    par = model[5]
    jk = model[6]
    jf = model[7]
    gamma = model[9]
    m = q0.shape[0]
    n_loads = loads.shape[1]
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
    qn = np.zeros(m)
    qdn = np.zeros(m)
    cur = cur0
    k1v = np.zeros(m)
    ws = (np.zeros(m), np.zeros(m), np.zeros(m), np.zeros(m), np.zeros(m), np.zeros(m), np.zeros(m),
          np.zeros(n_rec), np.zeros(n_rec), np.zeros(n_rec), np.zeros(m))
    fe, ue, ve = ws[7], ws[8], ws[9]
    la = np.zeros(n_loads)
    lm = np.zeros(n_loads)
    lb = np.zeros(n_loads)
    for n in range(n_steps + 1):
        k = 2 * n
        c1 = _derivative(q, qd, cur, loads[k], voff[k], model, jz, k1v, fe, ue, ve, ws[10])
        for o in range(n_out):
            s = 0.0
            for i in range(m):
                s += out_q[o, i] * q[i] + out_v[o, i] * qd[i] + out_a[o, i] * k1v[i]
            for l in range(n_loads):
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
        a = 0.0  # fraction of the step done; a stopper's contact starting or ending inside the step
        va = voff[k]  # splits it there (event location), so that no step straddles a change of force law
        for i in range(n_loads):
            la[i] = loads[k, i]
        for event in range(MAX_EVENTS + 1):
            if event > 0:
                c1 = _derivative(q, qd, cur, la, va, model, jz, k1v, fe, ue, ve, ws[10])
            vm = _loads_at(loads, voff, k, 0.5 * (a + 1.0), lm)
            vb = _loads_at(loads, voff, k, 1.0, lb)
            h = (1.0 - a) * dt
            cur_n = _rk4(q, qd, cur, h, la, lm, lb, va, vm, vb, k1v, c1, model, jz, ws, qn, qdn)
            s = _first_contact_event(q, qd, qn, qdn, h, kinds, rows, par) if event < MAX_EVENTS else -1.0
            if s < 0.0:
                break
            b = a + s * (1.0 - a)
            vm = _loads_at(loads, voff, k, 0.5 * (a + b), lm)
            vb = _loads_at(loads, voff, k, b, lb)
            cur = _rk4(q, qd, cur, (b - a) * dt, la, lm, lb, va, vm, vb, k1v, c1, model, jz, ws, qn, qdn)
            for i in range(m):
                q[i] = qn[i]
                qd[i] = qdn[i]
            _slide(q, kinds, rows, jk, jf, jz)
            a = b
            va = vb
            for i in range(n_loads):
                la[i] = lb[i]
        for i in range(m):
            q[i] = qn[i]
            qd[i] = qdn[i]
        cur = cur_n
        _slide(q, kinds, rows, jk, jf, jz)
    return y, eu, ev, ef, q, qd, cur, hq, hv


def stable_rate_hz(model: ModalModel, elements: list[Element] = ()) -> float:
    """Smallest rate with omega dt <= MAX_OMEGA_DT for the kept modes and <= MAX_CONTACT_OMEGA_DT for the
    stiffest element acting alone on its coordinate (omega^2 = k |Phi^T b|^2: k on the coordinate's
    effective mass), whose switching the event location resolves only if its motion is resolved."""
    omega = float(model.omega_rad_s.max()) / MAX_OMEGA_DT
    for e in elements:
        a = model.project(e.coordinate)
        omega = max(omega, math.sqrt(stiffening(e) * float(a @ a)) / MAX_CONTACT_OMEGA_DT)
    return omega


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
    model_args = (model.omega_rad_s**2, np.ascontiguousarray(model.damping), bm, kinds, np.ascontiguousarray(rows),
                  par, jk, jf, gm, float(gamma), coil_par, coil_a, int(volt))
    y, eu, ev, ef, q, qd, cur, hq, hv = _integrate(
        1.0 / rate_hz, int(n_steps), np.asarray(initial.q, float).copy(), np.asarray(initial.qd, float).copy(),
        float(initial.current_a), model_args, jz, load_arr, voff, out_mats[0], out_mats[1], out_mats[2], out_d,
        int(record_every))
    return Response(rate_hz=rate_hz, outputs=y, element_u=eu, element_v=ev, element_f=ef,
                    final=State(q=q, qd=qd, current_a=cur, sliders=jz),
                    modal_q=hq if record_every else None, modal_qd=hv if record_every else None)
