"""Regime monitor: per beam, free or hitting its stoppers, from physics every rig has.

Regimes: free (``linear``), one beam hitting (``localized-1``, ``localized-2``), both
(``impacting-both``). Each beam is judged on its own, with a probability, from features
that are ratios of quantities the data itself provides, so the decision carries from
one rig to another (stoppers soft or rigid, one- or two-sided, 500 Hz to 5 kHz, any noise
level). Per window (``window_s``, every ``hop_s``), with f the drive frequency (the base's
spectral peak) and a Hann-windowed spectrum of every channel:

- **distortion**: the power of the tip's acceleration in [1.5 f, 5.5 f] (the low harmonics) and in
  [5.5 f, 0.3 fs] (the beams' higher modes: high harmonics and impact ringing, reported apart as
  ``impact_ratio`` and ``impact_rms``), each above the channel's noise floor, over the power at the
  fundamental. The edge between them is the second mode's lowest place: a cantilever's second mode
  lies at 6.27 times its first (the Euler-Bernoulli ratio (4.694 / 1.875)^2; a tip mass raises it,
  to 8.5-16 on the generator's rigs) and a beam hits near resonance, the drive at most about 15 %
  above its first mode, so the harmonics up to the fifth lie between the first and second modes,
  where the coupling carries little, and those above may sit on the second modes, which are alike
  between the beams and carry much of the other beam's motion (independent regime seed 3022: the
  drive at 7.6 Hz, its tenth harmonic on the second modes at 74 and 76 Hz; a free beam showed 10 % of
  the hitting beam's power in [1.5 f, 10.5 f], the edge before, twice the share the coupling may
  carry there, and was called hitting in every window). The floor of white sensor
  noise is a low quantile of the bands' bins, the lower of this window's and the 10th percentile
  of the last 400 windows' (the noise is stationary; a window full of impacts raises its own).
  Removed: what the base's own harmonics would put into the tip, and the share of the other
  beam's excess the coupling carries over: at most ``cross_talk`` of its harmonic power and
  ``cross_talk_impact`` of its impact power (the beams' higher modes are alike), less where the
  stream has shown less. The share is a property of the rig at a drive frequency (the coupling's
  transfer at the harmonics), and it ranges over two decades between rigs (0.015 % to 6 % of the
  harmonic power on the generator's rigs), so the monitor measures it: in every window where the
  other beam distorts clearly, the ratio of this beam's excess to the other's is kept with the drive
  frequency; from 20 such windows within 10 % of the present drive frequency, twice their 10th
  percentile (five times for the bursty impact band) replaces the bound when lower. Windows where
  this beam hits too only raise the ratio, so the low quantile is the coupling's (once the beam has
  been free beside the other hitting at that frequency). A beam that grazes its stopper beside one
  that hits hard shows a few times the harmonics the coupling carried while it was free, which the
  fixed bound hid. Before the share is measured, the phase tells a contact from the coupling: a
  stopper on either side puts a beam's third harmonic in one phase against its fundamental, so two
  beams hitting near in phase show third harmonics in phase, while the coupling pulls a free beam
  through a spring at 3 f, where (above its first mode, below its second) it answers as a mass, in
  anti-phase; a third harmonic significantly in phase with the other beam's (summed over three
  windows) is the beam's own contact: none of its harmonic power is removed as the coupling's and it
  adds ``PHASE_EVIDENCE`` to the log-odds (``_own_contact``). The same test against the beam's own
  fundamental needs no hitting neighbour: a stopper pushes where the relative displacement peaks, so its
  third harmonic lies along the cube of the fundamental's phasor (``_clipping``); a component there, significant
  over the same windows, counts as the phase rule does and is required before an amplitude is learned as
  hitting. Hitting amplitudes are learned from
  steady windows only (``STEADY_LOG``). The impact band counts only where it stands out of its
  noise: every stopper folds the motion into the harmonics, so a silent harmonic band says free even
  when the wide, noisy impact band can say nothing. A linear beam
  driven by a sine answers with that sine alone; a stopper folds the motion and puts power at
  the harmonics (odd ones for two-sided stoppers, ``odd_distortion``; even ones too for
  one-sided), and a stiff one rings at the beam's higher modes. The acceleration weights
  harmonic n by n^2, which is what makes a soft stopper's small distortion of the displacement
  visible. The decision reads log10 of the distortion against ``distortion_on``, and only where
  the excess is significant against the floor (a beam that barely moves says nothing either
  way);
- **displacement amplitude against the gap**: the relative displacement at the drive
  frequency, Z = |tip - base| / (2 pi f)^2 at f, against the stopper gap learned online
  (evidence below the largest amplitudes the distortion called free and above the smallest it
  called hitting, none in between; far below every amplitude seen hitting a beam is free, and
  before any free amplitude is learned, above them it hits); with the gap from the
  config (``gap_m``), the peak of the displacement waveform rebuilt from the first eight
  harmonics (a stopper clips the motion: the fundamental of a beam on a stiff stopper stays
  below the gap);
- **stiffness**: harmonic balance of the beam's first mode at the drive frequency,
  z'' + 2 zeta w z' + w^2 z = -a_base gives w_eq^2 = w^2 Re(T / R), T the tip's and R the
  relative acceleration phasor: the describing-function (equivalent linear) natural
  frequency of this window, with the one learned in windows the distortion called free.
  Reported, not weighed: the coupling and the beating after a drive change move it by
  several per cent, as much as a soft stopper does. The pairs (amplitude, w_eq) are the
  beam's backbone as this window sees it;
- **phase to the base** and the **amplitude ratio** of the tips (localisation) are
  reported with every window.

Sign of each tip against the base: a passive beam takes power from the base, so the
mean of a_base times the tip's absolute velocity is negative, Im(conj(B) T) < 0 at the
drive frequency; the monitor accumulates that product over the stream and flips a tip
whose sign is the other way (an accelerometer mounted upside down), so relative motion,
phase and stiffness come out right without a calibration sign.

The per-beam log-odds is ``prior`` plus the evidences: the distortion's log10 against
``distortion_on`` per ``distortion_scale`` decades (clipped to +-3), the learned gap's (clipped
to +-1.5, down to -3 far below the amplitudes seen hitting) or the config's (-2 .. +3). The
beam's probability of hitting is the logistic, its confidence max(p, 1 - p). The decision
(``decide``) adds hysteresis and a dwell: a beam switches to hitting above p = 0.5 + ``hysteresis``
and back at or below 0.5 - ``hysteresis``, and a new regime is reported once it has been the
window's label in ``dwell`` clear windows (the p of every beam that changes outside that band) without another label
in between, or in ``max_dwell`` windows of any kind; the starting regime, each beam in its likelier state
(p > 0.5), is reported at the ``PHASE_WINDOWS``-th window (the windows before it are provisional).
The thresholds were set on generated rigs (seeds 0-30 of daq.sim.independent) other than those
``daq bench --regimes`` reports (seeds from 1000).

Streaming: ``regime_step(state, block) -> (state, windows, changes)`` is a pure function;
windows end on multiples of the hop counted from the first sample, so any split of the
stream into blocks gives the same output (tests/test_regimes.py proves it).
``RegimeMonitor`` holds the state for callers that prefer an object.
"""

from __future__ import annotations

import cmath
import math
from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np
import scipy.fft
from numba import njit

