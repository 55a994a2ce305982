"""Nonlinear elements acting on one physical coordinate u = b . x (a point's displacement, a rotation, or
the difference of two points), and the distributed membrane force of a beam with immovable ends.

Each element gives a force f(u, u', state) on its coordinate; by virtual work it loads the modes with
Phi^T b f. Forces are positive along +u.

- Contact (a stopper with a gap g; Hunt and Crossley, J. Appl. Mech. 42, 1975, with a linear spring):
  penetration p = u - g (positive side) or -u - g (negative side); while p > 0 the stopper pushes with
  k p + lambda p p', and only pushes (compressive only): f = -max(0, k p + lambda p p') on the positive
  side. The damping grows with the penetration, so the force is continuous at the impact; with
  lambda = 3 (1 - e) k / (2 v) an impact at velocity v rebounds with a restitution coefficient of about e
  (ibid., eq. 17).
- Cubic spring: f = -k3 u^3 (hardening k3 > 0, softening k3 < 0).
- Hysteretic (parallel Jenkins elements, each a spring k_j in series with a slider of slip force F_j;
  Iwan, J. Appl. Mech. 33, 1966; Segalman, J. Appl. Mech. 72, 2005): f = -sum_j clip(k_j (u - z_j), F_j)
  with the slider positions z_j updated by return mapping (Simo and Hughes, Computational Inelasticity,
  1998, sec. 1.2). An Iwan joint has many elements with distributed F_j; a dry rubbing contact is one
  element whose k_j is the tangential stiffness of the contact (stick) and F_j = mu N (slip). When the
  stuck stiffness is already in the linear structure (a joint), only the difference is applied here.
- Quadratic damping (aerodynamic drag of a plate): f = -c_q |v| v, v the coordinate's velocity, plus the
  base velocity when the drag acts on the absolute velocity of a base-excited structure.
- Membrane (von Karman stretching of a beam with immovable ends): axial force N = EA / (2L) u^T G u,
  transverse load -N G u (Woinowsky-Krieger, J. Appl. Mech. 17, 1950; Nayfeh and Mook, Nonlinear
  Oscillations, 1979, sec. 7.2).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CONTACT, CUBIC, HYSTERETIC, DRAG = 0, 1, 2, 3
SIDES = {"both": 0, "positive": 1, "negative": -1}


@dataclass
class Contact:
    coordinate: np.ndarray
    gap_m: float
    stiffness_n_per_m: float
    damping_n_s_per_m2: float  # Hunt-Crossley lambda
    side: str = "both"

    def __post_init__(self):
        if self.side not in SIDES:
            raise ValueError(f"side must be one of {tuple(SIDES)}")
        if self.gap_m < 0:
            raise ValueError("gap_m must be >= 0")


def hunt_crossley_damping(stiffness_n_per_m: float, restitution: float, velocity_m_s: float) -> float:
    """lambda (N s/m^2) giving a restitution coefficient of about `restitution` at `velocity_m_s`."""
    return 3.0 * (1.0 - restitution) * stiffness_n_per_m / (2.0 * velocity_m_s)


@dataclass
class Cubic:
    coordinate: np.ndarray
    k3_n_per_m3: float


@dataclass
class Hysteretic:
    coordinate: np.ndarray
    stiffness_n_per_m: np.ndarray  # per Jenkins element (N/m, or N m/rad on a rotation)
    slip_force_n: np.ndarray  # per Jenkins element (N, or N m on a rotation)
    stuck_in_linear_model: bool  # True: the linear structure already holds sum(k_j)

    @property
    def stuck_stiffness(self) -> float:
        return float(np.sum(self.stiffness_n_per_m))


@dataclass
class Drag:
    coordinate: np.ndarray
    coefficient_n_s2_per_m2: float
    absolute: bool = False  # add the base velocity (drag on the velocity relative to still air)


Element = Contact | Cubic | Hysteretic | Drag


@dataclass
class Membrane:
    matrix: np.ndarray  # G on the physical DOFs
    coefficient_n: float  # EA / (2 L)


def pack(elements: list[Element], project) -> tuple[np.ndarray, ...]:
    """Arrays for the compiled kernel: type codes, modal rows, parameters, Jenkins k, F and z."""
    n_el = len(elements)
    n_j = max([len(e.stiffness_n_per_m) for e in elements if isinstance(e, Hysteretic)] + [1])
    rows = np.array([project(e.coordinate) for e in elements]) if n_el else np.zeros((0, 1))
    kinds = np.zeros(n_el, dtype=np.int64)
    par = np.zeros((n_el, 4))
    jk = np.zeros((n_el, n_j))
    jf = np.zeros((n_el, n_j))
    for i, e in enumerate(elements):
        if isinstance(e, Contact):
            kinds[i] = CONTACT
            par[i] = (e.gap_m, e.stiffness_n_per_m, e.damping_n_s_per_m2, SIDES[e.side])
        elif isinstance(e, Cubic):
            kinds[i] = CUBIC
            par[i, 0] = e.k3_n_per_m3
        elif isinstance(e, Hysteretic):
            kinds[i] = HYSTERETIC
            par[i, 0] = e.stuck_stiffness if e.stuck_in_linear_model else 0.0
            jk[i, :len(e.stiffness_n_per_m)] = e.stiffness_n_per_m
            jf[i, :len(e.slip_force_n)] = e.slip_force_n
        elif isinstance(e, Drag):
            kinds[i] = DRAG
            par[i, 0] = e.coefficient_n_s2_per_m2
            par[i, 1] = 1.0 if e.absolute else 0.0
        else:
            raise TypeError(f"unknown element {type(e).__name__}")
    return kinds, rows, par, jk, jf


def stiffening(element: Element) -> float:
    """The largest stiffness the element can add to its coordinate (N/m): sets the integration step."""
    if isinstance(element, Contact):
        return element.stiffness_n_per_m
    if isinstance(element, Hysteretic) and not element.stuck_in_linear_model:
        return element.stuck_stiffness
    return 0.0
