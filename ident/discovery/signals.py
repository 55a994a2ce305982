"""Measured data as recorded, and what discovery makes of it before any model: the analysis band, sign
conventions, and every response's displacement, velocity and acceleration.

Any shape a lab records: the excitation a force, a base (frame) acceleration or an amplifier voltage;
responses displacements, velocities or accelerations in any mix; one sensor or many; a 1 s hammer hit or
hours of shaking. Nothing is assumed about the band: it comes from where the input and the responses
carry power (``preliminary_band``) and, once modes are known, from the modes (``modal_band``).

Signs. A response whose sign is opposite to the physics (an accelerometer upside down, a laser's axis
against the force) is recognised from frequency responses and flipped, and the report says so:
- under a force, a driving-point response is passive, Re(mobility) >= 0 at every frequency, so its
  receptance has Im H <= 0 across the band; a response with Im H > 0 across the band is a driving
  point read with the opposite sign (Ewins, "Modal Testing", 2000, sec. 2.5). A transfer point reads the
  same in every mode whose shape has one sign at it and at the driving point, so the driving point is the
  response that alone reads as one at every resonance carrying its power. Where several do (a chain driven
  near its first mode, all masses in phase), the record does not say which is driven: the most one-sided is
  taken, the report names the others (``Prepared.driving_alike``), and a modal baseline takes its
  reciprocity through whichever of them explains most (``discover._reciprocity``);
- under a shaken frame, a tip moving in its first mode has absolute acceleration a_b (1 - i / (2 zeta))
  at resonance, so Im(a_tip / a_b) < 0 at the lowest resonance; > 0 is a flipped sensor. Where that
  resonance does not say (a stopper struck through the record smears it), below every mode a tip moves
  with the frame, Re(a_tip / a_b) > 0, and < 0 there is a flipped sensor (``_below_resonance``).
Responses that are neither (transfer points) keep their sign; a pair of them is searched both as a
difference and as a sum, so an interface between two sensors is found whatever their conventions.

Kinematics are converted in the frequency domain on the whole record with one zero-phase band-pass
(Butterworth magnitudes, high-pass order 2 at the band's low edge, low-pass order 4 at its high edge),
so displacement, velocity and acceleration of every response are consistent with each other; the first
and last ``edge`` samples carry the filter's transients and are not analysed.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from scipy.fft import next_fast_len
from scipy.signal import coherence, csd, find_peaks, resample_poly, welch

EXCITATIONS = ("force", "base_acceleration", "voltage")
RESPONSES = ("displacement", "velocity", "acceleration")
MIN_CYCLES = 20  # the band's low edge holds at least this many periods in the record
# consecutive modes farther apart than this are two families: a cantilever's second bending mode lies at
# 6.27 times its first (more with a tip mass), a clamped-clamped beam's at 2.76, a chain's modes closer
FAMILY_GAP = 6.0
# samples x responses discovery analyses at most by default: its modal states and band-limited conversions
# are whole-record arrays, about 0.55 GB per million (stop 40: one hour of two accelerations at 1 kHz, 7.2
# million, peaked at 3.9 GB), so the default keeps a run near 3.5 GB
MAX_SAMPLES = 6_000_000
WORKING_RATE = 16.0  # a record decimated to fit the budget keeps at least this many samples per period of the
# preliminary band's top: the modal band (4.5 x the highest mode, below 0.45 fs) stays whole


@dataclass(frozen=True)
class Channel:
    name: str
    kind: str
    values: np.ndarray


@dataclass(frozen=True)
class Measurement:
    """One record: its sampling rate, the excitation and the responses (all the same length)."""

    fs_hz: float
    excitation: Channel
    responses: tuple[Channel, ...]
    start_s: float = 0.0  # where the first sample lies in the record it was taken from (an excerpt's offset)
    # runs where a channel held no number, bridged by interpolation (``bridged``): dropouts to discovery
    lost: tuple["Dropout", ...] = ()

    def __post_init__(self):
        if not (np.isfinite(self.fs_hz) and self.fs_hz > 0):
            raise ValueError(f"sampling rate must be a positive number of Hz, got {self.fs_hz}")
        if self.excitation.kind not in EXCITATIONS:
            raise ValueError(f"excitation {self.excitation.name!r}: kind {self.excitation.kind!r} is not one of "
                             f"{', '.join(EXCITATIONS)}")
        if not self.responses:
            raise ValueError("give at least one response")
        n = len(self.excitation.values)
        names = [self.excitation.name]
        for ch in self.responses:
            if ch.kind not in RESPONSES:
                raise ValueError(f"response {ch.name!r}: kind {ch.kind!r} is not one of {', '.join(RESPONSES)}")
            if len(ch.values) != n:
                raise ValueError(f"response {ch.name!r} has {len(ch.values)} samples, the excitation {n}")
            names.append(ch.name)
        if len(set(names)) != len(names):
            raise ValueError(f"a column is used twice: {names}")
        for ch in (self.excitation,) + self.responses:
            x = np.asarray(ch.values, float)
            if x.ndim != 1:
                raise ValueError(f"{ch.name!r} must be one column")
            bad = int(np.count_nonzero(~np.isfinite(x)))
            if bad:
                raise ValueError(f"{ch.name!r} holds {bad} NaN or inf samples: repair or cut them first")
            if np.ptp(x) == 0:
                if ch is self.excitation:
                    raise ValueError(f"the excitation {ch.name!r} is constant: nothing drove the structure")
                raise ValueError(f"response {ch.name!r} is constant (a dead or unplugged sensor?): leave it out "
                                 "(ident discover: name the responses to analyse with --response)")
        if n < 256:
            raise ValueError(f"{n} samples are too few for discovery; give at least 256")

    @property
    def n(self) -> int:
        return len(self.excitation.values)

    @property
    def names(self) -> list[str]:
        return [c.name for c in self.responses]

    @property
    def base_excited(self) -> bool:
        return self.excitation.kind == "base_acceleration"


def welch_segment(n: int, fs_hz: float, longest_s: float = 64.0) -> int:
    """Segment length of Welch estimates: a quarter of the record, a power of two, at most ``longest_s``."""
    return int(2 ** np.floor(np.log2(max(64, min(n // 4, fs_hz * longest_s)))))


def impulsive(u: np.ndarray) -> bool:
    """Is the excitation a transient (a hammer hit): 90 % of its energy within 5 % of the record?"""
    e = np.sort(np.asarray(u, float) ** 2)[::-1]
    k = max(1, int(0.05 * e.size))
    return bool(e[:k].sum() >= 0.9 * e.sum())


PAD_S = 0.002  # s: a hit's force window reaches this far on each side of it


def force_window(u: np.ndarray, fs_hz: float, pad_s: float = PAD_S) -> np.ndarray:
    """A hammer record's force with what its channel reads between the hits set to the quiet level (the
    median): the force window of impact testing (Ewins, "Modal Testing", 2000). Between hits the
    channel reads its sensor's noise, not a force: driven by it, a model moves where the structure does
    not (independent seed 101, a clamped-clamped beam: 7.3 s of a force channel's noise after the hit
    drove the baseline to ten times the response measured there). A hit is where the force stands
    above eight times the channel's noise (its median absolute deviation) and 1 % of the largest hit,
    widened by ``pad_s`` on each side."""
    u = np.asarray(u, float)
    w = max(1, int(round(pad_s * fs_hz)))
    near = np.convolve(hits(u).astype(float), np.ones(2 * w + 1), mode="same") > 0
    return np.where(near, u, float(np.median(u)))


def hits(u: np.ndarray) -> np.ndarray:
    """Where a hammer's force channel stands above eight times its noise (the median absolute deviation
    from its quiet level, the median) and 1 % of the largest hit: the samples of its hits."""
    x = np.asarray(u, float) - np.median(u)
    noise = 1.4826 * float(np.median(np.abs(x)))
    return np.abs(x) > max(8.0 * noise, 0.01 * float(np.max(np.abs(x))))


def rest_until(u: np.ndarray, Y: np.ndarray, quiet: float = 0.05) -> int | None:
    """A hammer record that starts at rest: the sample of its first hit, when before it every response
    (n, k) stays within ``quiet`` of its largest swing about its median; else None. Before such a
    record the structure was still: the record has no initial state, and the band-pass, which treats
    the record as preceded by nothing, is exact from its first sample on. A modal model's input gain is
    then fixed by the hit (``baselines.modal.Columns``); with an initial state fitted as well, the hit's
    forced response after it, a free decay, is one the initial state's free response fits as well."""
    at = np.flatnonzero(hits(u))
    if not at.size:
        return None
    first = int(at[0])
    Y = np.asarray(Y, float).reshape(len(u), -1)
    swing = np.abs(Y - np.median(Y, axis=0))
    if first and np.any(swing[:first].max(axis=0) > quiet * swing.max(axis=0)):
        return None
    return first


