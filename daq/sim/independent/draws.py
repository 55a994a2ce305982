"""Seeded draws shared by the case factories: beams tuned to a frequency, the rig, the instrument chain,
the excitation programmes, and the equivalent single-DOF parameters of an effect seen at a sensor.

Equivalent parameters (first-mode reduction; Ewins, Modal Testing, 2nd ed., 2000, sec. 2.3): with the
mass-normalised first mode phi, a sensor coordinate s and an effect coordinate e, the mode normalised to
1 at the sensor has modal mass m_eq = 1 / phi_s^2 and stiffness m_eq omega_1^2; with r = phi_e / phi_s
an element on e seen at the sensor has gap g / |r|, stiffness k r^2, Hunt-Crossley damping lambda |r|^3,
cubic coefficient k3 r^4, slip force F |r|, quadratic damping c |r|^3 (side flipped when r < 0).
"""

from __future__ import annotations

import math

import numpy as np
import scipy.signal

from .beams import BeamSpec, assemble_beam, strip_tip_inertia
from .excitation import (Gate, Hammer, Programme, Segment, Signal, Sum, Sweep, band_random, hammer_hit,
                         odd_multisine)
from .modal import normal_modes
from .rig import RigSpec, ShakerSpec, StingerSpec
from .sensors import AntiAlias, Card, Channel


def log_uniform(rng: np.random.Generator, low: float, high: float) -> float:
    return float(math.exp(rng.uniform(math.log(low), math.log(high))))


def pick(rng: np.random.Generator, weights: dict[str, float]) -> str:
    names = list(weights)
    p = np.array([weights[n] for n in names], dtype=float)
    return names[int(rng.choice(len(names), p=p / p.sum()))]


def first_hz(spec: BeamSpec) -> float:
    bm = assemble_beam(spec)
    omega, _ = normal_modes(bm.mass, bm.stiffness)
    return float(omega[0] / (2 * np.pi))


def tune(make, target_hz: float, low: float, high: float) -> BeamSpec:
    """Bisect the parameter p of make(p) -> BeamSpec (first frequency decreasing in p) to target_hz."""
    if not first_hz(make(high)) <= target_hz <= first_hz(make(low)):
        raise ValueError(f"{target_hz} Hz is out of reach in [{low}, {high}]")
    for _ in range(50):
        mid = 0.5 * (low + high)
        if first_hz(make(mid)) > target_hz:
            low = mid
        else:
            high = mid
    return make(0.5 * (low + high))


def draw_cantilevers(rng: np.random.Generator, joint_beam: int | None = None,
                     mistuning: tuple[float, float] = (0.0, 0.15),
                     first_range_hz: tuple[float, float] = (8.0, 15.0)) -> tuple[tuple[BeamSpec, BeamSpec], dict]:
    """Two aluminium strips with tip masses, beam 1's first mode drawn in first_range_hz (8-15 Hz), beam 2
    mistuned by 0-15 % (length or mass)."""
    thickness = float(rng.choice([1.5e-3, 1.5e-3, 2.0e-3]))
    common = dict(width_m=0.02, thickness_m=thickness, youngs_pa=rng.uniform(68e9, 71e9),
                  density_kg_m3=rng.uniform(2660, 2730), n_elements=12)
    tip_mass = rng.uniform(0.02, 0.04)
    block = (rng.uniform(0.012, 0.02), rng.uniform(0.006, 0.012))
    joint_ratio = rng.uniform(8, 25)  # K_joint = ratio EI / L: the joint holds 12-37 % of the tip compliance

    def make(beam: int, length: float, mass: float) -> BeamSpec:
        ei = common["youngs_pa"] * common["width_m"] * thickness**3 / 12
        root = joint_ratio * ei / length if joint_beam == beam else None
        return BeamSpec(length_m=length, tip_mass_kg=mass, tip_inertia_kg_m2=strip_tip_inertia(mass, *block),
                        root_stiffness_n_m_per_rad=root, **common)

    f1 = rng.uniform(*first_range_hz)
    b1 = tune(lambda length: make(0, length, tip_mass), f1, 0.08, 0.6)
    mistuning = rng.uniform(*mistuning) * rng.choice([-1, 1])
    via = str(rng.choice(["length", "tip_mass"]))
    f2 = f1 * (1 + mistuning)
    if via == "length":
        b2 = tune(lambda length: make(1, length, tip_mass), f2, 0.08, 0.6)
    else:
        b2 = tune(lambda mass: make(1, b1.length_m, mass), f2, 0.2 * tip_mass, 4 * tip_mass)
    info = {"first_hz_alone": [first_hz(b1), first_hz(b2)], "mistuning": float(mistuning),
            "mistuned_through": via}
    return (b1, b2), info


