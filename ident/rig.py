"""The shaker rig: two weakly coupled cantilevers with stoppers, base-excited (paper section 4, Fig. 8).

Each beam's first bending mode is one degree of freedom: the tip displacement
z_i relative to the base, with modal mass m_i (tip mass plus the beam's
effective mass), stiffness k_i and viscous damping c_i. A weak spring k_c
couples the tips. Stoppers at z = +gap_pos and z = -gap_neg act as stiff
springs k_s with optional contact damping c_s while touched (compressive
only: a stopper pushes, never pulls). The base acceleration a_b(t) drives both:

    m_i z_i'' + c_i z_i' + k_i z_i + k_c (z_i - z_j) + f_stop,i + f_extra,i = -m_i a_b + m_i a_kick,i

and the accelerometers read the absolute accelerations a_b and z_i'' + a_b.

Default parameters reproduce the regimes of the paper's Fig. 8 at 12.3 Hz
and 1.93 m/s^2 base amplitude, all four coexisting (which one appears
depends on the initial state or a kick): linear (tips 8.9 m/s^2 peak, in
phase with each other), localized on beam 1 or 2 (87.5 vs 9.5 m/s^2 peak),
both impacting (89 m/s^2). Coexistence needs each beam to be bistable
alone, so the uncoupled natural frequency (11.2 Hz) lies below the
excitation: the linear regime's tips then lag the base by about 158
degrees, not the 90 degrees of a resonance.
``f_extra`` holds the effects that the discovery tests hide in the data:
cubic stiffness, Coulomb friction and quadratic damping.

Streaming, like scipy.signal's ``sosfilt(..., zi=)``: :func:`integrate` takes a
state and a block of excitation at the sub-step rate and returns the new
state and the block's outputs, and any split into blocks gives the same result.
The integrator is fixed-step RK4 at ``substeps`` per output sample, compiled
with numba.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numba import njit


TWO_PI = 2.0 * np.pi


@dataclass(frozen=True)
class Beam:
    """One cantilever's first mode, with its stoppers and optional extra effects (SI units)."""

    # 32.75 g tip mass + effective mass of the 1.5 mm aluminium sheet
    mass_kg: float = field(default=0.040, metadata={"gt": 0.0})
    natural_frequency_hz: float = field(default=11.2, metadata={"gt": 0.0, "max": 1000.0})  # uncoupled
    damping_ratio: float = field(default=0.03, metadata={"min": 0.0, "max": 1.0})
    gap_pos_m: float = field(default=2.7e-3, metadata={"gt": 0.0, "inf_ok": True})  # + side stopper; inf = none
    gap_neg_m: float = field(default=2.7e-3, metadata={"gt": 0.0, "inf_ok": True})  # - side (a distance); inf = none
    stopper_stiffness_n_per_m: float = field(default=1.0e5, metadata={"min": 0.0})
    stopper_damping_n_s_per_m: float = field(default=2.0, metadata={"min": 0.0})
    cubic_stiffness_n_per_m3: float = 0.0  # positive hardens
    coulomb_friction_n: float = field(default=0.0, metadata={"min": 0.0})
    quadratic_damping_n_s2_per_m2: float = field(default=0.0, metadata={"min": 0.0})
    quadratic_stiffness_n_per_m2: float = 0.0  # force k2 z|z|; positive hardens

    @property
    def stiffness_n_per_m(self) -> float:
        return self.mass_kg * (TWO_PI * self.natural_frequency_hz) ** 2

    @property
    def damping_n_s_per_m(self) -> float:
        return 2.0 * self.damping_ratio * self.mass_kg * TWO_PI * self.natural_frequency_hz


@dataclass(frozen=True)
class RigParams:
    beam1: Beam = field(default_factory=Beam)
    beam2: Beam = field(default_factory=Beam)
    coupling_stiffness_n_per_m: float = field(default=1.0, metadata={"min": 0.0})

    def vector(self) -> np.ndarray:
        """Per-mass parameter vector of the compiled kernel (``N_PER_BEAM`` per beam, layout as ``_accel``
        reads it: w^2, c, k_coupling, gap+, gap-, k_stopper, c_stopper, k3, F_coulomb, c_quadratic, k2)."""
        out = []
        for b in (self.beam1, self.beam2):
            m = b.mass_kg
            out += [b.stiffness_n_per_m / m, b.damping_n_s_per_m / m, self.coupling_stiffness_n_per_m / m,
                    b.gap_pos_m, b.gap_neg_m, b.stopper_stiffness_n_per_m / m, b.stopper_damping_n_s_per_m / m,
                    b.cubic_stiffness_n_per_m3 / m, b.coulomb_friction_n / m,
                    b.quadratic_damping_n_s2_per_m2 / m, b.quadratic_stiffness_n_per_m2 / m]
        return np.array(out, dtype=float)

    def with_beams(self, **changes) -> "RigParams":
        """The same rig with fields of both beams changed, e.g. ``with_beams(damping_ratio=0.03)``."""
        return replace(self, beam1=replace(self.beam1, **changes), beam2=replace(self.beam2, **changes))


