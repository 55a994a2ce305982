"""The rig's serial frame format: encoders and a pure, vectorised, streaming decoder.

Two frames share one framing (sync, version, type bit, CRC-16/CCITT-FALSE); all little-endian.

Data frame, version 1, 24 bytes (one sample of the three channels):

    offset size field
    0      2    sync word 0xA5 0x5A
    2      1    format version (1)
    3      1    flags: bit 0 = a channel clipped at the ADC's range; bit 7 = 0 (data frame);
                bits 1-6 reserved, 0
    4      4    sequence counter, uint32, +1 per frame since boot, wraps
    8      8    device timestamp, uint64, microseconds since boot
    16     6    three channels (base, tip1, tip2), int16 ADC counts
    22     2    CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) over bytes 0..21

Status frame, version 1, 36 bytes (the device's identity, once a second and at boot):

    offset size field
    0      2    sync word 0xA5 0x5A
    2      1    format version (1)
    3      1    type: 0x80 (bit 7 set = status frame; bits 0-6 reserved, 0)
    4      4    status counter, uint32, +1 per status frame since boot
    8      8    device timestamp, uint64, microseconds since boot (the data frames' clock)
    16     8    session id, uint64, drawn at random at every boot
    24     4    device id, uint32, fixed per unit (serial number or a hash of the MCU's unique id)
    28     4    sample rate, uint32, millihertz
    32     1    firmware version, major
    33     1    firmware version, minor
    34     2    CRC-16/CCITT-FALSE over bytes 0..33

The :class:`Decoder` holds no port: it is fed bytes (``feed``) and returns the frames found, like
pyserial's ``Protocol.data_received``. It finds every sync candidate and checks all CRCs in numpy
at once, then resolves overlaps the way a byte-by-byte scanner would: a valid frame consumes its
bytes; a candidate whose CRC fails counts as one CRC error and the scan resumes at the next byte;
bytes that belong to no frame are counted as skipped. ``A5 5A`` followed by a version other than 1
(outside any valid frame) is counted in ``unknown_version``, its bytes as skipped.

Sequence numbers: a forward jump counts the frames lost (``dropped_frames``); a frame equal in
sequence and time to one of the last 256 is a duplicate (counted, delivered once); a sequence that
goes backwards, or device time that goes backwards, is a device restart (``sequence_resets``; the
frame is flagged in ``Frames.restart`` so the host re-anchors its clock).
"""

from __future__ import annotations

import binascii
from collections import deque
from dataclasses import dataclass, field

import numpy as np

SYNC = b"\xa5\x5a"
VERSION = 1
FRAME_LEN = 24
STATUS_LEN = 36
FLAG_CLIPPED = 0x01
TYPE_STATUS = 0x80
RECENT = 256  # frames remembered to recognise a duplicate

FRAME_DTYPE = np.dtype([
    ("sync", "<u2"), ("version", "u1"), ("flags", "u1"), ("seq", "<u4"), ("t_us", "<u8"),
    ("ch", "<i2", (3,)), ("crc", "<u2"),
])
assert FRAME_DTYPE.itemsize == FRAME_LEN
STATUS_DTYPE = np.dtype([
    ("sync", "<u2"), ("version", "u1"), ("type", "u1"), ("counter", "<u4"), ("t_us", "<u8"),
    ("session", "<u8"), ("device", "<u4"), ("rate_mhz", "<u4"), ("fw_major", "u1"), ("fw_minor", "u1"),
    ("crc", "<u2"),
])
assert STATUS_DTYPE.itemsize == STATUS_LEN


def _crc_table() -> np.ndarray:
    table = np.zeros(256, dtype=np.uint16)
    for i in range(256):
        c = i << 8
        for _ in range(8):
            c = ((c << 1) ^ 0x1021) if c & 0x8000 else (c << 1)
        table[i] = c & 0xFFFF
    return table


CRC_TABLE = _crc_table()


def _crc_table16() -> np.ndarray:
    """The register after 16 zero bits from each 16-bit state: two bytes per step (``reg ^= word``)."""
    reg = np.arange(65536, dtype=np.uint16)
    for _ in range(2):
        reg = (reg << 8) ^ CRC_TABLE[reg >> 8]
    return reg


CRC_TABLE16 = _crc_table16()
FEW_ROWS = 16  # up to this many rows crc16_rows calls binascii.crc_hqx (the same CRC: poly 0x1021, no reflection)