LABELS = ("linear", "localized-1", "localized-2", "impacting-both")
PEAK_HARMONICS = 8  # harmonics of the drive in the reconstructed displacement waveform
LEARNED_CAP = 1.5  # largest log-odds a learned gap may give
ABOVE_HIT_CAP = 1.0  # ... an amplitude above those seen hitting, before any free one was learned
LEARN_WINDOWS = 400  # confident windows kept per beam for the learned gap and stiffness (100 s at 0.25 s)
FLOOR_QUANTILE = 0.2
# the drive's periods a window must hold for its harmonics to stand clear of the fundamental's leakage through the
# Hann window: with fewer, a pure sine's sidelobes put more than distortion_on into the harmonic band (9e-4 of its
# power at 3.5 periods, 5.7e-3 at 3, 2.5e-4 to 3.3e-4 at 3.6 to 4), and a free beam reads as hitting; the windows
# carry their periods and the pipeline says once what window the drive needs (--regime-window)
MIN_PERIODS = 3.6
SLOW_WINDOWS = 8  # consecutive windows (2 s at the 0.25 s hop) too short for the drive before it is said
HARMONIC_TOP = 5.5  # the harmonic band's top edge over the drive frequency: below the second modes (module docstring)
# the coupling's share learned per stream (see _cross_talk): rows kept where the other beam distorts at least
# CROSS_STRONG times its band's noise and 10 x distortion_on; used from CROSS_MIN_WINDOWS rows within CROSS_BAND
# (log drive frequency) of the window's drive, their CROSS_QUANTILE times CROSS_MARGIN (harmonic, impact band)
CROSS_STRONG = 30.0
CROSS_MIN_WINDOWS = 20  # 5 s of windows
CROSS_BAND = 0.1
CROSS_QUANTILE = 0.1
CROSS_MARGIN = (2.0, 5.0)  # impacts come in bursts: their ratio scatters more than the harmonics'
# a beam's own contact told from the coupling's carry-over by the phase of the third harmonic (see _own_contact):
# the other beam's third harmonic must stand PHASE_REFERENCE times above its phasor's noise power (its phase then
# known within 6 degrees); this beam's component in phase with it, after what the base's third harmonic could put
# there, summed over the last PHASE_WINDOWS windows, PHASE_Z standard deviations of its noise above zero (one-sided
# 3e-5 per window for Gaussian noise: a 10-minute run has 2,400 windows; 3 gave the same on the dev seeds).
# Measured on dev seeds 0-30 of daq.sim.independent (windows of a truth stable for 1 s, the other beam hitting):
# the rule holds in 8,864 of 11,468 windows where this beam hits too and in 99 of 12,449 where it is free (66 of
# them on seed 6, 14 on seed 18), a likelihood ratio of about 100; PHASE_EVIDENCE, the log-odds it adds, is set
# well below its log (4.6), not tuned: the windows are not independent, and the distortion evidence it goes with
# counts part of the same contact
PHASE_REFERENCE = 100.0
PHASE_Z = 4.0
PHASE_EVIDENCE = 1.5
# a grazing beam's component stands 2-3 noise deviations out in each window (dev seed 5's "both" segment), so one
# window's test flickers; the sum of three (0.75 s of window ends; they overlap by half, their noise nearly
# independent) does not, and lets go of a contact that ended within the dwell
PHASE_WINDOWS = 3
# The clipping rule (``_clipping``): a beam's relative third harmonic in the phase a stopper gives it against its own
# fundamental, significant (PHASE_Z) over the same PHASE_WINDOWS windows. Per single window (z > 4), measured against
# the truth of the independent generator: in 97.8 % of 11,882 hitting and 2.8 % of 13,982 free beam-windows on dev
# seeds 0-30 (97.6 % and 2.8 % on seeds 6000-6023), a likelihood ratio of about 35. It adds PHASE_EVIDENCE (the
# windows overlap and the distortion evidence counts part of the same contact), keeps the beam's harmonics from
# being removed as the coupling's, and is required before an amplitude is learned as hitting: noise and a
# higher mode ringing at the start of a record give no phase (independent regime seed 6012: amplitudes of 0.07 mm
# learned as hitting from the start's ringing held a free beam "hitting" for 6 s after a drive change, its gap
# 2.65 mm)
# a window is steady when no channel's amplitude at the drive frequency differs by more than this (in log) between
# its halves: the drive ramping up from rest, a drive change or a beat makes a window's spectrum no state of the
# rig (at the start of a record, the tips' "distortion" was up to 8 times their fundamental's power, and the
# amplitudes learned there as hitting held a free beam "hitting" for 15-25 s on dev seeds 2020 and 2048). Set
# above every window of the steady runs of dev seeds 0-30 and 2007-2058 (largest 0.096, 99.9 % below 0.06; 19,352
# windows); 10-20 % of the programmes' windows lie above it. The cost: a beam that reaches its stopper while the
# drive changes is learned hitting later (dev seed 25: one change reported 45 s late, "far below" the amplitudes
# learned hitting in the steady windows before)
STEADY_LOG = 0.1
_FLOOR_NORM = -np.log(1 - FLOOR_QUANTILE)  # a white floor's mean power over its quantile


def label_of(hit1: bool, hit2: bool) -> str:
    return LABELS[int(hit1) + 2 * int(hit2)]


def _hits_of(label: str) -> tuple[bool, bool]:
    i = LABELS.index(label)
    return bool(i & 1), bool(i & 2)


@dataclass(frozen=True)
class RegimeConfig:
    fs_hz: float = field(default=2000.0, metadata={"gt": 0.0})
    window_s: float = field(default=0.5, metadata={"gt": 0.0})
    hop_s: float = field(default=0.25, metadata={"gt": 0.0})
    gap_m: tuple[float, float] | None = None  # tip-equivalent stopper gaps from the config; None: learn them
    dwell: int = field(default=2, metadata={"min": 1})  # clear windows a new regime must hold (see decide)
    max_dwell: int = field(default=8, metadata={"min": 1})  # ... or windows of any kind
    hysteresis: float = field(default=0.2, metadata={"min": 0.0, "max": 0.49})
    distortion_on: float = field(default=3e-4, metadata={"gt": 0.0})  # distortion power ratio at p = 0.5
    distortion_scale: float = field(default=0.5, metadata={"gt": 0.0})  # decades per unit of log-odds
    significance: float = field(default=0.5, metadata={"gt": 0.0})  # excess over the band's noise power
    gap_scale: float = field(default=0.03, metadata={"gt": 0.0})  # log amplitude / gap per unit log-odds
    min_frequency_hz: float = field(default=2.0, metadata={"gt": 0.0})
    # the share of one beam's excess power that the coupling may carry into the other: small at the
    # harmonics (far above the first modes), larger in the impact band (the beams' higher modes are alike)
    cross_talk: float = field(default=0.05, metadata={"min": 0.0})
    cross_talk_impact: float = field(default=0.3, metadata={"min": 0.0})
    prior: float = -1.0  # log-odds of hitting before any evidence


@dataclass(frozen=True)
class BeamState:
    """One beam in one window: the features, the evidence and the decision."""

    hitting: bool  # after hysteresis
    probability: float  # of hitting, this window
    confidence: float  # max(p, 1 - p)
    displacement_m: float  # relative displacement amplitude at the drive frequency
    peak_displacement_m: float  # peak of the relative displacement waveform (harmonics 1-8 of the drive)
    gap_m: float  # from the config, or learned (nan until learned)
    distortion: float  # harmonic-band power over the fundamental's, floor and base removed
    odd_distortion: float  # the part at 3 f and 5 f
    impact_ratio: float  # the part above 5.5 f (the higher modes: high harmonics, impact ringing)
    significant: bool  # the excess stands out of the noise floor
    natural_frequency_hz: float  # harmonic-balance (equivalent linear) natural frequency
    free_frequency_hz: float  # learned from windows judged free (nan until learned)
    phase_deg: float  # tip against the base at the drive frequency (tip lags: negative)
    sign: int  # the tip's sign against the base, from the energy flow
    evidence: tuple[float, float, float]  # log-odds from distortion, amplitude/gap, stiffness
    impact_rms: float  # m/s^2 in the impact band above the floor
    cross_talk: float  # share of the other beam's harmonic excess removed as the coupling's (bound or learned)