N_PER_BEAM = 11
# Velocity scale below which Coulomb friction is smoothed (tanh), m/s.
FRICTION_V_EPS = 1e-4


@njit(cache=True, nogil=True)
def _accel(p, z, v, ab, kick, out_a, out_contact):  # pragma: no cover - compiled
    for i in range(2):
        o = i * N_PER_BEAM
        j = 1 - i
        w2 = p[o]
        c = p[o + 1]
        kc = p[o + 2]
        gp = p[o + 3]
        gn = p[o + 4]
        ks = p[o + 5]
        cs = p[o + 6]
        k3 = p[o + 7]
        fc = p[o + 8]
        cq = p[o + 9]
        k2 = p[o + 10]
        f = w2 * z[i] + c * v[i] + kc * (z[i] - z[j]) + k3 * z[i] ** 3 + k2 * z[i] * abs(z[i])
        f += fc * np.tanh(v[i] / FRICTION_V_EPS) + cq * v[i] * abs(v[i])
        contact = 0
        if z[i] > gp:
            fs = ks * (z[i] - gp) + cs * v[i]
            if fs > 0.0:
                f += fs
            contact = 1
        elif z[i] < -gn:
            fs = ks * (z[i] + gn) + cs * v[i]
            if fs < 0.0:
                f += fs
            contact = -1
        out_a[i] = -f - ab + kick[i]
        out_contact[i] = contact


@njit(cache=True, nogil=True)
def _integrate(p, state, ab, kick, dt, m):  # pragma: no cover - compiled
    """RK4 with ``m`` sub-steps per output sample; ab (n*m + 1,), kick (n*m + 1, 2).

    State y = (z, v), y' = (v, a(z, v, t)); the excitation at a stage midpoint
    is the mean of its neighbours (linear interpolation between sub-steps).
    """
    n = (ab.shape[0] - 1) // m
    z = state[0:2].copy()
    v = state[2:4].copy()
    out = np.empty((n, 2, 3))  # per sample: (beam, [z, v, a_rel])
    contact = np.zeros((n, 2), dtype=np.int8)
    k1v = np.empty(2)
    k2v = np.empty(2)
    k3v = np.empty(2)
    k4v = np.empty(2)
    k1z = np.empty(2)
    k2z = np.empty(2)
    k3z = np.empty(2)
    k4z = np.empty(2)
    zs = np.empty(2)
    vs = np.empty(2)
    kmid = np.empty(2)
    cflag = np.empty(2, dtype=np.int64)
    h = dt / m
    for s in range(n):
        for q in range(m):
            k0 = s * m + q
            abm = 0.5 * (ab[k0] + ab[k0 + 1])
            for i in range(2):
                kmid[i] = 0.5 * (kick[k0, i] + kick[k0 + 1, i])
            _accel(p, z, v, ab[k0], kick[k0], k1v, cflag)
            for i in range(2):
                k1z[i] = v[i]
                zs[i] = z[i] + 0.5 * h * k1z[i]
                vs[i] = v[i] + 0.5 * h * k1v[i]
            _accel(p, zs, vs, abm, kmid, k2v, cflag)
            for i in range(2):
                k2z[i] = vs[i]
                zs[i] = z[i] + 0.5 * h * k2z[i]
                vs[i] = v[i] + 0.5 * h * k2v[i]
            _accel(p, zs, vs, abm, kmid, k3v, cflag)
            for i in range(2):
                k3z[i] = vs[i]
                zs[i] = z[i] + h * k3z[i]
                vs[i] = v[i] + h * k3v[i]
            _accel(p, zs, vs, ab[k0 + 1], kick[k0 + 1], k4v, cflag)
            for i in range(2):
                k4z[i] = vs[i]
                z[i] += h / 6.0 * (k1z[i] + 2.0 * k2z[i] + 2.0 * k3z[i] + k4z[i])
                v[i] += h / 6.0 * (k1v[i] + 2.0 * k2v[i] + 2.0 * k3v[i] + k4v[i])
        k_end = (s + 1) * m
        _accel(p, z, v, ab[k_end], kick[k_end], k1v, cflag)
        for i in range(2):
            out[s, i, 0] = z[i]
            out[s, i, 1] = v[i]
            out[s, i, 2] = k1v[i]
            contact[s, i] = cflag[i]
    new_state = np.empty(4)
    new_state[0:2] = z
    new_state[2:4] = v
    return new_state, out, contact


