"""The acquisition driver: owns the port, the read loop and the error path.

The decoder (daq.protocol) never sees a port; this module is the thin shell
around it, like pyserial's ReaderThread around a Protocol. It opens the port
(a device path or a pyserial URL such as ``rig://``), reads eagerly, decodes,
calibrates counts to m/s^2, and hands each block to the sinks. A lost port is
closed, retried with back-off and reopened; the gap becomes an event, never a
silent hole. Host and device clocks are both kept, and the device clock's
offset and drift are estimated by least squares.

Identity and time:

- The device's status frames (daq.protocol) name it: device id (the unit) and session id (the boot).
  The first one is recorded; a later one from another device id stops the acquisition with an error
  (``foreign_device``): its samples are never merged into this recording.
- After a reconnect to a device that sends status frames, everything read is held back (not decoded
  into samples, not passed to the sinks) until a status frame proves it is the same unit; another
  unit, or no status frame within ``IDENTIFY_S``, stops the acquisition. A stale ``/dev/pts/N`` that
  the kernel has given to another program is therefore never read into the recording.
- A device restart (sequence or device time going backwards, or a new session id of the same unit) is
  a ``device_restart`` event; the timeline ``t_s`` (seconds since the first sample, what the
  recording's log times follow) is re-anchored to the host clock so it stays monotonic and keeps the
  outage's length.
- A port given as ``/dev/ttyUSBn`` or ``/dev/ttyACMn`` is reopened through its ``/dev/serial/by-id/``
  link when there is one, so a reconnect finds the same adapter even if the kernel renumbers it.
"""

from __future__ import annotations

import bisect
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import serial

from .config import Config
from .lines import LineCounters, decoder_for
from .protocol import FLAG_CLIPPED, Frames, Status
from .transport import register_url_handler

IDENTIFY_S = 2.5  # after a reconnect, a status frame must arrive within this long (they come every second)
BY_ID = Path("/dev/serial/by-id")


@dataclass(frozen=True)
class Event:
    t: float  # seconds since the start of acquisition (host clock)
    kind: str  # drop, crc, disconnect, reconnect, clock, start, stop, device, device_restart, ...
    message: str
    level: str = "info"  # debug, info, warning, error
    data: dict = field(default_factory=dict)


@dataclass(frozen=True)
class SampleBlock:
    """Frames decoded from one read (one device session)."""

    seq: np.ndarray  # uint32
    t_device_s: np.ndarray  # device clock, seconds since its boot
    values: np.ndarray  # (n, 3) m/s^2, columns base, tip1, tip2
    counts: np.ndarray  # (n, 3) ADC counts
    clipped: np.ndarray  # (n,) bool
    host_ns: int  # host wall-clock time of the read that delivered them (epoch ns)
    host_t: float  # the same, seconds since acquisition start (monotonic)
    t_s: np.ndarray | None = None  # timeline: seconds since the first sample, monotonic across restarts

    def __post_init__(self):
        if self.t_s is None:  # a block from one session that starts the timeline
            t = np.asarray(self.t_device_s, float)
            object.__setattr__(self, "t_s", t - (t[0] if t.size else 0.0))

    def __len__(self) -> int:
        return len(self.seq)


