"""A test set-up (a reduced structure, the signals driving it, its nonlinear elements, the quantities
recorded) and its run over a record at an internal rate that is a multiple of the output rate.

The base velocity (for drag on the absolute velocity of a base-excited structure) is the integral of the
base acceleration on the half-step grid (trapezoidal rule) less its mean: the table oscillates about a
fixed position.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .elements import Element, Membrane
from .excitation import Signal
from .integrate import Coil, Load, Output, Response, State, internal_rate, simulate
from .modal import ModalModel


@dataclass
class Drive:
    """A signal driving the structure through a physical load vector (force per unit signal)."""

    name: str
    vector: np.ndarray
    signal: Signal


@dataclass
class Setup:
    model: ModalModel
    drives: list[Drive]
    outputs: dict[str, Output]
    elements: list[Element] = field(default_factory=list)
    membrane: Membrane | None = None
    coil: Coil | None = None
    base_drive: str | None = None  # name of the drive that is the base acceleration

    def rate_hz(self, fs_hz: int, min_rate_hz: float = 20e3) -> int:
        rate = internal_rate(fs_hz, self.model, self.elements, min_rate_hz)
        if self.coil is not None:  # the coil's real pole -R/L: |lambda dt| <= 1 (RK4 is stable to 2.78)
            pole = self.coil.resistance_ohm / self.coil.inductance_h
            rate = max(rate, int(np.ceil(pole / fs_hz)) * fs_hz)
        return rate


@dataclass
class Run:
    rate_hz: int
    fs_hz: int
    n_out: int
    outputs: dict[str, np.ndarray]  # at the internal rate, n_steps + 1 samples
    response: Response
    drive_samples: dict[str, np.ndarray]  # on the half-step grid

    @property
    def decimation(self) -> int:
        return self.rate_hz // self.fs_hz


def base_velocity(acceleration: np.ndarray, grid_rate_hz: float) -> np.ndarray:
    v = np.concatenate(([0.0], np.cumsum(0.5 * (acceleration[1:] + acceleration[:-1])))) / grid_rate_hz
    return v - v.mean()


def run(setup: Setup, fs_hz: int, duration_s: float, initial: State | None = None, rate_hz: int | None = None,
        record_every: int = 0) -> Run:
    """Simulate duration_s (n_out = round(duration_s fs) output samples) at the internal rate."""
    rate = rate_hz or setup.rate_hz(fs_hz)
    n_out = int(round(duration_s * fs_hz))
    n_steps = n_out * (rate // fs_hz)
    samples = {d.name: d.signal.sample(2 * rate, 2 * n_steps + 1) for d in setup.drives}
    loads = [Load(d.vector, samples[d.name]) for d in setup.drives]
    voff = base_velocity(samples[setup.base_drive], 2 * rate) if setup.base_drive else None
    resp = simulate(setup.model, rate, n_steps, loads, setup.elements, list(setup.outputs.values()),
                    membrane=setup.membrane, coil=setup.coil, initial=initial, velocity_offset=voff,
                    record_every=record_every)
    outputs = {name: resp.outputs[:, i] for i, name in enumerate(setup.outputs)}
    return Run(rate_hz=rate, fs_hz=fs_hz, n_out=n_out, outputs=outputs, response=resp, drive_samples=samples)
