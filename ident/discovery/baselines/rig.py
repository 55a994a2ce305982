"""The rig model (``ident.rig``) as a baseline: two coupled single-mode beams with the parameters of a
config file, driven by the measured base acceleration.

Per unit mass, z_i'' = -w_i^2 z_i - c_i z_i' - (k_c / m_i)(z_i - z_j) - a_b - f_i(z_i, z_i') / m_i, with
f_i the config's own nonlinear forces (stoppers, and any cubic, friction or drag it declares). The
linear part is brought to modal coordinates by its eigenvectors (x = [z1, z2, v1, v2] = 2 Re(V w)), so
this baseline and a fitted modal model run on the same integrator. A force at a tip acts on that
beam's mass, so coefficients come out in physical units and per unit mass alike.
"""

from __future__ import annotations

import numpy as np

from ...rig import FRICTION_V_EPS, RigParams
from ..catalogue import CAUSES, CONTACT, COULOMB, CUBIC, QDAMP, QUADRATIC, law_parameters
from ..model import Element, LinearModel
from ..signals import Prepared
from . import Baseline, Location


def _linear(p: RigParams) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A (4, 4), input b (4,) of x' = A x + b a_b, and the masses (2,)."""
    m = np.array([p.beam1.mass_kg, p.beam2.mass_kg])
    kc = p.coupling_stiffness_n_per_m
    K = np.diag([p.beam1.stiffness_n_per_m + kc, p.beam2.stiffness_n_per_m + kc]) - kc * (1 - np.eye(2))
    Cd = np.diag([p.beam1.damping_n_s_per_m, p.beam2.damping_n_s_per_m])
    A = np.zeros((4, 4))
    A[:2, 2:] = np.eye(2)
    A[2:, :2] = -K / m[:, None]
    A[2:, 2:] = -Cd / m[:, None]
    return A, np.array([0.0, 0.0, -1.0, -1.0]), m


class RigBaseline(Baseline):
    """The rig model of a config (see the module's docstring). Responses: tip1 and tip2, in that order."""

    label = "rig model from the config"
    causes = ("contact", "cubic_stiffness", "quadratic_stiffness", "coulomb_friction", "quadratic_damping",
              "hysteretic_joint", "linear_mismatch", "sensor_gain", "sensor_offset", "clipping")
    # an offset is judged on the raw record (``search.offset_findings``), beside the other findings

    def __init__(self, params: RigParams):
        self.params = params
        A, b, self.mass = _linear(params)
        lam, V = np.linalg.eig(A)
        up = np.flatnonzero(lam.imag > 0)
        if up.size != 2:
            raise ValueError("the rig model's beams must be underdamped (damping ratio below 1)")
        self._Vinv = np.linalg.inv(V)[up]
        self._V = V[:, up]
        poles = lam[up]
        self._force_gain = [self._Vinv[:, 2 + i] / self.mass[i] for i in range(2)]  # per newton at tip i
        elements = []
        for i, beam in enumerate((params.beam1, params.beam2)):
            lz = self._V[i]
            gain = self._force_gain[i]
            w = np.eye(2)[i]
            for side, gap in (("positive", beam.gap_pos_m), ("negative", beam.gap_neg_m)):
                if np.isfinite(gap) and beam.stopper_stiffness_n_per_m > 0:
                    p = law_parameters(CAUSES["contact"], {"gap": gap, "side": side})
                    p[0], p[3] = beam.stopper_stiffness_n_per_m, beam.stopper_damping_n_s_per_m
                    elements.append(Element(CONTACT, p, lz, gain, w))
            for code, value in ((CUBIC, beam.cubic_stiffness_n_per_m3), (QUADRATIC, beam.quadratic_stiffness_n_per_m2),
                                (QDAMP, beam.quadratic_damping_n_s2_per_m2)):
                if value:
                    elements.append(Element(code, np.array([value, 0.0, 0.0, 0.0]), lz, gain, w))
            if beam.coulomb_friction_n:
                elements.append(Element(COULOMB, np.array([beam.coulomb_friction_n, FRICTION_V_EPS, 0.0, 0.0]), lz,
                                        gain, w))
        self.model = LinearModel(poles, (self._Vinv @ b)[None, :], self._V[:2], tuple(elements))

    def locations(self, prep: Prepared) -> list[Location]:
        if len(prep.names) != 2:
            raise ValueError(f"the rig model has two tips: give two responses, got {len(prep.names)}")
        return [Location(prep.names[0], np.array([1.0, 0.0])), Location(prep.names[1], np.array([0.0, 1.0])),
                Location(f"{prep.names[0]}-{prep.names[1]}", np.array([1.0, -1.0]))]

    def gain_basis(self, loc: Location) -> list[np.ndarray]:
        return [loc.weights[0] * self._force_gain[0] + loc.weights[1] * self._force_gain[1]]

    def _mass(self, loc: Location) -> float:
        w = np.abs(loc.weights)
        return float(1.0 / np.sum(w / self.mass))  # a tip's mass, or the pair's reduced mass

    def per_mass(self, loc: Location, gain: np.ndarray) -> float:
        basis = self.gain_basis(loc)[0]
        theta = float(np.real(np.vdot(basis, gain)) / np.real(np.vdot(basis, basis)))
        return theta / self._mass(loc)

    def physical(self, loc: Location) -> float | None:
        return self._mass(loc)

    def initial_state(self, prep: Prepared, model: LinearModel, start: int, stop: int) -> np.ndarray:
        x = np.concatenate([prep.zva[0][start], prep.zva[1][start]])
        return self._Vinv @ x