def crc16_rows(rows: np.ndarray, init: np.ndarray | None = None) -> np.ndarray:
    """CRC-16/CCITT-FALSE of each row of a (n, k) uint8 array, vectorised over rows; ``init`` continues
    the CRCs of rows that came before (the state after their earlier bytes)."""
    if rows.shape[0] <= FEW_ROWS:  # binascii's C loop beats a dozen numpy passes over a few rows
        start = [0xFFFF] * rows.shape[0] if init is None else np.asarray(init, np.uint16).tolist()
        return np.array([binascii.crc_hqx(r.tobytes(), c) for r, c in zip(rows, start)], np.uint16)
    crc = np.full(rows.shape[0], 0xFFFF, dtype=np.uint16) if init is None else np.asarray(init, np.uint16)
    k = rows.shape[1]
    if k >= 2:
        words = np.ascontiguousarray(rows[:, :k - k % 2]).view(">u2").astype(np.uint16)
        for col in words.T:
            crc = CRC_TABLE16[crc ^ col]
    if k % 2:
        crc = (crc << 8) ^ CRC_TABLE[(crc >> 8) ^ rows[:, -1].astype(np.uint16)]
    return crc


def encode(seq: np.ndarray, t_us: np.ndarray, counts: np.ndarray, flags: np.ndarray | None = None) -> bytes:
    """Data frames for n samples: seq (n,), t_us (n,), counts (n, 3) int16 range, flags (n,)."""
    n = len(seq)
    fr = np.zeros(n, dtype=FRAME_DTYPE)
    fr["sync"] = 0x5AA5  # bytes A5 5A little-endian
    fr["version"] = VERSION
    fr["flags"] = 0 if flags is None else np.asarray(flags) & 0x7F
    fr["seq"] = np.asarray(seq, np.uint64) & 0xFFFFFFFF
    fr["t_us"] = t_us
    fr["ch"] = np.clip(counts, -32768, 32767)
    raw = fr.view(np.uint8).reshape(n, FRAME_LEN)
    fr["crc"] = crc16_rows(raw[:, :22])
    return fr.tobytes()


@dataclass(frozen=True)
class Status:
    """One status frame: who the device is and since when it runs."""

    counter: int
    t_us: int
    session_id: int
    device_id: int
    rate_hz: float
    firmware: tuple[int, int]
    index: int = 0  # data frames delivered before it in the same ``feed`` result

    def as_dict(self) -> dict:
        return {"counter": self.counter, "t_device": self.t_us * 1e-6, "session_id": f"{self.session_id:016x}",
                "device_id": f"{self.device_id:08x}", "rate_hz": self.rate_hz,
                "firmware": f"{self.firmware[0]}.{self.firmware[1]}", "protocol": VERSION}


def encode_status(counter: int, t_us: int, session_id: int, device_id: int, rate_hz: float,
                  firmware: tuple[int, int] = (1, 0)) -> bytes:
    """One status frame (36 bytes)."""
    fr = np.zeros(1, dtype=STATUS_DTYPE)
    fr["sync"] = 0x5AA5
    fr["version"] = VERSION
    fr["type"] = TYPE_STATUS
    fr["counter"] = counter & 0xFFFFFFFF
    fr["t_us"] = t_us
    fr["session"] = session_id & 0xFFFFFFFFFFFFFFFF
    fr["device"] = device_id & 0xFFFFFFFF
    fr["rate_mhz"] = int(round(rate_hz * 1000)) & 0xFFFFFFFF
    fr["fw_major"], fr["fw_minor"] = firmware
    raw = fr.view(np.uint8).reshape(1, STATUS_LEN)
    fr["crc"] = crc16_rows(raw[:, :34])
    return fr.tobytes()


@dataclass
class Counters:
    frames: int = 0  # valid data frames, duplicates included
    crc_errors: int = 0
    skipped_bytes: int = 0
    dropped_frames: int = 0  # sequence gaps
    duplicates: int = 0  # frames equal to one already delivered (delivered once)
    sequence_resets: int = 0  # sequence or device time went backwards (device restarted)
    status_frames: int = 0
    unknown_version: int = 0  # A5 5A followed by a version other than 1, outside any valid frame
    bytes_in: int = 0
    versions_seen: set = field(default_factory=set)  # the unknown version bytes met


@dataclass(frozen=True)
class Frames:
    """Data frames of one ``feed`` call, as columns, and the status frames among them."""

    seq: np.ndarray  # uint32
    t_us: np.ndarray  # uint64
    counts: np.ndarray  # (n, 3) int16
    flags: np.ndarray  # uint8
    gaps: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # frames lost before each
    restart: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))  # a device restart before each
    status: tuple[Status, ...] = ()
    # where each frame ends in the stream fed (bytes from the first byte fed), so a reader can tell which
    # read delivered it; empty where the decoder does not know (text lines)
    end: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))

    def __len__(self) -> int:
        return len(self.seq)

    def take(self, k: int) -> "Frames":
        """The first ``k`` data frames (and the status frames before them)."""
        return Frames(self.seq[:k], self.t_us[:k], self.counts[:k], self.flags[:k], self.gaps[:k], self.restart[:k],
                      tuple(s for s in self.status if s.index <= k), self.end[:k])


