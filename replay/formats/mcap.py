"""MCAP recordings of this tool: the one MCAP reader (every command's), and the writer for imports.

The reader walks the file's records in order (spec: mcap.dev/spec; opcode, little-endian length,
body) over a memory map and checks each one before it trusts it: every record's fields must add up
to its length, a chunk's compression must be known, it must decompress to its stated size (at most
``MAX_CHUNK_BYTES``) and match its CRC-32, its inner records must add up too, an attachment must
match its CRC, the summary must match the footer's CRC. Where a record fails, the walk
resynchronises: it looks for the next offset where a record passes (a chunk whose CRC matches, or
a record followed by another that passes), and the bytes in between are one damaged region. So a
damaged chunk costs that chunk, nothing after it; a damaged header costs nothing but the header;
and the schema and channel records, found in the first chunk, after every chunk (this tool's
recorder repeats them) and in the summary, name the channels of every intact chunk.

Readers (``read_samples``, ``read_recording``, ``read_columns``) refuse a file with damage or
without its footer with one line that says where and what to do ("chunk at byte N unreadable ...:
run replay recover"); ``replay recover`` (replay.recover) uses :func:`scan` to keep everything that
is intact. Samples come from the raw serial bytes of ``/rig/raw``, decoded in bulk with
daq.protocol (fast; the only record of the samples in recordings since the compact layout, read with
the ``calibration`` and ``samples`` metadata), else from the ``/rig/accel`` messages (imports,
text-line devices, ``--accel-json``, older recordings).
"""

from __future__ import annotations

import json
import mmap
import os
import struct
import time
import zlib
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import zstandard

from daq.config import Config, DaqConfig, parse_config
from daq.driver import SampleBlock
from daq.protocol import FLAG_CLIPPED, Decoder
from daq.recorder import RAW_LINES, TOPICS, McapRecorder
from daq.sim.rig import RigConfig

from ident.config import parse_yaml

from .base import Columns, Samples, on_grid, typical_step

try:  # the mcap package's own dependency for lz4 chunks
    import lz4.frame as _lz4
except ImportError:  # pragma: no cover
    _lz4 = None

SUFFIXES = (".mcap",)
MAGIC = b"\x89MCAP0\r\n"
(HEADER, FOOTER, SCHEMA, CHANNEL, MESSAGE, CHUNK, MESSAGE_INDEX, CHUNK_INDEX, ATTACHMENT, ATTACHMENT_INDEX,
 STATISTICS, METADATA, METADATA_INDEX, SUMMARY_OFFSET, DATA_END) = range(1, 16)
NAMES = {HEADER: "header", FOOTER: "footer", SCHEMA: "schema", CHANNEL: "channel", MESSAGE: "message",
         CHUNK: "chunk", MESSAGE_INDEX: "message index", CHUNK_INDEX: "chunk index", ATTACHMENT: "attachment",
         ATTACHMENT_INDEX: "attachment index", STATISTICS: "statistics", METADATA: "metadata",
         METADATA_INDEX: "metadata index", SUMMARY_OFFSET: "summary offset", DATA_END: "data end"}
MAX_CHUNK_BYTES = 1 << 30
COMPRESSIONS = ("", "zstd", "lz4")
CHANNELS = ("base", "tip1", "tip2")


class Bad(Exception):
    """A record that does not add up."""


@dataclass(frozen=True)
class SchemaRec:
    id: int
    name: str
    encoding: str
    data: bytes


@dataclass(frozen=True)
class ChannelRec:
    id: int
    schema_id: int
    topic: str
    message_encoding: str
    metadata: dict


@dataclass(frozen=True)
class AttachmentRec:
    log_time: int
    create_time: int
    name: str
    media_type: str
    data: bytes


@dataclass(frozen=True)
class Damage:
    offset: int  # first byte that could not be read
    end: int  # first byte read again after it
    what: str  # "chunk", "header", "bytes", ...
    reason: str

    def describe(self) -> str:
        if self.what == "cut":
            return f"cut short at byte {self.offset} ({self.reason})"
        if self.what == "bytes":
            return f"bytes {self.offset}-{self.end - 1} unreadable ({self.reason})"
        if self.what == "calibration metadata":
            return f"calibration metadata{f' at byte {self.offset}' if self.offset >= 0 else ''} damaged ({self.reason})"
        return f"{self.what} at byte {self.offset} unreadable ({self.reason})"


@dataclass(frozen=True)
class _ChunkLoc:
    offset: int  # of the record
    end: int
    data: tuple[int, int]  # compressed bytes [a, b) in the file
    compression: str
    size: int
    crc: int


