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
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from ident.config import build, parse_yaml, to_mapping
from .lines import LineFormat
from .sim.rig import RigConfig
from .sim.sensors import CHANNELS

MAX_CONFIG_BYTES = 1 << 20


G_M_PER_S2 = 9.80665  # standard gravity: 1 g in m/s^2 (a sensor's mV/g)
SCALE_KEYS = ("scale_m_per_s2_per_count", "sensitivity_counts_per_m_per_s2", "sensitivity_mv_per_g")


@dataclass(frozen=True)
class Calibration:
    """Counts -> m/s^2 for one channel (value = counts x scale + offset), and which sensor it is.

    The scale comes from at most one of: ``scale_m_per_s2_per_count``; ``sensitivity_counts_per_m_per_s2``
    (what ``daq calibrate`` writes; for a text-line device, "counts" are the numbers it prints); or
    ``sensitivity_mv_per_g`` (the sensor's certificate) with ``adc_mv_per_count`` (one ADC count in mV at
    the sensor's output, the conditioner's gain included: 3300 mV / 4096 counts / gain). None of them: the
    simulated sensor's nominal ADC step.
    """

    scale_m_per_s2_per_count: float | None = field(default=None, metadata={"gt": 0.0, "max": 1e6})
    offset_m_per_s2: float = field(default=0.0, metadata={"min": -1e6, "max": 1e6})
    sensitivity_counts_per_m_per_s2: float | None = field(default=None, metadata={"gt": 0.0, "max": 1e9})
    sensitivity_mv_per_g: float | None = field(default=None, metadata={"gt": 0.0, "max": 1e6})
    adc_mv_per_count: float | None = field(default=None, metadata={"gt": 0.0, "max": 1e6})
    sensor_model: str = ""
    serial_number: str = ""
    calibrated: str = ""  # when and against what (daq calibrate writes it)

    def check(self, where: str) -> None:
        given = [k for k in SCALE_KEYS if getattr(self, k) is not None]
        if len(given) > 1:
            raise ValueError(f"{where}: give one of {', '.join(given)}, not both")
        if (self.sensitivity_mv_per_g is None) != (self.adc_mv_per_count is None):
            raise ValueError(f"{where}: sensitivity_mv_per_g and adc_mv_per_count go together (mV per g of the "
                             f"sensor, mV per count of the ADC)")
        for key in ("sensor_model", "serial_number", "calibrated"):
            if len(getattr(self, key)) > 200:
                raise ValueError(f"{where}.{key} is longer than 200 characters")

    def scale(self, nominal: float) -> float:
        """m/s^2 per count."""
        if self.scale_m_per_s2_per_count is not None:
            return self.scale_m_per_s2_per_count
        if self.sensitivity_counts_per_m_per_s2 is not None:
            return 1.0 / self.sensitivity_counts_per_m_per_s2
        if self.sensitivity_mv_per_g is not None and self.adc_mv_per_count is not None:
            return self.adc_mv_per_count / self.sensitivity_mv_per_g * G_M_PER_S2
        return nominal

    def source(self) -> str:
        return next((k for k in SCALE_KEYS if getattr(self, k) is not None), "nominal ADC step")


@dataclass(frozen=True)
class Calibrations:
    base: Calibration = field(default_factory=Calibration)
    tip1: Calibration = field(default_factory=Calibration)
    tip2: Calibration = field(default_factory=Calibration)

    def __post_init__(self):
        for name in CHANNELS:
            getattr(self, name).check(f"daq.calibration.{name}")


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
    # how long acquisition waits for a lost port to come back, or for a silent one to send, before it stops
    # with an error (what came before stays recorded); 0 waits until Ctrl-C
    give_up_s: float = field(default=300.0, metadata={"min": 0.0, "max": 1e7})
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
            scales.append(cal.scale(sensor.lsb_m_per_s2))
            offsets.append(cal.offset_m_per_s2)
        return scales, offsets

    def with_link(self, format: str | None = None, baudrate: int | None = None) -> "Config":
        """This config with the device's format and baud rate replaced (command-line overrides)."""
        changes = {k: v for k, v in (("format", format), ("baudrate", baudrate)) if v is not None}
        return replace(self, daq=replace(self.daq, **changes)) if changes else self

    def calibration_metadata(self) -> dict[str, str]:
        """The recording's ``calibration`` metadata: per channel the scale and offset in use (what decoding
        the raw bytes needs), where the scale came from, and the sensor's model, serial number and
        sensitivity where the config gives them."""
        scales, offsets = self.scales()
        out = {}
        for name, sc, off in zip(CHANNELS, scales, offsets):
            cal = getattr(self.daq.calibration, name)
            out[f"{name}.scale_m_per_s2_per_count"] = repr(sc)
            out[f"{name}.offset_m_per_s2"] = repr(off)
            out[f"{name}.scale_from"] = cal.source()
            for key in ("sensitivity_counts_per_m_per_s2", "sensitivity_mv_per_g", "adc_mv_per_count"):
                if getattr(cal, key) is not None:
                    out[f"{name}.{key}"] = repr(getattr(cal, key))
            for key in ("sensor_model", "serial_number", "calibrated"):
                if getattr(cal, key):
                    out[f"{name}.{key}"] = getattr(cal, key)
        return out

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
    known = [f.name for f in fields(RigConfig)] + ["daq"]
    unknown = [k for k in data if k not in known]
    if unknown:  # (said here: the rig's own check would leave "daq" out of what is allowed)
        raise ValueError(f"{source}: unknown key '{unknown[0]}'; allowed: {', '.join(known)}")
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
    st = os.fstat(fd)
    if not stat.S_ISREG(st.st_mode):  # (before fdopen: a folder's descriptor there is "[Errno 21] ...: 3")
        os.close(fd)
        raise ValueError(f"{p}: {'a folder' if stat.S_ISDIR(st.st_mode) else 'not a regular file'}; "
                         f"give a YAML {what}")
    with os.fdopen(fd, "rb") as fh:
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