def _empty(status: tuple[Status, ...] = ()) -> Frames:
    return Frames(np.zeros(0, np.uint32), np.zeros(0, np.uint64), np.zeros((0, 3), np.int16), np.zeros(0, np.uint8),
                  np.zeros(0, np.int64), np.zeros(0, bool), status)


EMPTY = _empty()


class Decoder:
    """Streaming frame decoder: ``feed(bytes) -> Frames``, ``flush() -> Frames``; counters in ``self.counters``."""

    def __init__(self) -> None:
        self._buf = b""
        self._last: tuple[int, int] | None = None  # (seq, t_us) of the last delivered data frame
        self._recent: deque = deque(maxlen=RECENT)  # (seq, t_us) of the last delivered frames
        self.counters = Counters()

    def feed(self, data: bytes) -> Frames:
        self.counters.bytes_in += len(data)
        self._buf += bytes(data)
        return self._scan(final=False)

    def flush(self) -> Frames:
        """End of stream: complete frames left in the buffer are decoded, the rest is skipped."""
        return self._scan(final=True)

    def reopened(self, outage_s: float = 0.0) -> None:
        """The port was reopened (the driver tells every decoder). Nothing to do here: the CRC finds the
        frames' edges, the sequence counter the frames lost (daq.lines needs it)."""

    def _scan(self, final: bool) -> Frames:
        buf = self._buf
        n = len(buf)
        base = self.counters.bytes_in - n  # the stream offset of buf[0]
        if n < FRAME_LEN and not final:
            return EMPTY
        arr = np.frombuffer(buf, dtype=np.uint8)
        sync = np.flatnonzero((arr[:-2] == 0xA5) & (arr[1:-1] == 0x5A)) if n >= 3 else np.zeros(0, np.int64)
        if not sync.size:  # nothing that could start a frame: all but a possible frame's beginning is skipped
            keep_from = n if final else max(0, n - (FRAME_LEN - 1))
            self.counters.skipped_bytes += keep_from
            self._buf = buf[keep_from:]
            return EMPTY
        version = arr[sync + 2]
        cand = sync[version == VERSION]
        other = sync[version != VERSION]
        has_type = cand + 3 < n
        is_status = np.zeros(cand.size, bool)
        is_status[has_type] = (arr[cand[has_type] + 3] & TYPE_STATUS) != 0
        length = np.where(is_status, STATUS_LEN, FRAME_LEN)
        complete = has_type & (cand + length <= n)
        if final:
            limit = n  # nothing more will come: an incomplete candidate is no frame
        else:
            waiting = cand[~complete]
            limit = min(n - (FRAME_LEN - 1), int(waiting.min()) if waiting.size else n)
        use = complete & (cand < limit)
        cand, length, is_status = cand[use], length[use], is_status[use]
        ok = np.zeros(cand.size, bool)
        if cand.size:
            # one pass over the first 22 bytes of every candidate; a status frame's CRC continues from there
            rows = arr[cand[:, None] + np.arange(FRAME_LEN)]
            crc22 = crc16_rows(rows[:, :FRAME_LEN - 2])
            got = rows[:, 22].astype(np.uint16) | (rows[:, 23].astype(np.uint16) << 8)
            ok = ~is_status & (crc22 == got)
            if is_status.any():
                st_rows = arr[cand[is_status][:, None] + np.arange(FRAME_LEN - 2, STATUS_LEN)]
                crc = crc16_rows(st_rows[:, :STATUS_LEN - FRAME_LEN], crc22[is_status])
                ok[is_status] = crc == (st_rows[:, -2].astype(np.uint16) | (st_rows[:, -1].astype(np.uint16) << 8))
        starts, lens = _greedy(cand[ok], length[ok])
        ends = starts + lens
        end_frames = int(ends[-1]) if starts.size else 0
        keep_from = max(end_frames, limit)
        # Failed candidates and unknown versions outside accepted frames; all lie before keep_from.
        self.counters.crc_errors += int(np.count_nonzero(~_inside(cand[~ok], starts, ends)))
        strays = other[(other < keep_from) & ~_inside(other, starts, ends)]
        if strays.size:
            self.counters.unknown_version += int(strays.size)
            self.counters.versions_seen.update(int(v) for v in np.unique(arr[strays + 2]))
        self.counters.skipped_bytes += keep_from - int(lens.sum())
        self._buf = buf[keep_from:]
        if not starts.size:
            return EMPTY
        st_mask = lens == STATUS_LEN
        data_starts = starts[~st_mask]
        fr = arr[data_starts[:, None] + np.arange(FRAME_LEN)].copy().view(FRAME_DTYPE)[:, 0]
        # each status frame's place among the data frames (before duplicates are removed)
        status_pos = np.searchsorted(data_starts, starts[st_mask])
        st_rows = arr[starts[st_mask][:, None] + np.arange(STATUS_LEN)].copy().view(STATUS_DTYPE)[:, 0]
        self.counters.status_frames += len(st_rows)
        keep, gaps, restart = self._sequence(fr["seq"], fr["t_us"])
        self.counters.frames += len(fr)
        delivered_before = np.concatenate([[0], np.cumsum(keep)])
        status = tuple(Status(int(s["counter"]), int(s["t_us"]), int(s["session"]), int(s["device"]),
                              int(s["rate_mhz"]) / 1000.0, (int(s["fw_major"]), int(s["fw_minor"])),
                              int(delivered_before[p])) for s, p in zip(st_rows, status_pos))
        if not keep.any():
            return _empty(status)
        return Frames(fr["seq"][keep].copy(), fr["t_us"][keep].copy(), fr["ch"][keep].copy(), fr["flags"][keep].copy(),
                      gaps[keep], restart[keep], status, (base + FRAME_LEN + data_starts[keep]).astype(np.int64))

    def _sequence(self, seq: np.ndarray, t_us: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(delivered mask, frames lost before each, restart before each) for decoded data frames in order."""
        n = len(seq)
        if n == 0:
            return np.zeros(0, bool), np.zeros(0, np.int64), np.zeros(0, bool)
        s = seq.astype(np.int64)
        t = t_us.astype(np.uint64)
        if self._last is None:
            prev_s = np.concatenate([[s[0] - 1], s[:-1]])
            prev_t_ok = np.concatenate([[True], t[1:] >= t[:-1]])
        else:
            prev_s = np.concatenate([[self._last[0]], s[:-1]])
            prev_t_ok = np.concatenate([[t[0] >= np.uint64(self._last[1])], t[1:] >= t[:-1]])
        step = (s - prev_s) % 2**32
        if np.all((step == 1) & prev_t_ok):  # the usual case: every frame follows the one before
            self._remember(seq, t_us)
            return np.ones(n, bool), np.zeros(n, np.int64), np.zeros(n, bool)
        keep = np.ones(n, bool)
        gaps = np.zeros(n, np.int64)
        restart = np.zeros(n, bool)
        last, recent = self._last, self._recent
        for i, (si, ti) in enumerate(zip(s.tolist(), t.tolist())):
            if last is not None:
                st = (si - last[0]) % 2**32
                if 1 <= st <= 2**31 and ti >= last[1]:
                    gaps[i] = st - 1
                elif (si, ti) in recent:
                    keep[i] = False
                    self.counters.duplicates += 1
                    continue
                else:
                    restart[i] = True
                    self.counters.sequence_resets += 1
            last = (si, ti)
            recent.append(last)
        self._last = last
        self.counters.dropped_frames += int(gaps.sum())
        return keep, gaps, restart

    def _remember(self, seq: np.ndarray, t_us: np.ndarray) -> None:
        tail = slice(max(0, len(seq) - RECENT), len(seq))
        self._recent.extend(zip(seq[tail].astype(np.int64).tolist(), t_us[tail].astype(np.uint64).tolist()))
        self._last = (int(seq[-1]), int(t_us[-1]))


def _inside(pos: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """For each position, whether it falls inside one of the sorted, non-overlapping frames [start, end)."""
    if not starts.size or not pos.size:
        return np.zeros(pos.size, bool)
    k = np.searchsorted(starts, pos, side="right") - 1
    return (k >= 0) & (pos < ends[np.maximum(k, 0)])


def _greedy(valid: np.ndarray, lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Non-overlapping frames, first come first served (as a byte-by-byte scanner takes them)."""
    order = np.argsort(valid, kind="stable")
    valid, lengths = valid[order], lengths[order]
    if valid.size < 2 or np.all(np.diff(valid) >= lengths[:-1]):
        return valid, lengths
    out, out_len = [], []
    nxt = -1
    for p, ln in zip(valid.tolist(), lengths.tolist()):
        if p >= nxt:
            out.append(p)
            out_len.append(ln)
            nxt = p + ln
    return np.array(out, dtype=valid.dtype), np.array(out_len, dtype=lengths.dtype)
