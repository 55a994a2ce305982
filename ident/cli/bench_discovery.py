"""``ident bench discovery``: seeded hidden-effect cases, discovery run on each, judged against the truth.

Two generators: ``independent`` (``daq.sim.independent``: finite-element beams, a Duffing oscillator, a
chain of masses, a clamped-clamped beam; its own equations and integrator, importing nothing from
``ident``) and ``rig`` (``daq.sim.hidden``: this project's own rig model with one effect switched on, the
easy test). Prints the confusion table (true against named, with "ambiguous" and "nothing" as
columns), false extra findings, parameter errors and gains, and the run time per case.

Cases run in this process one after the other, or as Dask tasks (``--workers N`` local processes,
``--scheduler ADDRESS`` a cluster; ``ident.cli.engine``), printed in seed order either way: the same lines
and the same table as the serial run (only the run times differ).

A case is named right when the first finding (not ambiguous) has the true cause at the true location:
the sensor at the effect, or for an element between two sensors that pair (in either order, as a
difference or a sum). A finding beyond the true one, or any finding in a "none" case, is a false extra
finding.
"""

from __future__ import annotations

import json
import os
import platform
import time
from collections import Counter
from dataclasses import dataclass, field, replace
from pathlib import Path

import numba
import numpy as np
import scipy
import scipy.linalg  # noqa: F401 - scipy's OpenBLAS loaded, so that ``blas_kernels`` names it too
from threadpoolctl import threadpool_info
from numpy._core._multiarray_umath import __cpu_features__ as CPU_FEATURES  # numpy's kernels in use
from daq.safeio import PartFile, part_path
from daq.sim.hidden import hidden_case
from daq.sim.independent.cases import discovery_case

from ..discovery import Channel, Measurement, discover, to_json
from ..discovery.discover import noise_floor
from ..discovery.search import Settings, same_sensors
from ..jsonsafe import finite
from ..rig import RigParams
from .engine import ordered, session

SYNONYMS = {"friction_joint": "hysteretic_joint", "geometric_hardening": "cubic_stiffness"}
# per cause, (the truth's parameter, the finding's) in order of preference; the first pair both carry is
# compared. Per unit modal mass at the location, or a gap, or (for an element between two measured masses
# of a force-driven structure, whose law acts on their measured relative motion) the element's own
# physical value against the finding's "physical" one in newtons
COMPARED = {"contact": (("gap", "gap"),),
            "cubic_stiffness": (("coefficient_n_per_m3", "coefficient_n_per_m3"),
                                ("coefficient_per_mass", "coefficient_per_mass")),
            "quadratic_stiffness": (("coefficient_per_mass", "coefficient_per_mass"),),
            "coulomb_friction": (("force_n", "force_n"), ("force_per_mass", "force_per_mass")),
            "quadratic_damping": (("coefficient_n_s2_per_m2", "coefficient_n_s2_per_m2"),
                                  ("coefficient_per_mass", "coefficient_per_mass")),
            "linear_mismatch": (("stiffness_per_mass", "stiffness_per_mass"),),
            "sensor_gain": (("gain_error", "gain_error"),), "clipping": (("range_m_per_s2", "range"),),
            "hysteretic_joint": (("stiffness_per_mass", "stiffness_per_mass"),)}
# the generator's physical parameter of an element between two masses, by cause, in COMPARED's names
ELEMENT = {"contact": {"gap": "gap_m"}, "cubic_stiffness": {"coefficient_n_per_m3": "k3_n_per_m3"},
           "coulomb_friction": {"force_n": "slip_force_n"},
           "quadratic_damping": {"coefficient_n_s2_per_m2": "coefficient_n_s2_per_m2"}}


@dataclass
class Case:
    seed: int
    family: str
    measurement: Measurement
    rig: RigParams | None
    cause: str  # in this catalogue's names, or "none"
    location: str  # a column, or "A-B"
    truth: dict  # parameters in this catalogue's names
    info: str = ""
    clipped: frozenset = frozenset()  # responses the generator's instruments clipped (a true clipping finding)
    strength: float | None = None  # the generator's effect strength: RMS(effect's force) / RMS(static force)
    reference: Measurement | None = None  # the responses before the instruments' noise (``noise_floor``)
    driven: str | None = None  # under a force: the response at its point (a rig's: its beam's tip), where known
    signs: dict | None = None  # each response's sign against the excitation's as recorded


