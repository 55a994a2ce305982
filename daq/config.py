"""The tool's YAML config: the simulated rig (``daq.sim.rig.RigConfig``) plus the ``daq`` section.

One file, validated key by key; any error names the file, the key and what is
allowed (ident.config.build).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import yaml

from ident.config import build, to_mapping
from .sim.rig import RigConfig
from .sim.sensors import CHANNELS


@dataclass(frozen=True)
class Calibration:
    """Counts -> m/s^2 for one channel; ``scale`` None means the nominal ADC step of the sensor."""

    scale_m_per_s2_per_count: float | None = None
    offset_m_per_s2: float = 0.0


@dataclass(frozen=True)
class Calibrations:
    base: Calibration = field(default_factory=Calibration)
    tip1: Calibration = field(default_factory=Calibration)
    tip2: Calibration = field(default_factory=Calibration)


@dataclass(frozen=True)
class Faults:
    """Fault injection of the simulated device (all off by default)."""

    corrupt_byte_rate: float = field(default=0.0, metadata={"min": 0.0, "max": 1.0})
    drop_byte_rate: float = field(default=0.0, metadata={"min": 0.0, "max": 1.0})
    garbage_bursts_per_s: float = field(default=0.0, metadata={"min": 0.0})
    garbage_burst_bytes: int = field(default=64, metadata={"min": 1})
    drop_frame_rate: float = field(default=0.0, metadata={"min": 0.0, "max": 1.0})
    clock_drift_ppm: float = field(default=0.0, metadata={"min": -10000.0, "max": 10000.0})
    disconnect_at_s: tuple[float, ...] = ()
    disconnect_for_s: float = field(default=1.0, metadata={"min": 0.0})


@dataclass(frozen=True)
class DaqConfig:
    rate_hz: float = field(default=2000.0, metadata={"gt": 0.0, "max": 20000.0})
    baudrate: int = field(default=921600, metadata={"min": 9600})
    flush_s: float = field(default=1.0, metadata={"gt": 0.0, "max": 10.0})
    reconnect_backoff_s: tuple[float, ...] = (0.05, 0.1, 0.2, 0.5, 1.0)
    calibration: Calibrations = field(default_factory=Calibrations)
    faults: Faults = field(default_factory=Faults)


@dataclass(frozen=True)
class Config:
    rig: RigConfig
    daq: DaqConfig
    source: str = "<defaults>"

    def scales(self) -> tuple[list[float], list[float]]:
        """Per channel (scale per count, offset) with the sensor's nominal step as default."""
        scales, offsets = [], []
        for name, sensor in zip(CHANNELS, self.rig.sensors):
            cal = getattr(self.daq.calibration, name)
            scales.append(cal.scale_m_per_s2_per_count or sensor.lsb_m_per_s2)
            offsets.append(cal.offset_m_per_s2)
        return scales, offsets

    def to_mapping(self) -> dict:
        data = to_mapping(self.rig)
        data["daq"] = to_mapping(self.daq)
        return data


def parse_config(data: object, source: str) -> Config:
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ValueError(f"{source}: the top level must be a mapping of keys to values")
    data = dict(data)
    daq = build(DaqConfig, data.pop("daq", None), source, "daq")
    rig = build(RigConfig, data, source)
    return Config(rig, daq, source)


def load_config(path: str | Path | None) -> Config:
    """Read and validate a config file; ``None`` gives the defaults."""
    if path is None:
        return Config(RigConfig(), DaqConfig())
    p = Path(path)
    try:
        text = p.read_text()
    except FileNotFoundError:
        raise ValueError(f"{p}: config file not found") from None
    except OSError as exc:
        raise ValueError(f"{p}: cannot read config: {exc.strerror}") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark else ""
        raise ValueError(f"{p}: not valid YAML{where}: {getattr(exc, 'problem', exc)}") from None
    return parse_config(data, str(p))
