"""Transports for the simulated device: a real OS serial device (pty) and pyserial's ``rig://``.

``PtyServer`` plays the firmware's UART: it opens a pseudo-terminal, prints the
path of its device side (a symlink can point at it), and writes frames in real
time, paced against absolute deadlines (no drift from sleeping relative to the
last write). Unsent bytes wait in a transmit FIFO of ``TX_FIFO_BYTES``; when the
reader falls so far behind that it overflows, the device drops what does not
fit, as real firmware would, and the receiver sees a sequence gap. A configured disconnect closes the pty, waits, and opens a
new one behind the same symlink.
"""

from __future__ import annotations

import errno
import os
import threading
import time
import tty
from pathlib import Path

import serial

from .config import Config
from .sim.device import SimulatedDevice

TICK_S = 0.005
TX_FIFO_BYTES = 64 * 1024


def register_url_handler() -> None:
    """Make ``serial.serial_for_url('rig://...')`` open the simulated device in process."""
    if "daq.urlhandler" not in serial.protocol_handler_packages:
        serial.protocol_handler_packages.append("daq.urlhandler")


class PtyServer:
    def __init__(self, config: Config, link: str | Path | None = None, seed: int | None = None):
        self.device = SimulatedDevice(config, seed)
        self.config = config
        self.link = Path(link) if link else None
        self._stop = threading.Event()
        self._master: int | None = None
        self._slave: int | None = None
        self.path: str | None = None
        self.dropped_bytes = 0
        self.disconnects = 0
        self._fifo = bytearray()
        self.started = threading.Event()
        self._open_pty()

    def _open_pty(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)  # no line discipline: bytes pass unchanged, no echo
        os.set_blocking(master, False)
        self._master, self._slave = master, slave
        self.path = os.ttyname(slave)
        if self.link is not None:
            tmp = self.link.with_name(self.link.name + ".tmp")
            tmp.unlink(missing_ok=True)
            tmp.symlink_to(self.path)
            os.replace(tmp, self.link)  # atomic: a reader never sees a missing link

    def _close_pty(self) -> None:
        for fd in (self._master, self._slave):
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
        self._master = self._slave = None

    def stop(self) -> None:
        self._stop.set()

    def serve(self, duration_s: float | None = None, start: threading.Event | None = None) -> None:
        """Stream in real time until ``stop()`` or ``duration_s`` of device time.

        ``start``: wait for this event before the first sample (a recorder sets
        it once its port is open, so no frame is cut by the open's flush).
        """
        rate = self.device.rate_hz
        disconnects = sorted(self.config.daq.faults.disconnect_at_s)
        if start is not None:
            while not start.wait(0.05):
                if self._stop.is_set():
                    return
        self.started.set()
        t0 = time.monotonic()
        try:
            while not self._stop.is_set():
                now = time.monotonic() - t0
                due = int(now * rate) - self.device.seq
                if duration_s is not None:
                    due = min(due, int(round(duration_s * rate)) - self.device.seq)
                    if due <= 0 and self.device.seq >= int(round(duration_s * rate)):
                        break
                if disconnects and self.device.t_s >= disconnects[0]:
                    disconnects.pop(0)
                    self._disconnect(t0)
                    continue
                if due > 0:
                    self._fifo += self.device.frames(due)
                self._drain()
                # Next tick on the absolute grid t0 + k * TICK_S: no accumulated drift.
                elapsed = time.monotonic() - t0
                time.sleep(max(0.0, TICK_S - (elapsed % TICK_S)))
            end = time.monotonic() + 1.0  # let the reader take what is still in the FIFO
            while self._fifo and time.monotonic() < end and not self._stop.is_set():
                self._drain()
                time.sleep(TICK_S)
        finally:
            self._close_pty()
            if self.link is not None:
                self.link.unlink(missing_ok=True)

    def _disconnect(self, t0: float) -> None:
        """Cable pulled: close the pty, keep sampling (frames are lost), then a new pty."""
        self.disconnects += 1
        self._close_pty()
        self._fifo.clear()
        end = time.monotonic() + self.config.daq.faults.disconnect_for_s
        while time.monotonic() < end and not self._stop.is_set():
            due = int((time.monotonic() - t0) * self.device.rate_hz) - self.device.seq
            if due > 0:
                self.device.frames(due)  # the device runs on; nobody hears it
            time.sleep(TICK_S)
        self._open_pty()

    def _drain(self) -> None:
        """Write what the pty takes; keep the rest in the FIFO, drop beyond its size."""
        while self._fifo:
            try:
                n = os.write(self._master, self._fifo)
            except BlockingIOError:
                break
            except OSError as exc:
                if exc.errno in (errno.EIO, errno.EBADF):
                    break
                raise
            del self._fifo[:n]
        if len(self._fifo) > TX_FIFO_BYTES:
            over = len(self._fifo) - TX_FIFO_BYTES
            self.dropped_bytes += over
            del self._fifo[TX_FIFO_BYTES:]
