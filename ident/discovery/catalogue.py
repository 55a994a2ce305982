"""The catalogue of causes: each one as data, with its force law compiled once.

A mechanical cause is an internal restoring force f(z, v) at a location (a sensor, measured against the
ground or the shaking frame, or the relative motion of two sensors), added to the linear model's
equations with the sign of a spring: a positive coefficient hardens or dissipates. Every law is written
with a unit coefficient; the coefficient is what the search fits (it multiplies the modal gains of the
location, so it comes out per unit modal mass at the location, see ``baselines``). The laws:

    contact              f = k (z - g)  for z > g,  k (z + g)  for z < -g  (per side: both, positive, negative;
                                                        compressive only, with optional damping while touching)
    cubic_stiffness      f = k3 z^3                    (geometric hardening; k3 < 0 softens)
    quadratic_stiffness  f = k2 z |z|                  (an asymmetric-free alternative to the cubic)
    coulomb_friction     f = F tanh(v / eps)           (dry friction, eps a small fraction of the velocity)
    quadratic_damping    f = c2 v |v|                  (aerodynamic drag)
    hysteretic_joint     f = -sum_i k/N s_i            (Iwan: N Jenkins elements, stiffness k/N each, slip
                                                        displacements spread evenly from r delta to delta,
                                                        delta (r + (1 - r)(i + 1/2) / N); s_i the slider,
                                                        dragged along once |z - s_i| would exceed it)
    linear_mismatch      f = dk z + dc v               (a spring and a damper missing from the model)

The joint is written as the Iwan element minus its stuck stiffness (Segalman 2005, "A four-parameter Iwan
model for lap-type joints"; Worden & Tomlinson 2001, ch. 2): a model fitted in the stuck state already
holds that stiffness, so the element adds nothing until the joint slips, then takes stiffness away and
dissipates, which is what bolted joints do as the amplitude grows.

Sensor causes act on a simulated output, not on the equations: ``sensor_gain``, ``sensor_offset``,
``clipping``. They apply only to a baseline with physical parameters (the rig model): a model fitted to
the data absorbs a gain or an offset.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

# law codes of the compiled kernel
NONE, CONTACT, CUBIC, QUADRATIC, COULOMB, QDAMP, JOINT, LINEAR = range(8)
SIDES = ("both", "positive", "negative")
N_IWAN = 10  # Jenkins elements of the joint
ONSETS = (0.0, 0.4, 0.8)  # the joint's slip onsets scanned by the refinement (share of its largest slip)
N_LAW = 3  # numbers per law besides the coefficient(s): see each cause's ``law_parameters``


@dataclass(frozen=True)
class Parameter:
    name: str
    unit: str  # per unit modal mass at the location unless the name says otherwise
    description: str


@dataclass(frozen=True)
class Cause:
    """One cause of the catalogue.

    ``coefficients``: fitted by least squares (the law is linear in them); ``shape``: parameters that
    the law is not linear in (a gap, a side, a slip displacement), searched on a grid and refined by
    simulation. ``positive``: the coefficient must be positive for a physical cause (a stopper pushes, a
    friction dissipates). ``order``: complexity for the parsimony rule (number of fitted numbers).
    """

    name: str
    code: int
    coefficients: tuple[Parameter, ...]
    shape: tuple[Parameter, ...] = ()
    positive: bool = True
    kind: str = "mechanical"  # or "sensor"
    separates_by: str = ""  # the test that would tell this cause from a look-alike
    # a refit of a fitted linear part with the cause in place also starts from these strengths: shares of
    # the location's mode's stiffness (omega^2) or damping (2 zeta omega), as ``equivalent_coefficient``
    starts: tuple[float, ...] = ()
    # the parameters are read off the whole record (a sensor's full scale: its extreme), not fitted on the
    # training blocks, so every block may test the cause (``search.score``), not the held-out ones alone
    read_off_record: bool = False
    # the cause whose mechanism this law describes when its coefficient is negative (it softens), and the
    # test that tells the two apart: a first finding that softens has that cause as a look-alike where it
    # fits significantly and nearly as well too (``discover.SOFTENING_SHARE``)
    softening_mechanism: str = ""
    separates_softening: str = ""
    # acts only where the motion passes a threshold (a stopper's gap): what it adds lives in a few held-out
    # pieces, so its test against its own refitted linear part is on the mean gain alone (``search.over_own_part``)
    intermittent: bool = False

    @property
    def order(self) -> int:
        return len(self.coefficients) + len(self.shape)


CAUSES: dict[str, Cause] = {c.name: c for c in (
    Cause("contact", CONTACT,
          (Parameter("stiffness_per_mass", "1/s^2", "stopper stiffness per modal mass"),),
          (Parameter("gap", "m", "clearance to the stopper at the location"),
           Parameter("side", "", "both, positive or negative")),
          separates_by="a stepped sine whose levels straddle the gap: a contact switches on at one amplitude",
          # a stopper's regression is a soft spring (independent seed 22: 12 x softer than the generator's);
          # refitted from a stiff start the linear part gives the stiffness back and the stopper is found
          # (held-out gain 0.29 where the refinement from the regression reached 0.03)
          starts=(1.0, 10.0, 100.0), intermittent=True),
    Cause("cubic_stiffness", CUBIC, (Parameter("coefficient_per_mass", "1/(m^2 s^2)", "k3 per modal mass"),),
          positive=False,
          separates_by="a stepped sine at three or more levels: a cubic's frequency shift grows with amplitude^2",
          # a softening cubic is also how a joint that slips looks over the amplitudes a record holds: where
          # the joint fits significantly and nearly as well too, it is the finding's look-alike
          # (``discover._softening_look_alike``)
          softening_mechanism="hysteretic_joint",
          separates_softening="a stepped sine at several levels: a joint's damping grows with amplitude as it "
                              "slips, a cubic's does not"),
    Cause("quadratic_stiffness", QUADRATIC, (Parameter("coefficient_per_mass", "1/(m s^2)", "k2 per modal mass"),),
          positive=False,
          separates_by="a stepped sine at three or more levels: the shift grows with amplitude, not its square"),
    Cause("coulomb_friction", COULOMB, (Parameter("force_per_mass", "m/s^2", "friction force per modal mass"),),
          separates_by="a low level: dry friction damps small motion most (equivalent damping ~ 1/amplitude)",
          starts=(0.3, 1.0, 3.0)),
    Cause("quadratic_damping", QDAMP, (Parameter("coefficient_per_mass", "1/m", "drag coefficient per modal mass"),),
          separates_by="a high level: drag damps large motion most (equivalent damping ~ amplitude)",
          starts=(0.3, 1.0, 3.0)),
    Cause("hysteretic_joint", JOINT,
          (Parameter("stiffness_per_mass", "1/s^2", "joint stiffness lost when it slips, per modal mass"),),
          (Parameter("slip", "m", "displacement across the joint at which its strongest element slips"),
           Parameter("onset", "", "share of that slip below which no element slips (0: microslip from rest)")),
          separates_by="a stepped sine at several levels: a joint softens and damps more as it slips, "
                       "a friction damper does not soften", starts=(0.03, 0.1, 0.3)),
    Cause("linear_mismatch", LINEAR,
          (Parameter("stiffness_per_mass", "1/s^2", "missing stiffness per modal mass"),
           Parameter("damping_per_mass", "1/s", "missing damping per modal mass")), positive=False,
          separates_by="two levels: a linear mismatch is the same at both"),
    Cause("sensor_gain", NONE, (Parameter("gain_error", "", "0.05 reads 5 % high"),), positive=False,
          kind="sensor", separates_by="a calibrator on the sensor"),
    Cause("sensor_offset", NONE, (Parameter("offset", "unit of the response", "constant added"),),
          positive=False, kind="sensor", separates_by="a record at rest"),
    Cause("clipping", NONE, (Parameter("range", "unit of the response", "the sensor's full scale"),),
          kind="sensor", separates_by="a lower level", read_off_record=True),
)}
MECHANICAL = tuple(n for n, c in CAUSES.items() if c.kind == "mechanical")
SENSOR = tuple(n for n, c in CAUSES.items() if c.kind == "sensor")


@njit(cache=True, nogil=True)
def law(code, p, z, v, s):  # pragma: no cover - compiled
    """Restoring force of a law with coefficient(s) p[0] (p[1]: the damper of linear_mismatch) and
    shape p[1:] (contact: gap, side 0/1/2 for both/positive/negative, damping while touching; coulomb:
    eps; joint: slip, onset), at displacement z and velocity v; s the joint's sliders (read only: ``slide``
    moves them between steps)."""
    if code == CONTACT:
        g = p[1]
        side = p[2]
        f = 0.0
        if z > g and side != 2.0:
            f = max(p[0] * (z - g) + p[3] * v, 0.0)  # a stopper pushes, never pulls
        elif z < -g and side != 1.0:
            f = min(p[0] * (z + g) + p[3] * v, 0.0)
        return f
    if code == CUBIC:
        return p[0] * z * z * z
    if code == QUADRATIC:
        return p[0] * z * abs(z)
    if code == COULOMB:
        return p[0] * np.tanh(v / p[1])
    if code == QDAMP:
        return p[0] * v * abs(v)
    if code == JOINT:
        acc = 0.0
        for i in range(N_IWAN):
            acc += s[i]
        return -p[0] * acc / N_IWAN
    if code == LINEAR:
        return p[0] * z + p[1] * v
    return 0.0


@njit(cache=True, nogil=True)
def slide(code, p, z, s):  # pragma: no cover - compiled
    """Move the joint's sliders to displacement z (return mapping: element i slips beyond its limit)."""
    if code != JOINT:
        return
    for i in range(N_IWAN):
        d = p[1] * (p[2] + (1.0 - p[2]) * (i + 0.5) / N_IWAN)
        if s[i] < z - d:
            s[i] = z - d
        elif s[i] > z + d:
            s[i] = z + d