@dataclass(frozen=True)
class RegimeWindow:
    t_s: float  # end of the window, seconds since the start of the stream
    label: str  # the reported (debounced) regime
    raw_label: str  # this window's label before the dwell
    drive_frequency_hz: float
    beams: tuple[BeamState, BeamState]
    amplitude_ratio: float  # displacement amplitude tip1 / tip2 (localisation)
    periods: float = float("nan")  # the drive's periods in the window (below MIN_PERIODS the harmonics are leakage)
    provisional: bool = False  # before the starting regime is decided (``decide``): the label is this window's guess

    @property
    def impact_rms(self) -> tuple[float, float]:
        return (self.beams[0].impact_rms, self.beams[1].impact_rms)

    @property
    def phase_deg(self) -> tuple[float, float]:
        return (self.beams[0].phase_deg, self.beams[1].phase_deg)

    @property
    def confidence(self) -> float:
        """The regime's confidence: the product of the beams' confidences."""
        return self.beams[0].confidence * self.beams[1].confidence


@dataclass(frozen=True)
class RegimeChange:
    t_s: float
    regime: str
    previous: str
    confidence: float = float("nan")


@dataclass(frozen=True)
class SlowDrive:
    """The drive has held fewer than ``MIN_PERIODS`` periods in every window for ``SLOW_WINDOWS`` windows
    running: the window's leakage then reads as distortion, and a free beam may read as hitting."""

    t_s: float  # end of the window at which it was said
    drive_frequency_hz: float
    periods: float  # the drive's periods in that window
    window_s: float  # the monitor's window

    @property
    def window_needed_s(self) -> float:
        """The shortest window, in half seconds, that holds ``MIN_PERIODS`` periods (0 without a drive)."""
        f = self.drive_frequency_hz
        return math.ceil(2 * MIN_PERIODS / f) / 2 if f > 0 else 0.0

    @property
    def message(self) -> str:
        need = self.window_needed_s
        return (f"the drive at {self.drive_frequency_hz:.2f} Hz makes {self.periods:.1f} periods in the regime "
                f"monitor's {self.window_s:g} s window, fewer than {MIN_PERIODS:g}: the window's leakage puts more "
                f"than the distortion threshold into the harmonics, so a free beam may read as hitting"
                + (f"; give --regime-window {need:g} or more" if need else ""))


class SlowDriveWatch:
    """Follows the windows' periods and says once (``update`` returns a ``SlowDrive``) when the drive has
    stayed too slow for the window for ``SLOW_WINDOWS`` windows running (2 s at the 0.25 s hop): not while a
    drive merely stops or starts. The live pipeline and a campaign's regimes use the same rule."""

    def __init__(self, window_s: float):
        self.window_s = window_s
        self.said = False
        self._run = 0  # consecutive windows with fewer than MIN_PERIODS periods

    def update(self, windows: list[RegimeWindow]) -> SlowDrive | None:
        found = None
        for w in windows:
            self._run = self._run + 1 if w.periods < MIN_PERIODS else 0
            if self._run == SLOW_WINDOWS and found is None and not self.said:
                found = SlowDrive(w.t_s, w.drive_frequency_hz, w.periods, self.window_s)
        self.said = self.said or found is not None
        return found


@dataclass(frozen=True)
class Decision:
    """The regime decision carried from window to window (see ``decide``)."""

    hit: tuple[bool, bool] = (False, False)  # each beam's state after hysteresis
    label: str = LABELS[0]  # the reported regime
    candidate: str = LABELS[0]  # this window's label (after hysteresis, before the dwell)
    held: int = 0  # consecutive windows the candidate has been the label, this one included
    clear: int = 0  # ... of them clear: every beam's probability outside the hysteresis band
    started: bool = False  # the starting regime is decided (at the PHASE_WINDOWS-th window)
    seen: int = 0  # windows decided so far, counted until the start


def decide(prev: Decision, p: tuple[float, float], cfg: RegimeConfig) -> tuple[Decision, bool]:
    """One window's regime from the beams' probabilities of hitting: (decision, whether the reported regime
    changed). Pure; the only place where the regime is decided.

    - **Hysteresis**, per beam: a free beam is called hitting when p > 0.5 + h, a hitting one free again
      when p <= 0.5 - h (h = ``cfg.hysteresis``). The pair of states gives the window's label.
    - **Dwell**: a label other than the reported regime is reported once it has been the label of
      ``cfg.dwell`` *clear* windows with no other label in between, or of ``cfg.max_dwell`` windows of
      any kind. A window is clear when the p of every beam whose state differs from the reported regime
      (of every beam, while none does) lies outside the hysteresis band [0.5 - h, 0.5 + h], i.e. when it
      would set those beams' states whatever they were before. Windows with p inside the band
      (a beam grazing its stopper, the beating while a drive change passes) keep the label they inherit
      from the hysteresis but neither count towards the dwell nor break it: a regime that only flickers
      in through the band is not reported, a change that the data shows clearly is reported at exactly
      its ``dwell``-th window (with the defaults the second, 0.25 s after the first, as before), and a
      regime that stays unclear is still reported at its ``max_dwell``-th window (1.75 s after the first).
    - The starting regime (no change) is each beam's likelier state, p > 0.5, decided at the
      ``PHASE_WINDOWS``-th window: the phase rules sum that many windows, and the start must not rest on
      less evidence than any later decision. The windows before it carry their own likelier states as a
      provisional label (``RegimeWindow.provisional``) and report nothing. Independent regime seed 6015,
      held in "both" for 10 minutes: beam 2's first window at p = 0.27 (its harmonics taken for the
      coupling's before the stream had measured the coupling, the phase rules not yet summed), so the
      stream started "beam 1 hitting" and reported "both" 0.75 s later, a false change; at the third
      window both beams stand at p = 0.97. Hysteresis holds a state against evidence inside its band; at
      the start there is none to hold.
      Independent regime seed 6023, held in "both" for 10 minutes with the gaps learned: beam 1 at
      p = 0.49-0.62 throughout, so the free start the hysteresis gave (p > 0.7 to call it hitting) was
      never left: 0 % of the windows right, 100 % with this rule (``daq bench --regimes``, stop 46).

    Measured on the independent generator's programmes through the four regimes (those of ``daq bench
    --regimes``, seeds 0-15, where the thresholds were set): false changes 30 -> 22 against the plain
    two-window dwell, the same changes reported within 1 s; a longer plain dwell (three windows) gives
    17 but reports three changes late. Most false changes left are real intermediate regimes shorter
    than the benchmark's 1 s (one beam leaving its stopper a few periods before the other): a causal
    monitor cannot skip those without reporting some true changes later than 1 s.
    """
    h = cfg.hysteresis
    if not prev.started:  # the starting regime: each beam's likelier state (there is no state yet to hold)
        hit = tuple(bool(pi > 0.5) for pi in p)
    else:
        hit = tuple(bool(pi > 0.5 - h) if was else bool(pi > 0.5 + h) for pi, was in zip(p, prev.hit))
    raw = label_of(*hit)
    # the evidence for a change is carried by the beams that change: one beam leaving its stopper clearly
    # while the other grazes inside the band counts (independent regime seed 1012: both -> beam 2 alone
    # for 1.26 s, beam 1 clearly free, beam 2's p inside the band, so no window was clear)
    was = _hits_of(prev.label)
    moving = [i for i in range(2) if hit[i] != was[i]] or [0, 1]
    clear = all(p[i] > 0.5 + h or p[i] <= 0.5 - h for i in moving)
    if not prev.started:
        seen = prev.seen + 1
        return Decision(hit, raw, raw, 1, int(clear), seen >= PHASE_WINDOWS, seen), False
    held, n_clear = (prev.held + 1, prev.clear + int(clear)) if raw == prev.candidate else (1, int(clear))
    changed = raw != prev.label and (n_clear >= cfg.dwell or held >= cfg.max_dwell)
    return Decision(hit, raw if changed else prev.label, raw, held, n_clear, True), changed


