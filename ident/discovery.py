"""Model discovery against the rig model: what the simulation gets wrong, the cause, the gain.

Steps (Kaheman et al. 2019, "Learning discrepancy models from experimental
data", in physical coordinates):

0. Split: by default the record in 10 equal blocks, the 3rd, 5th, 8th and
   10th held out (``interleaved_split``), so training and held-out data both
   see every amplitude step and sweep frequency; or the user's slices.
1. Baseline: the rig model with nominal parameters, driven by the *measured*
   base acceleration, simulated over each held-out block from the measured
   state five decay times before it (``warm_up_s``); its error is the NRMSE
   of the tip accelerations below 50 Hz.
2. Physical coordinates: relative acceleration r = tip - base, band-limited
   integration to v and z (ident.physical).
3. Residual force per mass on the training data: d = r - r_nominal(z, v, base),
   r_nominal the nominal model's right-hand side evaluated on the measured states.
4. Each cause in the catalogue is a set of terms with physical parameters,
   fitted to d by least squares; nonlinear parameters (the gap, the side)
   are searched on a grid, not guessed, with a constant that undoes the mean
   integration removed (``best_contact``).
5. Every candidate extends the rig model (``extended_rig``). A contact's side,
   gap and stiffness are refined by simulation error on the training data
   where the stopper is hit; after a first scoring, the other causes close to
   a response's best are refined the same way (``refine``). Each is simulated
   over the held-out blocks and scored by its gain 1 - NRMSE_extended /
   NRMSE_baseline. Per response the simplest cause within ``PARSIMONY`` of the
   best gain is chosen; it is a finding if it gains more than ``gain_floor``.
   No finding means "nothing found".

Catalogue implemented here: ``contact`` (gap [m], side both|positive|negative,
stiffness_per_mass [1/s^2]), ``cubic_stiffness`` (coefficient_per_mass
[1/(m^2 s^2)], positive hardens), ``quadratic_stiffness`` (coefficient_per_mass
[1/(m s^2)] of a force k2 z|z|, positive hardens), ``coulomb_friction`` (force_per_mass
[m/s^2]), ``quadratic_damping`` (coefficient_per_mass [1/m]),
``linear_mismatch`` (stiffness_per_mass, damping_per_mass offsets), and the
sensor effects, fitted by comparing the nominal simulation with the
measurement on the training data: ``sensor_gain`` (gain_error, 0.05 = reads
5 % high), ``sensor_offset`` (offset_m_per_s2), ``clipping`` (range_m_per_s2,
recognised by samples piled at a channel's extreme value).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .filters import lowpass_zero_phase
from .physical import edge_samples, integrate_band
from .rig import FRICTION_V_EPS, N_PER_BEAM, TWO_PI, Beam, RigParams, simulate_measured_base

# the causes that change the rig's equations, then those that act on the sensors
MECHANICAL = ("contact", "cubic_stiffness", "quadratic_stiffness", "coulomb_friction", "quadratic_damping",
              "linear_mismatch")
EFFECTS = MECHANICAL + ("sensor_gain", "sensor_offset", "clipping")
CLIP_SHARE = 0.002  # a channel is clipped when this share of its samples sits at its extreme value
GAIN_FLOOR = 0.05
CONTACT_R2 = 0.05  # a contact explaining less of the residual force is not refined (nor named, in practice)
REFINE_WITHIN = 0.15  # candidates this close to a response's best gain are refined before the choice
SCAN = tuple(np.linspace(0.4, 1.6, 31))  # gap factors a contact's refinement scans before polishing
PARSIMONY = 0.02  # gains closer than this to the best do not justify more parameters


Segments = tuple[slice, ...]  # training or held-out data: one slice, or interleaved blocks
N_BLOCKS = 10  # the default split: the record in this many equal blocks ...
HELD_OUT = (2, 4, 7, 9)  # ... of which these (0-based) are held out: 40 %, spread over the record


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
    train: Segments
    test: Segments
    residual_rms: dict[str, float] = field(default_factory=dict)  # per response, m/s^2, training


def _beam_rhs(p: RigParams, i: int, z: np.ndarray, v: np.ndarray, base: np.ndarray) -> np.ndarray:
    """Relative acceleration the rig model predicts for beam i on measured states (N, 2)."""
    vec = p.vector()
    o = N_PER_BEAM * i
    w2, c, kc, gp, gn, ks, cs, k3, fc, cq, k2 = vec[o:o + N_PER_BEAM]
    zi, vi, zj = z[:, i], v[:, i], z[:, 1 - i]
    f = w2 * zi + c * vi + kc * (zi - zj) + k3 * zi**3 + k2 * zi * np.abs(zi) + fc * np.tanh(vi / FRICTION_V_EPS)
    f = f + cq * vi * np.abs(vi)
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


def _linear_per_mass(p: RigParams, i: int) -> float:
    """Beam i's linear restoring force per unit displacement and mass (w^2 + coupling), 1/s^2."""
    vec = p.vector()
    return float(vec[N_PER_BEAM * i] + vec[N_PER_BEAM * i + 2])


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


