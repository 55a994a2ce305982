"""Model discovery against the rig model: what the simulation gets wrong, the cause, the gain.

Steps (Kaheman et al. 2019, "Learning discrepancy models from experimental
data", in physical coordinates):

1. Baseline: the rig model with nominal parameters, driven by the *measured*
   base acceleration, simulated over the held-out (test) segment from the
   measured state at its start; its error is the NRMSE of the tip
   accelerations below 50 Hz.
2. Physical coordinates: relative acceleration r = tip - base, band-limited
   integration to v and z (ident.physical).
3. Residual force per mass on the training segment: d = r - r_nominal(z, v, base),
   r_nominal the nominal model's right-hand side evaluated on the measured states.
4. Each cause in the catalogue is a set of terms with physical parameters,
   fitted to d by least squares; nonlinear parameters (the gap, the side)
   are searched on a grid, not guessed.
5. Every candidate extends the rig model (its parameters map onto the rig's
   fields; a contact's gap and stiffness are then refined by simulation error
   on the training segment), is simulated over the test segment, and scored by its gain
   1 - NRMSE_extended / NRMSE_baseline. Candidates gaining more than
   ``gain_floor`` are findings, best first; none means "nothing found".

Catalogue implemented here: ``contact`` (gap [m], side both|positive|negative,
stiffness_per_mass [1/s^2]), ``cubic_stiffness`` (coefficient_per_mass
[1/(m^2 s^2)], positive hardens), ``coulomb_friction`` (force_per_mass
[m/s^2]), ``quadratic_damping`` (coefficient_per_mass [1/m]),
``linear_mismatch`` (stiffness_per_mass, damping_per_mass offsets), and the
sensor effects, fitted by comparing the nominal simulation with the
measurement on the training segment: ``sensor_gain`` (gain_error, 0.05 = reads
5 % high), ``sensor_offset`` (offset_m_per_s2), ``clipping`` (range_m_per_s2,
recognised by samples piled at a channel's extreme value).
Not yet: ``quadratic_stiffness`` (the rig model has no such term).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .filters import lowpass_zero_phase
from .physical import edge_samples, integrate_band
from .rig import FRICTION_V_EPS, Beam, RigParams, simulate_measured_base

EFFECTS = ("contact", "cubic_stiffness", "coulomb_friction", "quadratic_damping", "linear_mismatch", "sensor_gain",
           "sensor_offset", "clipping")
CLIP_SHARE = 0.002  # a channel is clipped when this share of its samples sits at its extreme value
GAIN_FLOOR = 0.05


@dataclass(frozen=True)
class Candidate:
    effect: str
    response: str  # tip1 or tip2
    parameters: dict
    params: RigParams  # the extended rig
    fit_r2: float  # share of the residual force variance the terms explain (training)
    output: tuple = ()  # sensor effects: (channel index 0/1, kind, value) applied to the simulated tips
    test_nrmse: float = np.nan
    gain: float = np.nan


@dataclass(frozen=True)
class Discovery:
    baseline_test_nrmse: float
    extended_test_nrmse: float
    gain: float
    findings: list[Candidate]
    candidates: list[Candidate]  # all, ranked by gain
    extended: RigParams
    nominal: RigParams
    extended_output: tuple  # sensor effects of the extended model (applied to its simulated tips)
    train: slice
    test: slice
    residual_rms: dict[str, float] = field(default_factory=dict)  # per response, m/s^2, training


def _beam_rhs(p: RigParams, i: int, z: np.ndarray, v: np.ndarray, base: np.ndarray) -> np.ndarray:
    """Relative acceleration the rig model predicts for beam i on measured states (N, 2)."""
    vec = p.vector()
    o = 10 * i
    w2, c, kc, gp, gn, ks, cs, k3, fc, cq = vec[o:o + 10]
    zi, vi, zj = z[:, i], v[:, i], z[:, 1 - i]
    f = w2 * zi + c * vi + kc * (zi - zj) + k3 * zi**3 + fc * np.tanh(vi / FRICTION_V_EPS) + cq * vi * np.abs(vi)
    pos = zi > gp
    neg = zi < -gn
    fs_pos = np.where(pos, ks * (zi - gp) + cs * vi, 0.0)
    fs_neg = np.where(neg, ks * (zi + gn) + cs * vi, 0.0)
    f = f + np.maximum(fs_pos, 0.0) + np.minimum(fs_neg, 0.0)
    return -f - base


def coordinates(values: np.ndarray, fs_hz: float, f_lo_hz: float = 2.0):
    """Base (N,) and tips (N, 2) below 50 Hz (for scoring), and full-band z, v, r (N, 2).

    The regression uses the full band: a stopper's force is an impulse ringing
    well above 50 Hz, and a low-pass smears it into something a cubic fits as well.
    """
    lp = lowpass_zero_phase(values, fs_hz, min(50.0, 0.45 * fs_hz))
    full = lowpass_zero_phase(values, fs_hz, 0.45 * fs_hz)  # anti-alias only
    r = full[:, 1:] - full[:, :1]
    v, z = integrate_band(r, fs_hz, f_lo_hz)
    return lp[:, 0], lp[:, 1:], z, v, r, full[:, 0]


def lsq1(h: np.ndarray, d: np.ndarray) -> tuple[float, float]:
    """Least-squares a in d ~ a h, and the share of d's energy it explains (r2)."""
    hh = float(h @ h)
    if hh <= 0:
        return 0.0, 0.0
    a = float(h @ d) / hh
    r2 = 1.0 - float(np.sum((d - a * h) ** 2)) / max(float(d @ d), 1e-300)
    return a, r2


