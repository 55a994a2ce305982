"""The simulated rig as a device: the firmware's sampling, ADC, clock, framing, identity and faults.

Like python-can's virtual bus, this is a first-class device, not a test
double: ``daq sim`` serves it on a pty, ``rig://`` serves it to pyserial in
process, and ``daq record`` uses it when no port is given. The firmware
samples the three accelerometers at ``rate_hz``, quantises them (daq.sim.sensors),
stamps each frame with its sequence number and its own clock (which may
drift), and streams frames; faults are injected into the byte stream on demand.

Identity: a status frame (daq.protocol) at boot and then once a second of device time carries
the unit's ``device_id`` (fixed), a ``session_id`` drawn at random at every boot, the firmware
version and the sample rate. ``restart()`` reboots the firmware: sequence and clock start again
at 0 under a new session id, while the rig itself keeps moving.
"""

from __future__ import annotations

import os

import numpy as np

from ..config import Config
from ..lines import encode_lines, header_line
from ..protocol import FLAG_CLIPPED, encode, encode_status
from .rig import RigSimulator
from .sensors import to_counts

DEFAULT_DEVICE_ID = 0x51D0_0001
FIRMWARE = (1, 0)


def new_session_id() -> int:
    """A random 64-bit session id, as firmware draws one at boot."""
    return int.from_bytes(os.urandom(8), "little")