@dataclass
class Verdict:
    seed: int
    family: str
    cause: str
    named: str  # the first finding's cause, "ambiguous" or "nothing"
    location: str
    right: bool
    extra: int  # false extra findings
    parameter_error: float | None
    gain: float | None
    seconds: float
    info: str = ""
    detail: list = field(default_factory=list)
    baseline_nrmse: float | None = None  # the baseline's held-out NRMSE
    twin: bool = False  # the case run without its effect (``independent_case(seed, twin=True)``)
    strength: float | None = None  # the case's effect strength (``Case.strength``)
    noise_floor: float | None = None  # the held-out NRMSE the responses' noise alone gives (``noise_floor``)
    record: dict | None = None  # with --save: the case's truth and discover's JSON (``saved_record``)
    sign: str | None = None  # under a force, the driving point discovery took (``driving_sign``)
    through: str | None = None  # ... and the response the modal baseline's reciprocity went through


RIG_CASE_S = 40.0  # the rig generator's case length


def rig_case(seed: int, duration_s: float = RIG_CASE_S) -> Case:
    c = hidden_case(seed, fs_hz=1000.0, duration_s=duration_s)
    m = Measurement(c.fs_hz, Channel("base", "base_acceleration", c.values[:, 0]),
                    (Channel("tip1", "acceleration", c.values[:, 1]), Channel("tip2", "acceleration", c.values[:, 2])))
    return Case(seed, f"rig ({c.excitation})", m, c.nominal, c.effect, f"tip{c.beam}", dict(c.truth))


def judge(case: Case, d, seconds: float) -> Verdict:
    """The first finding against the true cause and location, and the findings that are not the truth. A
    clipping found at a response the generator's instrument clipped is the truth too: neither the cause
    sought nor a false finding, it is set aside before judging (and shown in the detail)."""
    cause = SYNONYMS.get(case.cause, case.cause)
    kept = [(f, a) for f, a in zip(d.findings, d.ambiguous)
            if not (f.cause == "clipping" and f.location in case.clipped)]
    findings, ambiguous = [f for f, _ in kept], [a for _, a in kept]
    if not findings:
        named, loc, right = "nothing", "", cause == "none"
    elif ambiguous[0]:
        named, loc, right = "ambiguous", findings[0].location, False
    else:
        named, loc = findings[0].cause, findings[0].location
        right = cause != "none" and named == cause and same_sensors(loc, case.location)
    # every finding that is not the true cause at the true location is a false extra one
    extra = len(findings) - int(cause != "none" and any(f.cause == cause and same_sensors(f.location, case.location)
                                                        for f in findings))
    perr = gain = None
    if right and cause in COMPARED:
        found = findings[0].physical | findings[0].parameters
        truth = _in_mode(case.truth, d.per_mass_mode_hz(findings[0]))
        pairs = [(t, f) for t, f in COMPARED[cause] if truth.get(t) and f in found]
        if pairs:
            tkey, fkey = pairs[0]
            perr = abs(found[fkey] / truth[tkey] - 1)
        gain = findings[0].gain
    return Verdict(case.seed, case.family, cause, named, loc, right, extra, perr, gain, seconds, case.info,
                   [f"{f.label} gain {f.gain:.2f}" + ("" if any(f is g for g in findings) else " (clipped there: true)")
                    for f in d.findings], float(d.baseline_test_nrmse), strength=case.strength)


MODE_MATCH = 0.15  # a finding's mode and the structure's mode it is compared in: within 15 % in frequency


def _in_mode(truth: dict, mode_hz: float | None) -> dict:
    """The truth in the structure's mode nearest ``mode_hz`` (the mode a finding's per-mass parameters are
    per modal mass of), within ``MODE_MATCH``; else as given (the effect's beam's own first mode)."""
    modes = truth.get("by_mode") or []
    if not (modes and mode_hz and mode_hz > 0):
        return truth
    near = min(modes, key=lambda m: abs(m["frequency_hz"] - mode_hz))
    if abs(near["frequency_hz"] / mode_hz - 1) > MODE_MATCH:
        return truth
    return truth | {k: v for k, v in near.items() if k != "frequency_hz"}


