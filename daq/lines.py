"""Text-line devices: one sample per line, as an Arduino sketch prints it (``Serial.println``); sans-I/O.

The other protocol beside daq.protocol's binary frames, with the same shape: :class:`LineDecoder` is fed
bytes (``feed``), returns :class:`daq.protocol.Frames` and keeps :class:`LineCounters`, so the driver, the
recorder, the live pipeline, the events and the reconnects are those of the binary path. The config's
``daq.lines`` (:class:`LineFormat`) says how a line reads:

- fields separated by commas, tabs or spaces (``delimiter: auto`` takes commas when a line has one, else
  runs of tabs and spaces); surrounding spaces and a trailing delimiter are ignored; numbers in decimal or
  exponent notation;
- each of ``base``, ``tip1``, ``tip2`` and the optional ``counter``, ``time`` and ``clipped`` columns is
  named (a name from ``columns`` or from a header line the device prints, e.g. ``seq,t_us,base,tip1,tip2``)
  or given by position (from 0);
- the sample number comes from the counter column (unwrapped at ``counter_bits``; a jump forward is lost
  lines, a step back a device restart), else from the device-time column (time x rate), else from the
  line's place in the stream: then every complete line that is not a line of words counts, so a garbled
  line leaves a one-sample gap and times stay right;
- the device time comes from the time column (in ``time_unit_s``, unwrapped at ``time_wrap``: a sketch's
  ``micros()`` wraps at 2^32), else from the sample number at the configured rate. The driver anchors it to
  the host clock at the first line, as for binary frames.

What counts as what: a line that cannot be read (wrong number of fields, a mapped field that is not a
finite number, a counter that is not an integer, a line longer than ``max_line_bytes``) is a malformed line,
counted and skipped, never fatal; a line of words only (a header, or a message the sketch printed) is a text
line, used to learn column names when it holds them; the first line after the port opens or reopens may be
cut and is skipped unless it is a line of words; the partial line at the end of a stream is skipped (it may
be cut). Unlike a binary frame, a line has no checksum: a flipped digit that still reads as a number goes
undetected. Bytes of skipped and malformed lines are counted in ``skipped_bytes``.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .protocol import EMPTY, FLAG_CLIPPED, Counters, Decoder, Frames

ROLES = ("base", "tip1", "tip2", "counter", "time", "clipped")
CHANNEL_ROLES = ("base", "tip1", "tip2")
MAX_COLUMNS = 64
NUMBER = re.compile(rb"[+-]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][+-]?\d+)?")
WORD = re.compile(rb"[A-Za-z_][^\s,]*")
SEPARATORS = {"comma": b",", "tab": b"\t", "space": None, "auto": None}


def _is_word(p: bytes) -> bool:
    """A name, not a number: ``nan`` and ``inf`` are numbers a sketch printed, not words."""
    if not WORD.fullmatch(p):
        return False
    try:
        float(p)
    except ValueError:
        return True
    return False


def _spec_ok(value: Any) -> bool:
    if value is None:
        return True
    if isinstance(value, bool):
        return False
    if isinstance(value, int):
        return 0 <= value < MAX_COLUMNS
    return isinstance(value, str) and 0 < len(value) <= 64 and _is_word(value.encode("utf-8", "replace"))


@dataclass(frozen=True)
class LineFormat:
    """How a line-printing device prints one sample (the config's ``daq.lines``; see the module doc)."""

    delimiter: str = field(default="auto", metadata={"choices": ("auto", "comma", "tab", "space")})
    columns: tuple[str, ...] = field(default=(), metadata={"max_len": MAX_COLUMNS})  # names in printed order
    base: Any = 0  # a column name or a position from 0
    tip1: Any = 1
    tip2: Any = 2
    counter: Any = None  # optional: a sample counter (drops are gaps in it)
    time: Any = None  # optional: device time in time_unit_s
    clipped: Any = None  # optional: non-zero when a channel clipped
    time_unit_s: float = field(default=1e-6, metadata={"gt": 0.0, "max": 1.0})  # micros(): 1e-6, millis(): 1e-3
    time_wrap: float = field(default=2.0**32, metadata={"min": 0.0, "max": 2.0**64})  # in time units; 0: never
    counter_bits: int = field(default=32, metadata={"min": 8, "max": 64})
    max_line_bytes: int = field(default=256, metadata={"min": 16, "max": 4096})

    def __post_init__(self):
        for role in ROLES:
            spec = getattr(self, role)
            if not _spec_ok(spec):
                raise ValueError(f"daq.lines.{role} = {spec!r}: give a column name (letters, digits, _; no spaces or "
                                 f"commas) or a position from 0 to {MAX_COLUMNS - 1}" + ("" if role in CHANNEL_ROLES
                                                                                          else ", or leave it out"))
        for name in self.columns:
            if not _spec_ok(name):
                raise ValueError(f"daq.lines.columns: {name!r} is not a column name (letters, digits, _; no spaces "
                                 f"or commas)")
        if len(set(self.columns)) != len(self.columns):
            raise ValueError("daq.lines.columns names a column twice")
        used = self.specs()
        if self.columns:
            for role, spec in used.items():
                if isinstance(spec, str) and spec not in self.columns:
                    raise ValueError(f"daq.lines.{role} = {spec!r} is not among daq.lines.columns "
                                     f"({', '.join(self.columns)})")
                if isinstance(spec, int) and spec >= len(self.columns):
                    raise ValueError(f"daq.lines.{role} = {spec} is beyond the {len(self.columns)} columns")
            where = [self.columns.index(s) if isinstance(s, str) else s for s in used.values()]
        else:
            where = list(used.values())
        if len(set(where)) != len(where):
            raise ValueError("daq.lines: two of " + ", ".join(used) + " name the same column")

    def specs(self) -> dict[str, Any]:
        """The roles that are printed, and their column (name or position)."""
        return {r: getattr(self, r) for r in ROLES if getattr(self, r) is not None}

    def named(self) -> bool:
        """Whether a column is given by name (then names must come from ``columns`` or a header line)."""
        return any(isinstance(s, str) for s in self.specs().values())

    def layout(self) -> list[str | None]:
        """What a device printing this format prints in each column (a role, or None for another value):
        ``columns`` when given, else positions first and named roles after them."""
        specs = self.specs()
        if self.columns:
            by_name = {s: r for r, s in specs.items() if isinstance(s, str)}
            by_pos = {s: r for r, s in specs.items() if isinstance(s, int)}
            return [by_name.get(c, by_pos.get(i)) for i, c in enumerate(self.columns)]
        pos = {s: r for r, s in specs.items() if isinstance(s, int)}
        out: list[str | None] = [pos.get(i) for i in range(max(pos) + 1 if pos else 0)]
        out += [r for r, s in specs.items() if isinstance(s, str)]
        return out

    def header(self) -> list[str]:
        """Column names for a header line: ``columns``, or each column's name (its role for a positional one)."""
        if self.columns:
            return list(self.columns)
        specs = self.specs()
        return [(specs[r] if isinstance(specs[r], str) else r) if r else f"x{i}" for i, r in enumerate(self.layout())]


def _separator(fmt: LineFormat) -> str:
    return {"comma": ",", "tab": "\t", "space": " ", "auto": ","}[fmt.delimiter]


def header_line(fmt: LineFormat) -> bytes:
    """The header line a device printing ``fmt`` prints at boot (``\r\n`` like println)."""
    return (_separator(fmt).join(fmt.header()) + "\r\n").encode()


def encode_lines(fmt: LineFormat, seq: np.ndarray, t_us: np.ndarray, counts: np.ndarray,
                 clipped: np.ndarray | None = None) -> bytes:
    """Lines as a device printing ``fmt`` sends them (the simulated line device; ``\\r\\n`` like println):
    counts as integers, the counter modulo 2^counter_bits, the time in time_unit_s modulo time_wrap."""
    n = len(seq)
    sep = _separator(fmt)
    unit_us = fmt.time_unit_s * 1e6
    cols: dict[str, list[str]] = {}
    counts = np.asarray(counts)
    for j, role in enumerate(CHANNEL_ROLES):
        cols[role] = [str(int(v)) for v in counts[:, j]]
    cols["counter"] = [str(int(v)) for v in np.asarray(seq, np.uint64) % np.uint64(2**fmt.counter_bits)] \
        if fmt.counter_bits < 64 else [str(int(v)) for v in seq]
    t = np.asarray(t_us, np.float64) / unit_us
    if fmt.time_wrap:
        t = np.mod(t, fmt.time_wrap)
    integral = abs(unit_us - round(unit_us)) < 1e-9 and unit_us >= 1
    cols["time"] = [str(int(v)) for v in np.floor(t)] if integral else [f"{v:.9g}" for v in t]
    cols["clipped"] = ["1" if c else "0" for c in (np.zeros(n, bool) if clipped is None else clipped)]
    layout = fmt.layout()
    rows = zip(*[cols[r] if r else ["0"] * n for r in layout])
    return "".join(sep.join(r) + "\r\n" for r in rows).encode()


@dataclass
class LineCounters(Counters):
    """The binary decoder's counters (``frames`` = lines read as samples) and the line decoder's own."""

    malformed_lines: int = 0  # complete lines that could not be read: counted, skipped
    text_lines: int = 0  # lines of words: a header, or a message the sketch printed


class LineDecoder(Decoder):
    """Streaming decoder of a line-printing device: ``feed(bytes) -> Frames`` (``counts`` as printed, floats),
    ``flush()``, ``reopened(outage_s)``; sequence accounting (drops, duplicates, restarts) as daq.protocol's."""

    def __init__(self, fmt: LineFormat, rate_hz: float):
        super().__init__()
        self.counters = LineCounters()
        self.fmt = fmt
        self.rate_hz = float(rate_hz)
        self.last_problem = ""  # why the latest malformed line was refused
        self._auto = fmt.delimiter == "auto"
        self._sep = SEPARATORS[fmt.delimiter]
        self._partial = b""
        self._synced = False
        self._overlong = False
        self._pos: dict[str, int] | None = None
        self._nfields: int | None = None
        if fmt.columns:
            self._resolve(list(fmt.columns))
        elif not fmt.named():
            self._pos = dict(fmt.specs())
        self._index = 0  # the sample clock without counter and time columns
        self._counter_last: int | None = None
        self._counter_value = 0
        self._time_last: float | None = None
        self._time_value = 0.0
        self._cmod = 2**fmt.counter_bits

    # ------------------------------------------------------------------------------------------- input

    def feed(self, data: bytes) -> Frames:
        c = self.counters
        c.bytes_in += len(data)
        lines = (self._partial + bytes(data)).split(b"\n")
        self._partial = lines.pop()
        rows: list[tuple] = []
        for line in lines:
            if self._overlong:  # the end of a line already refused as too long
                self._overlong = False
                c.skipped_bytes += len(line) + 1
                continue
            self._line(line, rows)
        if len(self._partial) > self.fmt.max_line_bytes:
            self._malformed(len(self._partial), f"a line longer than {self.fmt.max_line_bytes} bytes")
            self._partial = b""
            self._overlong = True
        return self._frames(rows)

    def flush(self) -> Frames:
        """End of stream: the partial last line may be cut; it is skipped."""
        self.counters.skipped_bytes += len(self._partial)
        self._partial = b""
        return EMPTY

    def reopened(self, outage_s: float = 0.0) -> None:
        """The port was reopened after ``outage_s``: the partial line is dropped, the next line may be cut, and
        without counter and time columns the sample clock moves on by the lines printed meanwhile."""
        self.counters.skipped_bytes += len(self._partial)
        if self._partial.strip():
            self._index += 1  # a line cut by the outage: a sample the device printed
        self._partial = b""
        self._synced = False
        self._overlong = False
        if self.fmt.counter is None and self.fmt.time is None and outage_s > 0:
            self._index += int(round(outage_s * self.rate_hz))

    # ------------------------------------------------------------------------------------------- lines

    def _malformed(self, nbytes: int, why: str) -> None:
        self.counters.malformed_lines += 1
        self.counters.skipped_bytes += nbytes
        self.last_problem = why
        self._index += 1  # a sample the device printed and we could not read

    def _split(self, text: bytes) -> list[bytes]:
        sep = (b"," if b"," in text else None) if self._auto else self._sep
        parts = [p.strip() for p in text.split(sep)] if sep is not None else text.split()
        if len(parts) > 1 and parts[-1] == b"":
            parts.pop()  # a trailing delimiter
        return parts

    def _resolve(self, names: list[str]) -> bool:
        pos = {}
        for role, spec in self.fmt.specs().items():
            if isinstance(spec, str):
                if spec not in names:
                    return False
                pos[role] = names.index(spec)
            elif spec >= len(names):
                return False
            else:
                pos[role] = spec
        self._pos, self._nfields = pos, len(names)
        return True

    def _line(self, line: bytes, rows: list) -> None:
        size = len(line) + 1
        text = line.strip()
        first = not self._synced  # the bytes before the first newline after the port opened
        self._synced = True
        if not text:
            self.counters.skipped_bytes += size
            return
        parts = self._split(text)
        if all(_is_word(p) for p in parts):  # a line of words
            self.counters.text_lines += 1
            self.counters.skipped_bytes += size
            if not self.fmt.columns:
                names = [p.decode("ascii", "replace") for p in parts]
                if len(set(names)) == len(names):
                    self._resolve(names)
            return
        if first:  # it may have been cut: its start was sent before we listened
            self.counters.skipped_bytes += size
            self._index += 1
            return
        if len(line) > self.fmt.max_line_bytes:
            self._malformed(size, f"a line longer than {self.fmt.max_line_bytes} bytes")
            return
        if self._pos is None:
            self._malformed(size, "no header line naming the columns yet (" + ", ".join(
                str(s) for s in self.fmt.specs().values() if isinstance(s, str)) + "); give daq.lines.columns")
            return
        if self._nfields is None:
            if len(parts) <= max(self._pos.values()):
                self._malformed(size, f"{len(parts)} fields, columns up to position {max(self._pos.values())} "
                                      f"needed: {_show(text)}")
                return
            self._nfields = len(parts)  # the first readable line fixes the number of fields
        if len(parts) != self._nfields:
            self._malformed(size, f"{len(parts)} fields instead of {self._nfields}: {_show(text)}")
            return
        vals = {}
        for role, i in self._pos.items():
            p = parts[i]
            v = float(p) if NUMBER.fullmatch(p) else math.nan
            if not math.isfinite(v):
                self._malformed(size, f"{role} ({_show(p)}) is not a finite number: {_show(text)}")
                return
            vals[role] = v
        if "counter" in vals and not (vals["counter"].is_integer() and 0 <= vals["counter"] < self._cmod):
            self._malformed(size, f"counter {_show(parts[self._pos['counter']])} is not an integer from 0 to "
                                  f"2^{self.fmt.counter_bits}-1")
            return
        if "time" in vals and (vals["time"] < 0 or (self.fmt.time_wrap and vals["time"] >= self.fmt.time_wrap)):
            self._malformed(size, f"time {_show(parts[self._pos['time']])} is outside 0 to time_wrap")
            return
        rows.append((vals["base"], vals["tip1"], vals["tip2"], vals.get("counter"), vals.get("time"),
                     vals.get("clipped", 0.0), self._index))
        self._index += 1

    # ------------------------------------------------------------------------------------------ frames

    def _unwrap_counter(self, raw: int) -> int:
        if self._counter_last is None:
            self._counter_value = raw
        else:
            step = (raw - self._counter_last) % self._cmod
            self._counter_value = self._counter_value + step if step <= self._cmod // 2 else raw  # back: a restart
        self._counter_last = raw
        return self._counter_value

    def _unwrap_time(self, raw: float) -> float:
        wrap = self.fmt.time_wrap
        if self._time_last is None or not wrap:
            self._time_value = raw
        else:
            step = raw - self._time_last
            if step < -wrap / 2:
                step += wrap  # the device's clock wrapped (micros() after 71.6 minutes)
            self._time_value = self._time_value + step if step >= 0 else raw  # back: a restart
        self._time_last = raw
        return self._time_value

    def _frames(self, rows: list) -> Frames:
        if not rows:
            return EMPTY
        n = len(rows)
        counts = np.array([r[:3] for r in rows], np.float64)
        flags = np.where(np.array([r[5] for r in rows]) != 0, FLAG_CLIPPED, 0).astype(np.uint8)
        unit_us = self.fmt.time_unit_s * 1e6
        if self.fmt.time is not None:
            t_us = np.array([round(self._unwrap_time(r[4]) * unit_us) for r in rows], np.int64)
        if self.fmt.counter is not None:
            number = np.array([self._unwrap_counter(int(r[3])) for r in rows], np.int64)
        elif self.fmt.time is not None:
            number = np.rint(t_us * 1e-6 * self.rate_hz).astype(np.int64)
        else:
            number = np.array([r[6] for r in rows], np.int64)
        if self.fmt.time is None:
            t_us = np.floor(number * (1e6 / self.rate_hz) + 1e-6).astype(np.int64)
        seq = (number & 0xFFFFFFFF).astype(np.uint32)
        t_us = np.maximum(t_us, 0).astype(np.uint64)
        keep, gaps, restart = self._sequence(seq, t_us)
        self.counters.frames += n
        return Frames(seq[keep], t_us[keep], counts[keep], flags[keep], gaps[keep], restart[keep], ())


def _show(text: bytes, limit: int = 40) -> str:
    s = text.decode("ascii", "backslashreplace")
    return repr(s if len(s) <= limit else s[:limit - 3] + "...")


def decoder_for(daq) -> Decoder:
    """The decoder of a ``daq`` config section (daq.config.DaqConfig): binary frames or text lines."""
    return LineDecoder(daq.lines, daq.rate_hz) if daq.format == "lines" else Decoder()
