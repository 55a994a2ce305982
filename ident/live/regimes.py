"""Regime monitor: free (``linear``), one beam hitting (``localized-1``, ``localized-2``), both.

Decision feature: impact energy, the RMS of each *unfiltered* tip signal above
``hf_cutoff_hz`` (100 Hz) over a sliding window. Contact with a stiff stopper
rings at a few hundred hertz (here about 250 Hz), while the free motion at
12.3 Hz and its harmonics stay below: on the default rig the feature is
0.02 m/s^2 (sensor noise) without contact and about 9 m/s^2 with it. Each beam's
"hitting" flag switches on above ``on_m_per_s2`` and off below ``off_m_per_s2``
(hysteresis), and a new label must persist for ``dwell`` consecutive windows
before it is reported, so the monitor does not chatter. Supporting features
reported with every window: the tip amplitude ratio (RMS tip1 / tip2 below
50 Hz) and each tip's phase to the base at the dominant frequency.

Streaming: ``RegimeMonitor.step(block)`` takes any block of samples and
returns the windows completed in it; the split does not matter.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.signal import sosfilt

from ..filters import design_highpass, design_lowpass

LABELS = ("linear", "localized-1", "localized-2", "impacting-both")


def label_of(hit1: bool, hit2: bool) -> str:
    return LABELS[int(hit1) + 2 * int(hit2)]


@dataclass(frozen=True)
class RegimeConfig:
    fs_hz: float = field(default=2000.0, metadata={"gt": 0.0})
    window_s: float = field(default=0.5, metadata={"gt": 0.0})
    hop_s: float = field(default=0.25, metadata={"gt": 0.0})
    hf_cutoff_hz: float = field(default=100.0, metadata={"gt": 0.0})
    on_m_per_s2: float = field(default=1.0, metadata={"gt": 0.0})
    off_m_per_s2: float = field(default=0.3, metadata={"gt": 0.0})
    dwell: int = field(default=2, metadata={"min": 1})


@dataclass(frozen=True)
class RegimeWindow:
    t_s: float  # end of the window, seconds since the start of the stream
    label: str  # the reported (debounced) regime
    raw_label: str  # this window's label before the dwell
    impact_rms: tuple[float, float]  # m/s^2 above hf_cutoff_hz, tip1 and tip2
    amplitude_ratio: float  # RMS tip1 / tip2 below 50 Hz
    phase_deg: tuple[float, float]  # tip1, tip2 against the base at the dominant frequency


@dataclass(frozen=True)
class RegimeChange:
    t_s: float
    regime: str
    previous: str


class RegimeMonitor:
    def __init__(self, cfg: RegimeConfig = RegimeConfig()):
        if cfg.off_m_per_s2 >= cfg.on_m_per_s2:
            raise ValueError("off_m_per_s2 must be below on_m_per_s2 (that gap is the hysteresis)")
        if cfg.hf_cutoff_hz >= cfg.fs_hz / 2:
            raise ValueError(f"hf_cutoff_hz {cfg.hf_cutoff_hz} must be below Nyquist {cfg.fs_hz / 2}")
        self.cfg = cfg
        self.hop = max(1, int(round(cfg.hop_s * cfg.fs_hz)))
        self.n_hops = max(1, int(round(cfg.window_s / cfg.hop_s)))
        self._hp = design_highpass(cfg.fs_hz, cfg.hf_cutoff_hz, 4)
        self._lp = design_lowpass(cfg.fs_hz, 50.0, 4)
        self._zhp = np.zeros((self._hp.shape[0], 2, 2))
        self._zlp = np.zeros((self._lp.shape[0], 2, 3))
        self._pend_hf = np.zeros((0, 2))
        self._pend_lf = np.zeros((0, 3))
        self._hops_hf: list[np.ndarray] = []
        self._hops_lf: list[np.ndarray] = []
        self.n_seen = 0
        self.hit = [False, False]
        self.label = "linear"
        self._cand = "linear"
        self._cand_count = 0
        self.started = False

    def step(self, block: np.ndarray) -> tuple[list[RegimeWindow], list[RegimeChange]]:
        """block: (n, 3) unfiltered base, tip1, tip2 [m/s^2]."""
        x = np.asarray(block, float)
        if x.ndim != 2 or x.shape[1] != 3:
            raise ValueError(f"regime monitor needs blocks of shape (n, 3), got {x.shape}")
        if not np.all(np.isfinite(x)):
            raise ValueError("block contains NaN or inf")
        if len(x) == 0:
            return [], []
        hf, self._zhp = sosfilt(self._hp, x[:, 1:], axis=0, zi=self._zhp)
        lf, self._zlp = sosfilt(self._lp, x, axis=0, zi=self._zlp)
        self._pend_hf = np.concatenate([self._pend_hf, hf])
        self._pend_lf = np.concatenate([self._pend_lf, lf])
        windows, changes = [], []
        while len(self._pend_hf) >= self.hop:
            self._hops_hf.append(self._pend_hf[: self.hop])
            self._hops_lf.append(self._pend_lf[: self.hop])
            self._pend_hf = self._pend_hf[self.hop:]
            self._pend_lf = self._pend_lf[self.hop:]
            self._hops_hf = self._hops_hf[-self.n_hops:]
            self._hops_lf = self._hops_lf[-self.n_hops:]
            self.n_seen += self.hop
            if len(self._hops_hf) < self.n_hops:
                continue
            w, ch = self._window(np.concatenate(self._hops_hf), np.concatenate(self._hops_lf))
            windows.append(w)
            if ch:
                changes.append(ch)
        return windows, changes

    def _window(self, hf: np.ndarray, lf: np.ndarray) -> tuple[RegimeWindow, RegimeChange | None]:
        cfg = self.cfg
        t_end = self.n_seen / cfg.fs_hz
        rms = np.sqrt(np.mean(hf**2, axis=0))
        for i in range(2):
            if self.hit[i] and rms[i] < cfg.off_m_per_s2:
                self.hit[i] = False
            elif not self.hit[i] and rms[i] > cfg.on_m_per_s2:
                self.hit[i] = True
        raw = label_of(*self.hit)
        if raw == self._cand:
            self._cand_count += 1
        else:
            self._cand, self._cand_count = raw, 1
        change = None
        if not self.started:
            self.started = True
            self.label = raw
            self._cand_count = cfg.dwell
        elif raw != self.label and self._cand_count >= cfg.dwell:
            change = RegimeChange(t_end, raw, self.label)
            self.label = raw
        lf_rms = np.sqrt(np.mean(lf**2, axis=0))
        ratio = float(lf_rms[1] / lf_rms[2]) if lf_rms[2] > 0 else float("inf")
        phases = _phases(lf, cfg.fs_hz)
        return RegimeWindow(t_end, self.label, raw, (float(rms[0]), float(rms[1])), ratio, phases), change


def _phases(lf: np.ndarray, fs: float) -> tuple[float, float]:
    """Phase of each tip against the base at the base's dominant frequency, degrees."""
    spec = np.fft.rfft(lf * np.hanning(len(lf))[:, None], axis=0)
    k = int(np.argmax(np.abs(spec[1:, 0]))) + 1
    ref = spec[k, 0]
    if abs(ref) == 0:
        return (float("nan"), float("nan"))
    return (float(np.degrees(np.angle(spec[k, 1] / ref))), float(np.degrees(np.angle(spec[k, 2] / ref))))
