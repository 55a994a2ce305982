"""Read a recording of this tool (MCAP) into arrays: samples, raw bytes, events, status, config.

The samples come from ``/rig/accel`` (one JSON message per frame) where the recording has it, else
from decoding the serial bytes of ``/rig/raw`` with the ``calibration`` metadata (recordings since
the compact layout keep only those): the recorded range from the ``samples`` metadata, log times
from its device-clock anchor, publish times from the raw messages that completed each frame.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mcap.exceptions import McapError
from mcap.reader import make_reader

from daq.protocol import FLAG_CLIPPED, Decoder
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
                elif topic == TOPICS["raw"]:
                    raws.append((message.data, message.log_time))
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
    raw_bytes = b"".join(r[0] for r in raws) if raw else b""
    if not seq and raws and "calibration" in meta:
        return Recording(path, *samples_from_raw(raws, meta), raw_bytes, events, status, models,
                         meta.get("config", {}).get("yaml", ""), meta)
    return Recording(path, np.array(seq, np.int64), np.array(t, float), np.array(vals, float).reshape(-1, 3),
                     np.array(clip, bool), np.array(lt, np.int64), np.array(pt, np.int64), raw_bytes,
                     events, status, models, meta.get("config", {}).get("yaml", ""), meta)


def samples_from_raw(raws: list[tuple[bytes, int]], meta: dict[str, dict[str, str]]):
    """(seq, t_device, values, clipped, log_time_ns, publish_time_ns) decoded from the raw messages."""
    dec = Decoder()
    parts = []
    for data, host_ns in raws:
        fr = dec.feed(data)
        if len(fr):
            parts.append((fr, np.full(len(fr), host_ns, np.int64)))
    if not parts:
        z = np.zeros(0)
        return z.astype(np.int64), z, np.zeros((0, 3)), z.astype(bool), z.astype(np.int64), z.astype(np.int64)
    seq = np.concatenate([p[0].seq for p in parts]).astype(np.int64)
    seq = seq + (np.cumsum(np.diff(seq, prepend=seq[:1]) < -(2**31)) << 32)  # 32-bit wrap-around
    t_us = np.concatenate([p[0].t_us for p in parts])
    counts = np.concatenate([p[0].counts for p in parts]).astype(np.float64)
    flags = np.concatenate([p[0].flags for p in parts])
    pub = np.concatenate([p[1] for p in parts])
    keep = np.ones(len(seq), bool)
    span = meta.get("samples")
    if span:
        keep = (seq >= int(span["first_seq"])) & (seq <= int(span["last_seq"]))
    cal = meta["calibration"]
    names = ("base", "tip1", "tip2")
    scale = np.array([float(cal[f"{c}.scale_m_per_s2_per_count"]) for c in names])
    offset = np.array([float(cal[f"{c}.offset_m_per_s2"]) for c in names])
    t_dev = t_us[keep].astype(np.float64) * 1e-6
    anchor = span.get("anchor_ns") if span else None
    if anchor is None or anchor == "None":  # a recovered file has no closing metadata: anchor at the first read
        anchor_ns = int(pub[keep][0] - round(t_dev[0] * 1e9)) if keep.any() else 0
    else:
        anchor_ns = int(anchor)
    log = anchor_ns + np.rint(t_dev * 1e9).astype(np.int64)
    return (seq[keep], t_dev, counts[keep] * scale + offset, (flags[keep] & FLAG_CLIPPED) != 0, log, pub[keep])