@dataclass
class Scan:
    """Everything the walk found; ``damage`` lists what it could not read."""

    path: Path
    size: int
    schemas: dict[int, SchemaRec] = field(default_factory=dict)
    channels: dict[int, ChannelRec] = field(default_factory=dict)
    metadata: list[tuple[str, dict]] = field(default_factory=list)  # in file order
    metadata_at: list[tuple[int, int]] = field(default_factory=list)  # each one's bytes [a, b) in the file
    attachments: list[AttachmentRec] = field(default_factory=list)
    chunks: list[_ChunkLoc] = field(default_factory=list)  # intact chunks, in file order
    loose: list[int] = field(default_factory=list)  # offsets of messages outside chunks
    damage: list[Damage] = field(default_factory=list)
    footer: bool = False  # a valid footer and the closing magic
    data_end: bool = False
    _buf: object = None

    @property
    def complete(self) -> bool:
        return self.footer and not self.damage

    def meta(self, name: str) -> dict:
        found = [m for n, m in self.metadata if n == name]
        return found[-1] if found else {}

    def topic_ids(self, topic: str) -> set[int]:
        return {c.id for c in self.channels.values() if c.topic == topic}

    def problem(self) -> str | None:
        """One line for a reading command, or None if the file is whole."""
        if len(self.damage) == 1 and self.damage[0].what == "cut" and not self.footer:
            return (f"{self.path}: {self.damage[0].describe()}; no summary or footer (a recording that was "
                    f"killed, or a .part): run replay recover {self.path} -o FIXED.mcap")
        if self.damage:
            more = f" (and {len(self.damage) - 1} more damaged region(s))" if len(self.damage) > 1 else ""
            return (f"{self.path}: {self.damage[0].describe()}{more}: run replay recover {self.path} "
                    f"-o FIXED.mcap")
        if not self.footer:
            return (f"{self.path}: cut short at byte {self.size} (no summary or footer: a recording that was "
                    f"killed, or a .part): run replay recover {self.path} -o FIXED.mcap")
        return None

    def messages(self, channel_ids: Iterable[int] | None = None) -> Iterator[tuple[int, int, int, int, bytes, int]]:
        """(channel id, sequence, log time, publish time, data, chunk offset) of every intact message in file
        order, for the given channels (all if None)."""
        want = None if channel_ids is None else set(channel_ids)
        buf = self._buf
        items = [(c.offset, c) for c in self.chunks] + [(p, None) for p in self.loose]
        items.sort(key=lambda x: x[0])
        for off, c in items:
            if c is None:
                (length,) = struct.unpack_from("<Q", buf, off + 1)
                rec = _message(buf, off + 9, off + 9 + length)
                if want is None or rec[0] in want:
                    yield (*rec, off)
                continue
            data = _decompress(buf, c)
            for op, a, b in _inner(data):
                if op == MESSAGE:
                    (ch,) = struct.unpack_from("<H", data, a)
                    if want is None or ch in want:
                        yield (*_message(data, a, b), off)


# ----------------------------------------------------------------------------------------- parsing


class _Cur:
    """Bounded reads of one record body [pos, end)."""

    __slots__ = ("b", "p", "end")

    def __init__(self, b, p: int, end: int):
        self.b, self.p, self.end = b, p, end

    def take(self, n: int) -> int:
        p = self.p
        if n < 0 or p + n > self.end:
            raise Bad("field runs past the record")
        self.p = p + n
        return p

    def u16(self) -> int:
        return struct.unpack_from("<H", self.b, self.take(2))[0]

    def u32(self) -> int:
        return struct.unpack_from("<I", self.b, self.take(4))[0]

    def u64(self) -> int:
        return struct.unpack_from("<Q", self.b, self.take(8))[0]

    def u8(self) -> int:
        return self.b[self.take(1)]

    def raw(self, n: int) -> bytes:
        p = self.take(n)
        return bytes(self.b[p:p + n])

    def string(self) -> str:
        n = self.u32()
        try:
            return self.raw(n).decode("utf-8")
        except UnicodeDecodeError:
            raise Bad("a string is not UTF-8") from None

    def map_ss(self) -> dict:
        n = self.u32()
        end, out = self.p + n, {}
        if end > self.end:
            raise Bad("a map runs past the record")
        saved, self.end = self.end, end
        while self.p < end:
            k = self.string()
            out[k] = self.string()
        self.end = saved
        return out

    def skip_map(self, entry: int) -> None:
        n = self.u32()
        if n % entry:
            raise Bad("a map's length is not a whole number of entries")
        self.take(n)

    def done(self) -> None:
        if self.p != self.end:
            raise Bad("fields do not add up to the record's length")


def _message(b, a: int, end: int) -> tuple[int, int, int, int, bytes]:
    ch, seq, log, pub = struct.unpack_from("<HIQQ", b, a)
    return ch, seq, log, pub, bytes(b[a + 22:end])