class SimulatedDevice:
    """``calibrator``: (channel index, frequency [Hz], rms [m/s^2]): that sensor sits on a handheld reference
    calibrator instead of the rig (``daq calibrate`` without a port); its gain, offset, noise and ADC apply."""

    def __init__(self, config: Config, seed: int | None = None, device_id: int = DEFAULT_DEVICE_ID,
                 calibrator: tuple[int, float, float] | None = None):
        self.config = config
        self.calibrator = calibrator
        self.rate_hz = config.daq.rate_hz
        # Compile the rig kernel now (a throwaway simulator), not on the first real-time sample:
        # on a fresh install that takes seconds, which would show as a burst of overdue frames.
        RigSimulator(config.rig, self.rate_hz).advance(2)
        self.sim = RigSimulator(config.rig, self.rate_hz)
        self.rng = np.random.default_rng(config.rig.seed if seed is None else seed)
        self.device_id = int(device_id) & 0xFFFFFFFF
        self.sample_index = 0  # sample periods since the device was switched on (all boots)
        self.sent_frames = 0  # frames that left the device intact before byte faults
        self.boots = 0
        self._boot()

    def _boot(self) -> None:
        self.seq = 0  # next sequence number since boot (frames generated, including device-side drops)
        self.session_id = new_session_id()
        self.status_counter = 0
        self.boots += 1
        self._header_due = True  # a line-printing sketch prints its header in setup()

    def restart(self) -> None:
        """The firmware reboots: sequence and clock from 0, a new session id; the rig keeps moving."""
        self._boot()

    @property
    def t_s(self) -> float:
        """True time since the device was switched on, seconds (not reset by a restart)."""
        return self.sample_index / self.rate_hz

    def idle(self, n: int) -> None:
        """``n`` sample periods pass with nothing sent (the rig moves on; frames, if any, are lost)."""
        if n > 0:
            self.sim.advance(n)
            self.sample_index += n

    def skip(self, n: int) -> None:
        """``n`` frames are made but nobody hears them (a pulled cable): sequence and clock run on."""
        if n > 0:
            self.sim.advance(n)
            self.sample_index += n
            self.seq += n

    def status_frame(self) -> bytes:
        t_us = int(self.seq / self.rate_hz * 1e6 * (1.0 + self.config.daq.faults.clock_drift_ppm * 1e-6))
        frame = encode_status(self.status_counter, t_us, self.session_id, self.device_id, self.rate_hz, FIRMWARE)
        self.status_counter += 1
        return frame

    def frames(self, n: int) -> bytes:
        """The next ``n`` sample periods as bytes on the wire (status frames and faults included)."""
        if n <= 0:
            return b""
        _, out = self.sim.advance(n)
        counts = np.empty((n, 3), np.int32)
        clipped = np.zeros(n, bool)
        signals = [out.base, out.tip1, out.tip2]
        if self.calibrator is not None:
            ch, f_hz, rms = self.calibrator
            t = (self.sample_index + np.arange(n)) / self.rate_hz
            signals[ch] = rms * np.sqrt(2.0) * np.sin(2 * np.pi * f_hz * t)
        for j, (sig, sensor) in enumerate(zip(signals, self.config.rig.sensors)):
            counts[:, j], c = to_counts(sig, sensor, self.rng)
            clipped |= c
        seq = self.seq + np.arange(n)
        drift = 1.0 + self.config.daq.faults.clock_drift_ppm * 1e-6
        t_us = np.floor(seq / self.rate_hz * 1e6 * drift).astype(np.uint64)
        f = self.config.daq.faults
        keep = np.ones(n, bool)
        if f.drop_frame_rate > 0:
            keep = self.rng.random(n) >= f.drop_frame_rate
        self.sent_frames += int(keep.sum())
        if self.config.daq.format == "lines":
            return self._byte_faults(self._lines(seq, t_us, counts, clipped, keep), n / self.rate_hz)
        data = encode(seq[keep], t_us[keep], counts[keep], np.where(clipped[keep], FLAG_CLIPPED, 0))
        copies = keep.astype(np.int64)
        if f.duplicate_frame_rate > 0:  # a frame sent twice in a row (a firmware retry)
            copies[keep] += self.rng.random(int(keep.sum())) < f.duplicate_frame_rate
            data = np.repeat(np.frombuffer(data, np.uint8).reshape(-1, 24), copies[keep], axis=0).tobytes()
        # a status frame before the data frame of every whole second of device time (and at boot)
        per = max(1, int(round(self.rate_hz)))
        marks = np.flatnonzero(seq % per == 0)
        if marks.size:
            pieces, pos = [], 0
            sent_before = np.concatenate([[0], np.cumsum(copies)])
            for m in marks.tolist():
                cut = int(sent_before[m]) * 24
                pieces.append(data[pos:cut])
                self.seq = int(seq[m])
                pieces.append(self.status_frame())
                pos = cut
            pieces.append(data[pos:])
            data = b"".join(pieces)
        self.seq = int(seq[-1]) + 1
        self.sample_index += n
        return self._byte_faults(data, n / self.rate_hz)

    def _lines(self, seq, t_us, counts, clipped, keep) -> bytes:
        """A line-printing sketch (daq.lines): a header line at boot when columns are named, then one line per
        sample as the config's ``daq.lines`` says; a duplicated sample is its line printed twice."""
        fmt = self.config.daq.lines
        f = self.config.daq.faults
        idx = np.flatnonzero(keep)
        if f.duplicate_frame_rate > 0:
            idx = np.repeat(idx, 1 + (self.rng.random(idx.size) < f.duplicate_frame_rate))
        head = b""
        if self._header_due:
            self._header_due = False
            if fmt.named() or fmt.columns:
                head = header_line(fmt)
        self.seq = int(seq[-1]) + 1
        self.sample_index += len(seq)
        return head + encode_lines(fmt, seq[idx], t_us[idx], counts[idx], clipped[idx])

    def _byte_faults(self, data: bytes, span_s: float) -> bytes:
        f = self.config.daq.faults
        if not (f.corrupt_byte_rate or f.drop_byte_rate or f.garbage_bursts_per_s):
            return data
        arr = np.frombuffer(data, np.uint8).copy()
        if f.corrupt_byte_rate:
            hit = self.rng.random(arr.size) < f.corrupt_byte_rate
            arr[hit] ^= self.rng.integers(1, 256, hit.sum(), dtype=np.uint8)
        if f.drop_byte_rate:
            arr = arr[self.rng.random(arr.size) >= f.drop_byte_rate]
        if f.garbage_bursts_per_s:
            for _ in range(self.rng.poisson(f.garbage_bursts_per_s * span_s)):
                pos = int(self.rng.integers(0, arr.size + 1))
                junk = self.rng.integers(0, 256, f.garbage_burst_bytes, dtype=np.uint8)
                arr = np.concatenate([arr[:pos], junk, arr[pos:]])
        return arr.tobytes()
