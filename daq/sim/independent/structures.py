"""Other labs' structures: a single-mode Duffing oscillator, a chain of masses, and a clamped-clamped beam
with geometric (membrane-stretching) hardening.

- Duffing (the electronic "Silverbox" benchmark's model: Wigren and Schoukens, IFAC Proc. 46(11), 2013):
  m x'' + c x' + k x + k3 x^3 = F(t); one DOF, the cubic term is an elements.Cubic on x.
- Chain: masses m_0 .. m_{n-1} on a line, spring k_0 (and damper) from ground to m_0, k_i between
  m_{i-1} and m_i, and optionally k_n from m_{n-1} to ground; modal damping ratios per chain mode.
- Clamped-clamped beam: Euler-Bernoulli finite elements (beams.py) with immovable ends, so bending
  stretches the mid-plane and the axial force N = EA / (2L) integral (w')^2 dx couples the bending modes
  (a Membrane element); first frequency (lambda_1^2 / L^2) sqrt(EI / (rho A)), lambda_1 = 4.7300.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .beams import BeamModel, BeamSpec, assemble_beam
from .elements import Membrane
from .modal import Structure, modal_damping_matrix


def duffing_structure(mass_kg: float, stiffness_n_per_m: float, damping_n_s_per_m: float) -> Structure:
    return Structure(np.array([[mass_kg]]), np.array([[stiffness_n_per_m]]), np.array([[damping_n_s_per_m]]))


@dataclass(frozen=True)
class ChainSpec:
    masses_kg: tuple[float, ...]
    springs_n_per_m: tuple[float, ...]  # n (ground-m0, m0-m1, ...) or n + 1 (also m_{n-1}-ground)
    zetas: tuple[float, ...]  # modal damping ratio per chain mode

    @property
    def n_masses(self) -> int:
        return len(self.masses_kg)


def chain_stiffness(spec: ChainSpec, extra: dict[tuple[int, int], float] | None = None) -> np.ndarray:
    """K of the chain; extra {(i, j): k} adds springs between masses i and j."""
    n = spec.n_masses
    k = np.zeros((n, n))
    for i, ki in enumerate(spec.springs_n_per_m):
        a, b = i - 1, i  # spring i joins mass i - 1 (or ground) and mass i (or ground)
        for p, q in ((a, a), (b, b)):
            if 0 <= p < n:
                k[p, q] += ki
        if 0 <= a < n and 0 <= b < n:
            k[a, b] -= ki
            k[b, a] -= ki
    for (i, j), kij in (extra or {}).items():
        e = relative(n, i, j)
        k += kij * np.outer(e, e)
    return k


def relative(n: int, i: int, j: int) -> np.ndarray:
    """Vector b with b . x = x_i - x_j."""
    b = np.zeros(n)
    b[i] += 1.0
    b[j] -= 1.0
    return b


def unit(n: int, i: int) -> np.ndarray:
    b = np.zeros(n)
    b[i] = 1.0
    return b


def chain_structure(spec: ChainSpec, extra: dict[tuple[int, int], float] | None = None) -> Structure:
    m = np.diag(spec.masses_kg)
    k = chain_stiffness(spec, extra)
    return Structure(m, k, modal_damping_matrix(m, k, np.asarray(spec.zetas)))


@dataclass
class ClampedBeam:
    model: BeamModel
    structure: Structure
    membrane: Membrane


def clamped_clamped_beam(spec: BeamSpec, zetas: np.ndarray) -> ClampedBeam:
    if spec.support != "clamped-clamped":
        raise ValueError("the spec must be clamped-clamped")
    bm = assemble_beam(spec)
    z = np.full(bm.n_dof, zetas[-1])
    z[:min(len(zetas), bm.n_dof)] = zetas[:bm.n_dof]
    structure = Structure(bm.mass, bm.stiffness, modal_damping_matrix(bm.mass, bm.stiffness, z))
    coef = spec.youngs_pa * spec.area_m2 / (2 * spec.length_m)
    return ClampedBeam(model=bm, structure=structure, membrane=Membrane(bm.membrane, coef))