def _body(op: int, b, a: int, end: int):
    """Check (and parse where useful) the body of a record; raise Bad if it does not add up."""
    c = _Cur(b, a, end)
    if op == HEADER:
        c.string(), c.string()
    elif op == FOOTER:
        out = (c.u64(), c.u64(), c.u32())
        c.done()
        return out
    elif op == SCHEMA:
        sid, name, enc = c.u16(), c.string(), c.string()
        out = SchemaRec(sid, name, enc, c.raw(c.u32()))
        c.done()
        return out
    elif op == CHANNEL:
        out = ChannelRec(c.u16(), c.u16(), c.string(), c.string(), c.map_ss())
        c.done()
        return out
    elif op == MESSAGE:
        if end - a < 22:
            raise Bad("message shorter than its header")
        return None
    elif op == CHUNK:
        c.u64(), c.u64()
        size, crc, comp = c.u64(), c.u32(), c.string()
        n = c.u64()
        data = (c.take(n), c.p)
        c.done()
        if comp not in COMPRESSIONS:
            raise Bad(f"unknown compression {comp[:20]!r}")
        if size > MAX_CHUNK_BYTES:
            raise Bad(f"states {size} bytes uncompressed")
        return _ChunkLoc(0, 0, data, comp, size, crc)
    elif op == MESSAGE_INDEX:
        c.u16()
        c.skip_map(16)
    elif op == CHUNK_INDEX:
        c.u64(), c.u64(), c.u64(), c.u64()
        c.skip_map(10)
        c.u64(), c.string(), c.u64(), c.u64()
    elif op == ATTACHMENT:
        log, create, name, media = c.u64(), c.u64(), c.string(), c.string()
        data = c.raw(c.u64())
        crc_at = c.p
        crc = c.u32()
        c.done()
        if crc and zlib.crc32(b[a:crc_at]) != crc:
            raise Bad("attachment CRC mismatch")
        return AttachmentRec(log, create, name, media, data)
    elif op == ATTACHMENT_INDEX:
        c.u64(), c.u64(), c.u64(), c.u64(), c.u64(), c.string(), c.string()
    elif op == STATISTICS:
        c.u64(), c.u16(), c.u32(), c.u32(), c.u32(), c.u32(), c.u64(), c.u64()
        c.skip_map(10)
    elif op == METADATA:
        out = (c.string(), c.map_ss())
        c.done()
        return out
    elif op == METADATA_INDEX:
        c.u64(), c.u64(), c.string()
    elif op == SUMMARY_OFFSET:
        c.u8(), c.u64(), c.u64()
    elif op == DATA_END:
        c.u32()
    else:
        raise Bad(f"unknown opcode {op:#04x}")
    c.done()
    return None


def _decompress(b, loc: _ChunkLoc) -> bytes:
    """A chunk's records, checked against its size and CRC; Bad if they do not match."""
    a, e = loc.data
    comp = b[a:e]
    try:
        if loc.compression == "zstd":
            data = zstandard.ZstdDecompressor().decompress(bytes(comp), max_output_size=max(loc.size, 1))
        elif loc.compression == "lz4":
            if _lz4 is None:
                raise Bad("lz4 chunk and no lz4 module")
            data = _lz4.decompress(bytes(comp))
        else:
            data = bytes(comp)
    except (zstandard.ZstdError, RuntimeError, ValueError, MemoryError) as exc:
        raise Bad(f"does not decompress: {str(exc)[:60]}") from None
    if len(data) != loc.size:
        raise Bad(f"decompresses to {len(data)} bytes, states {loc.size}")
    if loc.crc and zlib.crc32(data) != loc.crc:
        raise Bad("CRC mismatch")
    return data


def _inner(data: bytes) -> Iterator[tuple[int, int, int]]:
    """(opcode, body start, body end) of a chunk's records; Bad if they do not add up."""
    pos, n = 0, len(data)
    while pos < n:
        if pos + 9 > n:
            raise Bad("a record header runs past the chunk")
        op = data[pos]
        (length,) = struct.unpack_from("<Q", data, pos + 1)
        end = pos + 9 + length
        if end > n:
            raise Bad("a record runs past the chunk")
        if op not in (SCHEMA, CHANNEL, MESSAGE):
            raise Bad(f"opcode {op:#04x} inside a chunk")
        yield op, pos + 9, end
        pos = end


# ------------------------------------------------------------------------------------------- walk


