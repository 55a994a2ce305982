"""Seeded discovery cases: a structure with one hidden cause at a physical location, its excitation, and
its instruments, with the truth the science is judged against.

`discovery_case(seed, family=None, cause=None)` draws (numpy Generator seeded with `seed`): the family,
the cause (among those the family makes sensible), the structure, the excitation and record, then runs
a linear preview of the record to set the excitation level (the response at the sensor reaches a drawn
target) and the effect's parameters relative to the response at the effect's coordinate (a gap at 45-85 %
of the smaller of the peak and 2.5 RMS, a stopper 2-1000 times the local static stiffness, a cubic term
worth 10-50 % of the local static stiffness at the peak (3-12 % when softening: half of a chain's cubics,
and every one of the ``duffing_softening`` family's; a clamped-clamped beam's hardening is its membrane
stretching alone, the hit scaled so that its backbone shifts 2-8 % at the preview's peak), friction and drag whose
equivalent viscous damping at the RMS amplitude is 0.5-2 times c_ref below, a joint whose 12-20 Jenkins
elements hold 40-80 % of its stiffness and start slipping at 5-30 % to 80-200 % of the peak rotation),
then runs the record with the effect and measures it.

`discovery_case(seed, twin=True)` is the same case's *twin*: every draw the same (structure, drive,
levels, instruments, the noise sequence, scaled to the same SNR of the twin's own signal), the record
run without the effect (a friction joint stays stuck, the clamped-clamped beam has no membrane
stretching). Its truth is cause "none", with the case it mirrors under `twin_of`. Twins show whether a
method names causes where there are none on exactly the structures it is judged on, and how much of a
case's error is the effect's at all. Tested: a case without an effect and its twin are the same record,
bit for bit; a Duffing oscillator's twin has the linear oscillator's receptance, its case does not.

The truth's `effect_strength` is RMS(f_nl) / RMS(k_static u) over the record, f_nl the element's force
(for a joint: its departure from the stuck joint; for membrane stretching: its generalised force on mode
1, against omega_1^2 q_1), u the effect's coordinate and k_static the linear structure's static stiffness
on that coordinate; `effect_vs_damping` (friction, drag) is RMS(f_nl) / RMS(c_ref u'), with
c_ref = 2 zeta_1 k_static / omega_rms the viscous damping at the first mode's damping ratio on the
coordinate (omega_rms = RMS(u') / RMS(u) in the linear preview).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from . import draws
from .beams import BeamSpec
from .elements import Contact, Cubic, Drag, Element, Hysteretic, Membrane, hunt_crossley_damping
from .excitation import Hammer, Hit, LinearGain, Scaled, Signal, Sweep, band_random, hammer_hit, odd_multisine
from .experiment import Drive, Run, Setup, base_velocity, run
from .integrate import Coil, Output
from .modal import normal_modes, reduce
from .recording import Case, seeded
from .rig import Rig, build_rig
from .sensors import UNITS, acquire
from .structures import ChainSpec, chain_structure, clamped_clamped_beam, duffing_structure, relative, unit

CAUSES = ("contact", "cubic_stiffness", "friction_joint", "coulomb_friction", "quadratic_damping", "none")
FAMILIES = {"rig_base": 0.45, "rig_force": 0.12, "rig_voltage": 0.08, "duffing": 0.12, "chain": 0.13,
            "cc_beam": 0.10}
_MECHANICAL = {"contact": 0.3, "cubic_stiffness": 0.14, "friction_joint": 0.14, "coulomb_friction": 0.14,
               "quadratic_damping": 0.14, "none": 0.14}
FAMILY_CAUSES = {"rig_base": _MECHANICAL, "rig_force": _MECHANICAL, "rig_voltage": _MECHANICAL,
                 "chain": _MECHANICAL, "duffing": {"cubic_stiffness": 0.8, "none": 0.2},
                 "cc_beam": {"cubic_stiffness": 0.8, "none": 0.2},
                 "duffing_softening": {"cubic_stiffness": 0.8, "none": 0.2}}
# ``duffing_softening`` is the Duffing oscillator with a softening cubic (k3 < 0). It is drawn only when
# asked for (``discovery_case(seed, "duffing_softening")``, ``ident bench discovery --family``), not among
# ``FAMILIES``, so every seeded case of the default draw stays what it was


@dataclass
class Site:
    """Where the effect acts and how it is seen: coordinate, sensor coordinate, first mode."""

    coordinate: np.ndarray
    sensor: np.ndarray
    mode: np.ndarray  # mass-normalised first mode (physical DOFs)
    omega: float
    zeta: float
    k_static: float  # N/m (N m/rad on a rotation)
    location: str | None
    position: dict

    @property
    def phi_sensor(self) -> float:
        return float(self.sensor @ self.mode)

    @property
    def phi_effect(self) -> float:
        return float(self.coordinate @ self.mode)


@dataclass
class Draft:
    """A family's structure, drive and instruments before the preview fixes levels and the effect."""

    family: str
    fs_hz: int
    duration_s: float
    setup: Setup
    scaled: list[str]  # drives scaled by the preview
    target_m: float  # peak displacement wanted at the sensor in the linear preview
    site: Site
    channels: list[tuple[str, str]]  # (column = output name, kind)
    excitation: str  # "column:kind"
    structure: dict
    signal_kind: str
    min_rate_hz: float = 20e3
    joint: tuple[float, np.ndarray] | None = None  # stuck stiffness (in the structure), Jenkins stiffnesses
    absolute_drag: bool = False
    blows: list[dict] = field(default_factory=list)  # truth of the unmeasured blows
    blow_drives: list[Drive] = field(default_factory=list)  # added after the preview, never scaled
    membrane: Membrane | None = None  # the clamped-clamped beam's (in the set-up unless the cause is none)
    membrane_target_shift: float = 0.0  # backbone shift wanted at the preview's peak


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


