"""The first generator of hidden-effect cases: the rig model of ``ident.rig`` with one effect switched on.

This is the data the discovery method was first built on: its own model class, so it is the easy
test (``ident bench discovery --generator rig``). The independent generator
(``daq.sim.independent``) is the one that judges the method.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ident.rig import RigParams

from .excitation import Excitation, Step, Sweep
from .rig import RigConfig, simulate_rig

# the catalogue of the rig path: mechanical causes, then the sensor effects
EFFECTS = ("contact", "cubic_stiffness", "quadratic_stiffness", "coulomb_friction", "quadratic_damping",
           "linear_mismatch", "sensor_gain", "sensor_offset", "clipping")
HIDDEN = ("none",) + EFFECTS


def _with_beam(p: RigParams, i: int, changes: dict) -> RigParams:
    name = "beam1" if i == 0 else "beam2"
    return replace(p, **{name: replace(getattr(p, name), **changes)})


@dataclass(frozen=True)
class HiddenCase:
    effect: str
    beam: int  # 1 or 2
    truth: dict  # the hidden parameters in the catalogue's units
    nominal: RigParams
    values: np.ndarray  # (N, 3) measured accelerations with sensor noise at ``snr_db``
    fs_hz: float
    excitation: str


def nominal_params() -> RigParams:
    """The model the user has: the default rig without stoppers (so contact can be hidden)."""
    return RigParams().with_beams(gap_pos_m=np.inf, gap_neg_m=np.inf)


def hidden_case(seed: int, effect: str | None = None, duration_s: float = 40.0, fs_hz: float = 2000.0,
                snr_db: float = 30.0) -> HiddenCase:
    """A seeded case: an effect from the catalogue (or none) on a random beam, parameters from
    physical ranges, a realistic test (amplitude steps, a sweep or broadband noise), sensor noise."""
    rng = np.random.default_rng([seed, 2019])
    effect = effect or HIDDEN[int(rng.integers(len(HIDDEN)))]
    beam = int(rng.integers(1, 3))
    nom = nominal_params()
    b = nom.beam1 if beam == 1 else nom.beam2
    m = b.mass_kg
    kind = str(rng.choice(["steps", "sweep", "noise"]))
    if kind == "steps":
        levels = rng.uniform(0.8, 3.0, 4)
        exc = Excitation(frequency_hz=float(rng.uniform(10.5, 13.5)), amplitude_m_per_s2=float(levels[0]),
                         ramp_s=1.0, steps=tuple(Step(10.0 * (j + 1), float(levels[j + 1])) for j in range(3)),
                         seed=seed)
    elif kind == "sweep":
        exc = Excitation(amplitude_m_per_s2=float(rng.uniform(1.5, 2.5)), ramp_s=1.0,
                         sweep=Sweep(8.0, 16.0, duration_s), seed=seed)
    else:
        exc = Excitation(amplitude_m_per_s2=0.0, ramp_s=1.0, noise_rms_m_per_s2=float(rng.uniform(2.0, 4.0)),
                         noise_band_hz=(3.0, 40.0), seed=seed)
    truth: dict = {}
    changes: dict = {}
    if effect == "contact":
        # a test that never reaches the stopper cannot reveal it: the gap lies within the
        # amplitude the beam reaches in the nominal run (50-85 % of it)
        _, o_nom = simulate_rig(RigConfig(rig=nom, excitation=exc), duration_s, fs_hz)
        reach = float(np.max(np.abs(o_nom.z[:, beam - 1])))
        gap = float(rng.uniform(0.5, 0.85) * reach)
        side = str(rng.choice(["both", "positive", "negative"]))
        k = float(rng.uniform(2e4, 1e5))
        truth = {"gap": gap, "side": side, "stiffness_per_mass": k / m}
        changes = {"gap_pos_m": gap if side != "negative" else np.inf,
                   "gap_neg_m": gap if side != "positive" else np.inf, "stopper_stiffness_n_per_m": k,
                   "stopper_damping_n_s_per_m": 0.0}
    elif effect == "cubic_stiffness":
        k3 = float(rng.uniform(1e6, 5e6))  # hardening (a softening cubic can make the beam escape)
        truth = {"coefficient_per_mass": k3 / m}
        changes = {"cubic_stiffness_n_per_m3": k3}
    elif effect == "quadratic_stiffness":
        k2 = float(rng.uniform(3e3, 1.5e4))  # as strong as the cubic's range at 2-3 mm
        truth = {"coefficient_per_mass": k2 / m}
        changes = {"quadratic_stiffness_n_per_m2": k2}
    elif effect == "linear_mismatch":
        # the beam's natural frequency 3-8 % off the nominal one
        fn = b.natural_frequency_hz * (1 + float(rng.uniform(0.03, 0.08) * rng.choice([-1, 1])))
        truth = {"stiffness_per_mass": (2 * np.pi * fn) ** 2 - b.stiffness_n_per_m / m}
        changes = {"natural_frequency_hz": fn}
    elif effect == "coulomb_friction":
        fc = float(rng.uniform(0.01, 0.04))
        truth = {"force_per_mass": fc / m}
        changes = {"coulomb_friction_n": fc}
    elif effect == "quadratic_damping":
        cq = float(rng.uniform(0.2, 1.0))
        truth = {"coefficient_per_mass": cq / m}
        changes = {"quadratic_damping_n_s2_per_m2": cq}
    truth_params = _with_beam(nom, beam - 1, changes) if changes else nom
    _, o = simulate_rig(RigConfig(rig=truth_params, excitation=exc), duration_s, fs_hz)
    vals = np.column_stack([o.base, o.tip1, o.tip2])
    vals = vals + rng.standard_normal(vals.shape) * vals.std(axis=0) * 10 ** (-snr_db / 20)
    ch = vals[:, beam]
    if effect == "sensor_gain":
        g = float(rng.uniform(0.05, 0.2) * rng.choice([-1, 1]))
        truth = {"gain_error": g}
        vals[:, beam] = ch * (1 + g)
    elif effect == "sensor_offset":
        off = float(rng.uniform(0.2, 0.8) * rng.choice([-1, 1]) * ch.std())
        truth = {"offset_m_per_s2": off}
        vals[:, beam] = ch + off
    elif effect == "clipping":
        rng_m = float(rng.uniform(0.6, 0.85) * np.max(np.abs(ch)))  # the accelerometer's range
        truth = {"range_m_per_s2": rng_m}
        vals[:, beam] = np.clip(ch, -rng_m, rng_m)
    return HiddenCase(effect, beam, truth, nom, vals, fs_hz, kind)