class _Walker:
    def __init__(self, buf, n: int, scan: Scan):
        self.b, self.n, self.s = buf, n, scan
        self.arr = np.frombuffer(buf, np.uint8) if n else np.zeros(0, np.uint8)

    def header(self, pos: int) -> tuple[int, int] | None:
        """(opcode, end) if a record header at pos fits in the file."""
        if pos + 9 > self.n:
            return None
        op = self.b[pos]
        (length,) = struct.unpack_from("<Q", self.b, pos + 1)
        end = pos + 9 + length
        if not 1 <= op <= 15 or end > self.n:
            return None
        return op, end

    def check(self, pos: int, deep: bool = True):
        """(op, end, parsed) of a record at pos that adds up; raise Bad otherwise. ``deep``: open chunks."""
        h = self.header(pos)
        if h is None:
            raise Bad("no record header here (opcode or length out of range)")
        op, end = h
        parsed = _body(op, self.b, pos + 9, end)
        if op == CHUNK:
            parsed = _ChunkLoc(pos, end, parsed.data, parsed.compression, parsed.size, parsed.crc)
            if deep:
                data = _decompress(self.b, parsed)
                parsed = (parsed, data)
        elif op == FOOTER:
            if not (end + 8 == self.n and bytes(self.b[end:self.n]) == MAGIC):
                raise Bad("footer not followed by the closing magic")
        return op, end, parsed

    def passes(self, pos: int) -> bool:
        if pos == self.n or (pos + 8 == self.n and bytes(self.b[pos:self.n]) == MAGIC):
            return True
        try:
            self.check(pos, deep=False)
            return True
        except Bad:
            return False

    def resync(self, start: int) -> int:
        """The next offset from ``start`` where records can be trusted again (the file's end if none)."""
        n, arr = self.n, self.arr
        window = 1 << 20
        lo = start
        while lo < n - 9:
            hi = min(n - 9, lo + window)
            ops = arr[lo:hi]
            idx = np.flatnonzero((ops >= 1) & (ops <= 15)) + lo
            if idx.size:
                lens = arr[idx[:, None] + 1 + np.arange(8)].copy().view("<u8")[:, 0]
                idx = idx[lens <= (n - idx - 9).astype(np.uint64)]
            for p in idx.tolist():
                try:
                    op, end, _ = self.check(p)
                except Bad:
                    continue
                if op in (CHUNK, FOOTER, ATTACHMENT) or self.passes(end):
                    return p
            lo = hi
        tail = n - 8
        if tail >= start and bytes(self.b[tail:n]) == MAGIC:
            return tail
        return n

    def walk(self) -> None:
        b, n, s = self.b, self.n, self.s
        pos = len(MAGIC)
        if n < len(MAGIC) or bytes(b[:len(MAGIC)]) != MAGIC:
            nxt = self.resync(0)
            s.damage.append(Damage(0, nxt, "bytes", "no MCAP magic at the start"))
            pos = nxt
        while pos < n:
            if pos + 8 == n and bytes(b[pos:n]) == MAGIC:
                break
            try:
                op, end, parsed = self.check(pos)
            except Bad as exc:
                h = self.header(pos)
                if h is None and pos + 9 <= n and 1 <= b[pos] <= 15 and bytes(b[n - 8:n]) != MAGIC:
                    (length,) = struct.unpack_from("<Q", b, pos + 1)
                    if pos + 9 + length > n and length < (1 << 40):  # a record the end of the file cut
                        nxt = self.resync(pos + 1)
                        if nxt >= n - 8:
                            s.damage.append(Damage(pos, nxt, "cut", f"the file ends {pos + 9 + length - n} bytes "
                                                                   f"before the end of this {NAMES[b[pos]]}"))
                            pos = nxt
                            continue
                what = NAMES.get(h[0], "bytes") if h else "bytes"
                if h and h[0] == CHUNK:
                    # if the chunk's fields add up, only its content is bad: skip it whole
                    try:
                        _body(CHUNK, b, pos + 9, h[1])
                        s.damage.append(Damage(pos, h[1], "chunk", str(exc)))
                        pos = h[1]
                        continue
                    except Bad:
                        pass
                nxt = self.resync(pos + 1)
                s.damage.append(Damage(pos, nxt, what if what != "message" else "bytes", str(exc)))
                pos = nxt
                continue
            self.take(op, pos, end, parsed)
            if op == DATA_END:
                s.data_end = True
            if op == FOOTER:
                s.footer = True
                s_start, _, crc = parsed
                if crc and s_start and 0 < s_start <= pos:
                    got = zlib.crc32(bytes(b[s_start:pos]))
                    got = zlib.crc32(bytes(b[pos:pos + 9 + 16]), got)
                    if got != crc:
                        s.damage.append(Damage(s_start, pos, "summary", "summary CRC mismatch"))
            pos = end

    def take(self, op: int, pos: int, end: int, parsed) -> None:
        s = self.s
        if op == SCHEMA:
            s.schemas.setdefault(parsed.id, parsed)
        elif op == CHANNEL:
            s.channels.setdefault(parsed.id, parsed)
        elif op == MESSAGE:
            s.loose.append(pos)
        elif op == CHUNK:
            loc, data = parsed
            try:
                for iop, a, e in _inner(data):
                    if iop == SCHEMA:
                        rec = _body(SCHEMA, data, a, e)
                        s.schemas.setdefault(rec.id, rec)
                    elif iop == CHANNEL:
                        rec = _body(CHANNEL, data, a, e)
                        s.channels.setdefault(rec.id, rec)
                    elif e - a < 22:
                        raise Bad("message shorter than its header")
            except Bad as exc:
                s.damage.append(Damage(pos, end, "chunk", str(exc)))
                return
            s.chunks.append(loc)
        elif op == METADATA:
            s.metadata.append(parsed)
            s.metadata_at.append((pos, end))
        elif op == ATTACHMENT:
            s.attachments.append(parsed)