# ----------------------------------------------------------------------------------------------- rig


def _rig_site(rig: Rig, cause: str, beam: int, rng: np.random.Generator) -> Site:
    length = rig.beams[beam].spec.length_m
    if cause == "friction_joint":
        coord, pos = rig.root_rotation(beam), {"beam": beam + 1, "x_m": 0.0, "fraction": 0.0, "at": "root"}
    else:
        frac = {"contact": (0.6, 1.0), "cubic_stiffness": (0.5, 1.0), "coulomb_friction": (0.3, 1.0),
                "quadratic_damping": (1.0, 1.0), "none": (1.0, 1.0)}[cause]
        f = rng.uniform(*frac)
        coord, pos = rig.point(beam, f * length), {"beam": beam + 1, "x_m": f * length, "fraction": f}
    omega, zeta, mode = rig.first_mode(beam)
    return Site(coordinate=coord, sensor=rig.tip(beam), mode=mode, omega=omega, zeta=zeta,
                k_static=1.0 / rig.structure.static_compliance(coord),
                location=None if cause == "none" else f"tip{beam + 1}", position=pos)


def _rig_draft(rng: np.random.Generator, family: str, cause: str) -> Draft:
    drive = {"rig_base": "base", "rig_force": "force", "rig_voltage": "voltage"}[family]
    beam = int(rng.choice([0, 0, 1]))
    beams, beams_info = draws.draw_cantilevers(rng, joint_beam=beam if cause == "friction_joint" else None)
    signal_kind = draws.pick(rng, {"stepped_sine": 0.35, "sweep": 0.25, "random": 0.2, "multisine": 0.2}
                             | ({"hammer": 0.25} if drive == "force" else {}))
    drive_beam = int(rng.integers(2))
    rig = build_rig(draws.draw_rig(rng, beams, drive, drive_beam, hammer=signal_kind == "hammer"))
    fs = int(rng.choice([500, 1000, 1000, 1000, 1000, 2000, 2500, 5000]))
    duration = float(round(rng.uniform(30, 50)))
    model = reduce(rig.structure, 0.6 * fs, 8 + (1 if drive == "voltage" else 0))
    modes = beams_info["first_hz_alone"]
    signal = (draws.draw_hammer_series(rng, duration) if signal_kind == "hammer"
              else draws.draw_tonal_signal(rng, signal_kind, modes, fs, duration))
    tips = {"tip1": Output([(rig.tip(0), 2)]), "tip2": Output([(rig.tip(1), 2)])}
    coil = None
    if drive == "base":
        drives = [Drive("base", -rig.structure.mass @ rig.structure.base_influence, signal)]
        tips = {name: replace(o, feed=[(0, 1.0)]) for name, o in tips.items()}
        outputs = {"base": Output([], [(0, 1.0)]), **tips}
        excitation = "base:base_acceleration"
    elif drive == "force":
        st = rig.spec.stinger
        drives = [Drive("force", rig.point(st.beam, st.x_m), signal)]
        outputs = {"force": Output([], [(0, 1.0)]), **tips}
        excitation = "force:force"
    else:
        sh = rig.spec.stinger.shaker
        drives = [Drive("voltage", np.zeros(rig.n_dof), signal)]
        coil = Coil(sh.inductance_h, sh.resistance_ohm, sh.force_factor_n_per_a, rig.armature(), voltage_load=0)
        outputs = {"voltage": Output([], [(0, 1.0)]), **tips}
        excitation = "voltage:voltage"
    setup = Setup(model, drives, outputs, coil=coil, base_drive="base" if drive == "base" else None)
    site = _rig_site(rig, cause, beam, rng)
    joint = None
    if cause == "friction_joint":
        stuck = rig.beams[beam].spec.root_stiffness_n_m_per_rad
        n_j = int(rng.integers(12, 21))
        joint = (stuck, np.full(n_j, rng.uniform(0.4, 0.8) * stuck / n_j))
    structure = {
        "beams": [b.describe() for b in beams], **beams_info,
        "modal_damping_ratios_alone": [list(z[:4]) for z in rig.spec.zetas],
        "coupling": {"x_m": list(rig.spec.coupling_x_m), "stiffness_n_per_m": rig.spec.coupling_n_per_m,
                     "damping_n_s_per_m": rig.spec.coupling_n_s_per_m},
        "system_modes_hz": list(model.frequencies_hz), "drive": drive}
    if rig.spec.stinger is not None:
        st = rig.spec.stinger
        omega, _, mode = rig.first_mode(st.beam)
        structure["stinger"] = {"beam": st.beam + 1, "x_m": st.x_m, "cell_mass_kg": st.cell_mass_kg,
                                "force_ratio_at_tip": float((rig.point(st.beam, st.x_m) @ mode)
                                                            / (rig.tip(st.beam) @ mode))}
        if st.shaker is not None:
            structure["shaker"] = vars(st.shaker)
    d = Draft(family=family, fs_hz=fs, duration_s=duration, setup=setup, scaled=[drives[0].name],
              target_m=rng.uniform(*((0.7e-3, 2.5e-3) if signal_kind in ("random", "multisine") else (1.5e-3, 5e-3))),
              site=site,
              channels=[(list(outputs)[0], excitation.split(":")[1]), ("tip1", "acceleration"),
                        ("tip2", "acceleration")],
              excitation=excitation, structure=structure, signal_kind=signal_kind, joint=joint,
              absolute_drag=drive == "base")
    if rng.uniform() < 0.2:
        d.blows = _draw_blows(rng, rig, duration, d.target_m)
        d.blow_drives = [Drive(f"blow{i + 1}", rig.point(b["beam"] - 1, b["x_m"]),
                               Hammer([Hit(b["time_s"], b["peak_force_n"], b["width_s"])]))
                         for i, b in enumerate(d.blows)]
    return d