def draw_zetas(rng: np.random.Generator, n: int, low: float = 0.005, high: float = 0.03) -> tuple[float, ...]:
    return tuple(log_uniform(rng, low, high) for _ in range(n))


def draw_rig(rng: np.random.Generator, beams: tuple[BeamSpec, BeamSpec], drive: str, drive_beam: int = 0,
             hammer: bool = False, coupling: tuple[float, float] = (0.01, 0.10)) -> RigSpec:
    """Damping, coupling (1-10 % of beam 1's first-mode stiffness at the coupling point) and the drive."""
    zetas = tuple(draw_zetas(rng, 2 * b.n_elements) for b in beams)
    frac = rng.uniform(0.4, 0.8)
    bm = assemble_beam(beams[0])
    omega, phi = normal_modes(bm.mass, bm.stiffness)
    p = bm.point(frac * beams[0].length_m)
    k_mode = omega[0] ** 2 / (p @ phi[:, 0]) ** 2
    m_mode = 1 / (p @ phi[:, 0]) ** 2
    k_c = rng.uniform(*coupling) * k_mode
    c_c = rng.uniform(0.0, 0.02) * 2 * math.sqrt(k_c * m_mode)
    stinger = None
    if drive == "force":
        x = rng.uniform(0.1, 0.6) * beams[drive_beam].length_m
        stinger = StingerSpec(beam=drive_beam, x_m=x, cell_mass_kg=0.0 if hammer else rng.uniform(1e-3, 5e-3))
    elif drive == "voltage":
        shaker = ShakerSpec(armature_mass_kg=rng.uniform(0.01, 0.03), suspension_n_per_m=rng.uniform(1e3, 5e3),
                            suspension_n_s_per_m=rng.uniform(0.5, 2.0), stinger_n_per_m=log_uniform(rng, 5e4, 5e5),
                            stinger_n_s_per_m=rng.uniform(1.0, 5.0), inductance_h=rng.uniform(2e-4, 1e-3),
                            resistance_ohm=rng.uniform(2.0, 5.0), force_factor_n_per_a=rng.uniform(1.0, 3.0))
        stinger = StingerSpec(beam=drive_beam, x_m=rng.uniform(0.15, 0.35) * beams[drive_beam].length_m,
                              cell_mass_kg=rng.uniform(1e-3, 5e-3), shaker=shaker)
    return RigSpec(beams=beams, zetas=zetas, coupling_x_m=(frac * beams[0].length_m, frac * beams[1].length_m),
                   coupling_n_per_m=k_c, coupling_n_s_per_m=c_c, stinger=stinger)


def draw_card(rng: np.random.Generator, fs_hz: int, bits: tuple[int, ...] = (12, 14, 16, 16, 16, 18, 24)) -> Card:
    if rng.uniform() < 0.6:
        aa = AntiAlias("butterworth", int(rng.integers(4, 9)), rng.uniform(0.36, 0.44) * fs_hz)
    else:  # the lowest order with the stopband (60-90 dB down) starting at the Nyquist frequency
        edge, stop_db = rng.uniform(0.38, 0.42) * fs_hz, rng.uniform(60, 90)
        order, _ = scipy.signal.ellipord(2 * np.pi * edge, 2 * np.pi * 0.5 * fs_hz, 0.1, stop_db, analog=True)
        aa = AntiAlias("elliptic", int(order), edge, passband_ripple_db=0.1, stopband_db=stop_db)
    return Card(fs_hz=fs_hz, bits=int(rng.choice(bits)), anti_alias=aa)


def draw_channel(rng: np.random.Generator, kind: str, snr_db: tuple[float, float] = (20, 40),
                 flip_probability: float = 0.3, clip_probability: float = 0.05) -> Channel:
    headroom = rng.uniform(0.9, 0.99) if rng.uniform() < clip_probability else rng.uniform(1.2, 4.0)
    return Channel(kind=kind, snr_db=rng.uniform(*snr_db), sign=-1 if rng.uniform() < flip_probability else 1,
                   gain=rng.uniform(0.98, 1.02), headroom=headroom)