def _with_beam(p: RigParams, i: int, **changes) -> RigParams:
    name = "beam1" if i == 0 else "beam2"
    return replace(p, **{name: replace(getattr(p, name), **changes)})


def contact_shape(z: np.ndarray, gap: float, side: str) -> np.ndarray:
    """Penetration beyond the stoppers: z - gap above +gap, z + gap below -gap (per side)."""
    h = np.zeros_like(z)
    if side in ("both", "positive"):
        h += np.maximum(z - gap, 0.0)
    if side in ("both", "negative"):
        h += np.minimum(z + gap, 0.0)
    return h


def best_contact(z: np.ndarray, d: np.ndarray, n_grid: int = 84) -> tuple[str, float, float, float] | None:
    """Search side and gap (a grid over 15-98 % of the largest |z|), stiffness by least squares:
    d ~ -k h(z); returns (side, gap, k per mass, r2) of the best fit with k > 0, or None."""
    best = None
    for side in ("both", "positive", "negative"):
        for g in np.linspace(0.15, 0.98, n_grid) * float(np.max(np.abs(z))):
            h = contact_shape(z, g, side)
            if not np.any(h):
                continue
            a, r2 = lsq1(-h, d)
            if a > 0 and (best is None or r2 > best[3]):
                best = (side, float(g), a, r2)
    return best


def fit_candidates(p: RigParams, i: int, z: np.ndarray, v: np.ndarray, d: np.ndarray) -> list[Candidate]:
    """Least-squares fit of every cause's terms to the residual force d of beam i."""
    b: Beam = p.beam1 if i == 0 else p.beam2
    m = b.mass_kg
    zi, vi = z[:, i], v[:, i]
    resp = f"tip{i + 1}"
    out = []
    found = best_contact(zi, d)
    if found is not None:
        side, g, a, r2 = found
        gp = g if side in ("both", "positive") else np.inf
        gn = g if side in ("both", "negative") else np.inf
        out.append(Candidate("contact", resp, {"gap": float(g), "side": side, "stiffness_per_mass": float(a)},
                             _with_beam(p, i, gap_pos_m=gp, gap_neg_m=gn, stopper_stiffness_n_per_m=a * m,
                                        stopper_damping_n_s_per_m=0.0), r2))
    a, r2 = lsq1(-zi**3, d)
    out.append(Candidate("cubic_stiffness", resp, {"coefficient_per_mass": a},
                         _with_beam(p, i, cubic_stiffness_n_per_m3=b.cubic_stiffness_n_per_m3 + a * m), r2))
    a, r2 = lsq1(-np.tanh(vi / FRICTION_V_EPS), d)
    if a > 0:
        out.append(Candidate("coulomb_friction", resp, {"force_per_mass": a},
                             _with_beam(p, i, coulomb_friction_n=b.coulomb_friction_n + a * m), r2))
    a, r2 = lsq1(-vi * np.abs(vi), d)
    if a > 0:
        out.append(Candidate("quadratic_damping", resp, {"coefficient_per_mass": a},
                             _with_beam(p, i, quadratic_damping_n_s2_per_m2=b.quadratic_damping_n_s2_per_m2 + a * m),
                             r2))
    H = -np.column_stack([zi, vi])
    coef = np.linalg.lstsq(H, d, rcond=None)[0]
    r2 = 1.0 - float(np.sum((d - H @ coef) ** 2)) / max(float(d @ d), 1e-300)
    k_new = b.stiffness_n_per_m / m + coef[0]
    c_new = b.damping_n_s_per_m / m + coef[1]
    if k_new > 0 and c_new >= 0:
        fn = float(np.sqrt(k_new) / (2 * np.pi))
        zeta = float(c_new / (2 * np.sqrt(k_new)))
        out.append(Candidate("linear_mismatch", resp, {"stiffness_per_mass": float(coef[0]),
                                                       "damping_per_mass": float(coef[1])},
                             _with_beam(p, i, natural_frequency_hz=fn, damping_ratio=zeta), r2))
    return out