def _draw_blows(rng: np.random.Generator, rig: Rig, duration: float, target_m: float) -> list[dict]:
    """1-2 unmeasured hammer blows on a beam, each moving its tip by 30-100 % of the target peak."""
    blows = []
    for _ in range(int(rng.integers(1, 3))):
        beam = int(rng.integers(2))
        x = rng.uniform(0.5, 1.0) * rig.beams[beam].spec.length_m
        omega, _, mode = rig.first_mode(beam)
        impulse = rng.uniform(0.3, 1.0) * target_m * omega / abs((rig.point(beam, x) @ mode) * (rig.tip(beam) @ mode))
        width = rng.uniform(0.5e-3, 2e-3)
        blows.append({"time_s": rng.uniform(0.2, 0.9) * duration, "beam": beam + 1, "x_m": x,
                      "peak_force_n": 2 * impulse / width, "width_s": width, "impulse_n_s": impulse})
    return blows


# ------------------------------------------------------------------------------------- other structures


def _duffing_draft(rng: np.random.Generator, cause: str, family: str = "duffing") -> Draft:
    fs = int(rng.choice([500, 610, 1000, 1250, 2000]))
    f0 = rng.uniform(20, min(80, fs / 6))
    mass = rng.uniform(0.5, 2.0)
    zeta = draws.log_uniform(rng, 0.005, 0.05)
    omega = 2 * np.pi * f0
    structure = duffing_structure(mass, mass * omega**2, 2 * zeta * omega * mass)
    model = reduce(structure, fs, 1)
    n_out = int(rng.integers(20000, 130001))
    duration = n_out / fs
    kind = draws.pick(rng, {"multisine": 0.35, "sweep": 0.25, "arrow": 0.25, "random": 0.15})
    band_hi = min(0.4 * fs, rng.uniform(2, 4) * f0)
    if kind == "multisine":
        period = int(rng.choice([2, 5, 10, 20]))
        signal: Signal = odd_multisine(0.5, band_hi, 1.0, period, rng)
    elif kind == "sweep":
        lo, hi = rng.uniform(0.2, 0.5) * f0, min(0.4 * fs, rng.uniform(2, 3) * f0)
        a, b = (lo, hi) if rng.uniform() < 0.5 else (hi, lo)
        signal = Sweep(a, b, duration - 1.0, 1.0, law=str(rng.choice(["linear", "log"])), start_s=0.5)
    elif kind == "arrow":  # noise whose amplitude grows linearly over the record (Silverbox's "arrow")
        signal = LinearGain(band_random(0.5, band_hi, 1.0, duration, rng), [0.0, duration], [0.0, 1.0])
    else:
        signal = band_random(0.5, band_hi, 1.0, duration, rng)
    b = np.array([1.0])
    setup = Setup(model, [Drive("force", b, signal)],
                  {"force": Output([], [(0, 1.0)]), "x1": Output([(b, 0)])})
    site = Site(coordinate=b, sensor=b, mode=model.shapes[:, 0], omega=omega, zeta=zeta,
                k_static=mass * omega**2, location=None if cause == "none" else "x1", position={"at": "mass"})
    return Draft(family=family, fs_hz=fs, duration_s=duration, setup=setup, scaled=["force"],
                 target_m=rng.uniform(0.5e-3, 2e-3), site=site, channels=[("force", "force"), ("x1", "displacement")],
                 excitation="force:force",
                 structure={"mass_kg": mass, "natural_frequency_hz": f0, "damping_ratio": zeta},
                 signal_kind=kind, min_rate_hz=10 * fs)