def scan(path: str | Path) -> Scan:
    """Walk a file's records, resynchronising past damage (see the module doc)."""
    path = Path(path)
    try:
        fh = open(path, "rb")
    except FileNotFoundError:
        raise ValueError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise ValueError(f"{path}: is a folder; give an .mcap file") from None
    with fh:
        size = os.fstat(fh.fileno()).st_size
        buf = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ) if size else b""
    s = Scan(path, size, _buf=buf)
    _Walker(buf, size, s).walk()
    if not s.channels and not s.chunks and not s.metadata and not s.loose:
        raise ValueError(f"{path}: no MCAP records found (not an MCAP file, or cut before its first record)")
    _check_calibration(s)
    return s


CALIBRATED = (".scale_m_per_s2_per_count", ".offset_m_per_s2")  # the calibration metadata's numbers


def attached_calibration(s: Scan) -> dict[str, str] | None:
    """The calibration metadata the recorder derives from the config it attached (``config.yaml``, an attachment
    whose CRC the walk checks), or None where there is no such attachment or it is not a config of this tool."""
    att = next((a for a in s.attachments if a.name == "config.yaml"), None)
    if att is None:
        return None
    try:
        return parse_config(parse_yaml(bytes(att.data).decode("utf-8"), "config.yaml"), "config.yaml").calibration_metadata()
    except (ValueError, UnicodeDecodeError):  # (an older recording's config: nothing to check against)
        return None


def _check_calibration(s: Scan) -> None:
    """Metadata records carry no CRC of their own: the calibration's scales and offsets, which turn every count
    into m/s^2, are checked against those of the attached config, and a difference is damage (one changed digit
    had exported tip 1 19 x too large, exit 0, and ``replay recover`` had called the file whole)."""
    found = [(i, m) for i, (name, m) in enumerate(s.metadata) if name == "calibration"]
    # a compact recording's samples are its serial bytes, read through the calibration: there it must be whole
    # (one changed byte in a key or in the record's name had read as no samples at all, and recover as whole)
    compact = bool(s.topic_ids(TOPICS["raw"])) and not s.topic_ids(TOPICS["accel"]) and raw_is_frames(s)
    want = attached_calibration(s) if found or compact else None
    if not want:
        return
    if not found:
        s.damage.append(Damage(-1, -1, "calibration metadata", "no record of it, where the config attached "
                                                               "(CRC-checked) gives one: its name damaged?"))
        return
    i, cal = found[-1]
    for key, value in want.items():
        if key.endswith(CALIBRATED) and (key in cal or compact):
            try:
                same = key in cal and float(cal[key]) == float(value)
            except ValueError:
                same = False
            if not same:
                a, b = s.metadata_at[i]
                got = f"{key} = {cal[key]}" if key in cal else f"no {key}"
                s.damage.append(Damage(a, b, "calibration metadata",
                                       f"{got} where the config attached (CRC-checked) gives {value}"))
                return


def open_intact(path: str | Path) -> Scan:
    """The scan of a whole, undamaged file; a one-line ValueError naming the damage otherwise."""
    s = scan(path)
    problem = s.problem()
    if problem:
        raise ValueError(problem)
    return s


# --------------------------------------------------------------------------------------- readers


@dataclass
class Recording:
    """Every message of a recording, per topic, as recorded."""

    path: Path
    seq: np.ndarray  # (n,) frame sequence numbers
    t_device: np.ndarray  # (n,) device clock [s] since its boot
    values: np.ndarray  # (n, 3) base, tip1, tip2 [m/s^2]
    clipped: np.ndarray  # (n,) bool
    log_time_ns: np.ndarray  # (n,) the timeline (monotonic across device restarts)
    publish_time_ns: np.ndarray  # (n,)
    raw: bytes = b""
    events: list[dict] = field(default_factory=list)
    status: list[dict] = field(default_factory=list)
    models: list[dict] = field(default_factory=list)
    devices: list[dict] = field(default_factory=list)  # status frames of the device
    config_yaml: str = ""
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    samples_topic: str = TOPICS["accel"]  # where the samples came from: /rig/accel, or /rig/raw decoded

    @property
    def rate_hz(self) -> float:
        """From the device clock within sessions; NaN with fewer than two samples."""
        d = np.diff(self.t_device)
        d = d[(d > 0) & (np.diff(self.seq) == 1)] if d.size else d
        return 1.0 / typical_step(d) if d.size else float("nan")

    @property
    def duration_s(self) -> float:
        return float(self.log_time_ns[-1] - self.log_time_ns[0]) * 1e-9 if self.log_time_ns.size else 0.0