def draw_tonal_signal(rng: np.random.Generator, kind: str, modes_hz: list[float], fs_hz: int, duration_s: float,
                      band_low_hz: float = 1.0) -> Signal:
    """A unit-scale signal of the given kind around the structure's lowest modes."""
    f_lo, f_hi = min(modes_hz), max(modes_hz)
    top = 0.4 * fs_hz
    band_hi = min(top, rng.uniform(3, 10) * f_hi)
    if kind == "stepped_sine":
        n = int(rng.integers(4, 9))
        dur = (duration_s - 1.0) / n
        steps = [Segment(dur, float(rng.choice(modes_hz)) * rng.uniform(0.92, 1.08), rng.uniform(0.3, 1.0))
                 for _ in range(n)]
        floor = band_random(band_low_hz, band_hi, rng.uniform(0.05, 0.2), duration_s, rng)
        return Sum([Programme(steps, transition_s=rng.uniform(0.3, 1.0)),
                    Gate(floor, 0.0, duration_s - 0.5, 0.5)])
    if kind == "sweep":
        lo = rng.uniform(0.3, 0.7) * f_lo
        hi = min(top, rng.uniform(1.5, 3.0) * f_hi if rng.uniform() < 0.7 else rng.uniform(0.1, 0.3) * fs_hz)
        a, b = (lo, hi) if rng.uniform() < 0.5 else (hi, lo)
        return Sweep(a, b, duration_s - 1.0, 1.0, law=str(rng.choice(["linear", "log"])), fade_s=0.5, start_s=0.5)
    if kind == "random":
        return Gate(band_random(rng.uniform(band_low_hz, 3 * band_low_hz), band_hi, 1.0, duration_s, rng),
                    0.0, duration_s - 0.5, 1.0)
    if kind == "multisine":
        period = int(rng.choice([2, 4, 5, 8, 10]))
        return Gate(odd_multisine(band_low_hz, band_hi, 1.0, period, rng), 0.0, duration_s + 10.0, 1.0)
    raise ValueError(f"unknown signal kind {kind}")


def draw_hammer_series(rng: np.random.Generator, duration_s: float) -> Hammer:
    hits = []
    t = rng.uniform(0.3, 1.0)
    while t < duration_s - 1.5:
        hits += hammer_hit(t, rng.uniform(0.7, 1.3), rng.uniform(0.3e-3, 2e-3), rng.uniform() < 0.2, rng)
        t += rng.uniform(2.0, 5.0)
    return Hammer(hits)


PER_MASS = {  # equivalent parameter -> the same divided by m_eq (SI units per kg)
    "stiffness_n_per_m": "stiffness_per_mass", "damping_n_s_per_m": "damping_per_mass",
    "contact_stiffness_n_per_m": "contact_stiffness_per_mass", "contact_damping_n_s_per_m2": "contact_damping_per_mass",
    "k3_n_per_m3": "k3_per_mass", "slip_force_n": "slip_force_per_mass", "slip_force_min_n": "slip_force_min_per_mass",
    "tangential_stiffness_n_per_m": "tangential_stiffness_per_mass",
    "coefficient_n_s2_per_m2": "coefficient_per_mass", "joint_stiffness_n_per_m": "joint_stiffness_per_mass",
    "slipping_stiffness_n_per_m": "slipping_stiffness_per_mass",
}


def equivalents(phi_sensor: float, phi_effect: float, omega: float, zeta: float, cause: str,
                params: dict) -> dict:
    """First-mode single-DOF parameters at the sensor (SI units), and the effect's parameters there."""
    m_eq = 1.0 / phi_sensor**2
    r = phi_effect / phi_sensor
    a = abs(r)
    eq = {"mass_kg": m_eq, "natural_frequency_hz": omega / (2 * np.pi), "damping_ratio": zeta,
          "stiffness_n_per_m": m_eq * omega**2, "damping_n_s_per_m": 2 * zeta * omega * m_eq,
          "mode_ratio": r}
    if cause == "contact":
        side = params["side"]
        if r < 0 and side != "both":
            side = "negative" if side == "positive" else "positive"
        eq |= {"gap_m": params["gap_m"] / a, "side": side,
               "contact_stiffness_n_per_m": params["stiffness_n_per_m"] * r**2,
               "contact_damping_n_s_per_m2": params["damping_n_s_per_m2"] * a**3}
    elif cause == "cubic_stiffness":
        eq |= {"k3_n_per_m3": params["k3_n_per_m3"] * r**4}
    elif cause == "coulomb_friction":
        eq |= {"slip_force_n": params["slip_force_n"] * a,
               "tangential_stiffness_n_per_m": params["tangential_stiffness_n_per_m"] * r**2}
    elif cause == "quadratic_damping":
        eq |= {"coefficient_n_s2_per_m2": params["coefficient_n_s2_per_m2"] * a**3}
    elif cause == "friction_joint":
        eq |= {"joint_stiffness_n_per_m": params["joint_stiffness"] * r**2,
               "slipping_stiffness_n_per_m": sum(params["jenkins_stiffness"]) * r**2,
               "slip_force_n": sum(params["jenkins_slip"]) * a,
               "slip_force_min_n": min(params["jenkins_slip"]) * a}
    for key, per_mass in PER_MASS.items():
        if key in eq:
            eq[per_mass] = eq[key] / m_eq
    return eq