@dataclass(frozen=True)
class RegimeState:
    """Everything the monitor carries from one block to the next (treated as immutable)."""

    cfg: RegimeConfig
    buf: np.ndarray  # (<= n_window, 3) the last samples
    since_hop: int  # samples since the last window end
    n_seen: int
    power_flow: np.ndarray  # (2,) accumulated Im(conj(B) T_i): negative for a tip with the base's sign
    floors: np.ndarray  # (k, 3) recent windows' spectral floors per bin (the sensor noise is their low quantile)
    free_z: tuple[np.ndarray, np.ndarray]  # displacement amplitudes of windows the distortion called free
    hit_z: tuple[np.ndarray, np.ndarray]  # ... called hitting
    free_w: tuple[np.ndarray, np.ndarray]  # harmonic-balance natural frequencies of free windows
    cross: tuple[np.ndarray, np.ndarray]  # (k, 3) per beam: drive frequency, its excess over the other's (harmonic, impact)
    decision: Decision
    # per beam, the last PHASE_WINDOWS windows' third-harmonic component in phase with the other beam's and its
    # noise variance ((0, 0) where the other beam's third harmonic was too weak to give a phase): see _own_contact
    in_phase: tuple[tuple[tuple[float, float], ...], tuple[tuple[float, float], ...]] = ((), ())
    # ... and the component of its third harmonic in the contact phase of its own fundamental (see _clipping)
    clipping: tuple[tuple[tuple[float, float], ...], tuple[tuple[float, float], ...]] = ((), ())


def regime_start(cfg: RegimeConfig = RegimeConfig()) -> RegimeState:
    if cfg.window_s < cfg.hop_s:
        raise ValueError(f"window_s {cfg.window_s} must not be shorter than hop_s {cfg.hop_s}")
    if cfg.gap_m is not None and not (len(cfg.gap_m) == 2 and all(g > 0 for g in cfg.gap_m)):
        raise ValueError(f"gap_m must be two positive gaps in metres (tip 1, tip 2), got {cfg.gap_m}")
    if int(round(cfg.window_s * cfg.fs_hz)) < 32:
        raise ValueError(f"window_s {cfg.window_s} s holds fewer than 32 samples at {cfg.fs_hz} Hz")
    empty = (np.zeros(0), np.zeros(0))
    cross = (np.zeros((0, 3)), np.zeros((0, 3)))
    return RegimeState(cfg, np.zeros((0, 3)), 0, 0, np.zeros(2), np.zeros((0, 3)), empty, empty, empty, cross,
                       Decision())