def _json(data: bytes, path: Path) -> dict:
    try:
        out = json.loads(data)
    except (ValueError, UnicodeDecodeError):
        raise ValueError(f"{path}: a message is not valid JSON (damage inside an intact chunk?)") from None
    if not isinstance(out, dict):
        raise ValueError(f"{path}: a message is not a JSON object")
    return out


def read_recording(path: str | Path, raw: bool = True) -> Recording:
    """Every message of an intact recording (refused with one line if damaged or cut short).

    The samples are the ``/rig/accel`` messages where the recording has them (``--accel-json``, imports,
    text-line devices, recordings before the compact layout), else the serial bytes of ``/rig/raw``
    decoded (:func:`decode_raw`), with the same sequence numbers, device times, values, flags and log
    times as ``/rig/accel`` would have had. ``raw`` keeps the serial bytes in ``Recording.raw``.
    """
    s = open_intact(path)
    path = Path(path)
    topic = {cid: c.topic for cid, c in s.channels.items()}
    seq, t, vals, clip, lt, pt = [], [], [], [], [], []
    raws, lists = [], {k: [] for k in ("events", "status", "model", "device")}
    for ch, _, log, pub, data, _ in s.messages():
        tp = topic.get(ch)
        if tp == TOPICS["accel"]:
            d = _json(data, path)
            try:
                seq.append(int(d["seq"]))
                t.append(float(d["t_device"]))
                vals.append((float(d["base"]), float(d["tip1"]), float(d["tip2"])))
            except (KeyError, TypeError, ValueError):
                raise ValueError(f"{path}: an /rig/accel message lacks seq, t_device, base, tip1 or tip2") from None
            clip.append(bool(d.get("clipped", False)))
            lt.append(log)
            pt.append(pub)
        elif tp == TOPICS["raw"]:
            raws.append((data, pub))
        else:
            for key in lists:
                if tp == TOPICS[key]:
                    lists[key].append(_json(data, path))
    meta = {name: dict(m) for name, m in s.metadata}
    columns = (np.array(seq, np.int64), np.array(t, float), np.array(vals, float).reshape(-1, 3),
               np.array(clip, bool), np.array(lt, np.int64), np.array(pt, np.int64))
    source = TOPICS["accel"]
    if not seq:
        dec = decode_raw(s, raws, lists["events"])
        if dec is not None:
            columns = (dec.seq, dec.t_device, dec.values, dec.clipped, dec.log_time_ns, dec.publish_time_ns)
            source = TOPICS["raw"]
    return Recording(path, *columns, b"".join(r[0] for r in raws) if raw else b"",
                     lists["events"], lists["status"], lists["model"], lists["device"],
                     meta.get("config", {}).get("yaml", ""), meta, source)


def _restart_starts(events: list[dict]) -> list[float]:
    return [float(e["timeline_s"]) for e in events if e.get("kind") == "device_restart" and "timeline_s" in e]


@dataclass(frozen=True)
class RawSamples:
    """The samples of a recording decoded from its serial bytes (``/rig/raw``)."""

    seq: np.ndarray  # (n,) int64, the device's 32-bit sequence numbers as sent
    t_device: np.ndarray  # (n,) device clock [s] since its boot
    values: np.ndarray  # (n, 3) base, tip1, tip2 [m/s^2], from the calibration metadata
    clipped: np.ndarray  # (n,) bool
    session: np.ndarray  # (n,) bool: a new device session (restart) starts at this frame
    log_time_ns: np.ndarray  # (n,) the timeline, as the recorder stamps /rig/accel
    publish_time_ns: np.ndarray  # (n,) the host time of the read that completed the frame
    fs_hz: float  # from the device clock within sessions (NaN with fewer than two samples)


def raw_is_frames(s: Scan) -> bool:
    """Whether the recording's /rig/raw holds binary frames (not a text-line device's lines)."""
    return not any(c.topic == TOPICS["raw"] and c.metadata.get("format") == RAW_LINES for c in s.channels.values())