def run_case(args: tuple[str, int, float, bool, bool, str | None]) -> Verdict:
    """One case (a Dask task): (generator, seed, the rig generator's case length in s, twin, keep, the
    independent generator's family or None for its draw); with ``keep`` the verdict carries the case's
    record for ``--save`` (``saved_record``)."""
    generator, seed, duration_s, twin, keep, family = args
    case = rig_case(seed, duration_s) if generator == "rig" else independent_case(seed, twin=twin, family=family)
    t0 = time.perf_counter()
    try:
        d = discover(case.measurement, rig=case.rig)
    except Exception as exc:  # noqa: BLE001 - a benchmark counts a crash as an error row and goes on
        d, v = None, Verdict(seed, case.family, SYNONYMS.get(case.cause, case.cause), f"error: {exc}", "", False, 0,
                             None, None, time.perf_counter() - t0, case.info, twin=twin, strength=case.strength)
    else:
        v = replace(judge(case, d, time.perf_counter() - t0), twin=twin, sign=driving_sign(case, d.prep),
                    through=reciprocity_through(case, d))
        if case.reference is not None:
            v = replace(v, noise_floor=noise_floor(d, case.measurement, case.reference))
    return replace(v, record=saved_record(case, v, d)) if keep else v


def saved_record(case: Case, v: Verdict, d) -> dict:
    """One line of ``--save``: the case (seed, twin, family, the generator's truth in this catalogue's names),
    the verdict as printed, and ``discover``'s result in the shape ``ident discover --json`` writes (every
    candidate with its held-out gain, p-value and parameters), so that misses can be studied and selection
    rules tried without running the cases again. ``d`` is None where discover raised."""
    verdict = {k: getattr(v, k) for k in ("named", "location", "right", "extra", "parameter_error", "gain",
                                          "seconds", "baseline_nrmse", "noise_floor", "sign", "through")}
    return finite({"seed": case.seed, "twin": v.twin, "family": case.family, "info": case.info,
                   "truth": {"cause": case.cause, "location": case.location, "strength": case.strength,
                             "parameters": case.truth, "clipped": sorted(case.clipped)},
                   "verdict": verdict, "discovery": None if d is None else to_json(d)})


def _joint_truth(eq: dict, effect: dict) -> dict:
    """A friction joint in this catalogue's terms: the stiffness it loses once every Jenkins element slips
    (their sum, per modal mass at the sensor; not the residual stiffness that stays) and the displacement
    at the sensor at which the last one slips (an element's slip force over its stiffness, at the joint,
    over the mode's motion at the joint per unit motion at the sensor: for a root joint, its rotation per
    metre of tip displacement)."""
    truth = {"stiffness_per_mass": eq["slipping_stiffness_per_mass"]}
    k = next((v for key, v in effect.items() if key.startswith("jenkins_stiffness")), None)
    limit = next((v for key, v in effect.items() if key.startswith("jenkins_slip")), None)
    if k and limit:
        per = abs(float(eq.get("mode_ratio", 1.0)))
        truth["slip"] = float(np.max(np.asarray(limit, float) / np.asarray(k, float))) / per
    return truth


def _equivalent_truth(cause: str, eq: dict, effect: dict) -> dict:
    """The generator's one-mode equivalents (``eq``) in this catalogue's names."""
    if cause == "contact":
        return {"gap": eq.get("gap_m"), "side": eq.get("side"), "stiffness_per_mass": eq.get("contact_stiffness_per_mass")}
    if cause == "cubic_stiffness":
        return {"coefficient_per_mass": eq.get("k3_per_mass")}
    if cause == "coulomb_friction":
        return {"force_per_mass": eq.get("slip_force_per_mass")}
    if cause == "quadratic_damping":
        return {"coefficient_per_mass": eq.get("coefficient_per_mass")}
    if cause == "hysteretic_joint" and "slipping_stiffness_per_mass" in eq:
        return _joint_truth(eq, effect)
    return {}