def regime_step(state: RegimeState, block: np.ndarray) -> tuple[RegimeState, list[RegimeWindow], list[RegimeChange]]:
    """Feed a block (n, 3) of unfiltered base, tip1, tip2 [m/s^2]; the windows completed in it."""
    x = np.asarray(block, float)
    if x.ndim != 2 or x.shape[1] != 3:
        raise ValueError(f"regime monitor needs blocks of shape (n, 3), got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise ValueError("block contains NaN or inf")
    cfg = state.cfg
    n_win = int(round(cfg.window_s * cfg.fs_hz))
    n_hop = max(1, int(round(cfg.hop_s * cfg.fs_hz)))
    done = []  # (samples, samples seen at its end) of every window the block completes
    buf, since, n_seen = state.buf, state.since_hop, state.n_seen
    i = 0
    while i < len(x):
        piece = x[i:i + n_hop - since]
        i += len(piece)
        buf = np.concatenate([buf, piece])[-n_win:]
        since += len(piece)
        n_seen += len(piece)
        if since == n_hop:
            since = 0
            if len(buf) == n_win:
                done.append((buf, n_seen))
    windows, changes = [], []
    if done:  # the spectra depend on the samples alone: all of the block's windows at once
        spectra = spectral_batch(np.stack([b for b, _ in done]), cfg.fs_hz, cfg.min_frequency_hz)
        for (_, end), sp in zip(done, spectra):
            state, w, ch = _window(state, sp, end / cfg.fs_hz)
            windows.append(w)
            if ch is not None:
                changes.append(ch)
    state = replace(state, buf=buf, since_hop=since, n_seen=n_seen)
    return state, windows, changes


def starting(windows: list[RegimeWindow]) -> RegimeWindow | None:
    """The window that decides the starting regime (the first not provisional), if these windows hold it."""
    return next((w for w in windows if not w.provisional), None)


class RegimeMonitor:
    """The pure stage with its state held: ``step(block) -> (windows, changes)``."""

    def __init__(self, cfg: RegimeConfig = RegimeConfig()):
        self.state = regime_start(cfg)
        self.cfg = cfg

    def step(self, block: np.ndarray) -> tuple[list[RegimeWindow], list[RegimeChange]]:
        self.state, windows, changes = regime_step(self.state, block)
        return windows, changes

    @property
    def label(self) -> str:
        return self.state.decision.label


@dataclass(frozen=True)
class _Spectral:
    f_hz: float
    phasors: np.ndarray  # (3,) complex amplitudes at f
    harmonics: np.ndarray  # (H, 3) complex amplitudes at n f, n = 1 .. H (H = PEAK_HARMONICS, below 0.45 fs); at
    # 3 f less the fundamental's own leakage through the window (``_leakage``)
    fundamental: np.ndarray  # (3,) power in [0.5 f, 1.5 f]
    harmonic: np.ndarray  # (3,) power in [1.5 f, HARMONIC_TOP f] (distortion)
    odd: np.ndarray  # (3,) power within f / 4 of 3 f and 5 f
    impact: np.ndarray  # (3,) power in [HARMONIC_TOP f, 0.3 fs] (the higher modes: high harmonics, impact ringing)
    bins: tuple[int, int, int]  # bins in the harmonic band, at the odd harmonics, in the impact band
    floor: np.ndarray  # (3,) this window's floor per bin (a low quantile of both bands)
    power_scale: float  # one-sided power in (m/s^2)^2 per unit of summed bins
    phasor_scale: float  # a phasor's noise power (|noise|^2 expected) per unit of the floor's per-bin power
    envelope: float  # largest |log| ratio of a channel's amplitude at f in the window's second half to its first's


@lru_cache(maxsize=16)
def _window_arrays(n: int, fs_hz: float) -> tuple[np.ndarray, np.ndarray, float, np.float64, np.ndarray]:
    """Hann window, sample times, the window's power normalisation and its sum, and the Hann window of either
    half (n // 2 samples), per window length and rate."""
    w = np.hanning(n)
    return w, np.arange(n) / fs_hz, float(np.sum(w**2)), w.sum(), np.hanning(n // 2)


def spectral_features(x: np.ndarray, fs_hz: float, min_frequency_hz: float = 2.0) -> _Spectral:
    """Drive frequency, phasors and band powers of one window (n, 3)."""
    return spectral_batch(np.asarray(x, float)[None], fs_hz, min_frequency_hz)[0]


def spectral_batch(xs: np.ndarray, fs_hz: float, min_frequency_hz: float = 2.0) -> list[_Spectral]:
    """``spectral_features`` of W windows (W, n, 3) at once (a block's windows: one FFT, one call per kernel).

    The element-wise work around the FFT (removing the mean and windowing, the power spectrum, its
    peak, the band sums and the floor's order statistic, the halves' phasors at f) runs in compiled
    kernels (``_windowed``, ``_power``, ``_bands``, ``_half_phasors``) that reproduce numpy's order of
    operations; the FFT is scipy's (numpy's pocketfft numbers, faster on a batch of rows), the harmonics'
    basis and its product with the window numpy's. The features are bit for bit those of the plain
    per-window numpy expressions the monitor had (every window of ``daq bench --regimes``' cached cases
    and of the recordings was checked); in numpy, one window at a time, they took half the monitor's
    time in calls on small arrays. The third harmonic's phasors then have the fundamental's own leakage
    through the window taken out (``_leakage``, since stop 61).
    """
    xs = np.require(xs, float, "CW")  # one compiled signature
    n_w, n = xs.shape[0], xs.shape[1]
    w, t, w2, w_sum, w_half = _window_arrays(n, float(fs_hz))
    xw = _windowed(xs, w)  # (W, 3, n): channels in rows, for the FFT
    pad = 4
    nfft = pad * n
    spec = scipy.fft.rfft(xw, nfft, axis=-1)
    df = fs_hz / nfft
    top = 0.3 * fs_hz
    lo = int(np.ceil(min_frequency_hz / df))
    hi = max(lo + 1, int(top / df))
    if lo >= spec.shape[-1]:
        raise ValueError(f"min_frequency_hz {min_frequency_hz} lies above the Nyquist frequency {fs_hz / 2}")
    p, peaks = _power(spec, lo, hi)  # (W, 3, nfft / 2 + 1) and each window's base peak bin in [lo, hi)
    fs_ = []
    for q in range(n_w):
        k = int(peaks[q])
        delta = 0.0
        if 0 < k < p.shape[-1] - 1:  # parabolic interpolation of the log peak
            a, b, c = np.log(p[q, 0, k - 1:k + 2] + 1e-300)
            den = a - 2 * b + c
            if den < 0:
                delta = 0.5 * (a - c) / den
        fs_.append(float((k + delta) * df))
    f = np.array(fs_)
    n_hs = [max(1, min(PEAK_HARMONICS, int(0.45 * fs_hz / fq))) if fq > 0 else 1 for fq in fs_]
    basis = np.empty((n_w, max(n_hs), n), complex)  # exp(-2 pi i h f t), h = 1 .. H, by products of the fundamental's
    basis[:, 0] = np.exp(-2j * np.pi * f[:, None] * t)
    for h in range(1, basis.shape[1]):
        np.multiply(basis[:, h - 1], basis[:, 0], out=basis[:, h])
    fund, harm, imp, odd, low, bins = _bands(p, f, df, top, HARMONIC_TOP, FLOOR_QUANTILE)
    floor = low / _FLOOR_NORM  # (zero where the bands are empty)
    scale = 2.0 / (n * w2 * pad)
    # white noise of variance s2 puts s2 sum(w^2) into each bin and 4 s2 sum(w^2) / sum(w)^2 into a phasor
    phasor = float(4.0 / w_sum**2)
    # each channel's amplitude at f in either half of the window (Hann windows of half the length)
    halves = np.abs(_half_phasors(xs, basis, w_half))
    envelope = np.max(np.abs(np.log((halves[1] + 1e-300) / (halves[0] + 1e-300))), axis=1)
    out = []
    for q in range(n_w):
        harmonics = 2 * (basis[q, :n_hs[q]] @ xw[q].T) / w_sum
        if n_hs[q] > 2:  # the fundamental's own leakage through the window taken out of the third harmonic
            harmonics[2] -= _leakage(harmonics[0], 2 * np.pi * fs_[q] / fs_hz, n, float(w_sum))
        out.append(_Spectral(fs_[q], harmonics[0], harmonics, fund[q], harm[q], odd[q], imp[q],
                             (int(bins[q, 0]), int(bins[q, 1]), int(bins[q, 2])), floor[q], scale, phasor,
                             float(envelope[q])))
    return out


def _geometric(theta: float, n: int) -> complex:
    """sum_{t < n} e^{i theta t} (n where e^{i theta} is 1: a short window can put 2 f at the Hann window's
    own frequency, 1 / (2 window), above the 2 Hz floor of drive frequencies)."""
    z = cmath.exp(1j * theta)
    return complex(n) if abs(1 - z) < 1e-12 else (1 - cmath.exp(1j * theta * n)) / (1 - z)


def _hann_sum(theta: float, n: int) -> complex:
    """sum_t w_t e^{i theta t} of numpy's Hann window of n samples, w_t = (1 - cos(2 pi t / (n - 1))) / 2."""
    phi = 2 * math.pi / (n - 1)
    return 0.5 * _geometric(theta, n) - 0.25 * (_geometric(theta + phi, n) + _geometric(theta - phi, n))


def _leakage(fundamental: np.ndarray, omega: float, n: int, w_sum: float) -> np.ndarray:
    """The phasor at 3 f (3,) that the fundamental alone (each channel's phasor c at f; ``omega`` = 2 pi f / fs
    per sample) puts there through the window: the sinusoid Re(c e^{i omega t}), its mean removed and
    windowed as the data are, projected as the harmonics are (2 / sum(w) sum_t w_t (.) e^{-3 i omega t}):
    c P + conj(c) Q, with P = (W(-2 omega) - m W(-3 omega)) / sum(w), Q = (W(-4 omega) - conj(m) W(-3 omega))
    / sum(w), W(theta) the Hann window's sum against e^{i theta t} and m the mean of e^{i omega t} over the
    window, all in closed form (``_hann_sum``; a window's sums would cost the monitor a tenth of its time).

    A pure sine's projection on its third harmonic is not zero in a window of a few periods: the Hann
    window's transform two and four harmonics away from the fundamental. A linear rig with 60 dB of sensor
    noise driven at 7.6 Hz (3.8 periods; ``tests/test_regimes.py``'s sine rig): the clipping rule's sum over
    three windows stood more than PHASE_Z noise deviations out, in the phase a stopper gives (``_clipping``),
    in 32 % of the beam-windows (up to 11.8) with the leakage left in, 1 % with it taken out (at 9.2 Hz 3 %
    either way). Only the third harmonic is corrected: the phase rules read it, and the others enter only
    the reconstructed peak displacement, where the leakage is a few parts in ten thousand."""
    w3 = _hann_sum(-3 * omega, n)
    m = _geometric(omega, n) / n
    p = (_hann_sum(-2 * omega, n) - m * w3) / w_sum
    q = (_hann_sum(-4 * omega, n) - m.conjugate() * w3) / w_sum
    return fundamental * p + fundamental.conj() * q


@njit(cache=True, nogil=True)
def _column_means(x, out):  # pragma: no cover - compiled
    """x.mean(axis=0) of one window x (n, c) into out (c,), as numpy's axis-0 mean of a C-contiguous array
    does it: the rows added in order, then divided by n."""
    n, c = x.shape
    out[:] = 0.0
    for i in range(n):
        for j in range(c):
            out[j] += x[i, j]
    for j in range(c):
        out[j] = out[j] / n


@njit(cache=True, nogil=True)
def _windowed(xs, w):  # pragma: no cover - compiled
    """(x - x.mean(axis=0)) * w[:, None] of every window x in xs (W, n, c), transposed to (W, c, n), the mean
    as numpy takes it (``_column_means``)."""
    n_w, n, c = xs.shape
    out = np.empty((n_w, c, n))
    m = np.empty(c)
    for q in range(n_w):
        _column_means(xs[q], m)
        for i in range(n):
            for j in range(c):
                out[q, j, i] = (xs[q, i, j] - m[j]) * w[i]
    return out


@njit(cache=True, nogil=True)
def _half_phasors(xs, basis, w_half):  # pragma: no cover - compiled
    """The phasors at f of either half of every window x in xs (W, n, c), (2, W, c): for k = 0 and m
    (m = n // 2), np.einsum("wt,wtc->wc", basis[:, 0, k:k + m] * w_half, centred[:, k:k + m]), with centred
    = xs - xs.mean(axis=1, keepdims=True) and basis (W, H, n) complex, row 0 the fundamental's. Bit for bit
    numpy's: the mean as in ``_column_means``; a complex times a real as numpy's complex product with the real
    promoted (imaginary part zero), in the product with the window and in einsum's, which adds the terms in
    order from zero (checked on random batches of 1-300 windows of 250-2,500 samples; tests/test_regimes.py
    keeps checking). In numpy, a block's two windows spent 80 us here, a fifth of their spectra."""
    n_w, n, c = xs.shape
    m = n // 2
    out = np.zeros((2, n_w, c), np.complex128)
    mean = np.empty(c)
    for q in range(n_w):
        _column_means(xs[q], mean)
        for h in range(2):
            k = h * m
            for j in range(c):
                re = 0.0
                im = 0.0
                for i in range(m):
                    b = basis[q, 0, k + i]
                    br = b.real * w_half[i] - b.imag * 0.0  # basis * w_half
                    bi = b.real * 0.0 + b.imag * w_half[i]
                    x = xs[q, k + i, j] - mean[j]
                    re += br * x - bi * 0.0  # einsum's product with x + 0j
                    im += br * 0.0 + bi * x
                out[h, q, j] = complex(re, im)
    return out


@njit(cache=True, nogil=True)
def _power(spec, lo, hi):  # pragma: no cover - compiled
    """(|spec|^2 as re^2 + im^2 of spec (W, c, bins), per window the first bin of the largest power of row 0
    in [lo, hi), as np.argmax)."""
    n_w, c, nb = spec.shape
    p = np.empty((n_w, c, nb))
    peaks = np.empty(n_w, np.int64)
    for q in range(n_w):
        for j in range(c):
            for i in range(nb):
                v = spec[q, j, i]
                p[q, j, i] = v.real * v.real + v.imag * v.imag
        k = lo
        for i in range(lo, min(hi, nb)):
            if p[q, 0, i] > p[q, 0, k]:
                k = i
        peaks[q] = k
    return p, peaks


@njit(cache=True, nogil=True)
def _first_bin(freq_hz, df, n_bins):  # pragma: no cover - compiled
    """The first bin at or above freq_hz (at most n_bins)."""
    return min(n_bins, int(np.ceil(freq_hz / df - 1e-9)))


@njit(cache=True, nogil=True)
def _bands(p, f, df, top, split, quantile):  # pragma: no cover - compiled
    """The band powers of ``_Spectral`` per window q and row of p (W, c, bins; bins df apart), f[q] the
    window's drive frequency: sums over [0.5 f, 1.5 f), [1.5 f, split f), [split f, top) and within f / 4 of
    3 f and 5 f (each added bin by bin from its first, as numpy's sum along the rows' axis); the
    ``quantile`` (lower order statistic) of the bins in [1.5 f, top) (exact whatever the selection
    algorithm; zero if there are none); the bins in the harmonic band, at the odd harmonics and in the
    impact band."""
    n_w, c, nb = p.shape
    fund, harm, imp = np.zeros((n_w, c)), np.zeros((n_w, c)), np.zeros((n_w, c))
    odd, low = np.zeros((n_w, c)), np.zeros((n_w, c))
    bins = np.zeros((n_w, 3), np.int64)
    for q in range(n_w):
        fq = f[q]
        i_f, i_h = _first_bin(0.5 * fq, df, nb), _first_bin(1.5 * fq, df, nb)
        i_i, i_top = _first_bin(min(split * fq, top), df, nb), _first_bin(top, df, nb)
        i_i = max(i_h, i_i)
        n_odd = 0
        for m in (3, 5):
            a0 = max(_first_bin((m - 0.25) * fq, df, nb), i_h)
            a1 = min(_first_bin((m + 0.25) * fq, df, nb), i_i)
            if a1 > a0:
                n_odd += a1 - a0
                for j in range(c):
                    part = 0.0
                    for i in range(a0, a1):
                        part += p[q, j, i]
                    odd[q, j] += part
        r = min(i_top - i_h - 1, int(quantile * (i_top - i_h - 1)))
        for j in range(c):
            for i in range(i_f, i_h):
                fund[q, j] += p[q, j, i]
            for i in range(i_h, i_i):
                harm[q, j] += p[q, j, i]
            for i in range(i_i, i_top):
                imp[q, j] += p[q, j, i]
            if i_top > i_h:
                low[q, j] = _kth(p[q, j, i_h:i_top], r)
        bins[q, 0], bins[q, 1], bins[q, 2] = i_i - i_h, n_odd, i_top - i_i
    return fund, harm, imp, odd, low, bins


def _low_quantile(a: np.ndarray, q: float) -> np.ndarray:
    """The q-quantile (lower order statistic) of each column of a (n, c), or of a (n,): the k-th smallest
    (k = int(q (n - 1))), an order statistic, so the same number whichever way it is found; a compiled
    selection (``_column_kth``) costs a fraction of np.partition's call on these few hundred numbers."""
    k = min(len(a) - 1, int(q * (len(a) - 1)))
    return _column_kth(a, k) if a.ndim == 2 else _column_kth(a[:, None], k)[0]


@njit(cache=True, nogil=True)
def _column_kth(a, k):  # pragma: no cover - compiled
    """The k-th smallest value of each column of a (n, c)."""
    out = np.empty(a.shape[1])
    for j in range(a.shape[1]):
        out[j] = _kth(a[:, j], k)
    return out


@njit(cache=True, nogil=True)
def _kth(a, k):  # pragma: no cover - compiled
    """The k-th smallest value of a (n,), a left as it is. Above 256 values the search is narrowed first
    (Floyd and Rivest's idea): a sorted sample of every (n // 63)-th value brackets the k-th, one pass counts
    the values below the bracket and gathers those inside it (without branches), and only these few are
    partitioned; should the bracket miss (it cannot be wrong, only unlucky), the whole array is. The
    spectra's floors select among a thousand bins per channel, where a partition of all of them spent
    most of its time on mispredicted branches."""
    n = a.shape[0]
    if n < 256:
        return np.partition(a.copy(), k)[k]
    s = np.sort(a[::max(1, n // 63)])
    r = k * s.shape[0] // n
    lo, hi = s[max(0, r - 3)], s[min(s.shape[0] - 1, r + 4)]
    inside = np.empty(n)
    below = 0
    m = 0
    for i in range(n):
        v = a[i]
        below += v < lo
        inside[m] = v
        m += (v >= lo) & (v <= hi)
    if below <= k < below + m:
        return np.partition(inside[:m], k - below)[k - below]
    return np.partition(a.copy(), k)[k]


# the monitor's compiled kernels (ident.live.pipeline.warm_up)
KERNELS = (_windowed, _half_phasors, _power, _bands, _column_kth)


def _clip(v: float, lo: float, hi: float) -> float:
    """np.clip for one number (NaN stays NaN), without numpy's per-call overhead on scalars."""
    return float(min(max(v, lo), hi))


def _angle_deg(q: complex) -> float:
    """np.degrees(np.angle(q)) for one number (np.angle's arctan2, without its conversions)."""
    return float(np.degrees(np.arctan2(q.imag, q.real)))


def _logistic(s: float) -> float:
    return float(1.0 / (1.0 + np.exp(-s)))


def _evidence(power: float, noise: float, fund: float, cfg: RegimeConfig) -> tuple[float, float, bool]:
    """(ratio to the fundamental, log-odds, significant) of an excess power over a band's noise power."""
    excess = power - noise
    ratio = excess / fund
    if excess > cfg.significance * noise:
        e = _clip(np.log10(max(ratio, 1e-9) / cfg.distortion_on) / cfg.distortion_scale, -3, 3)
        return ratio, e, True
    hidden = max(noise * cfg.significance, 0.0) / fund  # the most the noise could hide
    return ratio, _clip(np.log10(max(hidden, 1e-12) / cfg.distortion_on) / cfg.distortion_scale, -3, 0), False


def _window(state: RegimeState, sp: _Spectral, t_end: float) -> tuple[RegimeState, RegimeWindow, RegimeChange | None]:
    """One window's features, evidence and decision from its spectrum and what the stream has taught."""
    cfg = state.cfg
    f = sp.f_hz
    omega = 2 * np.pi * f
    base = sp.phasors[0]
    flow = state.power_flow + np.array([np.imag(np.conj(base) * sp.phasors[1 + i]) for i in range(2)])
    signs = tuple(1 if v <= 0 else -1 for v in flow)
    floors = np.vstack([state.floors, sp.floor[None, :]])[-LEARN_WINDOWS:]
    floor = np.minimum(sp.floor, _low_quantile(floors, 0.1))  # sensor noise: stationary, the quiet windows'
    nh, nodd, ni = sp.bins
    # the band powers as Python floats: the same arithmetic as on numpy's scalars, at a fraction of the cost
    fl, harm, imp, fund_, odd_ = (a.tolist() for a in (floor, sp.harmonic, sp.impact, sp.fundamental, sp.odd))
    # what the base's own distortion would put into a tip (transmissibility above resonance <= about 1)
    base_h = max(0.0, harm[0] - fl[0] * nh)
    base_i = max(0.0, imp[0] - fl[0] * ni)
    beams, probs = [], []
    free_z, hit_z, free_w = list(state.free_z), list(state.hit_z), list(state.free_w)
    cross = list(state.cross)
    in_phase, clipping = [], []
    zs = []
    # excess powers of both tips above the floor, the base's share removed
    ex_h = [harm[j] - fl[j] * nh - base_h for j in (1, 2)]
    ex_i = [imp[j] - fl[j] * ni - base_i for j in (1, 2)]
    for i in range(2):
        j = 1 + i
        o = 1 - i
        tip = signs[i] * sp.phasors[j]
        rel = tip - base
        z = float(abs(rel) / omega**2) if omega > 0 else 0.0
        zs.append(z)
        w2 = omega**2 * float((tip / rel).real) if abs(rel) > 0 else float("nan")
        fn = math.sqrt(w2) / (2 * np.pi) if w2 > 0 else float("nan")
        phase = _angle_deg(tip / base) if abs(base) > 0 else float("nan")
        fund = max(fund_[j], 1e-300)
        # what the other beam's distortion puts into this one through the coupling
        recent = (state.in_phase[i] + (_in_phase(sp.harmonics, signs, i, fl, sp.phasor_scale),))[-PHASE_WINDOWS:]
        in_phase.append(recent)
        own = _own_contact(recent)
        clip_recent = (state.clipping[i] + (_clipping(sp.harmonics, signs, i, fl, sp.phasor_scale),))[-PHASE_WINDOWS:]
        clipping.append(clip_recent)
        clipped = _own_contact(clip_recent)
        # what the coupling carries into the harmonics is in anti-phase: a third harmonic in phase is this beam's
        # contact, and none of its harmonics are removed as the coupling's (the impact band's still are: there the
        # beams' higher modes, alike, carry the other's ringing at resonance, in any phase)
        ct_h, ct_i = _cross_talk(state.cross[i], f, cfg)
        ct_h = 0.0 if own or clipped else ct_h
        own_h = ex_h[i] - ct_h * max(ex_h[o], 0.0)
        own_i = ex_i[i] - ct_i * max(ex_i[o], 0.0)
        noise_h, noise_i = fl[j] * nh, fl[j] * ni
        d_h, e_h, sig_h = _evidence(own_h, noise_h, fund, cfg)
        d_i, e_i, sig_i = _evidence(own_i, noise_i, fund, cfg) if ni else (0.0, -3.0, False)
        odd = (odd_[j] - fl[j] * nodd) / fund
        # every stopper folds the motion into the harmonics, so a harmonic band that shows nothing says free;
        # ringing above it adds evidence where it stands out, but an impact band buried in noise (wide: it
        # holds most of the noise) must not mask what the harmonic band shows
        e_d = max(e_h, e_i) if sig_i else e_h
        # the share the coupling carries: this beam's excess over the other's where the other distorts clearly
        o_fund = max(fund_[2 - i], 1e-300)
        strong_h = ex_h[o] > CROSS_STRONG * max(fl[2 - i] * nh, 1e-300) and ex_h[o] / o_fund > 10 * cfg.distortion_on
        strong_i = (ni > 0 and ex_i[o] > CROSS_STRONG * max(fl[2 - i] * ni, 1e-300)
                    and ex_i[o] / o_fund > 10 * cfg.distortion_on)
        if f > 0 and (strong_h or strong_i) and not own:  # the coupling's share: from windows of no own contact
            row = np.array([[f, max(ex_h[i], 0.0) / ex_h[o] if strong_h else np.nan,
                             max(ex_i[i], 0.0) / ex_i[o] if strong_i else np.nan]])
            cross[i] = np.vstack([cross[i], row])[-LEARN_WINDOWS:]
        significant = sig_h or sig_i
        distortion = max(d_h, 0.0) + max(d_i, 0.0)
        peak = _peak_displacement(signs[i] * sp.harmonics[:, j] - sp.harmonics[:, 0], omega)
        # evidence 2: amplitude against the gap
        if cfg.gap_m is not None:  # the waveform's peak (a stopper clips it: its fundamental stays below the gap)
            gap = float(cfg.gap_m[i])
            e_a = _clip(np.log(peak / gap) / cfg.gap_scale, -2.0, 3.0) if peak > 0 else -2.0
        else:
            gap, e_a = _gap_evidence(z, free_z[i], hit_z[i], cfg)
        # evidence 3: stiffness against the free beam's (reported; not weighed: coupling and beating move it)
        f_free = float(_low_quantile(free_w[i], 0.5)) / (2 * np.pi) if len(free_w[i]) >= 8 else float("nan")
        e_k = 0.0  # reported, not weighed (see the module's docstring)
        e_d += PHASE_EVIDENCE if own or clipped else 0.0
        score = cfg.prior + e_d + e_a + e_k
        p = _logistic(score)
        probs.append(p)
        # learning from the distortion alone (never from the decision it feeds), and a hitting amplitude only in
        # a steady window (STEADY_LOG: a transient's spectrum adds distortion, so it may call a free beam hitting,
        # never a hitting one free) and where this beam's excess is not the other's seen through the coupling
        if (e_d >= 2.0 and sp.envelope <= STEADY_LOG and ex_h[i] + ex_i[i] >= 0.5 * (ex_h[o] + ex_i[o])
                and clipped):
            hit_z[i] = np.append(hit_z[i], z)[-LEARN_WINDOWS:]
        elif e_d <= -2.0 and fund > 10 * noise_h:
            free_z[i] = np.append(free_z[i], z)[-LEARN_WINDOWS:]
            if math.isfinite(fn):
                free_w[i] = np.append(free_w[i], 2 * np.pi * fn)[-LEARN_WINDOWS:]
        impact_rms = math.sqrt(max(d_i, 0.0) * fund * sp.power_scale)
        beams.append((p, max(p, 1 - p), z, peak, gap, distortion, odd, max(d_i, 0.0), significant,
                      fn, f_free, phase, signs[i], (e_d, e_a, e_k), impact_rms, ct_h))
    decision, changed = decide(state.decision, (probs[0], probs[1]), cfg)
    beams = [BeamState(h, *b) for b, h in zip(beams, decision.hit)]
    change = None
    if changed:
        change = RegimeChange(t_end, decision.label, state.decision.label, beams[0].confidence * beams[1].confidence)
    ratio = zs[0] / zs[1] if zs[1] > 0 else float("inf")
    window = RegimeWindow(t_end, decision.label, decision.candidate, f, (beams[0], beams[1]), ratio,
                          f * cfg.window_s, not decision.started)
    state = replace(state, power_flow=flow, floors=floors, free_z=tuple(free_z), hit_z=tuple(hit_z),
                    free_w=tuple(free_w), cross=tuple(cross), decision=decision,
                    in_phase=(in_phase[0], in_phase[1]), clipping=(clipping[0], clipping[1]))
    return state, window, change


def _own_contact(recent: tuple[tuple[float, float], ...]) -> bool:
    """Whether beam i's third harmonic holds a component in phase with the other beam's, significant against
    the noise over the recent windows (``_in_phase``'s (component, noise variance) of each): their sum over
    PHASE_Z standard deviations of its noise.

    A stopper on either side flattens the peaks of the motion, which puts the beam's third harmonic in one
    phase against its fundamental (one- or two-sided alike: the odd harmonics of a clipped peak do not
    depend on its side), so two beams hitting with their fundamentals near in phase show third harmonics
    in phase. What the coupling carries into a free beam is the other beam's motion pulling it through a
    spring, at 3 f, above the free beam's first mode and below its second (a cantilever's second mode lies
    above 6 times its first; the drive lies within 30 % of the first): there the beam answers as a mass, in
    anti-phase with the pull. So a significant in-phase component is this beam's own contact, which the
    share of the other's distortion removed as the coupling's (a bound until the stream has measured it)
    hides when the beam grazes its stopper beside one that hits hard.

    Each window's component counts for at most PHASE_Z of its noise deviations, so the sum of three (which
    must exceed PHASE_Z sqrt(3) deviations) needs evidence in at least two windows: a grazing beam's 2-3
    deviations a window still pass, one window's burst alone does not. At the onset of one beam's contact
    the free beam's third harmonic can stand 15-100 deviations out in the phase of a contact for a single
    window (independent regime seeds 6008 and dev 20: 53 and 107, the windows before and after within 2),
    and uncapped that window carried the sum for three windows, long enough to report "both" before the
    right regime (0.4-1.4 s late). Capped, on this host's cached cases: changes reported within 1 s fresh
    131 -> 134 of 141, held out 146 -> 147 of 147, dev 177 -> 179 of 183; false changes in the programmes 62
    -> 55, 25 -> 27, 32 -> 33; windows right 96.3 -> 96.6, 99.8, 97.0 %; none in the steady runs either way.
    """
    total = sum(min(c, PHASE_Z * math.sqrt(v)) for c, v in recent if v > 0)
    var = sum(v for _, v in recent)
    return bool(var > 0 and total > PHASE_Z * math.sqrt(var))


def _in_phase(harmonics: np.ndarray, signs: tuple[int, int], i: int, floor: list[float],
              phasor_scale: float) -> tuple[float, float]:
    """(component of beam i's third harmonic in phase with the other beam's, less what the base's third harmonic
    could put there; the variance of that component's noise), or (0, 0) where the other beam's third harmonic
    does not stand PHASE_REFERENCE times above its noise (harmonics (H, 3): the phasors at n f of base, tip 1,
    tip 2; floor: each channel's noise power per bin; a phasor's noise power is phasor_scale times it)."""
    if harmonics.shape[0] < 3:
        return 0.0, 0.0
    j, o = 1 + i, 2 - i
    t_o = signs[1 - i] * harmonics[2, o]
    if abs(t_o) ** 2 <= PHASE_REFERENCE * phasor_scale * floor[o]:
        return 0.0, 0.0
    t_i = signs[i] * harmonics[2, j]
    return float((t_i * t_o.conjugate()).real / abs(t_o) - abs(harmonics[2, 0])), 0.5 * phasor_scale * floor[j]


def _clipping(harmonics: np.ndarray, signs: tuple[int, int], i: int, floor: list[float],
              phasor_scale: float) -> tuple[float, float]:
    """(component of beam i's relative third harmonic in the phase a stopper gives it against the beam's own
    relative fundamental; the variance of that component's noise), or (0, 0) without a fundamental.

    A stopper pushes back where the relative displacement peaks: it adds to the acceleration a pulse of the
    sign of the fundamental's there, once per period on one side or twice with alternating signs on both, so
    the third harmonic R3 lies along R1^3 / |R1|^2 (Re(R3 conj(R1)^3) > 0; R the relative acceleration
    phasors). Noise and a higher mode ringing give it no phase; what the coupling carries in takes its phase
    from the other beam's harmonics (in anti-phase with them: this beam answers the pull as a mass at 3 f)."""
    if harmonics.shape[0] < 3:
        return 0.0, 0.0
    j = 1 + i
    r1 = signs[i] * harmonics[0, j] - harmonics[0, 0]
    a = abs(r1)
    if a == 0:
        return 0.0, 0.0
    r3 = signs[i] * harmonics[2, j] - harmonics[2, 0]
    return float((r3 * (r1.conjugate() / a) ** 3).real), 0.5 * phasor_scale * floor[j]


def _cross_talk(rows: np.ndarray, f: float, cfg: RegimeConfig) -> tuple[float, float]:
    """(harmonic, impact) share of the other beam's excess power that the coupling carries into this beam at
    drive frequency f: cfg's bounds, or less where this stream has shown less."""
    out = [cfg.cross_talk, cfg.cross_talk_impact]
    if len(rows) < CROSS_MIN_WINDOWS or not f > 0:
        return out[0], out[1]
    near = rows[np.abs(np.log(rows[:, 0] / f)) < CROSS_BAND]
    for k in (0, 1):
        r = near[:, 1 + k]
        r = r[np.isfinite(r)]
        if len(r) >= CROSS_MIN_WINDOWS:
            out[k] = min(out[k], CROSS_MARGIN[k] * float(_low_quantile(r, CROSS_QUANTILE)))
    return out[0], out[1]


def _peak_displacement(rel_acc: np.ndarray, omega: float) -> float:
    """Peak |z| over a period of the displacement whose acceleration harmonics are rel_acc (phasors at n w):
    z_n = -a_n / (n w)^2, evaluated on 128 phases."""
    if not omega > 0:
        return 0.0
    n, phases = _harmonic_phases(len(rel_acc))
    zn = -rel_acc / (n * omega) ** 2
    return float(np.max(np.abs(np.real(phases @ zn))))


@lru_cache(maxsize=PEAK_HARMONICS)
def _harmonic_phases(n_harmonics: int) -> tuple[np.ndarray, np.ndarray]:
    """(n = 1 .. H, exp(i n theta) on 128 phases theta over a period): the same for every window (computing
    it took as long as the rest of the peak)."""
    n = np.arange(1, n_harmonics + 1)
    theta = np.linspace(0.0, 2 * np.pi, 128, endpoint=False)
    return n, np.exp(1j * np.outer(theta, n))


def _gap_evidence(z: float, free: np.ndarray, hit: np.ndarray, cfg: RegimeConfig) -> tuple[float, float]:
    """(learned gap or nan, log-odds) of a displacement amplitude against what the distortion has shown.

    Hitting needs an amplitude at least the gap, and the gap is at most the amplitudes at which the beam
    was seen hitting: far below them a beam is free whatever else is uncertain. Where the amplitudes
    called free and those called hitting do not overlap, the gap lies between them, but where depends on
    the stopper: a rigid one clips the motion (the hitting amplitudes sit at the gap), a soft one lets the
    beam go well beyond it (they sit far above, and the largest free amplitudes just below). So only an
    amplitude below every free one or above every hitting one is evidence; in between it says nothing and
    the distortion decides (an interpolation between them called a soft stopper's grazing beam free).
    Before any free amplitude is learned, one at or above the amplitudes seen hitting is at or beyond the
    gap (the gap is at most them): evidence of hitting, as far below them is of free (where free amplitudes
    above hitting ones were seen, the learned sets disagree and say nothing).
    """
    if z <= 0:
        return float("nan"), -LEARNED_CAP
    hi = float(_low_quantile(hit, 0.05)) if len(hit) >= 8 else float("nan")
    lo = float(_low_quantile(free, 0.95)) if len(free) >= 8 else float("nan")
    if np.isfinite(hi) and np.isfinite(lo) and lo < hi:
        gap = float(np.sqrt(lo * hi))  # reported
        spread = max(cfg.gap_scale, 0.5 * float(np.log(hi / lo)))
        if z <= lo:
            return gap, _clip(np.log(z / lo) / spread, -LEARNED_CAP, 0.0)
        if z >= hi:
            return gap, _clip(np.log(z / hi) / spread, 0.0, LEARNED_CAP)
        return gap, 0.0  # where in between the gap lies depends on the stopper (see the docstring)
    if np.isfinite(hi) and z < hi:  # below every amplitude seen hitting: far below, surely free
        return float("nan"), _clip(np.log(z / hi) / 0.15, -3.0, 0.0)
    if np.isfinite(hi) and not np.isfinite(lo):  # at or above amplitudes seen hitting: at or beyond the gap
        return float("nan"), _clip(np.log(z / hi) / 0.15, 0.0, ABOVE_HIT_CAP)
    return float("nan"), 0.0