def _chain_draft(rng: np.random.Generator, cause: str) -> Draft:
    n = int(rng.integers(3, 7))
    masses = tuple(rng.uniform(0.2, 2.0, n))
    springs = tuple(rng.uniform(5e3, 5e4, n + (1 if rng.uniform() < 0.5 else 0)))
    spec = ChainSpec(masses, springs, draws.draw_zetas(rng, n))
    pair = int(rng.integers(n - 1))
    extra = {}
    joint = None
    if cause == "friction_joint":
        stuck = rng.uniform(0.5, 2.0) * springs[pair + 1]
        n_j = int(rng.integers(12, 21))
        joint = (stuck, np.full(n_j, stuck / n_j))
        extra = {(pair, pair + 1): stuck}
    structure = chain_structure(spec, extra)
    f_max = normal_modes(structure.mass, structure.stiffness)[0].max() / (2 * np.pi)
    fs = int(rng.choice([f for f in (500, 1000, 2000, 2500, 5000, 10000) if f >= 4 * f_max][:3]))
    model = reduce(structure, fs, n)
    duration = float(round(rng.uniform(20, 60)))
    kind = draws.pick(rng, {"stepped_sine": 0.25, "sweep": 0.25, "random": 0.25, "multisine": 0.25})
    modes = list(model.frequencies_hz[:2])
    signal = draws.draw_tonal_signal(rng, kind, modes, fs, duration, band_low_hz=2.0)
    at = int(rng.integers(n))
    names = [f"a{i + 1}" for i in range(n)]
    outputs = {"force": Output([], [(0, 1.0)])} | {nm: Output([(unit(n, i), 2)]) for i, nm in enumerate(names)}
    setup = Setup(model, [Drive("force", unit(n, at), signal)], outputs)
    coord = relative(n, pair, pair + 1)
    mode = model.shapes[:, 0]
    site = Site(coordinate=coord, sensor=unit(n, pair), mode=mode, omega=float(model.omega_rad_s[0]),
                zeta=float(mode @ structure.damping @ mode / (2 * model.omega_rad_s[0])),
                k_static=1.0 / structure.static_compliance(coord),
                location=None if cause == "none" else f"{names[pair]}-{names[pair + 1]}",
                position={"between_masses": [pair + 1, pair + 2]})
    truth = {"masses_kg": list(masses), "springs_n_per_m": list(springs), "modal_damping_ratios": list(spec.zetas),
             "grounded_both_ends": len(springs) == n + 1, "force_on_mass": at + 1,
             "natural_frequencies_hz": list(model.frequencies_hz)}
    return Draft(family="chain", fs_hz=fs, duration_s=duration, setup=setup, scaled=["force"],
                 target_m=rng.uniform(0.2e-3, 2e-3), site=site,
                 channels=[("force", "force")] + [(nm, "acceleration") for nm in names], excitation="force:force",
                 structure=truth, signal_kind=kind, joint=joint)


