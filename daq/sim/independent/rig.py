"""The two-beam rig: two cantilevers clamped on a frame, weakly coupled by a spring and a damper between
two span points, driven by the frame's acceleration (base excitation), by a measured force through a
stinger, or by an electrodynamic shaker fed with a voltage.

Base excitation is written in coordinates relative to the frame, M x'' + C x' + K x = -M r a_b(t),
r the rigid-body translation vector (Clough and Penzien, Dynamics of Structures, 2nd ed., 1993, sec.
26-2); an accelerometer on a beam reads x'' + a_b. In the force variants the frame is fixed.

The electrodynamic shaker (McConnell and Varoto, Vibration Testing, 2nd ed., 2008, ch. 5) is an armature
of mass m_a on a suspension (k_s, c_s), a stinger (k_t, c_t) to a beam point, and a coil:
L i' + R i + Bl v_a = V(t), armature force Bl i. The armature is one more DOF of the structure.

Each beam's modal damping ratios are given for that beam alone (modal.modal_damping_matrix) so that the
coupled rig keeps them; the coupling and stinger dampers add to C.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .beams import BeamModel, BeamSpec, assemble_beam
from .modal import Structure, block_diag, modal_damping_matrix, normal_modes


@dataclass(frozen=True)
class ShakerSpec:
    armature_mass_kg: float = 0.02
    suspension_n_per_m: float = 3000.0
    suspension_n_s_per_m: float = 1.0
    stinger_n_per_m: float = 2e5
    stinger_n_s_per_m: float = 2.0
    inductance_h: float = 3e-4
    resistance_ohm: float = 4.0
    force_factor_n_per_a: float = 2.0


@dataclass(frozen=True)
class StingerSpec:
    """A drive at a span point of one beam: a force cell whose structure-side mass sits on the beam."""

    beam: int
    x_m: float
    cell_mass_kg: float = 0.0
    shaker: ShakerSpec | None = None  # None: an ideal force source (the force cell measures it)


@dataclass(frozen=True)
class RigSpec:
    beams: tuple[BeamSpec, BeamSpec]
    zetas: tuple[tuple[float, ...], tuple[float, ...]]  # modal damping ratios of each beam alone
    coupling_x_m: tuple[float, float]
    coupling_n_per_m: float
    coupling_n_s_per_m: float
    stinger: StingerSpec | None = None  # None: base excitation


@dataclass
class Rig:
    spec: RigSpec
    beams: list[BeamModel]
    structure: Structure
    offsets: list[int]
    beam_mass: list[np.ndarray] = field(default_factory=list)  # each beam alone, with its attachments
    beam_stiffness: list[np.ndarray] = field(default_factory=list)
    beam_damping: list[np.ndarray] = field(default_factory=list)

    @property
    def n_dof(self) -> int:
        return self.structure.n_dof

    def _embed(self, beam: int, local: np.ndarray) -> np.ndarray:
        b = np.zeros(self.n_dof)
        b[self.offsets[beam]:self.offsets[beam] + len(local)] = local
        return b

    def point(self, beam: int, x_m: float, derivative: int = 0) -> np.ndarray:
        return self._embed(beam, self.beams[beam].point(x_m, derivative))

    def tip(self, beam: int) -> np.ndarray:
        return self.point(beam, self.beams[beam].spec.length_m)

    def root_rotation(self, beam: int) -> np.ndarray:
        return self._embed(beam, self.beams[beam].root_rotation())

    def armature(self) -> np.ndarray:
        if self.spec.stinger is None or self.spec.stinger.shaker is None:
            raise ValueError("this rig has no shaker")
        b = np.zeros(self.n_dof)
        b[-1] = 1.0
        return b

    def first_mode(self, beam: int) -> tuple[float, float, np.ndarray]:
        """(omega rad/s, damping ratio, mass-normalised shape embedded in the rig's DOFs) of one beam alone."""
        omega, phi = normal_modes(self.beam_mass[beam], self.beam_stiffness[beam])
        zeta = float(phi[:, 0] @ self.beam_damping[beam] @ phi[:, 0] / (2 * omega[0]))
        return float(omega[0]), zeta, self._embed(beam, phi[:, 0])


def build_rig(spec: RigSpec) -> Rig:
    beams = [assemble_beam(s) for s in spec.beams]
    offsets = [0, beams[0].n_dof]
    masses, stiffs, damps = [], [], []
    for i, bm in enumerate(beams):
        m = bm.mass.copy()
        if spec.stinger is not None and spec.stinger.beam == i:
            p = bm.point(spec.stinger.x_m)
            m += spec.stinger.cell_mass_kg * np.outer(p, p)
        masses.append(m)
        stiffs.append(bm.stiffness.copy())
        z = np.full(bm.n_dof, spec.zetas[i][-1])
        z[:len(spec.zetas[i])] = spec.zetas[i][:bm.n_dof]
        damps.append(modal_damping_matrix(m, bm.stiffness, z))
    mass = block_diag(*masses)
    stiff = block_diag(*stiffs)
    damp = block_diag(*damps)
    n_beams_dof = mass.shape[0]
    base = np.concatenate([bm.translation_influence() for bm in beams])
    rig = Rig(spec=spec, beams=beams, structure=Structure(mass, stiff, damp), offsets=offsets,
              beam_mass=masses, beam_stiffness=stiffs, beam_damping=damps)
    c = rig.point(0, spec.coupling_x_m[0]) - rig.point(1, spec.coupling_x_m[1])
    stiff += spec.coupling_n_per_m * np.outer(c, c)
    damp += spec.coupling_n_s_per_m * np.outer(c, c)
    st = spec.stinger
    if st is not None and st.shaker is not None:
        sh = st.shaker
        mass, stiff, damp = (np.pad(a, ((0, 1), (0, 1))) for a in (mass, stiff, damp))
        mass[-1, -1] = sh.armature_mass_kg
        stiff[-1, -1] += sh.suspension_n_per_m
        damp[-1, -1] += sh.suspension_n_s_per_m
        rel = np.zeros(n_beams_dof + 1)
        rel[-1] = 1.0
        rel[:n_beams_dof] -= rig.point(st.beam, st.x_m)
        stiff += sh.stinger_n_per_m * np.outer(rel, rel)
        damp += sh.stinger_n_s_per_m * np.outer(rel, rel)
    rig.structure = Structure(mass, stiff, damp, base_influence=base if st is None else None)
    return rig