def best_contact(z: np.ndarray, d: np.ndarray, n_grid: int = 84,
                 sides: tuple[str, ...] = ("both", "positive", "negative"),
                 linear_per_mass: float = 0.0) -> tuple[str, float, float, float] | None:
    """Search side and gap (a grid over 15-98 % of the largest |z|), stiffness by least squares:
    d ~ -k h(z); returns (side, gap, k per mass, r2) of the best fit with k > 0, or None.

    With ``linear_per_mass`` (the nominal w^2 + coupling, 1/s^2) a constant is fitted as well. It
    undoes the mean that band-limited integration removes from z: a one-sided stopper makes the
    true motion's mean nonzero, so z is offset by some z0, the nominal restoring force on it puts
    -w^2 z0 into d, and the gap seen in z is off by z0. The returned one-sided gap is corrected.
    """
    best = None
    n, sd, dd = float(len(z)), float(d.sum()), float(d @ d)
    for side in sides:
        for g in np.linspace(0.15, 0.98, n_grid) * float(np.max(np.abs(z))):
            h = contact_shape(z, g, side)
            if not np.any(h):
                continue
            if linear_per_mass > 0:  # d ~ -a h + c, normal equations of the two columns
                hh, hs, hd = float(h @ h), float(h.sum()), float(h @ d)
                a, c = np.linalg.solve([[hh, -hs], [-hs, n]], [-hd, sd])
                sse = dd - 2 * (-a * hd + c * sd) + a * a * hh - 2 * a * c * hs + c * c * n
                r2 = 1.0 - sse / max(dd, 1e-300)
                z0 = -c / linear_per_mass
                gap = g + z0 if side == "positive" else g - z0 if side == "negative" else g
            else:
                a, r2 = lsq1(-h, d)
                gap = g
            if a > 0 and gap > 0 and (best is None or r2 > best[3]):
                best = (side, float(gap), float(a), r2)
    return best


def extended_rig(p: RigParams, i: int, effect: str, parameters: dict) -> RigParams | None:
    """The rig ``p`` with a mechanical cause (catalogue parameters, per mass) added to beam i; None
    when the parameters make no physical beam (a negative stiffness or damping)."""
    b: Beam = p.beam1 if i == 0 else p.beam2
    m = b.mass_kg
    x = parameters
    if effect == "contact":
        g, side = x["gap"], x["side"]
        return _with_beam(p, i, gap_pos_m=g if side != "negative" else np.inf,
                          gap_neg_m=g if side != "positive" else np.inf,
                          stopper_stiffness_n_per_m=x["stiffness_per_mass"] * m, stopper_damping_n_s_per_m=0.0)
    if effect == "cubic_stiffness":
        return _with_beam(p, i, cubic_stiffness_n_per_m3=b.cubic_stiffness_n_per_m3 + x["coefficient_per_mass"] * m)
    if effect == "quadratic_stiffness":
        return _with_beam(p, i, quadratic_stiffness_n_per_m2=b.quadratic_stiffness_n_per_m2
                          + x["coefficient_per_mass"] * m)
    if effect == "coulomb_friction":
        return _with_beam(p, i, coulomb_friction_n=b.coulomb_friction_n + x["force_per_mass"] * m)
    if effect == "quadratic_damping":
        return _with_beam(p, i, quadratic_damping_n_s2_per_m2=b.quadratic_damping_n_s2_per_m2
                          + x["coefficient_per_mass"] * m)
    if effect == "linear_mismatch":
        k_new = b.stiffness_n_per_m / m + x["stiffness_per_mass"]
        c_new = b.damping_n_s_per_m / m + x["damping_per_mass"]
        if k_new <= 0 or c_new < 0:
            return None
        return _with_beam(p, i, natural_frequency_hz=float(np.sqrt(k_new) / TWO_PI),
                          damping_ratio=float(c_new / (2 * np.sqrt(k_new))))
    raise ValueError(f"not a mechanical cause: {effect}")


