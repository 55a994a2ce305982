"""What an instrument chain does to a physical signal computed at the internal rate.

Per acquisition card (shared by its channels): an analog anti-alias filter (Butterworth or elliptic,
realised at the internal rate by the bilinear transform pre-warped at the cut-off, which is within a
fraction of a percent of the analog response below the output Nyquist frequency because the internal
rate is at least ten times the output rate), sampling at the output rate, and an ADC of `bits` bits.
Per channel: sensor noise added before the filter and scaled so that the sampled noise has the target
SNR relative to the RMS of the sampled signal, the sign convention (a sensor mounted upside down), a
calibration gain, clipping at the channel's range and quantisation to the ADC step 2 range / 2^bits
(a mid-tread quantiser with codes -2^(bits-1) .. 2^(bits-1) - 1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.signal

UNITS = {"acceleration": "m/s^2", "base_acceleration": "m/s^2", "velocity": "m/s", "displacement": "m",
         "force": "N", "voltage": "V", "time": "s"}


@dataclass(frozen=True)
class AntiAlias:
    kind: str  # butterworth | elliptic
    order: int
    cutoff_hz: float
    passband_ripple_db: float = 0.1
    stopband_db: float = 80.0

    def sos(self, rate_hz: float) -> np.ndarray:
        if self.kind == "butterworth":
            return scipy.signal.butter(self.order, self.cutoff_hz, fs=rate_hz, output="sos")
        if self.kind == "elliptic":
            return scipy.signal.ellip(self.order, self.passband_ripple_db, self.stopband_db, self.cutoff_hz,
                                      fs=rate_hz, output="sos")
        raise ValueError("kind must be butterworth or elliptic")

    def analog_gain(self, frequency_hz: float) -> float:
        """|H(j 2 pi f)| of the analog prototype."""
        wc = 2 * np.pi * self.cutoff_hz
        if self.kind == "butterworth":
            z, p, k = scipy.signal.butter(self.order, wc, analog=True, output="zpk")
        else:
            z, p, k = scipy.signal.ellip(self.order, self.passband_ripple_db, self.stopband_db, wc,
                                         analog=True, output="zpk")
        _, h = scipy.signal.freqs_zpk(z, p, k, worN=[2 * np.pi * frequency_hz])
        return float(abs(h[0]))

    def describe(self) -> dict:
        d = {"kind": self.kind, "order": self.order, "cutoff_hz": self.cutoff_hz}
        if self.kind == "elliptic":
            d |= {"passband_ripple_db": self.passband_ripple_db, "stopband_db": self.stopband_db}
        return d


@dataclass(frozen=True)
class Card:
    """An acquisition card: output rate, ADC resolution, anti-alias filter."""

    fs_hz: int
    bits: int
    anti_alias: AntiAlias


@dataclass(frozen=True)
class Channel:
    kind: str
    snr_db: float
    sign: int = 1
    gain: float = 1.0  # calibration: measured = sign * gain * true
    headroom: float = 2.0  # range = headroom * max |sign * gain * sampled signal|


@dataclass
class Acquired:
    values: np.ndarray
    clean: np.ndarray  # sign * gain * filtered, sampled signal (no noise, range or quantisation)
    info: dict


class Sampler:
    """The card's anti-alias filter and sampling of one channel, streamed over consecutive chunks.

    Each chunk is the physical signal at the internal rate; chunks after the first start with the last
    sample of the previous one (a simulation's final state), which is skipped. The channel's sensor noise
    (white at the internal rate, before the filter) is filtered and sampled alongside.
    """

    def __init__(self, card: Card, rate_hz: int, rng: np.random.Generator):
        if rate_hz % card.fs_hz:
            raise ValueError("the internal rate must be a multiple of the output rate")
        self.decimation = rate_hz // card.fs_hz
        self.sos = card.anti_alias.sos(rate_hz)
        self.zi_signal = np.zeros((self.sos.shape[0], 2))
        self.zi_noise = np.zeros((self.sos.shape[0], 2))
        self.rng = rng
        self.next_index = 0  # index within the next chunk (after skipping) of the next output sample
        self.started = False
        self.signal: list[np.ndarray] = []
        self.noise: list[np.ndarray] = []

    def push(self, chunk: np.ndarray) -> None:
        x = chunk[1:] if self.started else chunk
        self.started = True
        y, self.zi_signal = scipy.signal.sosfilt(self.sos, x, zi=self.zi_signal)
        w, self.zi_noise = scipy.signal.sosfilt(self.sos, self.rng.normal(size=len(x)), zi=self.zi_noise)
        idx = np.arange(self.next_index, len(x), self.decimation)
        self.signal.append(y[idx])
        self.noise.append(w[idx])
        self.next_index = int(idx[-1] + self.decimation - len(x)) if len(idx) else self.next_index - len(x)

    def sampled(self, n_out: int) -> tuple[np.ndarray, np.ndarray]:
        """(filtered signal, filtered unit noise) at the output rate, the first n_out samples."""
        y, w = np.concatenate(self.signal), np.concatenate(self.noise)
        if len(y) < n_out:
            raise ValueError(f"only {len(y)} samples for {n_out}")
        return y[:n_out], w[:n_out]


def digitise(y: np.ndarray, w: np.ndarray, card: Card, channel: Channel) -> Acquired:
    """Noise scaled to the channel's SNR, sign and gain, range, clipping and quantisation."""
    rms = float(np.sqrt(np.mean(y**2)))
    w = w * rms * 10 ** (-channel.snr_db / 20) / np.sqrt(np.mean(w**2))
    scale = channel.sign * channel.gain
    clean = scale * y
    full_range = channel.headroom * float(np.max(np.abs(clean)))
    step = 2 * full_range / 2**card.bits
    codes = np.clip(np.round(scale * (y + w) / step), -(2 ** (card.bits - 1)), 2 ** (card.bits - 1) - 1)
    values = codes * step
    err = values - clean
    info = {"kind": channel.kind, "unit": UNITS[channel.kind], "snr_db": channel.snr_db,
            "snr_db_achieved": float(20 * np.log10(np.sqrt(np.mean(clean**2)) / np.sqrt(np.mean(err**2)))),
            "sign": channel.sign, "gain": channel.gain, "range": full_range, "bits": card.bits,
            "step": step, "clipped_fraction": float(np.mean(np.abs(scale * (y + w)) > full_range))}
    return Acquired(values=values, clean=clean, info=info)


def acquire(signal: np.ndarray, rate_hz: int, card: Card, channel: Channel, n_out: int,
            rng: np.random.Generator) -> Acquired:
    """The channel's record of a physical signal given at rate_hz (at least n_out output samples long)."""
    sampler = Sampler(card, rate_hz, rng)
    sampler.push(signal)
    return digitise(*sampler.sampled(n_out), card, channel)