def _cc_beam_draft(rng: np.random.Generator, cause: str) -> Draft:
    e_pa, rho, h, w = rng.uniform(200e9, 210e9), 7850.0, rng.uniform(0.8e-3, 1.5e-3), 0.02
    f1 = rng.uniform(100, 200)
    length = math.sqrt(4.730040745**2 * math.sqrt(e_pa * h**2 / (12 * rho)) / (2 * np.pi * f1))
    spec = BeamSpec(length, w, h, e_pa, rho, n_elements=24, support="clamped-clamped")
    zetas = np.array(draws.draw_zetas(rng, 2 * 24, 0.002, 0.01))
    beam = clamped_clamped_beam(spec, zetas)
    fs = 10000
    model = reduce(beam.structure, 0.6 * fs, 6)
    duration = float(rng.uniform(1.0, 10.0))
    x_hit = rng.uniform(0.25, 0.5) * length
    b = beam.model.point(x_hit)
    t_hit = rng.uniform(1e-3, 1e-2)
    signal = Hammer(hammer_hit(t_hit, 1.0, rng.uniform(0.3e-3, 2e-3), rng.uniform() < 0.2, rng))
    setup = Setup(model, [Drive("force", b, signal)], {"force": Output([], [(0, 1.0)]), "v1": Output([(b, 1)])},
                  membrane=beam.membrane if cause != "none" else None)
    mode = model.shapes[:, 0]
    site = Site(coordinate=b, sensor=b, mode=mode, omega=float(model.omega_rad_s[0]), zeta=float(zetas[0]),
                k_static=1.0 / beam.structure.static_compliance(b), location=None if cause == "none" else "v1",
                position={"at": "distributed (membrane stretching)", "hit_x_m": x_hit, "sensor_x_m": x_hit})
    truth = {"beam": spec.describe(), "natural_frequencies_hz": list(model.frequencies_hz),
             "modal_damping_ratios": list(zetas[:model.n_modes]), "hit_time_s": t_hit, "hit_x_m": x_hit,
             "axial_stiffness_ea_n": e_pa * spec.area_m2}
    return Draft(family="cc_beam", fs_hz=fs, duration_s=duration, setup=setup, scaled=["force"], target_m=0.0,
                 site=site, channels=[("force", "force"), ("v1", "velocity")], excitation="force:force",
                 structure=truth, signal_kind="hammer", min_rate_hz=10 * fs, membrane=beam.membrane,
                 membrane_target_shift=rng.uniform(0.02, 0.08))


# ------------------------------------------------------------------------------------------- effects


def _membrane_k3_per_mass(draft: Draft) -> float:
    """Single-mode cubic coefficient at the sensor of the membrane force: EA/(2L) G_11^2 / phi_s^2."""
    g11 = draft.site.mode @ draft.membrane.matrix @ draft.site.mode
    return draft.membrane.coefficient_n * g11**2 / draft.site.phi_sensor**2