def decode_raw(s: Scan, raws: list[tuple[bytes, int]], events: list[dict]) -> RawSamples | None:
    """The samples of ``/rig/raw`` (messages as (bytes, publish time ns), in file order), or None when the file
    has no raw bytes, no calibration, or text lines (their samples are the /rig/accel messages).

    The recorded range: the first ``count`` frames of the ``samples`` metadata (the recorder kept the first
    ``count`` frames decoded from these bytes); in a recovered file, up to the last occurrence of its
    ``last_seq`` (raw bytes may be missing). Sessions: a new one where the sequence or device time goes
    back, or a status frame names a new session (as the driver cuts); each starts on the timeline where
    its ``device_restart`` event says. Log times: the ``anchor_ns`` of the ``samples`` metadata, plus the
    timeline. Without it: in a file cut before it was closed (no ``samples`` metadata), as the recorder
    anchors (the read that delivered the first frame arrived with the last frame it delivered); in a
    closed file from before ``anchor_ns`` was written (it has /rig/accel too), as its recorder anchored
    (the first frame at the host time of its read).
    """
    cal = s.meta("calibration")
    if not raws or not cal or not raw_is_frames(s):
        return None
    try:
        scale = np.array([float(cal[f"{c}.scale_m_per_s2_per_count"]) for c in CHANNELS])
        offset = np.array([float(cal[f"{c}.offset_m_per_s2"]) for c in CHANNELS])
    except (KeyError, ValueError):
        return None
    dec = Decoder()
    parts = [dec.feed(b"".join(r[0] for r in raws)), dec.flush()]
    seq = np.concatenate([p.seq for p in parts]).astype(np.int64)
    t_us = np.concatenate([p.t_us for p in parts])
    counts = np.concatenate([p.counts for p in parts])
    flags = np.concatenate([p.flags for p in parts])
    cuts = np.concatenate([p.restart for p in parts])
    end = np.concatenate([p.end for p in parts])
    session = None
    at = 0
    for p in parts:  # a new session id without a sequence reset is still a new clock
        for st in p.status:
            if session is not None and st.session_id != session and at + st.index < cuts.size and at + st.index > 0:
                cuts[at + st.index] = True
            session = st.session_id
        at += len(p)
    span = s.meta("samples")
    k = None
    if s.meta("recovery"):  # raw bytes may be missing: the recording ended at its last sequence number
        last = span.get("last_seq", "")
        hits = np.flatnonzero(seq == int(last)) if last.isdigit() else np.zeros(0, int)
        k = int(hits[-1]) + 1 if hits.size else None
    elif span.get("count", "").isdigit():
        k = int(span["count"])
    if k is not None:
        seq, t_us, counts, flags, cuts, end = seq[:k], t_us[:k], counts[:k], flags[:k], cuts[:k], end[:k]
    n = seq.size
    dt = np.diff(t_us.astype(np.float64))[(np.diff(seq) == 1) & ~cuts[1:]] if n > 1 else np.zeros(0)
    fs = 1e6 / typical_step(dt) if dt.size and np.median(dt) > 0 else float("nan")
    # the timeline, as the driver computes it: device time plus an offset per session
    t_dev = t_us.astype(np.float64) * 1e-6
    t_s = np.empty(n)
    starts = _restart_starts(events)
    a, j = 0, 0
    for b in list(np.flatnonzero(cuts[1:]) + 1) + [n]:
        if b <= a:
            continue
        if a == 0:
            shift = -float(t_dev[0])
        else:
            after = float(t_s[a - 1]) + (1.0 / fs if np.isfinite(fs) else 0.0)
            shift = (starts[j] if j < len(starts) else after) - float(t_dev[a])
            j += 1
        t_s[a:b] = t_dev[a:b] + shift
        a = b
    cum = np.cumsum([len(r[0]) for r in raws])
    pub = np.array([r[1] for r in raws], np.int64)[np.minimum(np.searchsorted(cum, end), len(raws) - 1)]
    anchor = span.get("anchor_ns", "")
    if anchor.lstrip("-").isdigit():
        anchor_ns = int(anchor)
    elif n and span:  # closed by a recorder that anchored at the first frame
        anchor_ns = int(pub[0]) - int(round(float(t_s[0]) * 1e9))
    elif n:
        first_read = np.flatnonzero((pub == pub[0]) & ~np.cumsum(cuts).astype(bool))
        anchor_ns = int(pub[0]) - int(round(float(t_s[first_read[-1]]) * 1e9))
    else:
        anchor_ns = 0
    log = anchor_ns + np.rint(t_s * 1e9).astype(np.int64)
    return RawSamples(seq, t_dev, counts.astype(np.float64) * scale + offset, (flags & FLAG_CLIPPED) != 0, cuts, log,
                      pub, fs)


