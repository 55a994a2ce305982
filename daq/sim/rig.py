"""The simulated rig as a stream: the rig's physics (``ident.rig``) driven by the shaker programme, read by sensors.

``RigConfig`` is everything that defines the simulated rig (mechanics, shaker programme, sensors);
``RigSimulator.advance(n)`` returns the next n samples whatever the block sizes (the excitation is a
function of absolute time), so the simulated device streams it in real time.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ident.rig import RigOutput, RigParams, integrate

from .excitation import Excitation, base_acceleration, kick_acceleration
from .sensors import Sensor


@dataclass(frozen=True)
class Sensors:
    base: Sensor = field(default_factory=Sensor)
    tip1: Sensor = field(default_factory=Sensor)
    tip2: Sensor = field(default_factory=Sensor)

    def __iter__(self):
        return iter((self.base, self.tip1, self.tip2))


@dataclass(frozen=True)
class RigConfig:
    """Everything that defines the simulated rig: mechanics, shaker programme, sensors."""

    rig: RigParams = field(default_factory=RigParams)
    excitation: Excitation = field(default_factory=Excitation)
    sensors: Sensors = field(default_factory=Sensors)
    substeps: int = field(default=8, metadata={"min": 1, "max": 64})
    seed: int = 0


class RigSimulator:
    """The rig as a stream: ``advance(n)`` returns the next n samples at ``rate_hz``.

    Holds the mechanical state and the time, so consecutive calls continue the
    same trajectory whatever their sizes (the excitation is a function of time).
    """

    def __init__(self, config: RigConfig, rate_hz: float, state: np.ndarray | None = None):
        if rate_hz <= 0:
            raise ValueError(f"rate_hz must be positive, got {rate_hz}")
        self.config = config
        self.rate_hz = float(rate_hz)
        self.state = np.zeros(4) if state is None else np.asarray(state, float).copy()
        self.n_done = 0

    def advance(self, n: int) -> tuple[np.ndarray, RigOutput]:
        """Times (n,) [s] and the rig response at them."""
        m = self.config.substeps
        k0 = self.n_done * m
        tt = (k0 + np.arange(n * m + 1)) / (self.rate_hz * m)
        exc = self.config.excitation
        ab = base_acceleration(exc, tt)
        kick = kick_acceleration(exc, tt) if exc.kicks else None
        self.state, out = integrate(self.config.rig, self.state, ab, 1.0 / self.rate_hz, m, kick)
        self.n_done += n
        return tt[m::m], out


def simulate_rig(config: RigConfig, duration_s: float, rate_hz: float = 2000.0,
                 state: np.ndarray | None = None) -> tuple[np.ndarray, RigOutput]:
    """The rig's true response over ``duration_s`` (no sensors): times and outputs."""
    n = int(round(duration_s * rate_hz))
    if n < 1:
        raise ValueError(f"duration {duration_s} s at {rate_hz} Hz gives no sample")
    return RigSimulator(config, rate_hz, state).advance(n)
