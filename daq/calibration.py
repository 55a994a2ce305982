"""A channel's sensitivity from a handheld reference calibrator: the sine fit of its 159.2 Hz line. Pure.

A handheld accelerometer calibrator shakes the sensor at 159.2 Hz (omega = 1000 rad/s, so 10 m/s^2 is also
10 mm/s and 10 um) with 10 m/s^2 rms, the usual field check. The channel's counts are fitted with the
four-parameter sine model of the digitiser-test standards (IEEE Std 1057 and IEEE Std 1241, the
"four-parameter least-squares sine fit"):

    x(t) = A cos(w t) + B sin(w t) + C,

linear least squares in A, B, C at a trial frequency, and Gauss-Newton steps in w with the column
t (-A sin(w t) + B cos(w t)) added, started from the peak of the Hann-windowed spectrum near the nominal
frequency (parabolic interpolation of its log magnitude). The calibrator's frequency is fitted, not
assumed: a calibrator 0.1 % off over 10 s would otherwise smear the line. Then

    sensitivity [counts per m/s^2] = sqrt((A^2 + B^2) / 2) / reference_rms,

and C is the channel's mean (its offset in counts). Noise and harmonics fall in the residual; the fit's
amplitude error is about residual_rms x sqrt(2 / n) (the least-squares standard error of A and B).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

CALIBRATOR_HZ = 159.2
CALIBRATOR_RMS_M_PER_S2 = 10.0
SCALE_KEYS = ("scale_m_per_s2_per_count", "sensitivity_counts_per_m_per_s2", "sensitivity_mv_per_g",
              "adc_mv_per_count")


@dataclass(frozen=True)
class SineFit:
    frequency_hz: float
    amplitude: float  # peak, in the signal's unit
    offset: float  # the mean, C
    phase_rad: float  # x = amplitude cos(w t + phase) + offset, t from the first sample
    residual_rms: float
    n: int

    @property
    def rms(self) -> float:
        return self.amplitude / math.sqrt(2.0)

    @property
    def amplitude_std(self) -> float:
        """Standard error of the amplitude from the residual (white-noise assumption)."""
        return self.residual_rms * math.sqrt(2.0 / self.n)

    @property
    def snr_db(self) -> float:
        return 20.0 * math.log10(self.rms / self.residual_rms) if self.residual_rms > 0 else math.inf


def fit_sine(x: np.ndarray, fs_hz: float, f0_hz: float = CALIBRATOR_HZ, band: float = 0.05,
             iterations: int = 50) -> SineFit:
    """Four-parameter least-squares sine fit of ``x`` sampled at ``fs_hz``, the line sought within
    ``f0_hz`` x (1 +- ``band``). A ValueError says what is wrong (too short, no line there)."""
    x = np.asarray(x, np.float64)
    n = x.size
    if not (np.isfinite(fs_hz) and fs_hz > 0) or not np.all(np.isfinite(x)):
        raise ValueError("the signal and its rate must be finite")
    if f0_hz * (1 + band) >= fs_hz / 2:
        raise ValueError(f"{f0_hz:g} Hz is above the Nyquist frequency of {fs_hz:g} Hz sampling")
    if n < 64 or n < 20 * fs_hz / f0_hz:
        raise ValueError(f"{n} samples hold fewer than 20 periods of {f0_hz:g} Hz; record longer")
    # start: the windowed spectrum's peak within the band
    m = 1 << int(math.ceil(math.log2(4 * n)))
    spec = np.abs(np.fft.rfft((x - x.mean()) * np.hanning(n), m))
    freqs = np.fft.rfftfreq(m, 1.0 / fs_hz)
    inband = np.flatnonzero((freqs >= f0_hz * (1 - band)) & (freqs <= f0_hz * (1 + band)))
    k = int(inband[np.argmax(spec[inband])])
    if k in (inband[0], inband[-1]) or spec[k] < 10 * np.median(spec[inband]):  # a slope or noise, not a line
        strongest = float(freqs[1 + np.argmax(spec[1:])])
        raise ValueError(f"no line between {f0_hz * (1 - band):.1f} and {f0_hz * (1 + band):.1f} Hz (the strongest "
                         f"is at {strongest:.1f} Hz): is the calibrator on this sensor and running?")
    a, b, c = np.log(spec[k - 1:k + 2] + 1e-300)
    f = float(freqs[k] + 0.5 * (a - c) / (a - 2 * b + c) * (freqs[1] - freqs[0]))
    t = (np.arange(n) - (n - 1) / 2.0) / fs_hz  # centred: the frequency column is orthogonal to the rest
    w = 2 * math.pi * f
    for _ in range(iterations):
        cw, sw = np.cos(w * t), np.sin(w * t)
        (A, B, C), *_ = np.linalg.lstsq(np.column_stack([cw, sw, np.ones(n)]), x, rcond=None)
        jac = np.column_stack([cw, sw, np.ones(n), t * (-A * sw + B * cw)])
        step, *_ = np.linalg.lstsq(jac, x - (A * cw + B * sw + C), rcond=None)
        w += step[3]
        if abs(step[3]) < 1e-13 * w:
            break
    cw, sw = np.cos(w * t), np.sin(w * t)
    (A, B, C), *_ = np.linalg.lstsq(np.column_stack([cw, sw, np.ones(n)]), x, rcond=None)
    resid = x - (A * cw + B * sw + C)
    f = w / (2 * math.pi)
    if abs(f / f0_hz - 1) > band:
        raise ValueError(f"the fit left the band around {f0_hz:g} Hz (ended at {f:.2f} Hz)")
    amp = float(math.hypot(A, B))
    phase = float(math.atan2(-B, A) + w * t[0])  # A cos + B sin = amp cos(w t + atan2(-B, A)), moved to sample 0
    return SineFit(float(f), amp, float(C), float((phase + math.pi) % (2 * math.pi) - math.pi),
                   float(np.sqrt(np.mean(resid**2))), n)


def sensitivity(fit: SineFit, reference_rms: float = CALIBRATOR_RMS_M_PER_S2) -> float:
    """Counts (the signal's unit) per m/s^2: the fitted line's rms over the calibrator's."""
    return fit.rms / reference_rms


def check_line(fit: SineFit, min_snr_db: float = 20.0) -> None:
    """Refuse a fit whose line does not stand out of the rest of the signal (a ValueError saying so)."""
    if fit.snr_db < min_snr_db:
        raise ValueError(f"the {fit.frequency_hz:.1f} Hz line is only {fit.snr_db:.1f} dB above the rest of the "
                         f"signal (at least {min_snr_db:g} dB needed): hold the calibrator still on the sensor, away "
                         f"from the running shaker")


def calibrated_mapping(data: dict[str, Any], channel: str, counts_per_m_per_s2: float, note: str,
                       offset_m_per_s2: float | None = None, model: str | None = None,
                       serial: str | None = None) -> dict[str, Any]:
    """A config mapping (parsed YAML) with ``daq.calibration.CHANNEL`` set to the new sensitivity: the other
    ways to give a scale are removed (one source only), offset, model and serial set where given, the rest
    of the file kept."""
    out = dict(data or {})
    daq = dict(out.get("daq") or {})
    cals = dict(daq.get("calibration") or {})
    cal = {k: v for k, v in dict(cals.get(channel) or {}).items() if k not in SCALE_KEYS}
    cal["sensitivity_counts_per_m_per_s2"] = float(counts_per_m_per_s2)
    if offset_m_per_s2 is not None:
        cal["offset_m_per_s2"] = float(offset_m_per_s2)
    if model is not None:
        cal["sensor_model"] = model
    if serial is not None:
        cal["serial_number"] = serial
    cal["calibrated"] = note
    cals[channel] = cal
    daq["calibration"] = cals
    out["daq"] = daq
    return out
