"""The acquisition driver: owns the port, the read loop and the error path.

The decoder (daq.protocol) never sees a port; this module is the thin shell
around it, like pyserial's ReaderThread around a Protocol. It opens the port
(a device path or a pyserial URL such as ``rig://``), reads eagerly, decodes,
calibrates counts to m/s^2, and hands each block to the sinks. A lost port is
closed, retried with back-off and reopened; the gap becomes an event, never a
silent hole. Host and device clocks are both kept, and the device clock's
offset and drift are estimated by least squares.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import serial

from .config import Config
from .protocol import FLAG_CLIPPED, Decoder
from .transport import register_url_handler


@dataclass(frozen=True)
class Event:
    t: float  # seconds since the start of acquisition (host clock)
    kind: str  # drop, crc, disconnect, reconnect, clock, start, stop, ...
    message: str
    level: str = "info"  # debug, info, warning, error
    data: dict = field(default_factory=dict)


@dataclass(frozen=True)
class SampleBlock:
    """Frames decoded from one read."""

    seq: np.ndarray  # uint32
    t_device_s: np.ndarray  # device clock, unwrapped seconds
    values: np.ndarray  # (n, 3) m/s^2, columns base, tip1, tip2
    counts: np.ndarray  # (n, 3) ADC counts
    clipped: np.ndarray  # (n,) bool
    host_ns: int  # host wall-clock time of the read that delivered them (epoch ns)
    host_t: float  # the same, seconds since acquisition start (monotonic)

    def __len__(self) -> int:
        return len(self.seq)


class ClockEstimator:
    """Host time ~ offset + (1 + drift) * device time, least squares over all reads.

    Each read contributes (device time of its last frame, host time of the
    read); transport latency biases the offset by its mean, not the drift.
    """

    def __init__(self) -> None:
        self._n = 0
        self._sx = self._sy = self._sxx = self._sxy = 0.0
        self._x0: float | None = None
        self._y0 = 0.0

    def update(self, t_device_s: float, t_host_s: float) -> None:
        if self._x0 is None:
            self._x0, self._y0 = t_device_s, t_host_s
        x, y = t_device_s - self._x0, t_host_s - self._y0
        self._n += 1
        self._sx += x
        self._sy += y
        self._sxx += x * x
        self._sxy += x * y

    def estimate(self) -> tuple[float, float] | None:
        """(offset_s: host minus device at device time 0, drift_ppm: host seconds per device second - 1)."""
        n = self._n
        den = n * self._sxx - self._sx**2
        if n < 3 or den <= 0:
            return None
        slope = (n * self._sxy - self._sx * self._sy) / den
        icpt = (self._sy - slope * self._sx) / n
        offset = self._y0 + icpt - slope * self._x0
        return offset, (slope - 1.0) * 1e6


class Acquisition:
    def __init__(self, port: str, config: Config, on_block: Callable[[SampleBlock], None] | None = None,
                 on_event: Callable[[Event], None] | None = None,
                 on_raw: Callable[[bytes, int], None] | None = None):
        register_url_handler()
        self.port = port
        self.config = config
        self.on_block = on_block or (lambda b: None)
        self.on_event = on_event or (lambda e: None)
        self.on_raw = on_raw or (lambda d, ns: None)
        self.decoder = Decoder()
        self.clock = ClockEstimator()
        self.stop_event = threading.Event()
        self.samples = 0
        self.reconnects = 0
        self._t0 = time.monotonic()
        scales, offsets = config.scales()
        self._scale = np.array(scales)
        self._offset = np.array(offsets)
        self._last_counters = (0, 0, 0)
        self.first_device_s: float | None = None
        self.last_device_s: float | None = None

    def now(self) -> float:
        return time.monotonic() - self._t0

    def _event(self, kind: str, message: str, level: str = "info", **data) -> None:
        self.on_event(Event(self.now(), kind, message, level, data))

    def _open(self) -> serial.SerialBase:
        return serial.serial_for_url(self.port, baudrate=self.config.daq.baudrate, timeout=0.05)

    def run(self, duration_s: float | None = None, opened: threading.Event | None = None) -> None:
        """Acquire until ``stop()``, or until ``duration_s`` of device time has been received."""
        self._t0 = time.monotonic()
        try:
            port = self._open()
        except (serial.SerialException, OSError, ValueError) as exc:
            raise ValueError(f"cannot open port {self.port}: {exc}") from None
        self._event("start", f"acquisition started on {self.port}")
        if opened is not None:
            opened.set()
        backoff = list(self.config.daq.reconnect_backoff_s) or [0.5]
        try:
            while not self.stop_event.is_set():
                try:
                    data = port.read(max(1, port.in_waiting))
                except (serial.SerialException, OSError) as exc:
                    port = self._reconnect(port, exc, backoff)
                    if port is None:
                        break
                    continue
                if not data:
                    continue
                if self._handle(data, duration_s):
                    break
        finally:
            try:
                if port is not None:
                    port.close()
            except (serial.SerialException, OSError):
                pass
            self.decoder.flush()
            self._report_counters()
            self._event("stop", f"acquisition stopped after {self.samples} samples")

    def stop(self) -> None:
        self.stop_event.set()

    def _reconnect(self, port, exc, backoff):
        t_lost = self.now()
        self._event("disconnect", f"port lost: {exc}", "warning")
        try:
            port.close()
        except (serial.SerialException, OSError):
            pass
        attempt = 0
        while not self.stop_event.is_set():
            time.sleep(backoff[min(attempt, len(backoff) - 1)])
            attempt += 1
            try:
                port = self._open()
            except (serial.SerialException, OSError):
                continue
            self.reconnects += 1
            self._event("reconnect", f"port reopened after {self.now() - t_lost:.2f} s and {attempt} attempts",
                        "warning", gap_s=self.now() - t_lost, attempts=attempt)
            return port
        return None

    def _handle(self, data: bytes, duration_s: float | None) -> bool:
        host_ns = time.time_ns()
        host_t = self.now()
        self.on_raw(data, host_ns)
        fr = self.decoder.feed(data)
        self._report_counters(fr)
        if not len(fr):
            return False
        t_dev = fr.t_us.astype(np.float64) * 1e-6
        if self.first_device_s is None:
            self.first_device_s = float(t_dev[0])
        stop = False
        if duration_s is not None:
            n_keep = int(np.searchsorted(t_dev - self.first_device_s, duration_s - 0.5 / self.config.daq.rate_hz))
            if n_keep < len(t_dev):
                stop = True
                fr = type(fr)(fr.seq[:n_keep], fr.t_us[:n_keep], fr.counts[:n_keep], fr.flags[:n_keep],
                              fr.gaps[:n_keep])
                t_dev = t_dev[:n_keep]
        if len(t_dev):
            self.clock.update(float(t_dev[-1]), host_t)
            self.last_device_s = float(t_dev[-1])
            values = fr.counts.astype(np.float64) * self._scale + self._offset
            block = SampleBlock(fr.seq, t_dev, values, fr.counts, (fr.flags & FLAG_CLIPPED) != 0, host_ns, host_t)
            self.samples += len(block)
            self.on_block(block)
        return stop

    def _report_counters(self, fr=None) -> None:
        c = self.decoder.counters
        crc, drop, skip = c.crc_errors, c.dropped_frames, c.skipped_bytes
        pc, pd, ps = self._last_counters
        if drop > pd and fr is not None and len(fr.gaps):
            where = np.flatnonzero(fr.gaps)
            for k in where[:10]:
                self._event("drop", f"{int(fr.gaps[k])} frame(s) lost before sequence {int(fr.seq[k])}",
                            "warning", frames=int(fr.gaps[k]), seq=int(fr.seq[k]))
        if crc > pc:
            self._event("crc", f"{crc - pc} frame(s) failed the CRC", "warning", count=crc - pc)
        if skip > ps:
            self._event("skip", f"{skip - ps} byte(s) outside any frame skipped", "debug", count=skip - ps)
        self._last_counters = (crc, drop, skip)

    def status(self) -> dict:
        c = self.decoder.counters
        est = self.clock.estimate()
        return {
            "t": self.now(), "samples": self.samples, "frames": c.frames, "crc_errors": c.crc_errors,
            "skipped_bytes": c.skipped_bytes, "dropped_frames": c.dropped_frames,
            "sequence_resets": c.sequence_resets, "reconnects": self.reconnects,
            "clock_offset_s": est[0] if est else None, "clock_drift_ppm": est[1] if est else None,
        }