def _session_index(seq: np.ndarray, restart: np.ndarray, starts: list[float], fs: float) -> np.ndarray:
    """Grid positions of decoded frames: within a device session by sequence number (32-bit wraps undone),
    a new session at the timeline position its device_restart event gives (else right after the last)."""
    index = np.empty(seq.size, np.int64)
    bounds = list(np.flatnonzero(restart)) + [seq.size]
    a, k, nxt = 0, 0, 0
    for b in bounds:
        if b <= a:
            continue
        s = seq[a:b]
        s = s + (np.cumsum(np.diff(s, prepend=s[:1]) < -(2**31)) << 32)
        start = nxt
        if a > 0:
            if k < len(starts):
                start = max(nxt, int(round(starts[k] * fs)))
            k += 1
        index[a:b] = s - s[0] + start
        nxt = int(index[b - 1]) + 1
        a = b
    return index


OWN_TIMES = "--time and --fs are for tables (CSV, MAT, TDMS); a recording (MCAP) carries its own times"


def read_samples(path: str | Path, *, fill: bool = True, **unused) -> Samples:
    """Samples of an intact recording: decoded in bulk from its raw bytes (fast), else from /rig/accel.

    Lost frames are holes in the sequence, filled by linear interpolation (``fill``) so the stream
    stays uniform; a device restart starts a new session at its place on the timeline.
    """
    if unused and any(v is not None for k, v in unused.items() if k not in ("base", "tip1", "tip2")):
        raise ValueError(OWN_TIMES)
    s = open_intact(path)
    path = Path(path)
    ev_ids, raw_ids = s.topic_ids(TOPICS["events"]), s.topic_ids(TOPICS["raw"])
    events, raw = [], []
    for m in s.messages(ev_ids | raw_ids):
        if m[0] in raw_ids:
            raw.append((m[4], m[3]))
        else:
            events.append(_json(m[4], path))
    meta = {name: dict(m) for name, m in s.metadata}
    fast = decode_raw(s, raw, events)
    if fast is not None and fast.seq.size >= 2 and np.isfinite(fast.fs_hz):
        index = _session_index(fast.seq, fast.session, _restart_starts(events), fast.fs_hz)
        seq, values, fs = fast.seq, fast.values, fast.fs_hz
    else:
        rec = read_recording(path, raw=False)
        if len(rec.seq) < 2:
            raise ValueError(f"{path}: holds fewer than two samples")
        d = np.diff(rec.log_time_ns)
        d = d[d > 0]
        if not d.size:
            raise ValueError(f"{path}: the samples' times do not advance")
        fs = 1e9 / typical_step(d)
        index = np.rint((rec.log_time_ns - rec.log_time_ns[0]) * (fs * 1e-9)).astype(np.int64)
        if np.any(np.diff(index) <= 0):
            index = np.arange(len(rec.seq))
        seq, values = rec.seq, rec.values
    return on_grid(index, values, seq, fs, str(path), fill, events=tuple(events), metadata=meta)


def read_columns(path: str | Path, names: list[str], time_col: str | None = None,
                 fs_hz: float | None = None, gaps: bool = False) -> Columns:
    """Channels base, tip1, tip2 of a recording by name; with ``gaps``, NaN on the rows of lost frames
    (else interpolated over them, as ``read_samples`` fills them)."""
    if time_col is not None or fs_hz is not None:
        raise ValueError(OWN_TIMES)
    bad = [c for c in names if c not in CHANNELS]
    if bad:
        raise ValueError(f"a recording has the channels base, tip1, tip2; not {bad[0]!r}")
    smp = read_samples(path)
    values = np.where(smp.filled[:, None], np.nan, smp.values) if gaps else smp.values
    return Columns({c: values[:, CHANNELS.index(c)] for c in names}, smp.fs_hz, str(path))


# ---------------------------------------------------------------------------------------- writer


def write_samples(path: str | Path, samples: Samples, *, force: bool = False, inputs: Iterable = (),
                  source: str = "") -> Path:
    """Samples as a recording of this tool (``/rig/accel`` and metadata; no raw bytes), written as
    ``path.part`` and renamed when complete."""
    cfg = Config(RigConfig(), DaqConfig(rate_hz=samples.fs_hz), source=source or f"imported from {samples.source}")
    rec = McapRecorder(path, cfg, port=f"import:{samples.source}", flush_s=3600.0, force=force, inputs=inputs,
                       accel_json=True)  # no serial bytes: the JSON samples are the record
    try:
        n = len(samples.t)
        now = time.time_ns()
        seq = samples.seq if samples.seq is not None else np.arange(n)
        keep = np.flatnonzero(seq >= 0)
        for k in range(0, keep.size, 2000):
            i = keep[k:k + 2000]
            rec.write_block(SampleBlock(seq[i].astype(np.uint32), samples.t[i], samples.values[i],
                                        np.zeros((i.size, 3), np.int16), np.zeros(i.size, bool), now, 0.0,
                                        samples.t[i]))
    finally:
        out = rec.close()
    return out
