"""Training and held-out data: interleaved blocks, and the blocks an unmodelled input spoils.

The record (filter edges cut) is cut into ``n_blocks`` equal blocks and every block whose index is 2 or
4 modulo 5 is held out (40 %), so both parts see the whole test (every amplitude step, every sweep
frequency, the start and the end of a decay). Each held-out block is predicted by a simulation that
starts ``warm`` samples before it from the state the baseline reads off the data there; its error is
one sample of the paired test that decides a finding.

Unmodelled inputs (a hammer blow on the structure, a jump between coexisting states) are transients
the measured input cannot produce. ``transients`` finds them as isolated bursts of the baseline's
error; the blocks they reach are left out of training and scoring, and the report names them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

HELD_OUT_MOD = (2, 4)  # block index modulo 5
N_BLOCKS = 20
MIN_BLOCKS = 5


def rows_of(segs) -> np.ndarray:
    """The sample indices of the segments (slices), in order."""
    return np.concatenate([np.arange(s.start, s.stop) for s in segs]) if segs else np.zeros(0, int)


@dataclass(frozen=True)
class Split:
    blocks: tuple[slice, ...]
    held_out: tuple[int, ...]
    excluded: tuple[int, ...] = ()  # blocks an unmodelled transient reaches

    @property
    def train(self) -> tuple[slice, ...]:
        return tuple(b for k, b in enumerate(self.blocks) if k not in self.held_out and k not in self.excluded)

    @property
    def test(self) -> tuple[slice, ...]:
        return tuple(b for k, b in enumerate(self.blocks) if k in self.held_out and k not in self.excluded)

    def rows(self, which: str) -> np.ndarray:
        return rows_of(self.train if which == "train" else self.test)

    def without(self, excluded) -> "Split":
        return Split(self.blocks, self.held_out, tuple(sorted(set(self.excluded) | set(excluded))))


def interleaved(n: int, edge: int, min_block: int, n_blocks: int = N_BLOCKS) -> Split:
    """``n_blocks`` equal blocks of the record with ``edge`` samples cut at each end (fewer blocks when a
    block would be shorter than ``min_block``, at least ``MIN_BLOCKS``)."""
    usable = n - 2 * edge
    k = int(min(n_blocks, usable // max(min_block, 1)))
    if k < MIN_BLOCKS:
        raise ValueError(f"the record is too short to hold out data: {usable} usable samples make fewer than "
                         f"{MIN_BLOCKS} blocks of {min_block} samples (a few periods of the slowest mode)")
    b = np.linspace(edge, n - edge, k + 1).astype(int)
    blocks = tuple(slice(int(b[i]), int(b[i + 1])) for i in range(k))
    return Split(blocks, tuple(i for i in range(k) if i % 5 in HELD_OUT_MOD))


def given(n: int, edge: int, train: slice, test: slice) -> Split:
    """The user's contiguous slices (refused when they overlap), each cut into blocks for the paired
    test: the held-out slice into up to ``N_BLOCKS`` // 2 blocks."""
    tr = slice(max(train.start, edge), min(train.stop, n - edge))
    te = slice(max(test.start, edge), min(test.stop, n - edge))
    if tr.start >= tr.stop or te.start >= te.stop:
        raise ValueError("--train and --test must each keep samples after the filter edges are cut")
    if tr.start < te.stop and te.start < tr.stop:
        raise ValueError(f"--train {train.start}:{train.stop} and --test {test.start}:{test.stop} overlap: "
                         f"held-out data must not be trained on")
    k = max(MIN_BLOCKS, min(N_BLOCKS // 2, (te.stop - te.start) // 200))
    tb = np.linspace(te.start, te.stop, k + 1).astype(int)
    test_blocks = [slice(int(tb[i]), int(tb[i + 1])) for i in range(k)]
    blocks = tuple(sorted([tr] + test_blocks, key=lambda s: s.start))
    return Split(blocks, tuple(i for i, b in enumerate(blocks) if b is not tr))


def transients(error: np.ndarray, window: int, settle: int, ratio: float = 20.0) -> list[int]:
    """Sample indices where the error (n, k) bursts and dies away: a window whose RMS (the largest over
    responses, each scaled by its median window RMS) exceeds ``ratio`` times the median of the 20
    windows before it, while the error ``settle`` to 2 ``settle`` samples later is back below twice that
    median. An effect that sets in and stays (impacts from some amplitude on) is not a transient."""
    e = np.asarray(error, float)
    n = e.shape[0] // window
    if n < 5:
        return []
    w = np.sqrt(np.mean(e[:n * window].reshape(n, window, -1) ** 2, axis=1))
    w = np.max(w / np.maximum(np.median(w, axis=0), 1e-300), axis=1)
    k1 = max(1, settle // window)
    out = []
    for i in range(1, n - 2 * k1):
        before = float(np.median(w[max(0, i - 20):i]))
        if w[i] > ratio * before and w[i] >= w[max(0, i - 20):i + k1].max() \
                and float(np.median(w[i + k1:i + 2 * k1])) < 2 * before:
            out.append(i * window)
    return out


def blocks_reached(split: Split, onsets: list[int], settle: int) -> list[int]:
    """Blocks that a transient starting at each onset reaches before it has decayed (``settle`` samples)."""
    hit = set()
    for t0 in onsets:
        for k, b in enumerate(split.blocks):
            if b.start < t0 + settle and b.stop > t0:
                hit.add(k)
    return sorted(hit)