def simulated_tips(p: RigParams, values: np.ndarray, fs: float, seg: slice, output: tuple = ()):
    """(measured tips, simulated tips) below 50 Hz over ``seg``, the rig driven by the measured base."""
    base, tips, z, v, _, _ = coordinates(values, fs)
    pred = lowpass_zero_phase(_simulated_tips(p, base, z, v, fs, seg, output), fs, min(50.0, 0.45 * fs))
    return tips[seg], pred


def _simulated_tips(p: RigParams, base: np.ndarray, z: np.ndarray, v: np.ndarray, fs: float, seg: slice,
                    output: tuple = ()) -> np.ndarray:
    """Tip accelerations of the rig over ``seg`` from the measured state, sensor effects applied."""
    st = np.array([z[seg.start, 0], z[seg.start, 1], v[seg.start, 0], v[seg.start, 1]])
    sim = simulate_measured_base(p, base[seg], fs, state=st)
    pred = np.column_stack([sim.tip1, sim.tip2])
    for ch, kind, value in output:
        if kind == "gain":
            pred[:, ch] *= 1.0 + value
        elif kind == "offset":
            pred[:, ch] += value
        elif kind == "clip":
            pred[:, ch] = np.clip(pred[:, ch], -value, value)
    return pred


def _test_error(p: RigParams, base: np.ndarray, tips: np.ndarray, z: np.ndarray, v: np.ndarray, fs: float,
                test: slice, output: tuple = ()) -> float:
    pred = _simulated_tips(p, base, z, v, fs, test, output)
    if not np.all(np.isfinite(pred)):
        return np.inf
    pred = lowpass_zero_phase(pred, fs, min(50.0, 0.45 * fs))
    meas = tips[test]
    return float(np.mean(np.sqrt(np.mean((pred - meas) ** 2, axis=0)) / meas.std(axis=0)))


def refine_contact(c: Candidate, i: int, base, tips, z, v, fs: float, train: slice, seconds: float = 8.0,
                   max_evals: int = 40) -> Candidate:
    """Refine a contact's gap and stiffness by simulation error on (part of) the training segment.

    The least-squares stiffness is low: displacement from integrated accelerations is smoothed
    during millisecond contacts. Nelder-Mead on (gap, log stiffness) against the measured tips.
    """
    from scipy.optimize import minimize

    seg = slice(train.start, min(train.stop, train.start + int(seconds * fs)))
    name = "beam1" if i == 0 else "beam2"
    beam = getattr(c.params, name)
    m = beam.mass_kg
    g0 = float(c.parameters["gap"])
    k0 = max(float(c.parameters["stiffness_per_mass"]), 1.0)
    side = c.parameters["side"]

    def params_for(x):
        g, k = g0 * x[0], k0 * np.exp(x[1])
        return replace(c.params, **{name: replace(beam, gap_pos_m=g if side != "negative" else np.inf,
                                                  gap_neg_m=g if side != "positive" else np.inf,
                                                  stopper_stiffness_n_per_m=k * m)}), g, k

    def err(x):
        if not 0.5 < x[0] < 1.5 or abs(x[1]) > 6:
            return 1e9
        return _test_error(params_for(x)[0], base, tips, z, v, fs, seg)

    res = minimize(err, np.array([1.0, 1.0]), method="Nelder-Mead",
                   options={"maxfev": max_evals, "xatol": 1e-3, "fatol": 1e-4})
    x = res.x if res.fun <= err(np.array([1.0, 0.0])) else np.array([1.0, 0.0])
    p, g, k = params_for(x)
    return replace(c, params=p, parameters={"gap": float(g), "side": side, "stiffness_per_mass": float(k)})


def sensor_candidates(p: RigParams, base, tips, raw_tips, z, v, fs: float, train: slice) -> list[Candidate]:
    """Output effects, from the nominal simulation against the measurement on the training segment:
    gain error (least-squares scale), offset (mean difference), clipping (samples piled at the extreme)."""
    pred = lowpass_zero_phase(_simulated_tips(p, base, z, v, fs, train), fs, min(50.0, 0.45 * fs))
    out = []
    for ch in range(2):
        meas, sim = tips[train, ch], pred[:, ch]
        resp = f"tip{ch + 1}"
        g = float(sim @ meas / max(sim @ sim, 1e-300)) - 1.0
        out.append(Candidate("sensor_gain", resp, {"gain_error": g}, p, 0.0, ((ch, "gain", g),)))
        o = float(np.mean(meas - sim))
        out.append(Candidate("sensor_offset", resp, {"offset_m_per_s2": o}, p, 0.0, ((ch, "offset", o),)))
        x = raw_tips[:, ch]
        top = float(np.max(np.abs(x)))
        at_top = np.mean(np.abs(x) >= top * (1 - 1e-6))
        if at_top >= CLIP_SHARE:
            out.append(Candidate("clipping", resp, {"range_m_per_s2": top}, p, 0.0, ((ch, "clip", top),)))
    return out