def fit_candidates(p: RigParams, i: int, z: np.ndarray, v: np.ndarray, d: np.ndarray) -> list[Candidate]:
    """Least-squares fit of every cause's terms to the residual force d of beam i."""
    zi, vi = z[:, i], v[:, i]
    fits = []
    found = best_contact(zi, d, linear_per_mass=_linear_per_mass(p, i))
    if found is not None:
        side, g, a, r2 = found
        fits.append(("contact", {"gap": g, "side": side, "stiffness_per_mass": a}, r2))
    for effect, key, shape, positive in (("cubic_stiffness", "coefficient_per_mass", zi**3, False),
                                         ("quadratic_stiffness", "coefficient_per_mass", zi * np.abs(zi), False),
                                         ("coulomb_friction", "force_per_mass", np.tanh(vi / FRICTION_V_EPS), True),
                                         ("quadratic_damping", "coefficient_per_mass", vi * np.abs(vi), True)):
        a, r2 = lsq1(-shape, d)
        if a > 0 or not positive:
            fits.append((effect, {key: a}, r2))
    H = -np.column_stack([zi, vi])
    coef = np.linalg.lstsq(H, d, rcond=None)[0]
    r2 = 1.0 - float(np.sum((d - H @ coef) ** 2)) / max(float(d @ d), 1e-300)
    fits.append(("linear_mismatch", {"stiffness_per_mass": float(coef[0]), "damping_per_mass": float(coef[1])}, r2))
    out = []
    for effect, x, r2 in fits:
        rig = extended_rig(p, i, effect, x)
        if rig is not None:
            out.append(Candidate(effect, f"tip{i + 1}", x, rig, r2))
    return out


def refine(c: Candidate, i: int, nominal: RigParams, base, tips, z, v, fs: float, train: Segments,
           seconds: float = 12.0, max_evals: int = 24) -> Candidate:
    """Refine a mechanical cause's numeric parameters by simulation error on training data.

    The least-squares coefficients on the residual force are biased by the band-limited
    integration (displacement and velocity are smoothed, their mean removed); scaling each
    coefficient (log scale, within 0.5-2x) to minimise the tips' simulation error over the
    ``seconds`` of training data where beam i moves most removes most of that bias.
    """
    from scipy.optimize import minimize

    keys = [k for k, val in c.parameters.items() if isinstance(val, float) and val != 0.0]
    if not keys:
        return c
    segs = busiest(z[:, i] ** 2, train, int(seconds * fs))

    def params_at(x):
        return {**c.parameters, **{k: c.parameters[k] * float(np.exp(xk)) for k, xk in zip(keys, x)}}

    def err(x):
        if np.max(np.abs(x)) > 0.7:
            return 1e9
        rig = extended_rig(nominal, i, c.effect, params_at(x))
        return 1e9 if rig is None else _test_error(rig, base, tips, z, v, fs, segs)

    n = len(keys)
    simplex = np.vstack([np.zeros(n), 0.1 * np.eye(n)])
    res = minimize(err, np.zeros(n), method="Nelder-Mead",
                   options={"maxfev": max_evals, "xatol": 5e-3, "fatol": 1e-5, "initial_simplex": simplex})
    if res.fun >= err(np.zeros(n)):
        return c
    x = params_at(res.x)
    return replace(c, parameters=x, params=extended_rig(nominal, i, c.effect, x))