def frf(u: np.ndarray, Y: np.ndarray, fs_hz: float, nperseg: int | None = None
        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frequencies, FRF (k, nf) of responses per input, and the input's spectrum (PSD, or |U|^2 of a
    transient). H1 (Welch, segments of ``nperseg`` samples, by default ``welch_segment``'s) for a stationary
    input; for a hammer hit the whole record's spectra, Y / U."""
    u = np.asarray(u, float)
    Y = np.asarray(Y, float).reshape(len(u), -1)
    if impulsive(u):
        nfft = int(2 ** np.ceil(np.log2(len(u))))
        U = np.fft.rfft(u - u[: max(1, len(u) // 100)].mean(), nfft)
        f = np.fft.rfftfreq(nfft, 1 / fs_hz)
        Yf = np.fft.rfft(Y - Y.mean(axis=0), nfft, axis=0).T
        puu = np.abs(U) ** 2
        return f, Yf / np.where(puu > 0, U, np.inf), puu
    nper = min(nperseg, len(u)) if nperseg else welch_segment(len(u), fs_hz)
    f, puu = welch(u, fs_hz, nperseg=nper)
    H = np.array([csd(u, Y[:, i], fs_hz, nperseg=nper)[1] for i in range(Y.shape[1])])
    return f, H / np.where(puu > 0, puu, np.inf), puu


def miso_frf(inputs: np.ndarray, Y: np.ndarray, fs_hz: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Frequencies, the FRF (k, nf) of responses to the first of several inputs (n, p) with the others
    conditioned out (multiple-input H1: H = S_xx^-1 S_xy per line), and the first input's PSD. With the
    nonlinear forces of a structure as the other inputs, this is the underlying linear structure's FRF
    (Adams & Allemang 2000, "A frequency domain method for estimating the parameters of a non-linear
    structural dynamic model through feedback"; Noel & Kerschen 2017, sec. 4)."""
    X = np.asarray(inputs, float).reshape(len(Y), -1)
    Y = np.asarray(Y, float).reshape(len(X), -1)
    s = np.maximum(X.std(axis=0), 1e-300)  # the inputs at unit variance: the ridge below is then relative
    X = X / s
    nper = welch_segment(len(X), fs_hz)
    p, k = X.shape[1], Y.shape[1]
    f = welch(X[:, 0], fs_hz, nperseg=nper)[0]
    Sxx = np.empty((f.size, p, p), complex)
    Sxy = np.empty((f.size, p, k), complex)
    for a in range(p):
        for b in range(p):
            Sxx[:, a, b] = csd(X[:, a], X[:, b], fs_hz, nperseg=nper)[1]
        for i in range(k):
            Sxy[:, a, i] = csd(X[:, a], Y[:, i], fs_hz, nperseg=nper)[1]
    ridge = 1e-9 * np.trace(Sxx, axis1=1, axis2=2).real[:, None, None] * np.eye(p)[None] + 1e-300 * np.eye(p)[None]
    H = np.linalg.solve(Sxx + ridge, Sxy)  # (nf, p, k)
    return f, H[:, 0, :].T / s[0], Sxx[:, 0, 0].real * s[0] ** 2


def _percentile_f(f: np.ndarray, p: np.ndarray, q: float) -> float:
    c = np.cumsum(p)
    return float(f[min(len(f) - 1, int(np.searchsorted(c, q * c[-1])))])


def preliminary_band(m: Measurement) -> tuple[float, float]:
    """Where the input and the responses carry power: from half the frequency below which 0.5 % of the
    input's power lies (at least ``MIN_CYCLES`` periods in the record) to the frequency below which 99 %
    of the responses' power lies above that edge, times 1.5 (room for harmonics), below 0.45 fs."""
    fs = m.fs_hz
    u = np.asarray(m.excitation.values, float)
    nper = welch_segment(m.n, fs)
    f, pu = welch(u - u.mean(), fs, nperseg=nper)
    floor = MIN_CYCLES * fs / m.n
    f_lo = max(0.5 * _percentile_f(f[1:], pu[1:], 0.005), floor, 2 * f[1])
    py = np.zeros_like(f)
    for ch in m.responses:
        y = np.asarray(ch.values, float)
        p = welch(y - y.mean(), fs, nperseg=nper)[1]
        py += p / max(p[f >= f_lo].sum(), 1e-300)
    keep = f >= f_lo
    f_hi = min(0.45 * fs, 1.5 * _percentile_f(f[keep], py[keep], 0.99))
    if f_hi <= 1.5 * f_lo:
        f_hi = min(0.45 * fs, 4 * f_lo)
    return float(f_lo), float(f_hi)


def _power(y, fs_hz: float, n: int) -> tuple[np.ndarray, np.ndarray]:
    """Welch's power spectrum of a signal, its mean taken out, without the zero-frequency line: the lines and
    their power (``below_band`` and ``above_band`` read shares of it)."""
    y = np.asarray(y, float)
    f, p = welch(y - y.mean(), fs_hz, nperseg=welch_segment(n, fs_hz))
    return f[1:], p[1:]


def below_band(m: Measurement, band: tuple[float, float], share: float = 0.5) -> list[str]:
    """Notes on the responses that carry most of their power (more than ``share``, in the kind recorded,
    the mean taken out) below the band's low edge: what moves them most is not analysed. Where the
    strongest line lies below ``MIN_CYCLES`` periods of the record, the note says the record is too short
    for it (a 0.3 s record of a 15 Hz oscillator: its band starts at 151 Hz)."""
    fs = m.fs_hz
    floor = MIN_CYCLES * fs / m.n
    out = []
    for ch in m.responses:
        f, p = _power(ch.values, fs, m.n)
        total = float(p.sum())
        if not total > 0:
            continue
        low = float(p[f < band[0]].sum()) / total
        if low <= share:
            continue
        peak = float(f[np.argmax(p)])
        note = (f"{ch.name}: {100 * low:.0f} % of its power lies below the analysed band's low edge "
                f"({band[0]:.3g} Hz): what moves it most is not analysed")
        if peak < floor:
            note += (f"; its strongest line, {peak:.3g} Hz, is below the {floor:.3g} Hz from which this "
                     f"{m.n / fs:.3g} s record holds {MIN_CYCLES} periods: a longer record reaches it")
        out.append(note)
    return out


ABOVE_SHARE = 0.1  # a response's share of its power above the band that ``above_band`` notes
INPUT_ABOVE = 0.01  # ... where the input carries at most this share of its own


def above_band(m: Measurement, band: tuple[float, float], share: float = ABOVE_SHARE,
               input_share: float = INPUT_ABOVE, keep: Sequence[slice] | None = None) -> list[str]:
    """Notes on the responses that carry more than ``share`` of their power (in the kind recorded, the mean
    taken out) above the band's top where the input carries at most ``input_share`` of its own: motion the
    input does not drive there, harmonics a nonlinearity makes (a stopper's impacts, which also ring the
    structure's higher modes) or blows nobody measured. Discovery analyses the band, so none of it is
    scored: the note says which responses carry it (detection by distortion, Noel & Kerschen 2017, before
    any model). It does not locate the cause: a beam that strikes rings the other through their coupling, and
    a response the input drives little shows a large share of little power.

    Measured on the independent generator's seeds 900-999 (stop 85, README): notes on 8 of 21 contacts and
    2 of 13 Coulomb frictions, none on the 11 records with nothing hidden nor on any cubic, joint or drag; on
    seeds 0-899, 29 of 193 contacts and 5 of 143 records with nothing hidden, each of those struck by blows
    nobody measured. That was on the whole record; discovery now passes ``keep``, the blocks that stay once it
    has left out those blows or dropouts reach (stop 86): the 5 are not noted (the blows have a note of their
    own), and of the 43 contacts of seeds 0-999 drawn with blows, 12 are noted where 15 were (263, 450 and
    915 lost it, each at the contact's sensor; 994 at the other beam's).
    Its strong stoppers 928, 967 and 993 (effect strengths 1.4-4.0, each "nothing" or a false finding) carry
    9, 48 and 49 % of their contact sensor's power above bands of 76, 70 and 54 Hz, where the input carries
    0.6 % or less, and the other beam's sensor 0.1-2 %."""
    top = float(band[1])
    runs = [(0, m.n)] if keep is None else _runs(keep)

    def above(y: np.ndarray) -> float:
        # power above the top and in all, summed over the runs of samples read (each its own Welch estimate)
        hi = total = 0.0
        for a, b in runs:
            if b - a < 64:  # too short for a spectrum
                continue
            f, p = _power(y[a:b], m.fs_hz, b - a)
            df = f[1] - f[0] if f.size > 1 else 1.0
            hi, total = hi + float(p[f > top].sum()) * df, total + float(p.sum()) * df
        return hi / total if total > 0 else 0.0

    driven = above(np.asarray(m.excitation.values, float))
    if not driven <= input_share:
        return []
    out = []
    for ch in m.responses:
        s = above(np.asarray(ch.values, float))
        if s > share:
            out.append(f"{ch.name}: {100 * s:.0f} % of its power lies above the analysed band's top ({top:.3g} Hz), "
                       f"where the input carries {100 * driven:.1f} % of its: motion the input does not drive "
                       f"(a nonlinearity's harmonics, such as a stopper's impacts ringing the structure's higher "
                       f"modes, wherever it sits, or blows nobody measured); not analysed")
    return out


def _runs(segments: Sequence[slice]) -> list[tuple[int, int]]:
    """The contiguous runs of samples that ``segments`` (slices, in order) cover: adjacent ones joined."""
    runs: list[tuple[int, int]] = []
    for seg in segments:
        if runs and runs[-1][1] == seg.start:
            runs[-1] = (runs[-1][0], seg.stop)
        else:
            runs.append((seg.start, seg.stop))
    return runs


# a response whose power in the band is no more coherent with the input than unrelated signals' is carries
# nothing the input drives: a dead, unplugged or disconnected sensor (``undriven``). Per number of Welch
# segments (a sixteenth, a quarter of the record), the share below which a response is so. On the
# independent generator's 168 stationary records of seeds 0-199, each response replaced by a constant and
# noise reaches 0.049 and 0.174 at most; the true responses 0.11 or more with sixteenths (the least: seed 3, a
# beam hitting a stopper 240 times its stiffness, chaotic), and the F-16's 0.70. A lightly damped mode
# decays over more than a sixteenth of a short record, which lowers its coherence there (two masses, modes at
# 3.1 and 12.8 Hz damped 0.2 and 0.8 %, 5 s: 0.08), not with quarters (0.59): a response is undriven only if it
# is at both
UNDRIVEN_SHARE = {16: 0.08, 4: 0.25}


def coherent_share(u: np.ndarray, y: np.ndarray, fs_hz: float, band: tuple[float, float], segments: int) -> float:
    """The share of ``y``'s power that is coherent with ``u`` (the ordinary coherence weighted by y's
    spectrum) over the band's lines where ``u`` carries power (1e-3 of its most or more), in Welch
    segments of 1 / ``segments`` of the record, half overlapped. Two unrelated signals' coherence is about
    the inverse of the number of segments averaged: a dead sensor's share stands near 0.03 with sixteenths
    and near 0.14 with quarters, whatever the record's length."""
    u = np.asarray(u, float)
    y = np.asarray(y, float)
    nper = int(2 ** np.floor(np.log2(max(64, len(u) // segments))))
    f, g = coherence(u, y, fs_hz, nperseg=nper)
    _, pu = welch(u, fs_hz, nperseg=nper)
    _, py = welch(y, fs_hz, nperseg=nper)
    lines = (f >= band[0]) & (f <= band[1])
    if not lines.any() or not pu[lines].max() > 0:
        return float("nan")
    lines &= pu > 1e-3 * pu[lines].max()
    total = float(py[lines].sum())
    return float(np.sum(g[lines] * py[lines]) / total) if total > 0 else float("nan")


# a hammer record's response that its hits move: its mean square over a stretch after a hit stands at least
# this many times above the same over a stretch before it (``hit_response``). Measured (stop 73):
# see the README's "a dead sensor on a hammer record"
HIT_RESPONSE = 4.0
MIN_BEFORE = 32  # samples of record before a hit (besides its force window) that ``hit_response`` needs at least
MAX_HITS = 50  # hits ``hit_response`` looks at, the first ones


def hit_response(u: np.ndarray, y: np.ndarray, fs_hz: float, band: tuple[float, float]) -> float:
    """How far a hammer record's response ``y`` follows its hits (force ``u``): for each hit with a stretch
    of record before it that no earlier hit's force window reaches, the response's mean square about its
    level there over up to a period of the band's low edge after the hit (its force window,
    ``force_window``), over its mean square over that stretch; the largest over the hits. A response the
    hits drive rings after a hit where it was at rest, or far less moved, before it; a dead sensor reads the
    same noise on both sides (about 1). The stretch before is up to a period, at least ``MIN_BEFORE``
    samples (an analyser's pre-trigger); NaN where no hit has that (a record that starts at its hit).
    The largest, not the first: a record cut from a series, or a first tap, has a hit whose before still
    rings from the one before it."""
    pad = max(1, int(round(PAD_S * fs_hz)))
    period = max(16, int(fs_hz / band[0]))
    h = hits(u)
    edges = np.flatnonzero(np.diff(np.r_[0, h.astype(np.int8), 0]))
    y = np.asarray(y, float)
    best, clear = float("nan"), 0  # clear: where the record is free of the last hit's force window
    for start, stop in zip(edges[::2][:MAX_HITS], edges[1::2][:MAX_HITS]):
        first, end = int(start) - pad, int(stop) + pad
        n = min(period, first - clear)
        clear = end
        if n < MIN_BEFORE or end + MIN_BEFORE > y.size:
            continue
        before = y[first - n:first]
        rest = float(np.median(before))
        ratio = float(np.mean((y[end:end + period] - rest) ** 2) / max(float(np.mean((before - rest) ** 2)), 1e-300))
        best = ratio if np.isnan(best) else max(best, ratio)
    return best


def undriven(m: Measurement, band: tuple[float, float]) -> list[tuple[int, float]]:
    """The responses (index, measure) that carry nothing the input drives. A stationary input: at each
    segment length of ``UNDRIVEN_SHARE`` their share of power coherent with it stays below what unrelated
    signals reach (``coherent_share``; the measure is that share with sixteenths). A hammer record, whose one
    hit's segments' coherence says nothing: they do not ring after the hits (``hit_response`` below
    ``HIT_RESPONSE``; the measure is it). Not judged on a record shorter than 16 x 64 samples."""
    u = np.asarray(m.excitation.values, float)
    if m.n < max(UNDRIVEN_SHARE) * 64:
        return []
    if impulsive(u):
        ratios = [(i, hit_response(u, ch.values, m.fs_hz, band)) for i, ch in enumerate(m.responses)]
        return [(i, r) for i, r in ratios if r < HIT_RESPONSE]
    out = []
    for i, ch in enumerate(m.responses):
        shares = {k: coherent_share(u, ch.values, m.fs_hz, band, k) for k in UNDRIVEN_SHARE}
        if all(shares[k] < limit for k, limit in UNDRIVEN_SHARE.items()):
            out.append((i, shares[max(UNDRIVEN_SHARE)]))
    return out


@dataclass(frozen=True)
class Dropout:
    """A response that reads one value, sample for sample, from ``start_s`` to ``stop_s`` (the record's time,
    as ``Measurement.start_s``) while the excitation moves: a loose connector, a lost sensor, a stalled
    converter; or, ``value`` NaN, a channel that held no number there (``bridged``)."""
    name: str
    start_s: float
    stop_s: float
    value: float


def span_text(start_s: float, stop_s: float) -> str:
    """A stretch of a record in words: from and to in seconds, or a short one's length in milliseconds."""
    if stop_s - start_s >= 0.1:
        return f"from {start_s:.2f} s to {stop_s:.2f} s"
    return f"for {1e3 * (stop_s - start_s):.3g} ms at {start_s:.3f} s"


def bridged(fs_hz: float, excitation: Channel, responses: tuple[Channel, ...], start_s: float = 0.0) -> Measurement:
    """A measurement whose channels' runs of NaN or inf samples (a recording's lost frames, a logger's lost
    packets, an export's empty cells) are bridged by linear interpolation and kept as ``Measurement.lost``:
    discovery leaves the blocks they reach out, as a dropout's (the excitation's too: a model driven
    through the bridge is not driven by what the structure felt there)."""
    kept, lost = [], []
    for ch in (excitation,) + tuple(responses):
        y = np.asarray(ch.values, float)  # (as given where whole: copied, a column's layout changed round-off)
        bad = ~np.isfinite(y) if y.ndim == 1 else np.zeros(y.shape, bool)
        if bad.all() and y.size:
            if ch is excitation:
                raise ValueError(f"the excitation {ch.name!r} holds no number")
            raise ValueError(f"response {ch.name!r} holds no number: leave it out (ident discover: name the "
                             "responses to analyse with --response)")
        if bad.any():
            at = np.arange(y.size)
            y = np.where(bad, np.interp(at, at[~bad], y[~bad]), y)
            edges = np.diff(np.concatenate([[0], bad.astype(np.int8), [0]]))
            lost += [Dropout(ch.name, start_s + a / fs_hz, start_s + b / fs_hz, float("nan"))
                     for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1))]
        kept.append(Channel(ch.name, ch.kind, y))
    return Measurement(fs_hz, kept[0], tuple(kept[1:]), start_s, tuple(lost))


def dropouts(m: Measurement, band: tuple[float, float]) -> list[Dropout]:
    """The runs where a response reads one value for half a period of the (preliminary) band's low edge or
    longer, 16 samples at least, while the excitation moves. The low edge is at most half the lowest
    frequency the input drives, so the run lasts a period of it or more. A measured signal carries noise
    and never repeats a value for long; a quantised one holds its peak's code for a share of a period (a
    sine 10 codes high: 14 %), and a motion too small for the converter reads one code while the input
    moves: around a dropout the response moves by more than three codes (its standard deviation over the
    run's length on each side). A hammer record is not judged: between its decays a quiet sensor may read
    its rest code for seconds."""
    u = np.asarray(m.excitation.values, float)
    if impulsive(u):
        return []
    run = max(16, int(np.ceil(0.5 * m.fs_hz / band[0])))
    out = []
    for ch in m.responses:
        y = np.asarray(ch.values, float)
        same = np.concatenate([[False], y[1:] == y[:-1]])  # same[i]: sample i repeats sample i - 1
        edges = np.diff(np.concatenate([[0], same.astype(np.int8), [0]]))
        steps = np.diff(np.unique(y))
        code = float(steps.min()) if steps.size else 0.0  # the channel's resolution
        for a, b in zip(np.flatnonzero(edges == 1) - 1, np.flatnonzero(edges == -1)):
            if b - a < run or not np.ptp(u[a:b]) > 0:
                continue
            # around a dropout the response moves by many codes; a motion too small for the converter (a
            # quiet start read on few bits) reads one code while the input moves and moves a code or two after
            around = np.concatenate([y[max(0, a - run):a], y[b:b + run]])
            if around.size and np.std(around) > 3.0 * code:
                out.append(Dropout(ch.name, m.start_s + a / m.fs_hz, m.start_s + b / m.fs_hz, float(y[a])))
    return out


HARMONICS = 4.5  # the band's top, in multiples of the highest mode (``modal_band``)


def modal_band(frequencies_hz: np.ndarray, fs_hz: float, n: int, harmonics: float = HARMONICS) -> tuple[float, float]:
    """The band a model with these modes explains: from 0.4 x the lowest mode (at least ``MIN_CYCLES``
    periods in the record) to ``harmonics`` x the highest (the drive's 3rd and 4th harmonics, which a
    nonlinearity makes, stay in), below 0.45 fs."""
    f = np.asarray(frequencies_hz, float)
    lo = max(0.4 * float(f.min()), MIN_CYCLES * fs_hz / n)
    return lo, min(0.45 * fs_hz, harmonics * float(f.max()))


def first_family(frequencies_hz: np.ndarray, displacement: np.ndarray, fs_hz: float) -> np.ndarray:
    """The modes a discovery analyses: all of them, or the family below the first gap of more than
    ``FAMILY_GAP`` between consecutive modes when the responses' displacements (each scaled to unit
    variance) carry less than half their power above that gap.

    The effects discovery looks for act on displacement and velocity, and those live in the first
    family; a second family in the band (the beams' second bending modes, which a force shaker or a
    hammer drives) adds four and a half times its frequency of band and the modal fit's error there
    (independent seed 68, a drag at tip 1 of a force-excited rig: the first fit found the 100-Hz pair,
    the band reached 450 Hz and the baseline held out at 0.48; in the first family's band, 3.6-43 Hz,
    0.17, and the drag was found). A record driven mostly at the second family keeps it: its motion is
    there."""
    f = np.sort(np.asarray(frequencies_hz, float))
    gaps = np.flatnonzero(f[1:] > FAMILY_GAP * f[:-1])
    if f.size < 2 or gaps.size == 0:
        return f
    cut = float(np.sqrt(f[gaps[0]] * f[gaps[0] + 1]))
    z = np.asarray(displacement, float).reshape(displacement.shape[0], -1)
    z = (z - z.mean(axis=0)) / np.maximum(z.std(axis=0), 1e-300)
    spec = np.abs(np.fft.rfft(z, axis=0)) ** 2
    lines = np.fft.rfftfreq(z.shape[0], 1.0 / fs_hz)
    above = float(spec[lines > cut].sum()) / max(float(spec[1:].sum()), 1e-300)
    return f[: gaps[0] + 1] if above < 0.5 else f


def bandpass_gain(f: np.ndarray, band: tuple[float, float]) -> np.ndarray:
    """Zero-phase magnitude: Butterworth high-pass order 2 and low-pass order 4, each applied twice (a
    low edge of 0 is no high-pass)."""
    lo, hi = band
    with np.errstate(divide="ignore", over="ignore"):
        hp = 1.0 / (1.0 + (lo / np.maximum(f, 1e-300)) ** 4) if lo > 0 else np.ones_like(f)
        lp = 1.0 / (1.0 + (f / hi) ** 8)
    return hp * lp


@lru_cache(maxsize=64)
def _operator(nfft: int, fs_hz: float, band: tuple[float, float], p: int) -> np.ndarray:
    """(i 2 pi f)^p times the band's zero-phase gain on the rfft lines of ``nfft`` samples."""
    f = np.fft.rfftfreq(nfft, 1 / fs_hz)
    w = 2j * np.pi * f
    with np.errstate(divide="ignore", invalid="ignore"):
        op = np.where(f > 0, w ** p if p >= 0 else 1.0 / w ** (-p), 0.0)
    return op * bandpass_gain(f, band)


def convert(x: np.ndarray, fs_hz: float, band: tuple[float, float], from_order: int, to_order: int,
            detrend: bool = True) -> np.ndarray:
    """Band-limited conversion along axis 0 between kinematic orders (0 displacement, 1 velocity,
    2 acceleration): multiply by (i 2 pi f)^(to - from) and the band's zero-phase gain, on the whole
    record zero-padded to twice its length, rounded up to a length with small prime factors (the linear
    trend removed first, unless not ``detrend``: then a low-pass alone keeps the mean). Any length of at
    least twice the record keeps the circular filter's wrap-around beyond the record; the next power of two
    was up to twice as long and half as fast."""
    x = np.asarray(x, float)
    n = x.shape[0]
    t = np.arange(n) - (n - 1) / 2
    x2 = x.reshape(n, -1)
    xd = x2
    if detrend:
        slope = (t @ x2) / max(float(t @ t), 1e-300)
        xd = x2 - np.outer(t, slope) - x2.mean(axis=0)
    nfft = next_fast_len(2 * n, real=True)
    X = np.fft.rfft(xd, nfft, axis=0)
    op = _operator(nfft, float(fs_hz), (float(band[0]), float(band[1])), to_order - from_order)
    if not detrend and to_order == from_order and band[0] <= 0:
        op = op.copy()
        op[0] = 1.0  # a low-pass alone keeps what it is given, its mean too
    X *= op[:, None]
    return np.fft.irfft(X, nfft, axis=0)[:n].reshape(x.shape)


def edge_samples(fs_hz: float, band: tuple[float, float]) -> int:
    """Samples at each end that carry the band-pass's transient: two periods of the low edge."""
    return int(np.ceil(2.0 * fs_hz / band[0]))


ORDER = {"displacement": 0, "velocity": 1, "acceleration": 2}


@dataclass(frozen=True)
class Prepared:
    """The record ready for models: kinematics per response relative to the frame (absolute under a
    force), the band, the signs applied and why."""

    fs_hz: float
    names: list[str]
    kinds: list[str]
    u: np.ndarray  # (n,) excitation, band-passed (for linear fits, compared with band-passed responses)
    drive: np.ndarray  # (n,) excitation as simulations take it: trend removed, anti-alias low-pass only
    base: np.ndarray  # (n, 3) frame displacement, velocity, acceleration (zeros under a force)
    zva: np.ndarray  # (3, n, k) relative displacement, velocity, acceleration of every response
    measured: np.ndarray  # (n, k) each response as measured (its own kind, absolute), band-passed, sign fixed
    band: tuple[float, float]
    edge: int
    signs: np.ndarray  # (k,) +1 as recorded, -1 flipped
    sign_notes: list[str] = field(default_factory=list)
    driving_point: int | None = None
    # the other responses that read as a driving point as well (``_driving_point``), each with its sign as one
    # as prepared (-1: it reads as one read against the force): reciprocity may be taken through one of them
    driving_alike: tuple[tuple[int, int], ...] = ()
    excitation_kind: str = "force"
    transient: bool = False  # a hammer-hit record
    blows: tuple[int, ...] = ()  # samples where unmodelled blows strike: free responses start there
    rest_until: int | None = None  # a hammer record that starts at rest: its first hit (``rest_until``)
    # of such a record, the force band-passed with its stillness before it: ``edge`` samples before sample
    # 0, then the record's. The zero-phase filter spreads the hit backwards, and what it spreads before the
    # record drives the modes as the record starts (``baselines.modal.Columns``)
    u_at_rest: np.ndarray | None = None
    start_s: float = 0.0  # the record's time at sample 0 (``Measurement.start_s``)

    @property
    def n(self) -> int:
        return self.u.shape[0]

    @property
    def base_excited(self) -> bool:
        return self.excitation_kind == "base_acceleration"


def _signs(m: Measurement, band: tuple[float, float]
           ) -> tuple[np.ndarray, list[str], int | None, tuple[tuple[int, int], ...]]:
    """Signs to apply to the responses and why (see the module's docstring), the driving point, and the
    other responses that read as one (``Prepared.driving_alike``)."""
    fs = m.fs_hz
    u = np.asarray(m.excitation.values, float)
    Y = np.column_stack([np.asarray(c.values, float) for c in m.responses])
    f, H, puu = frf(u, Y, fs)
    inband = (f >= band[0]) & (f <= band[1])
    sel = inband & (puu > 1e-3 * puu[inband].max())  # lines the input really drives (-30 dB)
    signs = np.ones(len(m.responses))
    notes: list[str] = []
    recs: list[tuple[int, np.ndarray, np.ndarray]] = []
    if sel.sum() < 4:
        return signs, ["signs: kept as recorded (too few excited lines to judge)"], None, ()
    for i, ch in enumerate(m.responses):
        order = ORDER[ch.kind]
        if m.base_excited:
            # absolute response per base acceleration, made an acceleration ratio
            T = H[i, sel] * (2j * np.pi * f[sel]) ** (2 - order)
            resp = np.abs(T - 1)
            peak = _lowest_peak(f[sel], resp)
            # judged at a resonance the input sweeps through (a peak with driven lines on both sides, the
            # relative motion near 90 degrees), a single tone saying nothing; else below it (``_below_resonance``)
            if 0 < peak < resp.size - 1 and abs(np.imag(T[peak] - 1)) > 0.7 * resp[peak]:
                flip, why = np.imag(T[peak]) > 0, "Im of its transmissibility is positive at the lowest"
            else:
                flip = _below_resonance(f[sel], T, puu[sel], f[sel][peak]) < 0
                why = "Re of its transmissibility is negative below its lowest"
            if flip:
                signs[i] = -1
                notes.append(f"{ch.name}: flipped ({why} resonance, {f[sel][peak]:.1f} Hz)")
            continue
        if m.excitation.kind != "force":
            continue
        rec = H[i, sel] / (2j * np.pi * f[sel]) ** order  # receptance
        recs.append((i, rec, np.abs(rec) ** 2 * puu[sel]))
    driving, alike, everywhere = _driving_point(recs)
    if driving is None and len(recs) == 1 and impulsive(u) and rest_until(u, Y) is not None:
        # one response hit from rest: its phase is no witness where the decay glides (a hardening beam's:
        # independent seeds' clamped-clamped beams read Im < 0 on 62-86 % of their power, or 13-34 % when
        # the laser faced the force), its first motion is
        i, rec, w = recs[0]
        moved = _first_motion(u, Y[:, i], ORDER[m.responses[i].kind], fs, band, float(f[sel][np.argmax(w)]))
        if moved:
            signs[i] = moved
            name = m.responses[i].name
            notes.append(f"{name}: flipped (moved against the hit: a driving point moves with it)" if moved < 0
                         else f"{name}: the driving point (moved with the hit)")
            return signs, notes, i, ()
    if driving is not None:
        i, neg = driving
        name = m.responses[i].name
        share = (f"Im of its receptance is positive on {100 * (1 - neg):.0f} % of the band's power" if neg < 0.5
                 else f"passive: Im of its receptance negative on {100 * neg:.0f} % of the band's power")
        signs[i] = -1 if neg < 0.5 else 1
        what = "flipped, as a driving point read against the force" if neg < 0.5 else "the driving point"
        if alike:
            notes.append(f"{name}: {what} ({share}); taken for it, but "
                         + ", ".join(m.responses[j].name for j, _ in alike)
                         + f" read{'s' if len(alike) == 1 else ''} as one too"
                         + ("" if everywhere else " (none of them at every resonance)")
                         + ": the record does not say which response is driven (an input through more of the "
                         "modes would)")
        elif not everywhere:
            notes.append(f"{name}: {what} ({share}); taken for it, though its sign changes at a resonance: "
                         "it may be a transfer point")
        elif neg < 0.5:
            notes.append(f"{name}: flipped (a driving point read against the force: {share})")
        else:
            notes.append(f"{name}: the driving point ({share})")
    if not notes:
        notes.append("signs: kept as recorded")
    return (signs, notes, None if driving is None else driving[0],
            tuple((j, 1 if neg >= 0.5 else -1) for j, neg in alike))


DRIVING_SHARE = 0.9  # a driving point's receptance has Im < 0 on at least this share of its power
RESONANCE_SHARE = 0.02  # a resonance counts for a response where it holds at least this share of its power


def _driving_point(recs: list[tuple[int, np.ndarray, np.ndarray]]
                   ) -> tuple[tuple[int, float] | None, list[tuple[int, float]], bool]:
    """The response taken for the driving point among receptances ``(index, receptance, power weight)`` on
    the driven lines, as ``(index, share of its power where Im < 0)``, every other response that reads as one
    as well (the same pairs), and whether it reads as one at every resonance.

    A response reads as a driving point (or as one read against the force) where Im of its receptance has
    one sign on ``DRIVING_SHARE`` of its power, and as one at every resonance where that sign also holds on
    most of the power within each resonance carrying ``RESONANCE_SHARE`` of its power: a transfer point
    changes sign at a mode whose shape has opposite signs at it and at the driving point. The one response
    that reads so at every resonance is the driving point. Where several do, or none does, the record does not say which response
    is driven, and the most one-sided of them is taken (the modal baseline's reciprocity needs one; taking
    none lost three right answers of seeds 0-99 (16, 21, 42) and gained none); the others are returned so
    that the report can say so and the baseline can choose among them (independent seed 72, a chain driven
    at its second mass near its first mode: all four masses read passive on 100 % of their power, and the
    first had been reported as the driving point)."""
    one_sided, everywhere = [], []
    if recs:
        regions = _resonances(sum(w / max(float(w.sum()), 1e-300) for _, _, w in recs))
    for i, rec, w in recs:
        total = max(float(w.sum()), 1e-300)
        neg = float(np.sum(w * (rec.imag < 0)) / total)
        if DRIVING_SHARE > neg > 1 - DRIVING_SHARE:
            continue
        one_sided.append((i, neg))
        if all((float(np.sum(w[g] * (rec.imag[g] < 0))) / float(w[g].sum()) > 0.5) == (neg > 0.5)
               for g in regions if float(w[g].sum()) >= RESONANCE_SHARE * total):
            everywhere.append((i, neg))
    pool = everywhere or one_sided
    if not pool:
        return None, [], False
    taken = max(pool, key=lambda c: abs(c[1] - 0.5))  # the first of equals
    return taken, [c for c in pool if c[0] != taken[0]], bool(everywhere)


FIRST_MOTION = 0.2  # a first motion is read where its mean holds this share of the largest displacement


def _first_motion(u: np.ndarray, y: np.ndarray, order: int, fs_hz: float, band: tuple[float, float],
                  f_mode: float) -> int:
    """+1 where a response hit from rest (``order`` its kinematic order) moves with the first hit, -1 where
    against it, 0 where its motion does not say.

    Hit by an impulse J at the driving point, a structure at rest moves there as the sum over its modes of
    phi_r^2 J sin(w_r t) / w_r, each term of J's sign until its half period: from an eighth to three eighths
    of the period of the mode ``f_mode`` (the receptance's peak), the displacement has the sign of the hit, and it has that sign whatever the decay does later (a gliding hardening decay, whose phase
    across its peak no longer says anything). A transfer point moves so in every mode whose shape has one
    sign at it and at the hit."""
    at = int(np.flatnonzero(hits(u))[0])
    quarter = max(1, int(round(fs_hz / f_mode / 4)))
    blow = float(np.sum((u - np.median(u))[at:at + quarter]))
    x = convert(y - np.median(y), fs_hz, band, order, 0)
    after = x[at + quarter // 2:at + 3 * quarter // 2]
    if after.size < quarter or blow == 0:  # a hit too near the record's end
        return 0
    lean = float(np.mean(after)) / max(float(np.abs(x).max()), 1e-300)
    return 0 if abs(lean) < FIRST_MOTION else int(np.sign(lean) * np.sign(blow))


def _resonances(power: np.ndarray) -> list[np.ndarray]:
    """The driven lines split into one run per resonance of ``power`` (the responses' summed, each scaled to
    unit sum): peaks standing ten times above the valleys beside them, split at the lowest line between
    two peaks."""
    k = max(1, power.size // 400)
    smooth = np.convolve(power, np.ones(2 * k + 1) / (2 * k + 1), mode="same")
    peaks, _ = find_peaks(np.log(smooth + 1e-300), prominence=np.log(10.0))
    cuts = [0] + [a + int(np.argmin(smooth[a:b])) for a, b in zip(peaks[:-1], peaks[1:])] + [power.size]
    return [np.arange(a, b) for a, b in zip(cuts[:-1], cuts[1:])]


QUASI_STATIC = 0.7  # lines below this share of the lowest resonance's frequency are below every mode
QUASI_STATIC_AGREE = 0.8  # the power-weighted share on which Re T's sign must agree there
QUASI_STATIC_GAIN = 0.7  # and the median |T| there at least this: below every mode |T| >= 1


def _below_resonance(f: np.ndarray, T: np.ndarray, power: np.ndarray, f_peak: float) -> int:
    """The sign of Re(T) of a response's absolute transmissibility ``T`` on the driven lines below
    ``QUASI_STATIC`` times its lowest resonance ``f_peak`` (+1 or -1), where at least three lines lie there,
    Re T has one sign on ``QUASI_STATIC_AGREE`` of their input power and their median |T| is at least
    ``QUASI_STATIC_GAIN``; else 0.

    Below every mode a tip moves with the frame: T = (1 + 2i zeta r) / (1 - r^2 + 2i zeta r) per mode at
    r = f / f_r, whose real part is positive for r < 1 whatever the damping; below every mode the frame's own
    motion and the lowest mode's term, both positive, dominate the sum over modes.
    A struck beam shows no resonance whose phase says its sign (the stopper smears it), but below it the
    frame still carries it. Independent seeds 700-799: 13 of 48 base-driven records had a tip with the wrong
    sign, 12 of them left as recorded, among them 8 of the 22 contacts (737's struck tip read 10-21 times
    its stopper's gap, the frame's motion added to its own); the sign of Re T there was right on 78 of the
    79 tips with three lines below their resonance (the one wrong: seed 726, whose band starts above the
    first mode, where the resonance's phase is wrong too). After the rule 3 of 48 (seeds 0-99: 7 of 39 -> 1);
    the rest are stepped sines with no line below the resonance.

    Lines below the band's lowest resonance lie below every mode only where the band holds the first: in a
    band above it (seed 726's, 75-849 Hz, where the beams' first modes are near 14 Hz) they lie between
    modes, where Re T < 0 and |T| is small (the isolation above a mode: 0.09 at its tip 2, where the tips below
    every mode read 1.02 or more on seeds 700-799), and the rule would flip a tip that is right."""
    low = f < QUASI_STATIC * f_peak
    if np.count_nonzero(low) < 3 or float(np.median(np.abs(T[low]))) < QUASI_STATIC_GAIN:
        return 0
    w = power[low]
    lean = float(np.sum(w * np.sign(T[low].real)) / max(float(w.sum()), 1e-300))
    return int(np.sign(lean)) if abs(lean) >= 2 * QUASI_STATIC_AGREE - 1 else 0


def _lowest_peak(f: np.ndarray, mag: np.ndarray) -> int:
    """Index of the lowest-frequency peak that reaches half the largest."""
    top = float(mag.max())
    for k in range(1, len(mag) - 1):
        if mag[k] >= 0.5 * top and mag[k] >= mag[k - 1] and mag[k] >= mag[k + 1]:
            return k
    return int(np.argmax(mag))


def prepare(m: Measurement, band: tuple[float, float] | None = None) -> Prepared:
    """Band (given, or ``preliminary_band``), signs, and the kinematics of every response."""
    fs = m.fs_hz
    band = band or preliminary_band(m)
    lo, hi = band
    if not 0 < lo < hi < fs / 2:
        raise ValueError(f"analysis band {lo:.3g}-{hi:.3g} Hz does not fit below Nyquist ({fs / 2:.3g} Hz)")
    edge = edge_samples(fs, band)
    if m.n < 8 * edge:
        raise ValueError(f"{m.n} samples hold too few periods of the band's low edge ({lo:.3g} Hz); "
                         f"give at least {8 * edge} samples or a record with higher frequencies")
    signs, notes, driving, alike = _signs(m, band)
    u_raw = np.asarray(m.excitation.values, float)
    k = len(m.responses)
    n = m.n
    base = np.zeros((n, 3))
    if m.base_excited:
        for order in range(3):
            base[:, order] = convert(u_raw, fs, band, 2, order)
    zva = np.empty((3, n, k))
    measured = np.empty((n, k))
    for i, ch in enumerate(m.responses):
        y = signs[i] * np.asarray(ch.values, float)
        o = ORDER[ch.kind]
        measured[:, i] = convert(y, fs, band, o, o)
        for order in range(3):
            zva[order, :, i] = convert(y, fs, band, o, order) - base[:, order]
    transient = impulsive(u_raw)
    still = None
    if transient:
        still = rest_until(u_raw, np.column_stack([np.asarray(c.values, float) for c in m.responses]))
        u_raw = force_window(u_raw, fs)
    u = convert(u_raw, fs, band, 0, 0)
    at_rest = None
    if transient:
        # a hammer's force is nil between its hits: its zero is the channel's quiet level (the median), and
        # no mean or trend is taken out, which would spread the hits over the record as a steady force (a
        # clamped-clamped beam hit 3 ms into its 7.5 s record, independent seed 197: a force ramping from
        # -0.05 % to +0.02 % of the hit's peak after it, switched on at each simulation's start; the baseline
        # held out 7.8 times worse than predicting zero, 0.17 without it, and its cubic is found)
        force = u_raw - float(np.median(u_raw))
        drive = convert(force, fs, (0.0, 0.45 * fs), 0, 0, detrend=False)
        if still is not None:
            # before the record the force read its quiet level: band-passed with that stillness in front,
            # the force's start is exact and its spread before the record is known
            at_rest = convert(np.concatenate([np.zeros(edge), force]), fs, band, 0, 0, detrend=False)
    else:
        drive = convert(u_raw, fs, (0.0, 0.45 * fs), 0, 0)
    return Prepared(fs, m.names, [c.kind for c in m.responses], u, drive, base, zva, measured, band, edge, signs,
                    notes, driving, alike, m.excitation.kind, transient, rest_until=still, u_at_rest=at_rest,
                    start_s=m.start_s)


# --- records over the memory budget -------------------------------------------------------------------


@dataclass(frozen=True)
class Excerpt:
    """What a record became to fit the budget: every ``step``-th sample's worth (anti-aliased) of the
    original samples [start, stop), and why."""

    measurement: Measurement
    step: int
    start: int
    stop: int
    notes: tuple[str, ...] = ()

    def index(self, sample: int) -> int:
        """An original sample index in the excerpt (floored alike for starts and stops, so slices that did
        not overlap still do not)."""
        return (sample - self.start) // self.step


def _each_channel(m: Measurement, f, fs_hz: float, start_s: float) -> Measurement:
    """``m`` with ``f`` applied to every channel's values."""
    ch = lambda c: Channel(c.name, c.kind, f(np.asarray(c.values, float)))  # noqa: E731
    return Measurement(fs_hz, ch(m.excitation), tuple(ch(c) for c in m.responses), start_s, m.lost)


def _decimated(m: Measurement, q: int) -> Measurement:
    """Every channel low-passed below the new Nyquist and decimated by ``q`` (polyphase FIR, zero phase)."""
    return _each_channel(m, lambda x: resample_poly(x, 1, q), m.fs_hz / q, m.start_s)


def _cut(m: Measurement, start: int, stop: int) -> Measurement:
    return _each_channel(m, lambda x: x[start:stop], m.fs_hz, m.start_s + start / m.fs_hz)


def widest_span(m: Measurement, length: int, per_span: int = 20) -> int:
    """Start of the ``length`` samples whose motion spans the widest range of amplitudes: the responses'
    RMS (each over its whole-record RMS, summed) in ``per_span`` blocks of the span, the mean of its louder
    half over that of its quieter half; the earliest of equals. Discovery sees a nonlinearity as what
    changes with amplitude, and its baseline needs the low amplitudes beside the high ones."""
    block = max(1, length // per_span)
    count = m.n // block
    r = np.zeros(count)
    for ch in m.responses:
        y = np.asarray(ch.values, float)[:count * block]
        y = y - y.mean()
        r += np.sqrt(np.mean(y.reshape(count, block) ** 2, axis=1)) / max(float(np.sqrt(np.mean(y**2))), 1e-300)
    # the louder half of the span's blocks over the quieter half: widest when two levels share the span
    # evenly, so a step between them sits in its middle, not at an edge where a few blocks make it
    w = np.sort(np.lib.stride_tricks.sliding_window_view(np.maximum(r, 1e-12), per_span), axis=1)
    half = per_span // 2
    spread = w[:, per_span - half:].mean(axis=1) / w[:, :half].mean(axis=1)
    return int(np.argmax(spread)) * block


def within_budget(m: Measurement, max_samples: int, keep: tuple[int, int] | None = None,
                  step: int | None = None, kept: str = "the training and test samples") -> Excerpt:
    """The record as recorded when its samples x responses fit ``max_samples``; else decimated to the
    lowest rate that keeps ``WORKING_RATE`` samples per period of the preliminary band's top (the band
    where the input and the responses carry power), or by ``step`` when given (a fit record decimated as
    the analysed one), and if that is still too much, the span of the budget's length with the widest
    range of amplitudes (``widest_span``), or the span around ``keep`` (original samples [start, stop),
    ``kept`` says what they are; refused if they do not fit). The notes say what was done."""
    k = len(m.responses)
    if m.n * k <= max_samples and not (step and step > 1):
        return Excerpt(m, 1, 0, m.n)
    notes = []
    if step is None:
        top = preliminary_band(m)[1]
        q = max(1, int(m.fs_hz // (WORKING_RATE * top)))
        why = f"the responses' power lies below {top:.3g} Hz"
    else:
        q, why = step, "as the analysed record"
    out = m
    if q > 1:
        out = _decimated(m, q)
        notes.append(f"decimated {q} x to {out.fs_hz:.6g} Hz to fit the memory budget ({max_samples:,} samples x "
                     f"responses): {why}")
    length = max_samples // k
    if out.n <= length:
        return Excerpt(out, q, 0, m.n, tuple(notes))
    if keep is not None:
        a, b = keep[0] // q, -(-keep[1] // q)
        if b - a > length:
            raise ValueError(f"{kept} span {(keep[1] - keep[0]) / m.fs_hz:.6g} s; at {out.fs_hz:.6g} Hz with {k} "
                             f"response{'s' if k > 1 else ''} at most {length / out.fs_hz:.6g} s fit the memory "
                             f"budget ({max_samples:,} samples x responses): choose a shorter span or a larger "
                             "budget (--max-samples)")
        # the rest of the budget as context on both sides: the band-pass's edges fall outside the given samples
        a = min(max(0, a - (length - (b - a)) // 2), out.n - length)
    else:
        a = min(widest_span(out, length), out.n - length)
    b = a + length
    notes.append(f"analysed {m.start_s + a * q / m.fs_hz:.6g}-{m.start_s + min(m.n, b * q) / m.fs_hz:.6g} s of "
                 f"{m.start_s:.6g}-{m.start_s + m.n / m.fs_hz:.6g} s to fit the memory budget ("
                 + (f"the span around {kept}" if keep is not None
                    else "the span with the widest range of amplitudes") + ")")
    return Excerpt(_cut(out, a, b), q, a * q, min(m.n, b * q), tuple(notes))