@dataclass(frozen=True)
class RigOutput:
    """One block of rig response at the output sample times (after each step).

    base, tip1, tip2: absolute accelerations [m/s^2]; z, v: relative tip
    displacement [m] and velocity [m/s], shape (n, 2); contact: -1, 0, +1 per beam.
    """

    base: np.ndarray
    tip1: np.ndarray
    tip2: np.ndarray
    z: np.ndarray
    v: np.ndarray
    contact: np.ndarray


def integrate(params: RigParams, state: np.ndarray, base_accel: np.ndarray, dt: float,
              substeps: int, kick: np.ndarray | None = None) -> tuple[np.ndarray, RigOutput]:
    """Advance the rig over one block.

    state: [z1, z2, v1, v2]. base_accel: (n * substeps + 1,) base acceleration at
    the sub-step times from the current time to the end of the block (the first
    value is the one at the current time). kick: the same shape times 2, extra
    acceleration applied to each tip (a hammer blow). Returns (new_state, output
    for the n samples after the current time).
    """
    base_accel = np.ascontiguousarray(base_accel, dtype=float)
    m = int(substeps)
    if m < 1 or (base_accel.size - 1) % m:
        raise ValueError(f"base_accel must have n*substeps + 1 samples, got {base_accel.size} "
                         f"for substeps = {m}")
    if kick is None:
        kick = np.zeros((base_accel.size, 2))
    kick = np.ascontiguousarray(kick, dtype=float)
    if kick.shape != (base_accel.size, 2):
        raise ValueError(f"kick must have shape {(base_accel.size, 2)}, got {kick.shape}")
    st = np.asarray(state, dtype=float)
    if st.shape != (4,) or not np.all(np.isfinite(st)):
        raise ValueError("rig state must be 4 finite numbers [z1, z2, v1, v2]")
    new, out, contact = _integrate(params.vector(), st, base_accel, kick, float(dt), m)
    ab_out = base_accel[m::m]
    return new, RigOutput(ab_out, out[:, 0, 2] + ab_out, out[:, 1, 2] + ab_out, out[:, :, 0].copy(),
                          out[:, :, 1].copy(), contact)


def simulate_measured_base(params: RigParams, base: np.ndarray, fs_hz: float, substeps: int = 8,
                           state: np.ndarray | None = None) -> RigOutput:
    """The rig driven by a *measured* base acceleration (samples at ``fs_hz``), linear between samples.

    Output sample k is the response at the time of base sample k (the first one is the initial state).
    """
    base = np.asarray(base, float)
    if base.ndim != 1 or base.size < 2:
        raise ValueError("base acceleration must be a 1-D series of at least 2 samples")
    if not np.all(np.isfinite(base)):
        raise ValueError("base acceleration contains NaN or inf")
    n = base.size - 1
    k = np.arange(n * substeps + 1) / substeps
    ab = np.interp(k, np.arange(base.size), base)
    st = np.zeros(4) if state is None else np.asarray(state, float)
    _, out = integrate(params, st, ab, 1.0 / fs_hz, substeps)
    # prepend the initial sample so outputs align with the input samples
    a0 = np.zeros(2)
    _accel(params.vector(), st[:2].copy(), st[2:].copy(), base[0], np.zeros(2), a0, np.zeros(2, np.int64))
    first = lambda arr, v: np.concatenate([np.asarray(v)[None], arr])  # noqa: E731
    return RigOutput(base, first(out.tip1, a0[0] + base[0]), first(out.tip2, a0[1] + base[0]),
                     first(out.z, st[:2]), first(out.v, st[2:]), first(out.contact, np.zeros(2, np.int8)))