def simulated_tips(p: RigParams, base, tips, z, v, fs: float, segs: Segments, output: tuple = ()):
    """(measured tips, simulated tips) below 50 Hz over the segments, concatenated; the rig driven by
    the measured base and started ``warm_up_s`` before each segment from the measured state there.
    ``base, tips, z, v`` as ``coordinates`` returns them."""
    meas, pred = [], []
    for seg in segs:
        meas.append(tips[seg])
        pred.append(_simulated_tips(p, base, z, v, fs, seg, output))
    return np.concatenate(meas), np.concatenate(pred)


def warm_up_s(p: RigParams, most: float = 10.0) -> float:
    """Five time constants of the slower beam's free decay (at most ``most`` s): simulating this long
    before a segment makes the start state's error (integrated from measured accelerations) negligible."""
    tau = max(1.0 / max(b.damping_ratio * TWO_PI * b.natural_frequency_hz, 1e-9) for b in (p.beam1, p.beam2))
    return min(5.0 * tau, most)


def _simulated_tips(p: RigParams, base: np.ndarray, z: np.ndarray, v: np.ndarray, fs: float, seg: slice,
                    output: tuple = ()) -> np.ndarray:
    """Tip accelerations of the rig below 50 Hz over ``seg``, sensor effects applied; the simulation
    starts ``warm_up_s`` earlier (or at the record's start) from the measured state there."""
    start = max(0, seg.start - int(warm_up_s(p) * fs))
    st = np.array([z[start, 0], z[start, 1], v[start, 0], v[start, 1]])
    sim = simulate_measured_base(p, base[start:seg.stop], fs, state=st)
    pred = np.column_stack([sim.tip1, sim.tip2])
    for ch, kind, value in output:
        if kind == "gain":
            pred[:, ch] *= 1.0 + value
        elif kind == "offset":
            pred[:, ch] += value
        elif kind == "clip":
            pred[:, ch] = np.clip(pred[:, ch], -value, value)
    if not np.all(np.isfinite(pred)):
        return pred[seg.start - start:]
    return lowpass_zero_phase(pred, fs, min(50.0, 0.45 * fs))[seg.start - start:]


def _test_error(p: RigParams, base: np.ndarray, tips: np.ndarray, z: np.ndarray, v: np.ndarray, fs: float,
                test: Segments, output: tuple = ()) -> float:
    """NRMSE of the tips below 50 Hz over the segments (mean over the two tips); inf if it diverges."""
    meas, pred = simulated_tips(p, base, tips, z, v, fs, test, output)
    if not np.all(np.isfinite(pred)):
        return np.inf
    return float(np.mean(np.sqrt(np.mean((pred - meas) ** 2, axis=0)) / meas.std(axis=0)))


def busiest(weight: np.ndarray, segs: Segments, n: int) -> Segments:
    """Windows inside ``segs``, about ``n`` samples together, where ``weight`` (per sample: contact
    or not, squared displacement) sums highest: the best window of up to ``n`` samples in each
    segment, the busiest first, until they hold ``n`` samples. Under a sweep these are the
    resonance passage, not a segment's start."""
    found = []
    for seg in segs:
        m = min(n, seg.stop - seg.start)
        acc = np.concatenate([[0.0], np.cumsum(weight[seg])])
        sums = acc[m:] - acc[:-m]
        k = int(np.argmax(sums))
        found.append((-float(sums[k]), seg.start + k, m))
    out, total = [], 0
    for _, start, m in sorted(found):
        out.append(slice(start, start + m))
        total += m
        if total >= n:
            break
    return tuple(sorted(out, key=lambda s: s.start))