def _draw_effect(rng: np.random.Generator, cause: str, draft: Draft, stats: dict,
                 strength: float = 1.0) -> tuple[list[Element], dict, dict]:
    """(elements, physical parameters for the truth, generic parameters for the equivalents)."""
    site = draft.site
    u_peak = max(stats["u_pos"], stats["u_neg"])
    c_ref = _linear_damping(site, stats)
    if cause == "contact":
        side = draws.pick(rng, {"both": 0.5, "positive": 0.25, "negative": 0.25})
        reach = {"both": min(stats["u_pos"], stats["u_neg"]), "positive": stats["u_pos"],
                 "negative": stats["u_neg"]}[side]
        gap = rng.uniform(0.45, 0.85) * min(reach, 2.5 * stats["u_rms"]) / strength
        k = draws.log_uniform(rng, 2, 1000) * site.k_static
        restitution = rng.uniform(0.6, 0.9)
        lam = hunt_crossley_damping(k, restitution, stats["v_peak"])
        p = {"gap_m": gap, "side": side, "stiffness_n_per_m": k, "damping_n_s_per_m2": lam,
             "restitution": restitution, "restitution_at_m_s": stats["v_peak"],
             "stiffness_ratio_to_static": k / site.k_static}
        return [Contact(site.coordinate, gap, k, lam, side)], p, p
    if cause == "cubic_stiffness" and draft.family == "cc_beam":
        return [], {}, {}  # the membrane in the set-up is the effect: no spring at a point beside it
    if cause == "cubic_stiffness":
        soft = draft.family == "duffing_softening" or (draft.family == "chain" and rng.uniform() < 0.5)
        eta = (rng.uniform(0.03, 0.12) if soft else rng.uniform(0.1, 0.5)) * strength
        k3 = (-1 if soft else 1) * eta * site.k_static / u_peak**2
        p = {"k3_n_per_m3": k3, "kind": "softening" if soft else "hardening"}
        return [Cubic(site.coordinate, k3)], p, p
    if cause == "coulomb_friction":
        slip = rng.uniform(0.5, 2.0) * strength * c_ref * np.pi * stats["omega_rms"] * math.sqrt(2) * stats["u_rms"] / 4
        kt = draws.log_uniform(rng, 10, 50) * site.k_static
        p = {"slip_force_n": slip, "tangential_stiffness_n_per_m": kt}
        return [Hysteretic(site.coordinate, np.array([kt]), np.array([slip]), stuck_in_linear_model=False)], p, p
    if cause == "quadratic_damping":
        c_q = rng.uniform(0.5, 2.0) * strength * c_ref * 3 * np.pi / (8 * math.sqrt(2) * stats["v_drag_rms"])
        p = {"coefficient_n_s2_per_m2": c_q, "velocity": "absolute" if draft.absolute_drag else "relative"}
        return [Drag(site.coordinate, c_q, absolute=draft.absolute_drag)], p, p
    if cause == "friction_joint":
        stuck, k_j = draft.joint
        s = np.linspace(rng.uniform(0.05, 0.3), rng.uniform(0.8, 2.0), len(k_j)) / strength
        slip = k_j * u_peak * s
        rot = "at" in site.position and site.position["at"] == "root"
        unit_k, unit_f = ("n_m_per_rad", "n_m") if rot else ("n_per_m", "n")
        p = {f"joint_stiffness_{unit_k}": stuck, f"jenkins_stiffness_{unit_k}": list(k_j),
             f"jenkins_slip_{'moment' if rot else 'force'}_{unit_f}": list(slip),
             f"residual_stiffness_{unit_k}": stuck - float(np.sum(k_j)), "n_jenkins": len(k_j)}
        generic = {"joint_stiffness": stuck, "jenkins_stiffness": list(k_j), "jenkins_slip": list(slip)}
        return [Hysteretic(site.coordinate, k_j, slip, stuck_in_linear_model=True)], p, generic
    return [], {}, {}


def _preview(draft: Draft) -> dict:
    """Linear run with probes on the effect and sensor coordinates: peaks for scaling and design."""
    setup = draft.setup
    probes = [Cubic(draft.site.coordinate, 0.0), Cubic(draft.site.sensor, 0.0)]
    linear = replace(setup, elements=probes, membrane=None)
    r = run(linear, draft.fs_hz, draft.duration_s, rate_hz=linear.rate_hz(draft.fs_hz, draft.min_rate_hz))
    u, v, s = r.response.element_u[:, 0], r.response.element_v[:, 0], r.response.element_u[:, 1]
    v_drag = v + _base_velocity(r, setup) if draft.absolute_drag else v
    return {"u_pos": float(u.max()), "u_neg": float(-u.min()), "u_rms": _rms(u), "v_peak": float(np.abs(v).max()),
            "v_rms": _rms(v), "v_drag_rms": _rms(v_drag), "omega_rms": _rms(v) / _rms(u),
            "sensor_peak": float(np.abs(s).max())}


