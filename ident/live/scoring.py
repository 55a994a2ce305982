"""How a regime monitor's output compares with a per-sample truth (the regime benchmark's rules).

Truth: one regime code per sample (0 free, 1 beam 1 hitting, 2 beam 2 hitting, 3 both; the
code is hit1 + 2 hit2, the order of ``ident.live.regimes.LABELS``). A truth that holds for
less than ``min_run_s`` (1 s) is flicker, not a regime (a beam grazing its stopper turns the
truth's hitting flag on and off from one period to the next); a **true change** is the start
of a run of at least ``min_run_s`` whose regime differs from the previous such run's. Its
time t_c is that start; the old regime's last sample t_d (t_d <= t_c) opens the transition.

- **windows right**: the share of windows whose reported regime equals the truth at the
  window's end, not counting windows that end in [t_d, t_c + ``settle_s``) of a true
  change (the first second after it, and any flicker before it);
- **latency** of a true change: the first time at or after t_d at which the reported
  regime is the new one, less t_c (at most ``settle_s`` counts as reported in time; a
  change never reported has infinite latency);
- **false changes**: reported changes that belong to no true change (a reported change
  belongs to a true change when it reports the change's new regime within
  [t_d, t_c + ``settle_s``]); of them, **never held**: those whose new regime the raw
  truth (flicker included) held at no sample of the ``settle_s`` before the report, the
  samples its window's end covers (t_r - ``settle_s`` <= k / fs < t_r). The others report a
  regime the rig held at some sample of that second: most often a brief intermediate regime
  shorter than ``min_run_s`` (one beam leaving its stopper a few periods before the other),
  which a monitor that reports sooner reports more of, or a return to the regime the rig is in
  after a false change away from it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class TrueChange:
    t_departure_s: float
    t_s: float
    code: int
    previous: int


@dataclass(frozen=True)
class RegimeScore:
    windows: int  # scored windows
    windows_right: int
    true_changes: tuple[TrueChange, ...]
    latencies_s: tuple[float, ...]  # per true change (inf: never reported)
    false_changes: int
    reported_changes: int
    false_never_held: int = 0  # false changes to a regime the raw truth held at no sample of the settle_s before

    @property
    def share_right(self) -> float:
        return self.windows_right / self.windows if self.windows else float("nan")

    @property
    def changes_in_time(self) -> int:
        return sum(1 for v in self.latencies_s if v <= 1.0 + 1e-9)


def true_changes(codes: np.ndarray, fs_hz: float, min_run_s: float = 1.0) -> list[TrueChange]:
    """The truth's regime changes, flicker shorter than min_run_s removed."""
    codes = np.asarray(codes)
    if codes.size == 0:
        return []
    edges = np.flatnonzero(np.diff(codes) != 0) + 1
    starts = np.concatenate([[0], edges])
    ends = np.concatenate([edges, [len(codes)]])
    stable = [(s, e, int(codes[s])) for s, e in zip(starts, ends) if (e - s) / fs_hz >= min_run_s]
    out = []
    for (s0, e0, c0), (s1, e1, c1) in zip(stable, stable[1:]):
        if c1 != c0:
            out.append(TrueChange((e0 - 1) / fs_hz, s1 / fs_hz, c1, c0))
    return out


def scored_windows(window_t_s: np.ndarray, changes: list[TrueChange] | tuple[TrueChange, ...], n_truth: int,
                   fs_hz: float, settle_s: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(which windows are scored, the truth sample at each window's end): every window but those ending in
    [t_d, t_c + ``settle_s``) of a true change."""
    t = np.asarray(window_t_s, float)
    idx = np.clip(np.round(t * fs_hz).astype(int) - 1, 0, n_truth - 1)
    keep = np.ones(len(t), bool)
    for c in changes:
        keep &= ~((t >= c.t_departure_s) & (t < c.t_s + settle_s))
    return keep, idx


def score_regimes(window_t_s: np.ndarray, window_codes: np.ndarray, changes: list[tuple[float, int]],
                  truth_codes: np.ndarray, fs_hz: float, min_run_s: float = 1.0,
                  settle_s: float = 1.0) -> RegimeScore:
    """window_t_s, window_codes: every window's end time and reported regime code; changes: the reported
    changes as (time, new code); truth_codes: per sample, sample k at time k / fs_hz."""
    t = np.asarray(window_t_s, float)
    codes = np.asarray(window_codes, int)
    truth = np.asarray(truth_codes, int)
    tcs = true_changes(truth, fs_hz, min_run_s)
    keep, idx = scored_windows(t, tcs, len(truth), fs_hz, settle_s)
    right = int(np.sum(codes[keep] == truth[idx[keep]]))
    latencies = []
    for c in tcs:
        after = (t >= c.t_departure_s) & (codes == c.code)
        latencies.append(float(t[np.argmax(after)] - c.t_s) if after.any() else float("inf"))
    false = never = 0
    for tr, code in changes:
        if not any(c.t_departure_s <= tr <= c.t_s + settle_s and code == c.code for c in tcs):
            false += 1
            end = int(round(tr * fs_hz))  # the report's window ends with sample end - 1 (as ``idx`` above)
            lo, hi = max(0, end - int(round(settle_s * fs_hz))), min(len(truth), end)
            never += int(not np.any(truth[lo:hi] == code))
    return RegimeScore(int(keep.sum()), right, tuple(tcs), tuple(latencies), false, len(changes), never)