def refine_contact(c: Candidate, i: int, nominal: RigParams, base, tips, z, v, d, fs: float, train: Segments,
                   seconds: float = 8.0, max_evals: int = 80) -> Candidate:
    """Refine a contact's side, gap and stiffness by simulation error on training data where it is hit.

    The least-squares fit is biased twice: displacement from integrated accelerations is smoothed
    during millisecond contacts (stiffness low), and its mean is removed, which shifts a one-sided
    stopper's apparent gap and can make it look two-sided. So each side starts from its own
    least-squares gap, scans the gap (``SCAN``) on the busiest 2 s, and the two sides that
    scan best are polished by Nelder-Mead on (gap, log stiffness) against the measured tips over
    the ``seconds`` of training data with the most samples beyond the gap; the side with the
    smallest simulation error is kept.
    """
    from scipy.optimize import minimize

    zi = z[indices(train), i]
    hit_weight = (np.abs(z[:, i]) > float(c.parameters["gap"])).astype(float)
    segs = busiest(hit_weight, train, int(seconds * fs))
    short = busiest(hit_weight, train, int(2 * fs))
    starts = []
    for side in ("both", "positive", "negative"):
        found = best_contact(zi, d, sides=(side,), linear_per_mass=_linear_per_mass(nominal, i))
        if found is None:
            continue
        _, g0, k0, _ = found
        k0 = max(k0, 1.0)

        def params_at(x, side=side, g0=g0, k0=k0):
            return {"gap": float(g0 * x[0]), "side": side, "stiffness_per_mass": float(k0 * np.exp(x[1]))}

        def err(x, params_at=params_at, on=segs):
            if not 0.3 < x[0] < 1.7 or abs(x[1]) > 6:
                return 1e9
            return _test_error(extended_rig(nominal, i, "contact", params_at(x)), base, tips, z, v, fs, on)

        # A stiff stopper under random excitation makes the error a narrow valley in the gap (impacts
        # decide the trajectory): scan the gap on the busiest 2 s first ...
        e1, g1 = min((err(np.array([f, 1.0]), on=short), f) for f in SCAN)
        starts.append((e1, g1, params_at, err))
    best = None
    for _, g1, params_at, err in sorted(starts, key=lambda s: s[0])[:2]:  # ... then polish the two best sides
        # from the scan's point or the regression's, whichever fits the polishing window better; the
        # simplex spans 3 % in the gap and a factor e^1.5 in stiffness (uncertain by orders of magnitude),
        # restarted once because a fresh simplex follows the long gap-stiffness valley further
        x = min((np.array([g1, 1.0]), np.array([1.0, 0.0]), np.array([1.0, 1.0])), key=err)
        for step in (1.5, 0.7):
            res = minimize(err, x, method="Nelder-Mead",
                           options={"maxfev": max_evals // 2, "xatol": 1e-3, "fatol": 1e-5,
                                    "initial_simplex": [x, x * (1.03, 1), x + (0.0, step)]})
            x = res.x
        e = float(res.fun)
        if best is None or e < best[0]:
            best = (e, params_at(x))
    x = best[1]
    return replace(c, params=extended_rig(nominal, i, "contact", x), parameters=x)


def sensor_candidates(p: RigParams, base, tips, raw_tips, z, v, fs: float, train: Segments) -> list[Candidate]:
    """Output effects, from the nominal simulation against the measurement on the training segment:
    gain error (least-squares scale), offset (mean difference), clipping (samples piled at the extreme)."""
    meas_all, pred = simulated_tips(p, base, tips, z, v, fs, train)
    out = []
    for ch in range(2):
        meas, sim = meas_all[:, ch], pred[:, ch]
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


def _check_length(n: int, edge: int) -> None:
    if n < 10 * edge:
        raise ValueError(f"{n} samples are too few for discovery; need at least {10 * edge}")


def split(n: int, edge: int, train: slice | None, test: slice | None) -> tuple[slice, slice]:
    """Training and held-out segments; default the first 60 % and the last 40 %, integration edges cut."""
    _check_length(n, edge)
    cut = int(0.6 * n)
    train = train or slice(edge, cut)
    test = test or slice(cut, n - edge)
    return (slice(max(train.start or 0, edge), min(train.stop or n, n - edge)),
            slice(max(test.start or 0, edge), min(test.stop or n, n - edge)))


