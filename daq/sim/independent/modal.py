"""Linear structures in physical coordinates and their modal reduction.

A structure is M x'' + C x' + K x = f (n physical DOFs). Its modes solve K phi = omega^2 M phi and are
mass-normalised (Phi^T M Phi = I), so the reduced equations for x = Phi q are

    q'' + Phi^T C Phi q' + diag(omega^2) q = Phi^T f

(Craig and Kurdila, Fundamentals of Structural Dynamics, 2nd ed., 2006, ch. 10 and 11). Modal damping
ratios zeta_i are put into a physical damping matrix C = M Phi diag(2 zeta_i omega_i) Phi^T M (ibid.
sec. 10.4) so that substructures keep their own damping when they are coupled; discrete dampers are
added to C. Forces at points (the nonlinear elements, loads) act on coordinates u = b . x and enter the
modal equations as Phi^T b f.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg


@dataclass
class Structure:
    """M, K, C on n physical DOFs, and the rigid-body vector r of a base translation (None: fixed base)."""

    mass: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    base_influence: np.ndarray | None = None

    @property
    def n_dof(self) -> int:
        return self.mass.shape[0]

    def static_compliance(self, b: np.ndarray) -> float:
        """Static displacement of the coordinate b . x under a unit force on it (m/N)."""
        return float(b @ np.linalg.solve(self.stiffness, b))


def normal_modes(mass: np.ndarray, stiffness: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(omega_rad_s ascending, mass-normalised shapes as columns)."""
    w2, phi = scipy.linalg.eigh(stiffness, mass)
    return np.sqrt(np.clip(w2, 0.0, None)), phi


def modal_damping_matrix(mass: np.ndarray, stiffness: np.ndarray, zetas: np.ndarray) -> np.ndarray:
    """Physical C giving the damping ratio zetas[i] to mode i (all n modes of (M, K))."""
    omega, phi = normal_modes(mass, stiffness)
    mp = mass @ phi
    return mp @ np.diag(2.0 * np.asarray(zetas) * omega) @ mp.T


def block_diag(*blocks: np.ndarray) -> np.ndarray:
    return scipy.linalg.block_diag(*blocks)


@dataclass
class ModalModel:
    """Mass-normalised modes kept by the reduction, with the projected damping."""

    omega_rad_s: np.ndarray  # (m,)
    shapes: np.ndarray  # (n, m), Phi
    damping: np.ndarray  # (m, m), Phi^T C Phi
    structure: Structure

    @property
    def n_modes(self) -> int:
        return len(self.omega_rad_s)

    @property
    def frequencies_hz(self) -> np.ndarray:
        return self.omega_rad_s / (2 * np.pi)

    def project(self, b: np.ndarray) -> np.ndarray:
        """Phi^T b: the modal row of a coordinate u = b . x (and the modal force of a unit force on it)."""
        return self.shapes.T @ b

    def base_load(self) -> np.ndarray:
        """Modal force per unit base acceleration: -Phi^T M r (relative coordinates)."""
        r = self.structure.base_influence
        if r is None:
            raise ValueError("this structure has a fixed base")
        return -self.shapes.T @ (self.structure.mass @ r)


def reduce(structure: Structure, max_frequency_hz: float, min_modes: int) -> ModalModel:
    """Keep all modes below max_frequency_hz, and at least the min_modes lowest."""
    omega, phi = normal_modes(structure.mass, structure.stiffness)
    n_keep = max(min_modes, int(np.sum(omega / (2 * np.pi) < max_frequency_hz)))
    n_keep = min(n_keep, len(omega))
    phi = phi[:, :n_keep]
    return ModalModel(omega_rad_s=omega[:n_keep], shapes=phi, damping=phi.T @ structure.damping @ phi,
                      structure=structure)