@njit(cache=True, nogil=True)
def _law_series(code, p, z, v):  # pragma: no cover - compiled
    n = z.shape[0]
    out = np.empty(n)
    s = np.zeros(N_IWAN)
    for k in range(n):
        slide(code, p, z[k], s)
        out[k] = law(code, p, z[k], v[k], s)
    return out


def law_parameters(cause: Cause, shape: dict, column: int = 0) -> np.ndarray:
    """The kernel's parameter vector for a unit coefficient and the given shape parameters; ``column``
    picks the coefficient of a law with two (linear_mismatch: 0 the spring, 1 the damper)."""
    p = np.zeros(1 + N_LAW)
    p[column] = 1.0
    if cause.code == CONTACT:
        p[1], p[2] = float(shape["gap"]), float(SIDES.index(shape["side"]))
    elif cause.code == COULOMB:
        p[1] = float(shape["eps"])
    elif cause.code == JOINT:
        p[1], p[2] = float(shape["slip"]), float(shape.get("onset", 0.0))
    return p


def shapes(cause: Cause, z: np.ndarray, v: np.ndarray, n_grid: int = 24) -> list[tuple[dict, np.ndarray]]:
    """The cause's force shapes on a measured coordinate: (shape parameters, unit-coefficient force per
    column of the regression). Nonlinear shape parameters on a grid spanning the motion: a contact's gap
    over 10-95 % of the largest |z| on each side, a joint's slip over 1-100 % of the z range (its
    elements slipping from rest: the onset is scanned by simulation, ``search.refine``)."""
    z = np.ascontiguousarray(z, float)
    v = np.ascontiguousarray(v, float)
    top = float(np.max(np.abs(z))) if z.size else 0.0
    if cause.code == CONTACT:
        out = []
        for side in SIDES:
            for g in np.linspace(0.1, 0.95, n_grid) * top:
                shp = {"gap": float(g), "side": side}
                f = _law_series(CONTACT, law_parameters(cause, shp), z, v)
                if np.count_nonzero(f) >= 3:
                    out.append((shp, f[:, None]))
        return out
    if cause.code == JOINT:
        out = []
        for frac in np.geomspace(0.01, 1.0, n_grid // 2):
            shp = {"slip": float(frac * 2 * top), "onset": 0.0}
            out.append((shp, _law_series(JOINT, law_parameters(cause, shp), z, v)[:, None]))
        return out
    if cause.code == COULOMB:
        shp = {"eps": friction_eps(v)}
        return [(shp, np.tanh(v / shp["eps"])[:, None])]
    if cause.code == LINEAR:
        return [({}, np.column_stack([z, v]))]
    return [({}, _law_series(cause.code, law_parameters(cause, {}), z, v)[:, None])]


def describing_stiffness(cause: str, parameters: dict, amplitude: np.ndarray) -> np.ndarray | None:
    """A stiffness law's first-order equivalent stiffness per unit modal mass on a sinusoid of displacement
    amplitude ``amplitude`` at its location (describing functions, Worden & Tomlinson 2001, ch. 2): a free
    decay's backbone follows w(A)^2 = w0^2 + this. None for a law that is no stiffness of amplitude (a
    damper, a joint's hysteresis, a linear mismatch, a sensor).

    - cubic k3 z^3: 3/4 k3 A^2;  quadratic k2 z|z|: 8 / (3 pi) k2 A;
    - a stopper k beyond the gap g on both sides: k (1 - 2/pi (asin(g/A) + g/A sqrt(1 - (g/A)^2))) for
      A > g, nothing below; on one side, half of it (to first order: the offset one side's push gives the
      motion is left out)."""
    a = np.abs(np.asarray(amplitude, float))
    if cause == "cubic_stiffness":
        return 0.75 * parameters["coefficient_per_mass"] * a**2
    if cause == "quadratic_stiffness":
        return 8.0 / (3.0 * np.pi) * parameters["coefficient_per_mass"] * a
    if cause == "contact":
        r = np.clip(parameters["gap"] / np.maximum(a, 1e-300), 0.0, 1.0)
        share = 1.0 - 2.0 / np.pi * (np.arcsin(r) + r * np.sqrt(1.0 - r**2))
        return parameters["stiffness_per_mass"] * share * (1.0 if parameters["side"] == "both" else 0.5)
    return None


def equivalent_coefficient(cause: Cause, level: float, omega: float, zeta: float, v_rms: float) -> float:
    """The coefficient whose linear equivalent is ``level`` times a mode's stiffness or damping per unit
    modal mass (omega^2, 2 zeta omega), on a sinusoid of velocity amplitude sqrt(2) v_rms (first-order
    describing functions, Worden & Tomlinson 2001, ch. 2): a joint that has fully slipped has lost its
    stiffness k; drag c2 v|v| damps like 8 c2 V / (3 pi); dry friction F like 4 F / (pi V). A stopper's
    stiffness is taken as that share of the mode's stiffness itself: no describing function, only a
    start (its equivalent stiffness depends on how far beyond the gap the motion goes)."""
    v = np.sqrt(2.0) * v_rms
    if cause.code == JOINT or cause.code == CONTACT:
        return level * omega**2
    if cause.code == QDAMP:
        return level * 2 * zeta * omega * 3 * np.pi / (8 * v) if v > 0 else 0.0
    if cause.code == COULOMB:
        return level * 2 * zeta * omega * np.pi * v / 4
    raise ValueError(f"{cause.name} has no strength to start from")


def friction_eps(v: np.ndarray) -> float:
    """Velocity scale of the smoothed Coulomb law: 1 % of the velocity's RMS (a stick-slip switch the
    fixed-step integrator can follow)."""
    return 0.01 * float(np.sqrt(np.mean(np.asarray(v, float) ** 2))) + 1e-12


def force_series(code: int, p: np.ndarray, z: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The law evaluated along a measured coordinate (the joint's sliders carried through it)."""
    return _law_series(int(code), np.ascontiguousarray(p, float), np.ascontiguousarray(z, float),
                       np.ascontiguousarray(v, float))


def slope(code: int, p: np.ndarray, z_max: float, v_max: float) -> tuple[float, float]:
    """Largest stiffness and damping (force per displacement, per velocity) the law reaches within the
    motion: sets the integrator's step."""
    c = abs(float(p[0]))
    if code == CONTACT or code == JOINT:
        return c, 0.0
    if code == CUBIC:
        return 3 * c * z_max**2, 0.0
    if code == QUADRATIC:
        return 2 * c * z_max, 0.0
    if code == COULOMB:
        return 0.0, c / float(p[1])
    if code == QDAMP:
        return 0.0, 2 * c * v_max
    if code == LINEAR:
        return c, abs(float(p[1]))
    return 0.0, 0.0