def independent_case(seed: int, generated=None, twin: bool = False, family: str | None = None) -> Case:
    """The generator's case ``seed`` as a measurement and its truth (``generated``: that case, if already
    drawn; ``twin``: the case run without its effect, cause "none"; ``family``: that family's case, else
    the family drawn)."""
    c = generated or discovery_case(seed, family, twin=twin)
    t = c.truth
    col, kind = t["excitation"].split(":")
    responses = tuple(Channel(n, k, np.asarray(c.columns[n], float)) for n, k in (r.split(":") for r in t["responses"]))
    m = Measurement(float(c.fs_hz), Channel(col, kind, np.asarray(c.columns[col], float)), responses)
    cause = SYNONYMS.get(t["cause"], t["cause"])
    truth = _equivalent_truth(cause, t.get("equivalent", {}), t.get("effect", {}))
    if len(t.get("equivalent_modes") or []) > 1:
        # the same per mode of the structure: a finding's per-mass parameters are one mode's (``judge``)
        truth["by_mode"] = [{"frequency_hz": e["natural_frequency_hz"], **_equivalent_truth(cause, e, t.get("effect", {}))}
                            for e in t["equivalent_modes"]]
    if "-" in (t.get("location") or "") and kind == "force":
        # the generator's one-mode equivalent of a chain's element is taken at one mass of the pair, not
        # at their difference (seed 14: 1/511 of the cubic it put there); the element's own value is the
        # reference
        truth = {ours: t["effect"][theirs] for ours, theirs in ELEMENT.get(cause, {}).items()}
    mirrored = t.get("twin_of")
    info = (f"{'twin of ' + mirrored['cause'] + ', ' if mirrored else ''}{c.fs_hz:.0f} Hz, "
            f"strength {t.get('effect_strength', 0):.2f}, "
            f"{len(t.get('unmeasured_blows') or [])} blows, signs {''.join('+' if v > 0 else '-' for v in t['signs'].values())}")
    clipped = frozenset(n for n, i in t.get("channels", {}).items() if i.get("clipped_fraction", 0.0) > 0)
    strength = t.get("effect_strength") if cause != "none" else None
    reference = None
    if all(f"clean:{ch.name}" in c.truth_series for ch in responses):
        reference = Measurement(m.fs_hz, m.excitation, tuple(
            Channel(ch.name, ch.kind, np.asarray(c.truth_series[f"clean:{ch.name}"], float)) for ch in responses))
    st = t.get("structure") or {}
    driven = signs = None
    if kind == "force":
        names = [ch.name for ch in responses]
        driven = (f"a{st['force_on_mass']}" if "force_on_mass" in st
                  else f"tip{st['stinger']['beam']}" if "stinger" in st
                  else names[0] if len(names) == 1 else None)
        signs = {ch.name: int(t["signs"][ch.name] * t["signs"][col]) for ch in responses}
    return Case(seed, c.family, m, None, cause, t.get("location") or "", truth, info, clipped,
                None if strength is None else float(strength), reference, driven, signs)


def driving_sign(case: Case, prep) -> str | None:
    """Under a force with a known driven response, what discovery made of the driving point: "right" (the
    driven response taken, its sign as analysed the physics'), "wrong sign" (taken, its sign not), "another"
    (another response taken), "none" (none taken)."""
    if case.driven is None or case.signs is None or prep is None:
        return None
    if prep.driving_point is None:
        return "none"
    if prep.names[prep.driving_point] != case.driven:
        return "another"
    return "right" if case.signs[case.driven] * prep.signs[prep.driving_point] > 0 else "wrong sign"


def reciprocity_through(case: Case, d) -> str | None:
    """Under a force with a known driven response, whether the modal baseline took its reciprocity through it
    ("driven") or through another response ("another"); None where it took none."""
    through = getattr(d.baseline, "driving_point", None)
    if case.driven is None or through is None:
        return None
    return "driven" if d.prep.names[through] == case.driven else "another"


