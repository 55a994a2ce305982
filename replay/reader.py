"""Read a recording of this tool (MCAP) into arrays: samples, raw bytes, events, status, config."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mcap.exceptions import McapError
from mcap.reader import make_reader

from daq.recorder import TOPICS


@dataclass
class Recording:
    path: Path
    seq: np.ndarray  # (n,) frame sequence numbers
    t_device: np.ndarray  # (n,) device clock [s]
    values: np.ndarray  # (n, 3) base, tip1, tip2 [m/s^2]
    clipped: np.ndarray  # (n,) bool
    log_time_ns: np.ndarray  # (n,)
    publish_time_ns: np.ndarray  # (n,)
    raw: bytes = b""
    events: list[dict] = field(default_factory=list)
    status: list[dict] = field(default_factory=list)
    models: list[dict] = field(default_factory=list)
    config_yaml: str = ""
    metadata: dict[str, dict[str, str]] = field(default_factory=dict)

    @property
    def rate_hz(self) -> float:
        if self.t_device.size < 2:
            return float("nan")
        return float(1.0 / np.median(np.diff(self.t_device)))

    @property
    def duration_s(self) -> float:
        return float(self.t_device[-1] - self.t_device[0]) if self.t_device.size else 0.0


def read_recording(path: str | Path, raw: bool = True) -> Recording:
    path = Path(path)
    try:
        fh = open(path, "rb")
    except FileNotFoundError:
        raise ValueError(f"{path}: no such file") from None
    seq, t, vals, clip, lt, pt = [], [], [], [], [], []
    raws, events, status, models = [], [], [], []
    meta: dict[str, dict[str, str]] = {}
    with fh:
        try:
            reader = make_reader(fh)
            for _, channel, message in reader.iter_messages():
                topic = channel.topic
                if topic == TOPICS["accel"]:
                    d = json.loads(message.data)
                    seq.append(d["seq"])
                    t.append(d["t_device"])
                    vals.append((d["base"], d["tip1"], d["tip2"]))
                    clip.append(d.get("clipped", False))
                    lt.append(message.log_time)
                    pt.append(message.publish_time)
                elif topic == TOPICS["raw"] and raw:
                    raws.append(message.data)
                elif topic == TOPICS["events"]:
                    events.append(json.loads(message.data))
                elif topic == TOPICS["status"]:
                    status.append(json.loads(message.data))
                elif topic == TOPICS["model"]:
                    models.append(json.loads(message.data))
            for m in reader.iter_metadata():
                meta[m.name] = dict(m.metadata)
        except (McapError, ValueError, EOFError, KeyError) as exc:
            raise ValueError(f"{path}: not a readable recording ({type(exc).__name__}: {exc}); "
                             f"if it was cut short, run: replay recover {path} -o FIXED.mcap") from None
    return Recording(path, np.array(seq, np.int64), np.array(t, float), np.array(vals, float).reshape(-1, 3),
                     np.array(clip, bool), np.array(lt, np.int64), np.array(pt, np.int64), b"".join(raws),
                     events, status, models, meta.get("config", {}).get("yaml", ""), meta)