class ClockEstimator:
    """Host time ~ offset + (1 + drift) * device time, fitted as the line below every read.

    Each read contributes (device time of its last frame, host time of the read). The host time is late
    by the transport's latency, which is never negative and grows in bursts when the host is busy, so
    the line is fitted under the points, not through them: the lower convex hull's edge at the reads'
    mean device time, the line below all points with the least total distance to them (Moon, Skelly &
    Towsley 1999, "Estimation and removal of clock skew from network delay measurements"). A least-squares
    line followed the bursts: a 3 s recording with the device 3000 ppm fast (-2991 ppm host seconds per
    device second) read -2085 ppm beside a benchmark on both cores, and -2618, -2776, -2944 beside four
    busy processes, where the hull read -2991, -2951, -2971. The offset is host minus device at the
    quickest reads.
    Device time increases within a session (a new device clock gets a new estimator).
    """

    def __init__(self) -> None:
        self._n = 0
        self._sx = 0.0
        self._x0: float | None = None
        self._y0 = 0.0
        self._hull: list[tuple[float, float]] = []  # lower convex hull, device time increasing

    def update(self, t_device_s: float, t_host_s: float) -> None:
        if self._x0 is None:
            self._x0, self._y0 = t_device_s, t_host_s
        x, y = t_device_s - self._x0, t_host_s - self._y0
        h = self._hull
        if h and x <= h[-1][0]:
            if x < h[-1][0] or y >= h[-1][1]:
                return  # device time went back (not counted), or a later read of the same frame
            h.pop()
        self._n += 1
        self._sx += x
        while len(h) >= 2 and (h[-1][0] - h[-2][0]) * (y - h[-2][1]) <= (h[-1][1] - h[-2][1]) * (x - h[-2][0]):
            h.pop()  # h[-1] lies on or above the segment from h[-2] to the new point
        h.append((x, y))

    def estimate(self) -> tuple[float, float] | None:
        """(offset_s: host minus device at device time 0, drift_ppm: host seconds per device second - 1)."""
        h = self._hull
        if self._n < 3 or len(h) < 2:
            return None
        mean_x = self._sx / self._n
        i = max(0, min(len(h) - 2, bisect.bisect_right([p[0] for p in h], mean_x) - 1))
        (xa, ya), (xb, yb) = h[i], h[i + 1]
        slope = (yb - ya) / (xb - xa)
        offset = self._y0 + ya - slope * (xa + self._x0)
        return offset, (slope - 1.0) * 1e6


def stable_port(port: str, by_id: Path | None = None) -> str:
    """The ``/dev/serial/by-id/`` link of a USB serial device path, if one points at it; else ``port``."""
    by_id = BY_ID if by_id is None else by_id
    if "://" in port or not port.startswith("/dev/") or str(Path(port).parent) == str(by_id):
        return port
    try:
        target = os.path.realpath(port)
        for link in sorted(by_id.iterdir()):
            if os.path.realpath(link) == target:
                return str(link)
    except OSError:
        pass
    return port


class ForeignDevice(Exception):
    """The port now reaches another device than the one being recorded."""


@dataclass
class _Held:
    """What a reopened port delivered before its identity was known."""

    t0: float
    raw: list = field(default_factory=list)  # (bytes, host_ns)
    frames: list = field(default_factory=list)  # (Frames, host_ns, host_t)