def report(verdicts: list[Verdict], wall_s: float) -> str:
    causes = sorted({v.cause for v in verdicts})
    named = sorted({v.named for v in verdicts if v.named not in ("ambiguous", "nothing")
                    and not v.named.startswith("error")} - set(causes))
    cols = causes + named + ["ambiguous", "nothing", "error"]
    conf = Counter((v.cause, v.named if not v.named.startswith("error") else "error") for v in verdicts)
    lines = [f"confusion (rows true, columns named first), {len(verdicts)} cases:",
             " " * 19 + "".join(f"{c[:10]:>11s}" for c in cols)]
    for tr in causes:
        lines.append(f"{tr:19s}" + "".join(f"{conf[(tr, c)]:11d}" for c in cols))
    n = len(verdicts)
    right = sum(v.right for v in verdicts)
    clean = sum(v.extra == 0 for v in verdicts)
    none = [v for v in verdicts if v.cause == "none"]
    lines.append(f"named right (cause and location): {right}/{n} = {100 * right / n:.1f} %")
    lines.append(f"cases without a false extra finding: {clean}/{n} = {100 * clean / n:.1f} %")
    lines.append(f"'none' cases with a finding: {sum(v.named not in ('nothing',) for v in none)}/{len(none)}")
    for c in causes:
        errs = [v.parameter_error for v in verdicts if v.cause == c and v.parameter_error is not None]
        gains = [v.gain for v in verdicts if v.cause == c and v.gain is not None]
        if errs:
            lines.append(f"{c:19s} parameter error median {100 * np.median(errs):.1f} %, max {100 * np.max(errs):.1f} %"
                         f" ({len(errs)} cases); gain median {np.median(gains):.2f}, min {np.min(gains):.2f}")
    lines += by_strength(verdicts)
    lines += by_floor(verdicts)
    taken = Counter(v.sign for v in verdicts if v.sign is not None)
    through = Counter(v.through for v in verdicts if v.through is not None)
    if taken:
        lines.append(f"driving point under a force ({sum(taken.values())} cases whose driven response is known: the "
                     f"mass pushed, the one response, or the tip of the stinger's beam): taken with its sign right "
                     f"{taken['right']}, its sign wrong {taken['wrong sign']}, another response taken "
                     f"{taken['another']}, none {taken['none']}; the modal baseline's reciprocity through the "
                     f"driven response {through['driven']}, through another {through['another']}")
    secs = [v.seconds for v in verdicts]
    lines.append(f"run time per case: median {np.median(secs):.1f} s, max {np.max(secs):.1f} s; "
                 f"wall {wall_s:.0f} s")
    return "\n".join(lines)


def by_floor(verdicts: list[Verdict]) -> list[str]:
    """How far each class of case's baseline errs above the response-noise floor (``noise_floor``): near 1
    no cause can gain (the effect is not in the data as scored); far above it the data hold more than the
    baseline predicts, and a miss is the method's."""
    rows = [v for v in verdicts if v.noise_floor and v.baseline_nrmse is not None and np.isfinite(v.baseline_nrmse)]
    if not rows:
        return []
    lines = ["baseline's held-out NRMSE over the responses' noise floor (what no model of the noise-free record "
             "goes below):"]
    for label, pick in (("named right", lambda v: v.right and v.cause != "none"),
                        ("missed", lambda v: not v.right),
                        ("'none', nothing found", lambda v: v.right and v.cause == "none")):
        r = np.array([v.baseline_nrmse / v.noise_floor for v in rows if pick(v)])
        if r.size:
            lines.append(f"  {label:22s} {r.size:3d} cases: median {np.median(r):5.1f} x (quartiles "
                         f"{np.percentile(r, 25):.1f}-{np.percentile(r, 75):.1f}, least {r.min():.1f})")
    # a linear baseline errs this far above the floor on records with nothing hidden: a miss beyond every one
    # of them is a record that holds what the baseline misses
    free = [v.baseline_nrmse / v.noise_floor for v in rows if v.cause == "none"]
    missed = [v.baseline_nrmse / v.noise_floor for v in rows if not v.right and v.cause != "none"]
    if free and missed:
        lines.append(f"  misses beyond every 'none' case ({max(free):.1f} x): {sum(r > max(free) for r in missed)}"
                     f"/{len(missed)}")
    return lines


