"""Transports for the simulated device: a real OS serial device (pty) and pyserial's ``rig://``.

``PtyServer`` plays the firmware's UART: it opens a pseudo-terminal, prints the
path of its device side (a symlink can point at it), and writes frames in real
time, paced against absolute deadlines (no drift from sleeping relative to the
last write). Unsent bytes wait in a transmit FIFO of ``TX_FIFO_BYTES``; when the
reader falls so far behind that it overflows, the device drops what does not
fit, as real firmware would, and the receiver sees a sequence gap. A configured disconnect closes the pty, removes
the symlink (as udev removes /dev/serial/by-id/... when a cable is pulled), waits, and opens a new pty behind a
new symlink. A configured restart reboots the firmware (sequence and clock from 0, a new session id) on the
same pty.

The symlink (``--link``) is only ever this server's own: an existing path that is not a symlink is refused,
an existing symlink is replaced only if it points at a pseudo-terminal or nowhere (a stale link of an earlier
run) or with ``force`` (the link, never the file it points at), and at the end the link is removed only if it
still points at this server's pty.
"""

from __future__ import annotations

import errno
import os
import secrets
import threading
import time
import tty
from pathlib import Path

import serial

from .config import Config
from .sim.device import DEFAULT_DEVICE_ID, SimulatedDevice

TICK_S = 0.005
TX_FIFO_BYTES = 64 * 1024


def register_url_handler() -> None:
    """Make ``serial.serial_for_url('rig://...')`` open the simulated device in process."""
    if "daq.urlhandler" not in serial.protocol_handler_packages:
        serial.protocol_handler_packages.append("daq.urlhandler")


def check_link(link: Path, force: bool = False) -> None:
    """Refuse a ``--link`` path that is not this kind of server's own symlink (see the module doc)."""
    if not os.path.lexists(link):
        return
    if not link.is_symlink():
        raise ValueError(f"--link {link} exists and is not a symlink; daq sim only replaces its own links")
    target = os.readlink(link)
    stale = not link.exists() or os.path.realpath(link).startswith("/dev/pts/")
    if not stale and not force:
        raise ValueError(f"--link {link} points at {target}, not a pseudo-terminal; give --force to replace "
                         f"the link (the file it points at is kept)")


class PtyServer:
    def __init__(self, config: Config, link: str | Path | None = None, seed: int | None = None,
                 device_id: int = DEFAULT_DEVICE_ID, force_link: bool = False,
                 calibrator: tuple[int, float, float] | None = None):
        self.link = Path(link) if link else None
        if self.link is not None:
            check_link(self.link, force_link)
        self.device = SimulatedDevice(config, seed, device_id, calibrator)
        self.config = config
        self._stop = threading.Event()
        self._master: int | None = None
        self._slave: int | None = None
        self.path: str | None = None
        self.dropped_bytes = 0
        self.disconnects = 0
        self.restarts = 0
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
            tmp = self.link.with_name(f".{self.link.name}.{secrets.token_hex(4)}.tmp")
            tmp.symlink_to(self.path)  # a fresh name: fails rather than touch anything that exists
            os.replace(tmp, self.link)  # atomic: a reader never sees a half-made link

    def _unlink(self) -> None:
        """Remove the link if it is still ours (pointing at the pty we hold open)."""
        if self.link is None or self.path is None or self._master is None:
            return
        try:
            if os.readlink(self.link) == self.path:
                self.link.unlink()
        except (FileNotFoundError, OSError):
            pass

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
        dev = self.device
        disconnects = sorted(self.config.daq.faults.disconnect_at_s)
        restarts = sorted(self.config.daq.faults.restart_at_s)
        if start is not None:
            while not start.wait(0.05):
                if self._stop.is_set():
                    return
        self.started.set()
        t0 = time.monotonic()
        try:
            while not self._stop.is_set():
                now = time.monotonic() - t0
                due = int(now * rate) - dev.sample_index
                if duration_s is not None:
                    due = min(due, int(round(duration_s * rate)) - dev.sample_index)
                    if due <= 0 and dev.sample_index >= int(round(duration_s * rate)):
                        break
                if disconnects and dev.t_s >= disconnects[0]:
                    disconnects.pop(0)
                    self._disconnect(t0)
                    continue
                if restarts and dev.t_s >= restarts[0]:
                    restarts.pop(0)
                    self._restart(t0)
                    continue
                if due > 0:
                    self._fifo += dev.frames(due)
                self._drain()
                # Next tick on the absolute grid t0 + k * TICK_S: no accumulated drift.
                elapsed = time.monotonic() - t0
                time.sleep(max(0.0, TICK_S - (elapsed % TICK_S)))
            end = time.monotonic() + 1.0  # let the reader take what is still in the FIFO
            while self._fifo and time.monotonic() < end and not self._stop.is_set():
                self._drain()
                time.sleep(TICK_S)
        finally:
            self._unlink()
            self._close_pty()

    def _disconnect(self, t0: float) -> None:
        """Cable pulled: close the pty and remove the link, keep sampling (frames are lost), then a new pty."""
        self.disconnects += 1
        self._unlink()
        self._close_pty()
        self._fifo.clear()
        self._wait(t0, self.config.daq.faults.disconnect_for_s, self.device.skip)
        if not self._stop.is_set():
            self._open_pty()

    def _restart(self, t0: float) -> None:
        """Firmware reboot: what is in the transmit FIFO is lost, nothing is sent while it boots."""
        self.restarts += 1
        self._fifo.clear()
        self._wait(t0, self.config.daq.faults.restart_for_s, self.device.idle)
        self.device.restart()

    def _wait(self, t0: float, span_s: float, advance) -> None:
        end = time.monotonic() + span_s
        while time.monotonic() < end and not self._stop.is_set():
            due = int((time.monotonic() - t0) * self.device.rate_hz) - self.device.sample_index
            advance(due)  # the rig runs on; nobody hears it
            time.sleep(TICK_S)

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