class Acquisition:
    def __init__(self, port: str, config: Config, on_block: Callable[[SampleBlock], None] | None = None,
                 on_event: Callable[[Event], None] | None = None,
                 on_raw: Callable[[bytes, int], None] | None = None,
                 on_status: Callable[[Status, int], None] | None = None):
        register_url_handler()
        self.port_given = port
        self.port = stable_port(port)
        self.config = config
        self.on_block = on_block or (lambda b: None)
        self.on_event = on_event or (lambda e: None)
        self.on_raw = on_raw or (lambda d, ns: None)
        self.on_status = on_status or (lambda s, ns: None)
        self.decoder = decoder_for(config.daq)  # binary frames (daq.protocol) or text lines (daq.lines)
        self.clock = ClockEstimator()
        self.stop_event = threading.Event()
        self.samples = 0
        self.reconnects = 0
        self.restarts = 0
        self.error: str | None = None  # why the acquisition stopped early, if it did
        self.identity: Status | None = None  # the first status frame: the device being recorded
        self.session: Status | None = None  # the latest status frame
        self._t0 = time.monotonic()
        scales, offsets = config.scales()
        self._scale = np.array(scales)
        self._offset = np.array(offsets)
        self._last_counters = (0, 0, 0, 0, 0, 0)
        self.first_device_s: float | None = None
        self.last_device_s: float | None = None
        self._epoch_offset: float | None = None  # timeline = device time + this
        self._timeline_last = -np.inf
        self._host_first: float = 0.0
        self._held: _Held | None = None
        self._port: serial.SerialBase | None = None
        self._restart_note: tuple[Status, Status] | None = None  # (old, new) session seen in a status frame
        self._last_seq: int | None = None

    def now(self) -> float:
        return time.monotonic() - self._t0

    def _event(self, kind: str, message: str, level: str = "info", **data) -> None:
        self.on_event(Event(self.now(), kind, message, level, data))

    def _open_port(self) -> serial.SerialBase:
        return serial.serial_for_url(self.port, baudrate=self.config.daq.baudrate, timeout=0.05)

    def open(self) -> None:
        """Open the port (before any output is created); a one-line ValueError if it cannot be opened."""
        if self._port is not None:
            return
        try:
            self._port = self._open_port()
        except (serial.SerialException, OSError, ValueError) as exc:
            raise ValueError(f"cannot open port {self.port_given}: {exc}") from None

    @property
    def resolved_port(self) -> str:
        return self.port if "://" in self.port else os.path.realpath(self.port)

    def run(self, duration_s: float | None = None, opened: threading.Event | None = None) -> None:
        """Acquire until ``stop()``, or until ``duration_s`` of samples (timeline) has been received."""
        self._t0 = time.monotonic()
        self.open()
        port = self._port
        via = f" (via {self.port})" if self.port != self.port_given else ""
        self._event("start", f"acquisition started on {self.port_given}{via}", port=self.port_given,
                    stable_port=self.port, resolved=self.resolved_port)
        if opened is not None:
            opened.set()
        backoff = list(self.config.daq.reconnect_backoff_s) or [0.5]
        give_up = self.config.daq.give_up_s
        heard = self.now()  # when the port last delivered a byte (or was opened)
        try:
            while not self.stop_event.is_set():
                try:
                    data = port.read(max(1, port.in_waiting))
                except (serial.SerialException, OSError) as exc:
                    port = self._reconnect(port, exc, backoff)
                    if port is None:
                        break
                    heard = self.now()
                    continue
                if not data:
                    if self._held is not None and self.now() - self._held.t0 > IDENTIFY_S:
                        self._foreign(f"{self.port_given} answered without a status frame within {IDENTIFY_S} s "
                                      f"after the reconnect; the recorded device sends one every second")
                        break
                    if give_up > 0 and self.now() - heard > give_up:
                        self._give_up(f"nothing arrived from {self.port_given} for {give_up:g} s")
                        break
                    continue
                heard = self.now()
                try:
                    if self._handle(data, duration_s):
                        break
                except ForeignDevice as exc:
                    self._foreign(str(exc))
                    break
        finally:
            try:
                if port is not None:
                    port.close()
            except (serial.SerialException, OSError):
                pass
            self._port = None
            if self._held is None and self.error is None:
                self._deliver(self.decoder.flush(), time.time_ns(), self.now(), duration_s)
            self._report_counters()
            self._event("stop", f"acquisition stopped after {self.samples} samples"
                        + (f": {self.error}" if self.error else ""), "error" if self.error else "info")

    def stop(self) -> None:
        self.stop_event.set()

    def _foreign(self, message: str) -> None:
        held = self._held
        n_bytes = sum(len(d) for d, _ in held.raw) if held else 0
        self.error = message
        self._held = None
        self._event("foreign_device", f"{message}; {n_bytes} byte(s) read from it were not recorded; "
                    "acquisition stopped", "error", bytes_discarded=n_bytes)

    def _give_up(self, message: str) -> None:
        """Stop waiting for a device that is gone or silent (``daq.give_up_s``): the recording ends with an
        error, and everything received before stays in it."""
        self.error = f"{message} (daq.give_up_s; 0 waits until Ctrl-C)"
        self._event("give_up", f"{message}; acquisition stopped", "error")

    def _reconnect(self, port, exc, backoff):
        t_lost = self.now()
        self._event("disconnect", f"port lost: {exc}", "warning")
        try:
            port.close()
        except (serial.SerialException, OSError):
            pass
        give_up = self.config.daq.give_up_s
        attempt = 0
        while not self.stop_event.is_set():
            if give_up > 0 and self.now() - t_lost > give_up:
                self._give_up(f"{self.port_given} was lost and did not come back within {give_up:g} s "
                              f"({attempt} attempts to reopen it)")
                return None
            time.sleep(backoff[min(attempt, len(backoff) - 1)])
            attempt += 1
            try:
                port = self._open_port()
            except (serial.SerialException, OSError, ValueError):
                continue
            self.reconnects += 1
            self.decoder.reopened(self.now() - t_lost)
            self._event("reconnect", f"port reopened after {self.now() - t_lost:.2f} s and {attempt} attempts"
                        + (" (held until the device proves its identity)" if self.identity else ""),
                        "warning", gap_s=self.now() - t_lost, attempts=attempt, resolved=self.resolved_port)
            if self.identity is not None:
                self._held = _Held(self.now())
            return port
        return None

    def _handle(self, data: bytes, duration_s: float | None) -> bool:
        host_ns = time.time_ns()
        host_t = self.now()
        if self._held is not None:
            held = self._held
            held.raw.append((data, host_ns))
            fr = self.decoder.feed(data)
            held.frames.append((fr, host_ns, host_t))
            proof = [s for f, _, _ in held.frames for s in f.status]
            if not proof:
                if host_t - held.t0 > IDENTIFY_S:
                    raise ForeignDevice(f"{self.port_given} answered without a status frame within {IDENTIFY_S} s "
                                        "after the reconnect; the recorded device sends one every second")
                return False
            self._check_identity(proof[0])  # raises ForeignDevice
            self._held = None
            for raw, ns in held.raw:
                self.on_raw(raw, ns)
            for f, ns, t in held.frames:
                if self._deliver(f, ns, t, duration_s):
                    return True
            return False
        self.on_raw(data, host_ns)
        return self._deliver(self.decoder.feed(data), host_ns, host_t, duration_s)

    def _check_identity(self, st: Status) -> None:
        ident = self.identity
        if ident is not None and st.device_id != ident.device_id:
            raise ForeignDevice(f"{self.port_given} now reaches device {st.device_id:08x} (session "
                                f"{st.session_id:016x}), not the recorded device {ident.device_id:08x}")

    def _deliver(self, fr: Frames, host_ns: int, host_t: float, duration_s: float | None) -> bool:
        """Sinks get the frames of one read: split at restarts, on the timeline; True once the duration is reached."""
        self._report_counters(fr)
        cuts = set(np.flatnonzero(fr.restart).tolist())
        for st in fr.status:
            self._check_identity(st)
            if self.identity is None:
                self.identity = st
                self._event("device", f"device {st.device_id:08x}, session {st.session_id:016x}, firmware "
                            f"{st.firmware[0]}.{st.firmware[1]}, {st.rate_hz:g} Hz", **st.as_dict())
                if abs(st.rate_hz - self.config.daq.rate_hz) > 1e-6 * self.config.daq.rate_hz:
                    self._event("rate", f"the device samples at {st.rate_hz:g} Hz, the config says "
                                f"{self.config.daq.rate_hz:g} Hz", "warning")
            elif self.session is not None and st.session_id != self.session.session_id:
                if st.index not in cuts and st.index < len(fr):
                    cuts.add(st.index)  # new session without a sequence reset: still a new clock
                self._restart_note = (self.session, st)
            self.session = st
            self.on_status(st, host_ns)
        if not len(fr):
            return False
        bounds = sorted(cuts | {0, len(fr)})
        for a, b in zip(bounds[:-1], bounds[1:]):
            if a in cuts and self._epoch_offset is not None:
                self._restart(fr, a, b, host_t)
            if self._emit(fr, a, b, host_ns, host_t, duration_s):
                return True
        return False

    def _restart(self, fr: Frames, a: int, b: int, host_t: float) -> None:
        d0 = float(fr.t_us[a]) * 1e-6
        rate = self.config.daq.rate_hz
        # the read at host_t delivered frames up to device time t_us[b - 1]: that one arrived about then
        estimate = (host_t - self._host_first) - float(fr.t_us[b - 1]) * 1e-6
        self._epoch_offset = max(estimate, self._timeline_last + 1.0 / rate - d0)
        self.restarts += 1
        self.clock = ClockEstimator()  # a new device clock
        prev, new = self._restart_note or (None, None)
        self._restart_note = None
        sess = (f"; session {prev.session_id:016x} -> {new.session_id:016x}" if prev and new else "")
        self._event("device_restart", f"device restarted (sequence {self._last_seq} -> {int(fr.seq[a])}{sess}); "
                    f"timeline re-anchored at {d0 + self._epoch_offset:.3f} s", "warning",
                    previous_seq=self._last_seq, seq=int(fr.seq[a]), t_device=d0,
                    timeline_s=d0 + self._epoch_offset)

    def _emit(self, fr: Frames, a: int, b: int, host_ns: int, host_t: float, duration_s: float | None) -> bool:
        t_dev = fr.t_us[a:b].astype(np.float64) * 1e-6
        if self._epoch_offset is None:
            self._epoch_offset = -float(t_dev[0])
            self._host_first = host_t
            self.first_device_s = float(t_dev[0])
        t_s = t_dev + self._epoch_offset
        stop = False
        if duration_s is not None:
            n_keep = int(np.searchsorted(t_s, duration_s - 0.5 / self.config.daq.rate_hz))
            if n_keep < len(t_s):
                stop = True
                b = a + n_keep
                t_dev, t_s = t_dev[:n_keep], t_s[:n_keep]
        if b <= a:
            return stop
        self.clock.update(float(t_dev[-1]), host_t)
        self.last_device_s = float(t_dev[-1])
        self._timeline_last = float(t_s[-1])
        self._last_seq = int(fr.seq[b - 1])
        values = fr.counts[a:b].astype(np.float64) * self._scale + self._offset
        block = SampleBlock(fr.seq[a:b], t_dev, values, fr.counts[a:b], (fr.flags[a:b] & FLAG_CLIPPED) != 0,
                            host_ns, host_t, t_s)
        self.samples += len(block)
        self.on_block(block)
        return stop

    def _report_counters(self, fr: Frames | None = None) -> None:
        c = self.decoder.counters
        now = (c.crc_errors, c.dropped_frames, c.skipped_bytes, c.duplicates, c.unknown_version,
               getattr(c, "malformed_lines", 0))
        pc, pd, ps, pdup, punk, pbad = self._last_counters
        crc, drop, skip, dup, unk, bad = now
        if fr is not None and len(fr.gaps):
            where = np.flatnonzero(fr.gaps)
            for k in where[:10]:
                self._event("drop", f"{int(fr.gaps[k])} frame(s) lost before sequence {int(fr.seq[k])}",
                            "warning", frames=int(fr.gaps[k]), seq=int(fr.seq[k]))
        if crc > pc:
            self._event("crc", f"{crc - pc} frame(s) failed the CRC", "warning", count=crc - pc)
        if skip > ps:
            self._event("skip", f"{skip - ps} byte(s) outside any frame skipped", "debug", count=skip - ps)
        if dup > pdup:
            self._event("duplicate", f"{dup - pdup} duplicate frame(s) dropped (each sample kept once)", "warning",
                        count=dup - pdup)
        if unk > punk:
            self._event("unknown_version", f"{unk - punk} frame start(s) A5 5A with an unknown protocol version "
                        f"({', '.join(str(v) for v in sorted(c.versions_seen))}; this host reads version 1) skipped",
                        "warning", count=unk - punk, versions=sorted(c.versions_seen))
        if bad > pbad:
            self._event("malformed", f"{bad - pbad} malformed line(s) skipped (last: {self.decoder.last_problem})",
                        "warning", count=bad - pbad, last=self.decoder.last_problem)
        self._last_counters = now

    def status(self) -> dict:
        c = self.decoder.counters
        est = self.clock.estimate()
        realtime = est is not None and abs(est[1]) < 50_000  # a drift beyond 5 % is no clock: a replayed source
        out = {
            "t": self.now(), "samples": self.samples, "frames": c.frames, "crc_errors": c.crc_errors,
            "skipped_bytes": c.skipped_bytes, "dropped_frames": c.dropped_frames, "duplicates": c.duplicates,
            "sequence_resets": c.sequence_resets, "restarts": self.restarts, "reconnects": self.reconnects,
            "status_frames": c.status_frames, "unknown_version": c.unknown_version,
            "clock_offset_s": est[0] if realtime else None, "clock_drift_ppm": est[1] if realtime else None,
            "device_rate_ratio": (1e-6 * est[1] + 1.0) if est is not None else None,
        }
        if isinstance(c, LineCounters):
            out["malformed_lines"], out["text_lines"] = c.malformed_lines, c.text_lines
        if self.identity is not None:
            out["device_id"] = f"{self.identity.device_id:08x}"
        if self.session is not None:
            out["session_id"] = f"{self.session.session_id:016x}"
        return out
