"""Accelerometer and ADC model: what the rig's three sensors do to the true accelerations.

Per channel, in this order: gain error, offset, white noise, clipping at the
accelerometer's range, ADC quantisation to signed integer counts. The host
turns counts back into m/s^2 with the calibration (scale per count and offset).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

CHANNELS = ("base", "tip1", "tip2")


@dataclass(frozen=True)
class Sensor:
    gain: float = field(default=1.0, metadata={"gt": 0.0, "max": 100.0})  # true over nominal: 1.02 = reads 2 % high
    offset_m_per_s2: float = field(default=0.0, metadata={"min": -1e4, "max": 1e4})
    noise_rms_m_per_s2: float = field(default=0.02, metadata={"min": 0.0, "max": 1e4})
    range_m_per_s2: float = field(default=160.0, metadata={"gt": 0.0, "max": 1e6})  # +-16 g accelerometer
    # the data frame carries int16 counts: more than 16 bits would clip every count beyond +-32767
    adc_bits: int = field(default=16, metadata={"min": 8, "max": 16})

    @property
    def lsb_m_per_s2(self) -> float:
        """Nominal calibration: full range over 2^bits counts."""
        return 2.0 * self.range_m_per_s2 / 2**self.adc_bits

    @property
    def count_limits(self) -> tuple[int, int]:
        return -(2 ** (self.adc_bits - 1)), 2 ** (self.adc_bits - 1) - 1


def to_counts(values: np.ndarray, sensor: Sensor, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """True accelerations (n,) -> ADC counts (n,) int32 and a clipped flag (n,)."""
    v = np.asarray(values, float) * sensor.gain + sensor.offset_m_per_s2
    if sensor.noise_rms_m_per_s2 > 0:
        v = v + sensor.noise_rms_m_per_s2 * rng.standard_normal(v.shape)
    lo, hi = sensor.count_limits
    clipped = np.abs(v) >= sensor.range_m_per_s2
    counts = np.clip(np.rint(v / sensor.lsb_m_per_s2), lo, hi)
    return counts.astype(np.int32), clipped


def from_counts(counts: np.ndarray, scale_m_per_s2: float, offset_m_per_s2: float = 0.0) -> np.ndarray:
    """Calibration: counts -> m/s^2."""
    return np.asarray(counts, float) * scale_m_per_s2 + offset_m_per_s2
