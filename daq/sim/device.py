"""The simulated rig as a device: the firmware's sampling, ADC, clock, framing, and faults.

Like python-can's virtual bus, this is a first-class device, not a test
double: ``daq sim`` serves it on a pty, ``rig://`` serves it to pyserial in
process, and ``daq record`` uses it when no port is given. The firmware
samples the three accelerometers at ``rate_hz``, quantises them (daq.sim.sensors),
stamps each frame with its sequence number and its own clock (which may
drift), and streams frames; faults are injected into the byte stream on demand.
"""

from __future__ import annotations

import numpy as np

from .rig import RigSimulator
from .sensors import to_counts

from ..config import Config
from ..protocol import FLAG_CLIPPED, encode


class SimulatedDevice:
    def __init__(self, config: Config, seed: int | None = None):
        self.config = config
        self.rate_hz = config.daq.rate_hz
        # Compile the rig kernel now (a throwaway simulator), not on the first real-time sample:
        # on a fresh install that takes seconds, which would show as a burst of overdue frames.
        RigSimulator(config.rig, self.rate_hz).advance(2)
        self.sim = RigSimulator(config.rig, self.rate_hz)
        self.rng = np.random.default_rng(config.rig.seed if seed is None else seed)
        self.seq = 0  # next sequence number (frames generated, including device-side drops)
        self.sent_frames = 0  # frames that left the device intact before byte faults

    @property
    def t_s(self) -> float:
        """Device's simulated time (true time since start), seconds."""
        return self.seq / self.rate_hz

    def frames(self, n: int) -> bytes:
        """The next ``n`` sample periods as bytes on the wire (faults applied)."""
        if n <= 0:
            return b""
        _, out = self.sim.advance(n)
        counts = np.empty((n, 3), np.int32)
        clipped = np.zeros(n, bool)
        for j, (sig, sensor) in enumerate(zip((out.base, out.tip1, out.tip2), self.config.rig.sensors)):
            counts[:, j], c = to_counts(sig, sensor, self.rng)
            clipped |= c
        seq = self.seq + np.arange(n)
        drift = 1.0 + self.config.daq.faults.clock_drift_ppm * 1e-6
        t_us = np.floor(seq / self.rate_hz * 1e6 * drift).astype(np.uint64)
        self.seq += n
        f = self.config.daq.faults
        keep = np.ones(n, bool)
        if f.drop_frame_rate > 0:
            keep = self.rng.random(n) >= f.drop_frame_rate
        self.sent_frames += int(keep.sum())
        data = encode(seq[keep], t_us[keep], counts[keep], np.where(clipped[keep], FLAG_CLIPPED, 0))
        return self._byte_faults(data, n / self.rate_hz)

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