def _linear_damping(site: Site, stats: dict) -> float:
    """c_ref = 2 zeta_1 k_static / omega_rms: viscous damping at the first mode's ratio on the coordinate
    (k_static its static stiffness, omega_rms = RMS(u') / RMS(u) its motion's RMS frequency)."""
    return 2 * site.zeta * site.k_static / stats["omega_rms"]


def _base_velocity(r: Run, setup: Setup) -> np.ndarray:
    return base_velocity(r.drive_samples[setup.base_drive], 2 * r.rate_hz)[::2]


def _finish(rng: np.random.Generator, draft: Draft, cause: str, seed: int, twin: bool = False) -> Case:
    stats = _preview(draft)
    if draft.family == "cc_beam":
        k3pm = _membrane_k3_per_mass(draft)
        shift = draft.membrane_target_shift
        target = math.sqrt(((1 + shift) ** 2 - 1) * draft.site.omega**2 / (0.75 * k3pm))
    else:
        target = draft.target_m
    gain = target / stats["sensor_peak"]
    stats = {k: v if k == "omega_rms" else v * gain for k, v in stats.items()}  # the preview is linear
    drives = [replace(d, signal=Scaled(d.signal, gain)) if d.name in draft.scaled else d for d in draft.setup.drives]
    setup = replace(draft.setup, drives=drives + draft.blow_drives)
    effect_seed = int(rng.integers(2**63))
    u_bound = 10 * max(stats["u_pos"], stats["u_neg"])
    strength = 1.0
    for _attempt in range(4):  # a softening spring can escape: then the same effect, weakened
        elements, params, generic = _draw_effect(np.random.default_rng(effect_seed), cause, draft, stats, strength)
        trial = replace(setup, elements=elements)
        rate = trial.rate_hz(draft.fs_hz, draft.min_rate_hz)
        r = run(trial, draft.fs_hz, draft.duration_s, rate_hz=rate)
        u = r.response.element_u
        if all(np.isfinite(x).all() for x in r.outputs.values()) and (not elements or np.abs(u).max() < u_bound):
            break
        strength *= 0.5
    else:
        raise RuntimeError("the simulation diverged even with a weakened effect")
    truth = _truth(draft, cause, params, generic, r, stats, rate)
    if twin:  # the same draws, run without the effect: the effect's own truth kept as what it mirrors
        r = run(replace(setup, elements=[], membrane=None), draft.fs_hz, draft.duration_s, rate_hz=rate)
        mirrored = {k: truth[k] for k in ("cause", "location", "position", "effect", "effect_strength")}
        truth = _truth(replace(draft, site=replace(draft.site, location=None)), "none", {}, {}, r, stats, rate)
        truth["twin_of"] = mirrored
    card = draws.draw_card(rng, draft.fs_hz)
    columns = {"t": np.arange(r.n_out) / draft.fs_hz}
    kinds, units, instruments = {"t": "time"}, {"t": "s"}, {}
    clean = {"t": columns["t"]}  # each channel as its instrument saw it before noise, range and quantisation
    for name, kind in draft.channels:
        ch = draws.draw_channel(rng, kind)
        acq = acquire(r.outputs[name], r.rate_hz, card, ch, r.n_out, rng)
        columns[name], kinds[name], units[name], instruments[name] = acq.values, kind, UNITS[kind], acq.info
        clean[f"clean:{name}"] = acq.clean
    exc_col = draft.excitation.split(":")[0]
    truth |= {"seed": seed, "signs": {c: instruments[c]["sign"] for c in instruments},
              "snr_db": {c: instruments[c]["snr_db_achieved"] for c in instruments},
              "channels": instruments, "card": {"fs_hz": card.fs_hz, "bits": card.bits,
                                                "anti_alias": card.anti_alias.describe()},
              "excitation": draft.excitation,
              "responses": [f"{c}:{k}" for c, k in draft.channels if c != exc_col],
              "excitation_signal": {"kind": draft.signal_kind,
                                    **{d.name: d.signal.describe() for d in setup.drives if d.name in draft.scaled}},
              "unmeasured_blows": draft.blows}
    return Case(family=draft.family, fs_hz=float(draft.fs_hz), columns=columns, kinds=kinds, units=units, truth=truth,
                truth_series=clean)


