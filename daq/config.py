"""The tool's YAML config: the simulated rig (``daq.sim.rig.RigConfig``) plus the ``daq`` section.

One file, validated key by key; any error names the file, the key and what is
allowed (ident.config.build). Bounded: a file above ``MAX_CONFIG_BYTES`` (1 MiB) or
not a regular file is refused before it is read, YAML aliases and anchors and
nesting deeper than 32 levels are refused while parsing (ident.config.parse_yaml),
every number must be finite and within its field's range.
"""

from __future__ import annotations

import os
import stat
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ident.config import build, parse_yaml, to_mapping
from .lines import LineFormat
from .sim.rig import RigConfig
from .sim.sensors import CHANNELS

MAX_CONFIG_BYTES = 1 << 20


@dataclass(frozen=True)
class Calibration:
    """Counts -> m/s^2 for one channel; ``scale`` None means the nominal ADC step of the sensor."""

    scale_m_per_s2_per_count: float | None = field(default=None, metadata={"gt": 0.0, "max": 1e6})
    offset_m_per_s2: float = field(default=0.0, metadata={"min": -1e6, "max": 1e6})


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
    garbage_bursts_per_s: float = field(default=0.0, metadata={"min": 0.0, "max": 100.0})
    garbage_burst_bytes: int = field(default=64, metadata={"min": 1, "max": 4096})
    drop_frame_rate: float = field(default=0.0, metadata={"min": 0.0, "max": 1.0})
    duplicate_frame_rate: float = field(default=0.0, metadata={"min": 0.0, "max": 1.0})  # a frame sent twice
    clock_drift_ppm: float = field(default=0.0, metadata={"min": -10000.0, "max": 10000.0})
    disconnect_at_s: tuple[float, ...] = field(default=(), metadata={"min": 0.0, "max": 1e7, "max_len": 1000})
    disconnect_for_s: float = field(default=1.0, metadata={"min": 0.0, "max": 3600.0})
    restart_at_s: tuple[float, ...] = field(default=(), metadata={"min": 0.0, "max": 1e7, "max_len": 1000})
    restart_for_s: float = field(default=0.2, metadata={"min": 0.0, "max": 3600.0})  # boot time: nothing sent


@dataclass(frozen=True)
class DaqConfig:
    rate_hz: float = field(default=2000.0, metadata={"min": 1.0, "max": 100_000.0})
    baudrate: int = field(default=921600, metadata={"min": 9600, "max": 100_000_000})
    format: str = field(default="frames", metadata={"choices": ("frames", "lines")})  # binary frames v1 or text lines
    lines: LineFormat = field(default_factory=LineFormat)  # how a text-line device prints (daq.lines)
    flush_s: float = field(default=1.0, metadata={"gt": 0.0, "max": 10.0})
    reconnect_backoff_s: tuple[float, ...] = field(default=(0.05, 0.1, 0.2, 0.5, 1.0),
                                                   metadata={"min": 0.0, "max": 60.0, "max_len": 32})
    calibration: Calibrations = field(default_factory=Calibrations)
    faults: Faults = field(default_factory=Faults)

    def __post_init__(self):
        lines = self.lines
        if self.format == "lines" and lines.time is not None and lines.counter is None \
                and lines.time_unit_s > 0.5 / self.rate_hz:
            raise ValueError(f"daq.lines.time_unit_s = {lines.time_unit_s:g} s is coarser than half the sample period "
                             f"({0.5e3 / self.rate_hz:g} ms): sample numbers cannot come from the time column; print "
                             f"a finer time (micros()) or add a counter column")


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


def read_yaml_file(path: str | Path, what: str = "config file", max_bytes: int = MAX_CONFIG_BYTES) -> Any:
    """A YAML file as plain data, bounded: a regular file of at most ``max_bytes``, no aliases or
    anchors, nesting at most 32 deep; one-line ValueError naming the file otherwise."""
    p = Path(path)
    try:
        fd = os.open(p, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))  # a FIFO must not block the open
    except FileNotFoundError:
        raise ValueError(f"{p}: {what} not found") from None
    except OSError as exc:
        raise ValueError(f"{p}: cannot read {what}: {exc.strerror}") from None
    with os.fdopen(fd, "rb") as fh:
        st = os.fstat(fh.fileno())
        if not stat.S_ISREG(st.st_mode):
            raise ValueError(f"{p}: not a regular file; give a YAML {what}")
        if st.st_size > max_bytes:
            raise ValueError(f"{p}: {st.st_size} bytes; a {what} may hold at most {max_bytes} bytes")
        raw = fh.read(max_bytes + 1)
    if len(raw) > max_bytes:
        raise ValueError(f"{p}: more than {max_bytes} bytes; a {what} may hold at most {max_bytes} bytes")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise ValueError(f"{p}: not UTF-8 text; give a YAML {what}") from None
    return parse_yaml(text, str(p))


def load_config(path: str | Path | None) -> Config:
    """Read and validate a config file; ``None`` gives the defaults."""
    if path is None:
        return Config(RigConfig(), DaqConfig())
    return parse_config(read_yaml_file(path), str(path))
