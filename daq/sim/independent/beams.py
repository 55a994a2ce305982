"""Euler-Bernoulli beams by finite elements: mass, stiffness and membrane matrices, points along the span.

Hermite cubic elements with two degrees of freedom per node, the transverse displacement w (m) and the
slope theta = dw/dx (rad). For an element of length l (Przemieniecki, Theory of Matrix Structural
Analysis, 1968, eqs. 5.116 and 11.28; Cook et al., Concepts and Applications of FEA, 4th ed., 2002,
secs. 2.4, 11.3 and 18.4):

    K_e = EI / l^3 [[12, 6l, -12, 6l], [6l, 4l^2, -6l, 2l^2], [-12, -6l, 12, -6l], [6l, 2l^2, -6l, 4l^2]]
    M_e = rho A l / 420 [[156, 22l, 54, -13l], [22l, 4l^2, 13l, -3l^2], [54, 13l, 156, -22l],
                         [-13l, -3l^2, -22l, 4l^2]]
    G_e = 1 / (30 l) [[36, 3l, -36, 3l], [3l, 4l^2, -3l, -l^2], [-36, -3l, 36, -3l], [3l, -l^2, -3l, 4l^2]]

G is the consistent matrix of the integral of (w')^2 (the geometric stiffness for a unit axial force):
the integral of (w')^2 over the span is u^T G u, which gives the von Karman membrane force of a beam
with immovable ends, N = EA / (2 L) u^T G u.

A tip mass m_t with rotary inertia J_t sits on the tip node. The root is clamped, clamped through a
rotational spring (a joint: w fixed, theta held by the spring), or both ends are clamped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SUPPORTS = ("cantilever", "clamped-clamped")


@dataclass(frozen=True)
class BeamSpec:
    """Geometry and material of a uniform strip (SI units)."""

    length_m: float
    width_m: float
    thickness_m: float
    youngs_pa: float = 70e9
    density_kg_m3: float = 2700.0
    n_elements: int = 12
    tip_mass_kg: float = 0.0
    tip_inertia_kg_m2: float = 0.0
    support: str = "cantilever"
    root_stiffness_n_m_per_rad: float | None = None  # None: rigid clamp; else a rotational root joint

    def describe(self) -> dict:
        return {"length_m": self.length_m, "width_m": self.width_m, "thickness_m": self.thickness_m,
                "youngs_pa": self.youngs_pa, "density_kg_m3": self.density_kg_m3, "n_elements": self.n_elements,
                "tip_mass_kg": self.tip_mass_kg, "tip_inertia_kg_m2": self.tip_inertia_kg_m2,
                "support": self.support, "root_stiffness_n_m_per_rad": self.root_stiffness_n_m_per_rad}

    @property
    def area_m2(self) -> float:
        return self.width_m * self.thickness_m

    @property
    def ei_n_m2(self) -> float:
        return self.youngs_pa * self.width_m * self.thickness_m**3 / 12.0

    @property
    def mass_per_length_kg_m(self) -> float:
        return self.density_kg_m3 * self.area_m2


def hermite(xi: float, length_m: float, derivative: int = 0) -> np.ndarray:
    """Hermite cubic shape functions (or their x-derivatives) at xi = x / l in [0, 1] of an element."""
    l = length_m
    if derivative == 0:
        return np.array([1 - 3 * xi**2 + 2 * xi**3, l * (xi - 2 * xi**2 + xi**3),
                         3 * xi**2 - 2 * xi**3, l * (-xi**2 + xi**3)])
    if derivative == 1:
        return np.array([-6 * xi + 6 * xi**2, l * (1 - 4 * xi + 3 * xi**2),
                         6 * xi - 6 * xi**2, l * (-2 * xi + 3 * xi**2)]) / l
    if derivative == 2:
        return np.array([-6 + 12 * xi, l * (-4 + 6 * xi), 6 - 12 * xi, l * (-2 + 6 * xi)]) / l**2
    raise ValueError("derivative must be 0, 1 or 2")


def element_matrices(spec: BeamSpec) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(K_e, M_e, G_e) of one element of the uniform beam."""
    l = spec.length_m / spec.n_elements
    k = spec.ei_n_m2 / l**3 * np.array([[12, 6 * l, -12, 6 * l], [6 * l, 4 * l**2, -6 * l, 2 * l**2],
                                        [-12, -6 * l, 12, -6 * l], [6 * l, 2 * l**2, -6 * l, 4 * l**2]])
    m = spec.mass_per_length_kg_m * l / 420.0 * np.array(
        [[156, 22 * l, 54, -13 * l], [22 * l, 4 * l**2, 13 * l, -3 * l**2],
         [54, 13 * l, 156, -22 * l], [-13 * l, -3 * l**2, -22 * l, 4 * l**2]])
    g = 1.0 / (30.0 * l) * np.array([[36, 3 * l, -36, 3 * l], [3 * l, 4 * l**2, -3 * l, -l**2],
                                     [-36, -3 * l, 36, -3 * l], [3 * l, -l**2, -3 * l, 4 * l**2]])
    return k, m, g