STRENGTH_BINS = (0.1, 0.3, 1.0)  # edges of the effect-strength classes ``by_strength`` counts in


def by_strength(verdicts: list[Verdict]) -> list[str]:
    """Per true cause, named right out of the cases in each class of the generator's effect strength
    (RMS of the effect's force over RMS of the linear static force on its coordinate): whether a cause is
    missed when it is weak, as expected, or when it is strong, which no threshold explains (stop 36: 1 of
    8 contacts of strength 0.8 and more named right, 8 of 10 weaker ones). Empty when no case carries a
    strength (the rig generator's cases)."""
    rated = [v for v in verdicts if v.strength is not None and v.cause != "none"]
    if not rated:
        return []
    edges = (0.0,) + STRENGTH_BINS + (np.inf,)
    heads = [f"< {STRENGTH_BINS[0]:g}"] + [f"{a:g}-{b:g}" for a, b in zip(STRENGTH_BINS, STRENGTH_BINS[1:])] + \
        [f">= {STRENGTH_BINS[-1]:g}"]
    lines = ["named right by effect strength (RMS of its force / RMS of the static force), right/cases:",
             " " * 19 + "".join(f"{h:>11s}" for h in heads)]
    for c in sorted({v.cause for v in rated}):
        cells = []
        for lo, hi in zip(edges[:-1], edges[1:]):
            in_bin = [v for v in rated if v.cause == c and lo <= v.strength < hi]
            cells.append(f"{sum(v.right for v in in_bin)}/{len(in_bin)}" if in_bin else "-")
        lines.append(f"{c:19s}" + "".join(f"{x:>11s}" for x in cells))
    return lines


def twin_report(verdicts: list[Verdict], gain_floor: float = Settings().gain_floor) -> str:
    """What the twins (each case run without its effect) say: the findings made where there is nothing,
    on exactly the structures, drives and instruments of the cases; and how much of the baseline's
    held-out error each effect is at all, 1 - (twin's NRMSE / case's NRMSE), against the gain floor a
    finding must pass (an effect that costs the linear model less cannot become a finding)."""
    cases = {v.seed: v for v in verdicts if not v.twin}
    twins = {v.seed: v for v in verdicts if v.twin}
    if not twins:
        return ""
    false = [v for v in twins.values() if v.named != "nothing"]
    lines = [f"twins (each case run without its effect): {len(false)}/{len(twins)} with a finding"
             + "".join(f"\n  seed {v.seed} ({cases[v.seed].cause if v.seed in cases else '?'} removed): "
                       f"{'; '.join(v.detail) or v.named}" for v in sorted(false, key=lambda v: v.seed))]
    share = {}
    for seed, v in cases.items():
        t = twins.get(seed)
        if v.cause != "none" and t and v.baseline_nrmse and t.baseline_nrmse is not None:
            share[seed] = 1.0 - t.baseline_nrmse / v.baseline_nrmse
    if share:
        lines.append(f"the effect's share of the baseline's held-out error (1 - twin's NRMSE / case's), "
                     f"against the gain floor {gain_floor:g}:")
        for c in sorted({cases[s].cause for s in share}):
            mine = [s for s in share if cases[s].cause == c]
            low = [s for s in mine if share[s] < gain_floor]
            high = [s for s in mine if s not in low]
            lines.append(f"  {c:19s} median {np.median([share[s] for s in mine]):6.2f}; below the floor "
                         f"{len(low)}/{len(mine)} (named right {sum(cases[s].right for s in low)}), above "
                         f"{len(high)} (named right {sum(cases[s].right for s in high)})")
        high = [s for s in share if share[s] >= gain_floor]
        lines.append(f"named right where the effect is at least the gain floor of the baseline's error: "
                     f"{sum(cases[s].right for s in high)}/{len(high)}")
    return "\n".join(lines)