def split(n: int, edge: int, train: slice | None, test: slice | None) -> tuple[slice, slice]:
    """Training and held-out segments; default the first 60 % and the last 40 %, integration edges cut."""
    if n < 10 * edge:
        raise ValueError(f"{n} samples are too few for discovery; need at least {10 * edge}")
    cut = int(0.6 * n)
    train = train or slice(edge, cut)
    test = test or slice(cut, n - edge)
    return (slice(max(train.start or 0, edge), min(train.stop or n, n - edge)),
            slice(max(test.start or 0, edge), min(test.stop or n, n - edge)))


def discover(values: np.ndarray, fs_hz: float, nominal: RigParams, *, train: slice | None = None,
             test: slice | None = None, gain_floor: float = GAIN_FLOOR) -> Discovery:
    """Find what the nominal rig model misses in measured (N, 3) accelerations base, tip1, tip2."""
    values = np.asarray(values, float)
    if values.ndim != 2 or values.shape[1] != 3:
        raise ValueError(f"expected accelerations base, tip1, tip2 as (N, 3), got {values.shape}")
    if not np.all(np.isfinite(values)):
        raise ValueError("data contain NaN or inf: repair or remove those samples first")
    tr, te = split(len(values), edge_samples(fs_hz, 2.0), train, test)
    base, tips, z, v, r, base_full = coordinates(values, fs_hz)
    base_err = _test_error(nominal, base, tips, z, v, fs_hz, te)
    cands, resid = [], {}
    for i in range(2):
        d = r[tr, i] - _beam_rhs(nominal, i, z[tr], v[tr], base_full[tr])
        resid[f"tip{i + 1}"] = float(np.sqrt(np.mean(d**2)))
        for c in fit_candidates(nominal, i, z[tr], v[tr], d):
            if c.effect == "contact":
                c = refine_contact(c, i, base, tips, z, v, fs_hz, tr)
            cands.append(c)
    cands += sensor_candidates(nominal, base, tips, values[:, 1:], z, v, fs_hz, tr)
    scored = []
    for c in cands:
        err = _test_error(c.params, base, tips, z, v, fs_hz, te, c.output)
        gain = 1.0 - err / base_err if np.isfinite(err) and base_err > 0 else -np.inf
        scored.append(replace(c, test_nrmse=err, gain=gain))
    scored.sort(key=lambda c: -c.gain)
    findings = []
    ext = nominal
    ext_out: tuple = ()
    for resp in ("tip1", "tip2"):
        best = next((c for c in scored if c.response == resp), None)
        if best is not None and best.gain > gain_floor:
            findings.append(best)
            i = int(resp[-1]) - 1
            name = "beam1" if i == 0 else "beam2"
            ext = replace(ext, **{name: getattr(best.params, name)})
            ext_out += best.output
    findings.sort(key=lambda c: -c.gain)
    ext_err = _test_error(ext, base, tips, z, v, fs_hz, te, ext_out) if findings else base_err
    return Discovery(base_err, ext_err, 1.0 - ext_err / base_err if base_err > 0 else 0.0, findings, scored,
                     ext, nominal, ext_out, tr, te, resid)


# --- hidden-effect cases: the tests' and the benchmark's generator ---------------------------

HIDDEN = ("none", "contact", "cubic_stiffness", "coulomb_friction", "quadratic_damping", "sensor_gain",
          "sensor_offset", "clipping")


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
    from .excitation import Excitation, Step, Sweep
    from .rig import RigConfig, simulate_rig

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
    elif effect == "coulomb_friction":
        fc = float(rng.uniform(0.01, 0.04))
        truth = {"force_per_mass": fc / m}
        changes = {"coulomb_friction_n": fc}
    elif effect == "quadratic_damping":
        cq = float(rng.uniform(0.2, 1.0))
        truth = {"coefficient_per_mass": cq / m}
        changes = {"quadratic_damping_n_s2_per_m2": cq}
    truth_params = _with_beam(nom, beam - 1, **changes) if changes else nom
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