@dataclass
class BeamModel:
    """Assembled matrices on the free degrees of freedom of one beam."""

    spec: BeamSpec
    mass: np.ndarray
    stiffness: np.ndarray
    membrane: np.ndarray  # G: integral of (w')^2 = u^T G u
    free: np.ndarray  # indices of the free DOFs among the 2 (n + 1) nodal DOFs

    @property
    def n_dof(self) -> int:
        return len(self.free)

    def _restrict(self, full: np.ndarray) -> np.ndarray:
        return full[self.free]

    def point(self, x_m: float, derivative: int = 0) -> np.ndarray:
        """Vector b with b . u = w(x) (derivative 0), w'(x) (1) or w''(x) (2) at x_m along the span."""
        n = self.spec.n_elements
        l = self.spec.length_m / n
        if not -1e-12 <= x_m <= self.spec.length_m + 1e-12:
            raise ValueError(f"x_m = {x_m} outside the beam [0, {self.spec.length_m}]")
        e = min(int(x_m / l), n - 1)
        full = np.zeros(2 * (n + 1))
        full[2 * e:2 * e + 4] = hermite((x_m - e * l) / l, l, derivative)
        return self._restrict(full)

    def root_rotation(self) -> np.ndarray:
        """Vector b with b . u = theta(0), the rotation in the root joint."""
        if self.spec.root_stiffness_n_m_per_rad is None:
            raise ValueError("a clamped root does not rotate")
        return self.point(0.0, derivative=1)

    def translation_influence(self) -> np.ndarray:
        """Rigid-body vector r of a transverse translation of the supports (1 on w, 0 on theta)."""
        full = np.zeros(2 * (self.spec.n_elements + 1))
        full[0::2] = 1.0
        return self._restrict(full)

    def static_compliance(self, b: np.ndarray) -> float:
        """Static displacement of the coordinate b . u under a unit force on it (m/N)."""
        return float(b @ np.linalg.solve(self.stiffness, b))


def assemble_beam(spec: BeamSpec) -> BeamModel:
    """Assemble K, M and G, add the tip mass and the root joint, remove the constrained DOFs."""
    if spec.support not in SUPPORTS:
        raise ValueError(f"support must be one of {SUPPORTS}")
    if spec.n_elements < 8:
        raise ValueError("use at least 8 elements per beam")
    n = spec.n_elements
    size = 2 * (n + 1)
    k_full = np.zeros((size, size))
    m_full = np.zeros((size, size))
    g_full = np.zeros((size, size))
    k_e, m_e, g_e = element_matrices(spec)
    for e in range(n):
        s = slice(2 * e, 2 * e + 4)
        k_full[s, s] += k_e
        m_full[s, s] += m_e
        g_full[s, s] += g_e
    fixed = {0}
    if spec.root_stiffness_n_m_per_rad is None:
        fixed.add(1)
    else:
        k_full[1, 1] += spec.root_stiffness_n_m_per_rad
    if spec.support == "clamped-clamped":
        fixed |= {size - 2, size - 1}
    else:
        m_full[size - 2, size - 2] += spec.tip_mass_kg
        m_full[size - 1, size - 1] += spec.tip_inertia_kg_m2
    free = np.array([i for i in range(size) if i not in fixed])
    ix = np.ix_(free, free)
    return BeamModel(spec=spec, mass=m_full[ix], stiffness=k_full[ix], membrane=g_full[ix], free=free)


def strip_tip_inertia(mass_kg: float, length_m: float, thickness_m: float) -> float:
    """Rotary inertia (kg m^2) of a rectangular tip block about its centre, bending axis across the width."""
    return mass_kg * (length_m**2 + thickness_m**2) / 12.0