def environment() -> str:
    """What the figures were computed with: the libraries whose round-off the fits follow and the processor
    (its BLAS kernels). The search's answers can hang on round-off: independent seed 73 with two BLAS
    threads; seed 3's twin, without a finding in stop 33's run and with a false quadratic stiffness (gain
    0.27) in the next session's fresh install of the same deciding code (numpy 2.4.6, scipy 1.17.1, numba
    0.68.1, AMD EPYC; the earlier run's versions and processor were not recorded, hence this line)."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            cpu = next((line.split(":", 1)[1].strip() for line in f if line.startswith("model name")), cpu)
    except OSError:
        pass
    return (f"numpy {np.__version__}, scipy {scipy.__version__}, numba {numba.__version__}, "
            f"Python {platform.python_version()}, {cpu}, one BLAS thread per case, numpy's SIMD kernels "
            f"{simd_level()}, OpenBLAS kernels {blas_kernels()}")


def blas_kernels() -> str:
    """The kernel sets numpy's and scipy's OpenBLAS run (held to Haswell's where the CPU has AVX2: see
    daq/__init__.py), and what OPENBLAS_CORETYPE says."""
    kinds = sorted({str(i.get("architecture")) for i in threadpool_info() if i.get("internal_api") == "openblas"})
    return f"{'/'.join(kinds) or 'none'} (OPENBLAS_CORETYPE={os.environ.get('OPENBLAS_CORETYPE', '')!r})"


def simd_level() -> str:
    """The highest x86-64 level of numpy's kernels in use (the AVX-512 ones are held off by default: see
    daq/__init__.py), and what NPY_DISABLE_CPU_FEATURES says."""
    levels = [k for k in ("X86_V2", "X86_V3", "X86_V4") if CPU_FEATURES.get(k)]
    return (levels[-1] if levels else "baseline") + f" (NPY_DISABLE_CPU_FEATURES={os.environ.get('NPY_DISABLE_CPU_FEATURES', '')!r})"


def run_discovery(generator: str, n_cases: int, first_seed: int = 0, workers: int | None = None,
                  scheduler: str | None = None, duration_s: float = RIG_CASE_S, twins: bool = False,
                  save: Path | None = None, family: str | None = None, resume: bool = False) -> int:
    """The benchmark: in this process, or on a local Dask cluster of ``workers`` processes, or on the
    cluster at ``scheduler``; the lines in seed order either way. ``twins``: each independent case is
    also run without its effect (``twin_report``). ``save``: a JSON-lines file, one ``saved_record`` per
    case (and twin) in the printed order, streamed as ``NAME.part`` and renamed when the run completes (a
    run cut short leaves the part, whole lines up to its last case); an existing file is never replaced.
    ``family``: the independent generator's family on every seed instead of the family drawn
    (``FAMILY_CAUSES``: one not drawn by default, such as ``duffing_softening``, included). ``resume``: the
    part of a ``save`` run cut short (``_resumed``) gives the cases it holds, and only the rest are run."""
    t0 = time.perf_counter()
    jobs = [(generator, s, duration_s, twin, save is not None, family) for s in range(first_seed, first_seed + n_cases)
            for twin in ((False, True) if twins else (False,))]
    verdicts = []
    if resume:
        if save is None:
            raise ValueError("--resume continues a --save run cut short: give its --save OUT.jsonl")
        verdicts, out = _resumed(save, jobs)
        jobs = jobs[len(verdicts):]
    else:
        out = _saving(save) if save is not None else None
    print(environment(), flush=True)
    if verdicts:
        print(f"resumed {len(verdicts)} records from {out.part} (their run times are the first run's)")
        for v in verdicts:
            _print(v)
    try:
        with session(scheduler, workers) as client:
            for v in ordered(client, run_case, jobs, "discovery"):
                if out is not None:
                    out.file.write(json.dumps(v.record) + "\n")
                    out.file.flush()
                    v = replace(v, record=None)
                verdicts.append(v)
                _print(v)
    except BaseException:
        if out is not None and not verdicts and not resume:  # nothing saved yet (no scheduler, say): no part left
            # to block a rerun (a resumed part is the first run's: it stays)
            out.abort()
        raise
    if out is not None:
        print(f"saved {len(verdicts)} records to {out.commit()}")
    print()
    print(report([v for v in verdicts if not v.twin], time.perf_counter() - t0))
    if twins:
        print(twin_report(verdicts))
    return 0


def _saving(save: Path) -> PartFile:
    """The ``--save`` stream, refused with one line if the file or its part exists (a benchmark never replaces a
    file, and a part is a run cut short whose whole lines are worth keeping)."""
    for path, what in ((save, "give another name (a benchmark never replaces a file)"),
                       (part_path(save), "a run cut short, whole lines up to its last case: continue it with "
                                         "--resume, move it away or give another name")):
        if path.exists() or path.is_symlink():
            raise ValueError(f"--save: {path} exists: {what}")
    return PartFile(save, label="--save", mode="w", check=False)


def _resumed(save: Path, jobs: list[tuple]) -> tuple[list[Verdict], PartFile]:
    """The verdicts a run cut short saved in ``save``'s part, and the part opened to append the rest. Its
    whole lines must be the first of ``jobs`` (same seeds, twins and generator, in order), else it is
    refused with one line and left as it was; a line cut off mid-way at its end is dropped."""
    part = part_path(save)
    try:
        data = part.read_bytes()
    except FileNotFoundError:
        raise ValueError(f"--resume: {part} does not exist: nothing to resume") from None
    keep = data.rfind(b"\n") + 1
    verdicts = []
    for k, line in enumerate(data[:keep].splitlines()):
        try:
            r = json.loads(line)
            v = restored(r)
        except (ValueError, KeyError, TypeError) as exc:
            raise ValueError(f"--resume: line {k + 1} of {part} is not a saved case ({exc}); left as it was") from None
        want = jobs[k] if k < len(jobs) else None
        rig = v.family.startswith("rig (")
        if (want is None or (v.seed, v.twin) != (want[1], want[3]) or rig != (want[0] == "rig")
                or (want[5] is not None and v.family != want[5])):
            expected = "no more cases" if want is None else f"seed {want[1]}{' (twin)' if want[3] else ''}"
            raise ValueError(f"--resume: line {k + 1} of {part} is seed {v.seed}{' (twin)' if v.twin else ''} of "
                             f"the {'rig' if rig else 'independent'} generator where this run has {expected}: "
                             "give the first run's --generator, --seed, --cases, --family and --twins")
        verdicts.append(v)
    return verdicts, PartFile.resumed(save, keep, label="--save")


def restored(r: dict) -> Verdict:
    """The verdict a ``saved_record`` line holds (``--resume``): as ``judge`` printed it."""
    t, v, d = r["truth"], r["verdict"], r["discovery"]
    clipped = set(t.get("clipped") or ())
    detail = [] if d is None else [
        f"{f['effect']} at {f['response']} gain {f['gain']:.2f}"
        + (" (clipped there: true)" if f["effect"] == "clipping" and f["response"] in clipped else "")
        for f in d["findings"]]
    return Verdict(int(r["seed"]), r["family"], SYNONYMS.get(t["cause"], t["cause"]), v["named"], v["location"],
                   bool(v["right"]), int(v["extra"]), v["parameter_error"], v["gain"], float(v["seconds"]), r["info"],
                   detail, v["baseline_nrmse"], twin=bool(r["twin"]), strength=t["strength"],
                   noise_floor=v["noise_floor"], sign=v["sign"], through=v["through"])


def _print(v: Verdict) -> None:
    if v.twin:
        print(f"twin {v.seed:4d} {v.family:17s} {'(' + v.cause + ')':18s} -> {v.named:18s} {v.location:10s}"
              f"  [{v.seconds:.0f} s] {'; '.join(v.detail)}  ({v.info})", flush=True)
        return
    mark = "" if v.right else "  WRONG"
    floor = (f", baseline {v.baseline_nrmse:.3g} = {v.baseline_nrmse / v.noise_floor:.1f} x the noise floor"
             if v.noise_floor and v.baseline_nrmse is not None else "")
    print(f"case {v.seed:4d} {v.family:17s} {v.cause:18s} -> {v.named:18s} {v.location:10s}"
          f"{'' if v.extra == 0 else f' +{v.extra} extra'}{mark}  [{v.seconds:.0f} s] {'; '.join(v.detail)}"
          f"  ({v.info}{floor})", flush=True)