def interleaved_split(n: int, edge: int, train: slice | None = None,
                      test: slice | None = None) -> tuple[Segments, Segments]:
    """Training and held-out data for the rig path.

    Given slices are used as ``split`` uses them (one segment each). The default cuts the record
    (integration edges removed) into ``N_BLOCKS`` equal blocks and holds out the 3rd, 5th, 8th and
    10th: both parts then see the whole test (every amplitude step, every sweep frequency), so an
    effect that acts only near a resonance is not all in one part.
    """
    if train is not None or test is not None:
        tr, te = split(n, edge, train, test)
        return (tr,), (te,)
    _check_length(n, edge)
    b = np.linspace(edge, n - edge, N_BLOCKS + 1).astype(int)
    train: list[slice] = []
    for k in range(N_BLOCKS):
        if k in HELD_OUT:
            continue
        if train and train[-1].stop == b[k]:  # adjacent training blocks are one segment
            train[-1] = slice(train[-1].start, int(b[k + 1]))
        else:
            train.append(slice(int(b[k]), int(b[k + 1])))
    return tuple(train), tuple(slice(int(b[k]), int(b[k + 1])) for k in HELD_OUT)


def indices(segs: Segments) -> np.ndarray:
    return np.concatenate([np.arange(s.start, s.stop) for s in segs])


def simplest_of_best(cands: list[Candidate], tolerance: float = PARSIMONY) -> Candidate | None:
    """The candidate with the fewest parameters among those within ``tolerance`` of the best gain
    (ties by gain): a three-parameter contact must beat a one-parameter stiffness by more than
    noise does. ``cands`` sorted by gain, best first."""
    if not cands:
        return None
    near = [c for c in cands if c.gain >= cands[0].gain - tolerance]
    return min(near, key=lambda c: len(c.parameters))


def discover(values: np.ndarray, fs_hz: float, nominal: RigParams, *, train: slice | None = None,
             test: slice | None = None, gain_floor: float = GAIN_FLOOR) -> Discovery:
    """Find what the nominal rig model misses in measured (N, 3) accelerations base, tip1, tip2."""
    values = np.asarray(values, float)
    if values.ndim != 2 or values.shape[1] != 3:
        raise ValueError(f"expected accelerations base, tip1, tip2 as (N, 3), got {values.shape}")
    if not np.all(np.isfinite(values)):
        raise ValueError("data contain NaN or inf: repair or remove those samples first")
    tr, te = interleaved_split(len(values), edge_samples(fs_hz, 2.0), train, test)
    itr = indices(tr)
    base, tips, z, v, r, base_full = coordinates(values, fs_hz)
    base_err = _test_error(nominal, base, tips, z, v, fs_hz, te)
    cands, resid = [], {}
    for i in range(2):
        d = r[itr, i] - _beam_rhs(nominal, i, z[itr], v[itr], base_full[itr])
        resid[f"tip{i + 1}"] = float(np.sqrt(np.mean(d**2)))
        for c in fit_candidates(nominal, i, z[itr], v[itr], d):
            if c.effect == "contact" and c.fit_r2 >= CONTACT_R2:
                c = refine_contact(c, i, nominal, base, tips, z, v, d, fs_hz, tr)
            cands.append(c)
    cands += sensor_candidates(nominal, base, tips, values[:, 1:], z, v, fs_hz, tr)

    def score(c: Candidate) -> Candidate:
        err = _test_error(c.params, base, tips, z, v, fs_hz, te, c.output)
        return replace(c, test_nrmse=err, gain=1.0 - err / base_err if np.isfinite(err) and base_err > 0 else -np.inf)

    cands = sorted(map(score, cands), key=lambda c: -c.gain)
    # the leading mechanical causes of each response (a contact is refined already) are refined by
    # simulation error too, so that they compete on equal terms, then scored again
    lead = {resp: max((c.gain for c in cands if c.response == resp), default=-np.inf) for resp in ("tip1", "tip2")}
    scored = sorted((score(refine(c, int(c.response[-1]) - 1, nominal, base, tips, z, v, fs_hz, tr))
                     if c.effect in MECHANICAL and c.effect != "contact" and c.gain > gain_floor
                     and c.gain >= lead[c.response] - REFINE_WITHIN else c for c in cands), key=lambda c: -c.gain)
    findings = []
    ext = nominal
    ext_out: tuple = ()
    for resp in ("tip1", "tip2"):
        best = simplest_of_best([c for c in scored if c.response == resp])
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
