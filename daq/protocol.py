"""The rig's serial frame format: encoder and a pure, vectorised, streaming decoder.

Frame, version 1, 24 bytes, little-endian:

    offset size field
    0      2    sync word 0xA5 0x5A
    2      1    format version (1)
    3      1    flags: bit 0 = a channel clipped at the ADC's range
    4      4    sequence counter, uint32, +1 per frame, wraps
    8      8    device timestamp, uint64, microseconds since device start
    16     6    three channels (base, tip1, tip2), int16 ADC counts
    22     2    CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) over bytes 0..21

The :class:`Decoder` holds no port: it is fed bytes (``feed``) and returns the
frames found, like pyserial's ``Protocol.data_received``. It finds every sync
candidate and checks all CRCs in numpy at once, then resolves overlaps the way
a byte-by-byte scanner would: a valid frame consumes its 24 bytes; a candidate
whose CRC fails counts as one CRC error and the scan resumes at the next byte;
bytes that belong to no frame are counted as skipped. Sequence gaps count the
frames lost between two decoded ones.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

SYNC = b"\xa5\x5a"
VERSION = 1
FRAME_LEN = 24
FLAG_CLIPPED = 0x01

FRAME_DTYPE = np.dtype([
    ("sync", "<u2"), ("version", "u1"), ("flags", "u1"), ("seq", "<u4"), ("t_us", "<u8"),
    ("ch", "<i2", (3,)), ("crc", "<u2"),
])
assert FRAME_DTYPE.itemsize == FRAME_LEN


def _crc_table() -> np.ndarray:
    table = np.zeros(256, dtype=np.uint16)
    for i in range(256):
        c = i << 8
        for _ in range(8):
            c = ((c << 1) ^ 0x1021) if c & 0x8000 else (c << 1)
        table[i] = c & 0xFFFF
    return table


CRC_TABLE = _crc_table()


def crc16_rows(rows: np.ndarray) -> np.ndarray:
    """CRC-16/CCITT-FALSE of each row of a (n, k) uint8 array, vectorised over rows."""
    crc = np.full(rows.shape[0], 0xFFFF, dtype=np.uint16)
    for j in range(rows.shape[1]):
        idx = ((crc >> 8) ^ rows[:, j]) & 0xFF
        crc = ((crc << 8) & 0xFFFF).astype(np.uint16) ^ CRC_TABLE[idx]
    return crc


def encode(seq: np.ndarray, t_us: np.ndarray, counts: np.ndarray, flags: np.ndarray | None = None) -> bytes:
    """Frames for n samples: seq (n,), t_us (n,), counts (n, 3) int16 range, flags (n,)."""
    n = len(seq)
    fr = np.zeros(n, dtype=FRAME_DTYPE)
    fr["sync"] = 0x5AA5  # bytes A5 5A little-endian
    fr["version"] = VERSION
    fr["flags"] = 0 if flags is None else flags
    fr["seq"] = np.asarray(seq, np.uint64) & 0xFFFFFFFF
    fr["t_us"] = t_us
    fr["ch"] = np.clip(counts, -32768, 32767)
    raw = fr.view(np.uint8).reshape(n, FRAME_LEN)
    fr["crc"] = crc16_rows(raw[:, :22])
    return fr.tobytes()


@dataclass
class Counters:
    frames: int = 0
    crc_errors: int = 0
    skipped_bytes: int = 0
    dropped_frames: int = 0  # sequence gaps
    sequence_resets: int = 0  # sequence went backwards (device restarted)
    bytes_in: int = 0


@dataclass(frozen=True)
class Frames:
    """Decoded frames of one ``feed`` call, as columns."""

    seq: np.ndarray  # uint32
    t_us: np.ndarray  # uint64
    counts: np.ndarray  # (n, 3) int16
    flags: np.ndarray  # uint8
    gaps: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # frames lost before each

    def __len__(self) -> int:
        return len(self.seq)


EMPTY = Frames(np.zeros(0, np.uint32), np.zeros(0, np.uint64), np.zeros((0, 3), np.int16), np.zeros(0, np.uint8))


class Decoder:
    """Streaming frame decoder: ``feed(bytes) -> Frames``; counters in ``self.counters``."""

    def __init__(self) -> None:
        self._buf = b""
        self._last_seq: int | None = None
        self.counters = Counters()

    def feed(self, data: bytes) -> Frames:
        self.counters.bytes_in += len(data)
        buf = self._buf + bytes(data)
        n = len(buf)
        if n < FRAME_LEN:
            self._buf = buf
            return EMPTY
        arr = np.frombuffer(buf, dtype=np.uint8)
        last_start = n - FRAME_LEN  # candidates beyond this are incomplete
        cand = np.flatnonzero((arr[:-2] == 0xA5) & (arr[1:-1] == 0x5A) & (arr[2:] == VERSION))
        cand = cand[cand <= last_start]
        if cand.size:
            rows = arr[cand[:, None] + np.arange(FRAME_LEN)]
            got = rows[:, 22].astype(np.uint16) | (rows[:, 23].astype(np.uint16) << 8)
            ok = crc16_rows(rows[:, :22]) == got
        else:
            rows = np.zeros((0, FRAME_LEN), np.uint8)
            ok = np.zeros(0, bool)
        valid = cand[ok]
        accepted = _greedy(valid)
        # Failed candidates outside accepted frames are CRC errors.
        bad = cand[~ok]
        if accepted.size and bad.size:
            k = np.searchsorted(accepted, bad, side="right") - 1
            inside = (k >= 0) & (bad < accepted[np.maximum(k, 0)] + FRAME_LEN)
            bad = bad[~inside]
        # Scan position: after the last accepted frame, or where incomplete candidates begin.
        end_frames = int(accepted[-1]) + FRAME_LEN if accepted.size else 0
        keep_from = max(end_frames, last_start + 1)
        # A failed candidate counts once its position has been scanned (before keep_from).
        self.counters.crc_errors += int(np.count_nonzero(bad < keep_from))
        self.counters.skipped_bytes += keep_from - accepted.size * FRAME_LEN
        self._buf = buf[keep_from:]
        if not accepted.size:
            return EMPTY
        fr = np.frombuffer(buf, dtype=np.uint8)[accepted[:, None] + np.arange(FRAME_LEN)].copy().view(FRAME_DTYPE)[:, 0]
        seq = fr["seq"].astype(np.int64)
        prev = np.concatenate([[self._last_seq if self._last_seq is not None else seq[0] - 1], seq[:-1]])
        step = (seq - prev) % 2**32
        resets = step > 2**31  # went backwards
        gaps = np.where(resets, 0, step - 1)
        self.counters.sequence_resets += int(resets.sum())
        self.counters.dropped_frames += int(gaps.sum())
        self.counters.frames += len(seq)
        self._last_seq = int(seq[-1])
        return Frames(fr["seq"].copy(), fr["t_us"].copy(), fr["ch"].copy(), fr["flags"].copy(), gaps)

    def flush(self) -> None:
        """End of stream: whatever is left in the buffer is skipped."""
        self.counters.skipped_bytes += len(self._buf)
        self._buf = b""


def _greedy(valid: np.ndarray) -> np.ndarray:
    """Non-overlapping frames, first come first served (as a byte-by-byte scanner takes them)."""
    if valid.size < 2 or np.all(np.diff(valid) >= FRAME_LEN):
        return valid
    out = []
    nxt = -1
    for p in valid.tolist():
        if p >= nxt:
            out.append(p)
            nxt = p + FRAME_LEN
    return np.array(out, dtype=valid.dtype)