def _truth(draft: Draft, cause: str, params: dict, generic: dict, r: Run, stats: dict, rate: int) -> dict:
    site = draft.site
    truth = {"cause": cause, "location": site.location, "position": site.position, "effect": params,
             "structure": draft.structure, "duration_s": r.n_out / draft.fs_hz, "n_samples": r.n_out,
             "internal_rate_hz": rate, "preview": stats}
    eq_cause = cause if params else "none"
    truth["equivalent"] = {"sensor": site.location or draft.channels[1][0],
                           **draws.equivalents(site.phi_sensor, site.phi_effect, site.omega, site.zeta, eq_cause,
                                               generic)}
    truth["equivalent_modes"] = _modal_equivalents(draft, eq_cause, generic)
    resp = r.response
    if cause == "cubic_stiffness" and draft.family == "cc_beam":
        k3pm = _membrane_k3_per_mass(draft)
        m_eq = 1 / site.phi_sensor**2
        truth["equivalent"] |= {"k3_n_per_m3": k3pm * m_eq, "k3_per_mass": k3pm}
        truth["effect"] = {"kind": "membrane stretching",
                           "axial_coefficient_ea_over_2l_n": draft.setup.membrane.coefficient_n,
                           "predicted_backbone_shift_at_preview_peak": draft.membrane_target_shift}
        f, q1 = resp.element_f[:, -1], resp.element_u[:, -1]
        truth["effect_strength"] = _rms(f) / _rms(site.omega**2 * q1)
    elif params:
        f, u, v = resp.element_f[:, 0], resp.element_u[:, 0], resp.element_v[:, 0]
        truth["effect_strength"] = _rms(f) / _rms(site.k_static * u)
        if cause in ("coulomb_friction", "quadratic_damping"):
            truth["effect_vs_damping"] = _rms(f) / _rms(_linear_damping(site, stats) * v)
        if cause == "contact":
            truth["contact_share"] = float(np.mean(f != 0.0))
    else:
        truth["effect_strength"] = 0.0
    return truth


def _modal_equivalents(draft: Draft, cause: str, generic: dict) -> list[dict]:
    """The one-mode equivalents at the sensor in each mode of the structure below twice the site's first
    mode (``draws.equivalents`` with the structure's mass-normalised shapes, not the effect's beam alone).
    ``equivalent`` takes the beam's own first mode; two coupled beams of close frequency share it between
    two modes, and a coefficient per modal mass is then one mode's or the other's (independent seed 6: a
    cubic at tip 2 is 6.0e7 per kg in the beam's own mode, 2.7e7 and 3.2e7 in the rig's 8.89 and 9.46 Hz
    modes)."""
    model, site = draft.setup.model, draft.site
    out = []
    for j in np.flatnonzero(model.omega_rad_s < 2.0 * site.omega):
        mode = model.shapes[:, j]
        phi_s, phi_e = float(site.sensor @ mode), float(site.coordinate @ mode)
        if abs(phi_s) < 1e-12 * np.abs(mode).max():
            continue  # the sensor does not move in it
        w = float(model.omega_rad_s[j])
        out.append(draws.equivalents(phi_s, phi_e, w, float(model.damping[j, j]) / (2 * w), cause, generic))
    return out


@seeded
def discovery_case(seed: int, family: str | None = None, cause: str | None = None, twin: bool = False) -> Case:
    """A seeded discovery case; family and cause are drawn unless given. ``twin``: the same case run
    without its effect (the module docstring)."""
    rng = np.random.default_rng(seed)
    family = family or draws.pick(rng, FAMILIES)
    if family not in FAMILY_CAUSES:
        raise ValueError(f"family must be one of {tuple(FAMILY_CAUSES)}")
    cause = cause or draws.pick(rng, FAMILY_CAUSES[family])
    if cause not in FAMILY_CAUSES[family]:
        raise ValueError(f"cause {cause} does not apply to {family}: {tuple(FAMILY_CAUSES[family])}")
    if family.startswith("rig"):
        draft = _rig_draft(rng, family, cause)
    elif family.startswith("duffing"):
        draft = _duffing_draft(rng, cause, family)
    elif family == "chain":
        draft = _chain_draft(rng, cause)
    else:
        draft = _cc_beam_draft(rng, cause)
    return _finish(rng, draft, cause, seed, twin)
