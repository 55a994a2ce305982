"""MCAP recorder sink: every sample, the raw bytes, events and status, crash-safe.

Channels (JSON schema encoding, readable by Foxglove and PlotJuggler):

- ``/rig/raw`` (no schema, ``application/octet-stream``): the serial bytes
  exactly as read: the record of the samples (about 14 bytes per sample with
  zstd), decoded again by any reader with the ``calibration`` metadata;
  log_time = publish_time = host read time.
- ``/rig/accel`` (``rig.Accel``, only with ``accel_json=True``, ``daq record
  --accel-json``, and for imported CSVs, which have no serial bytes): one
  message per frame with scalar fields ``seq``, ``t_device`` [s], ``base``,
  ``tip1``, ``tip2`` [m/s^2], ``clipped``, plottable as is in Foxglove and
  PlotJuggler (about 41 more bytes per sample). ``log_time`` is the sample's
  time on the device clock, anchored to the host clock at the first frame
  (the anchor is also in the ``samples`` metadata, so readers give
  raw-decoded samples the same times); ``publish_time`` is when the host read
  the bytes that carried it.
- ``/rig/events`` (``foxglove.Log``): drops, CRC failures, disconnects,
  reconnects, regime changes; with our fields ``t`` and ``kind`` added.
- ``/rig/status`` (``rig.Status``): counters and clock estimates once a second.
- ``/rig/model`` (``rig.Model``): every rolling window's model per beam: equations,
  coefficients with their ensemble spread and inclusion probability, active set, integration
  NRMSE, natural frequency (and spread) and displacement amplitude (the backbone). ``log_time``
  is the data time of the window's last sample (device clock, anchored as ``/rig/accel``), so
  models line up with the data they fit; ``publish_time`` is when the model was computed.
  Regime and model-change events on ``/rig/events`` are stamped the same way.

The resolved config is stored as metadata ``config`` (YAML text) and as the
attachment ``config.yaml``; the calibration as metadata ``calibration``.

Crash safety: chunks are zstd-compressed and closed every ``flush_s`` (1 s)
by ``Writer.flush()``, so after kill -9 or power loss at most the last second
is missing and ``replay recover`` rebuilds an indexed file from the rest.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import yaml
from mcap.writer import CompressionType, Writer

from .config import Config
from .driver import Event, SampleBlock

ACCEL_SCHEMA = {
    "type": "object",
    "title": "rig.Accel",
    "properties": {
        "seq": {"type": "integer", "description": "frame sequence number"},
        "t_device": {"type": "number", "description": "device clock [s]"},
        "base": {"type": "number", "description": "base acceleration [m/s^2]"},
        "tip1": {"type": "number", "description": "tip 1 acceleration [m/s^2]"},
        "tip2": {"type": "number", "description": "tip 2 acceleration [m/s^2]"},
        "clipped": {"type": "boolean", "description": "a channel hit the ADC range"},
    },
}
LOG_SCHEMA = {
    "type": "object",
    "title": "foxglove.Log",
    "properties": {
        "timestamp": {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}},
        "level": {"type": "integer", "description": "1 debug, 2 info, 3 warning, 4 error, 5 fatal"},
        "message": {"type": "string"},
        "name": {"type": "string"},
        "file": {"type": "string"},
        "line": {"type": "integer"},
        "t": {"type": "number", "description": "seconds since the start of the recording"},
        "kind": {"type": "string"},
    },
}
STATUS_SCHEMA = {"type": "object", "title": "rig.Status", "additionalProperties": True}
MODEL_SCHEMA = {
    "type": "object",
    "title": "rig.Model",
    "properties": {
        "t": {"type": "number", "description": "end of the window, seconds since the start"},
        "beam": {"type": "integer"},
        "equations": {"type": "array", "items": {"type": "string"}},
        "integration_nrmse": {"type": "number"},
        "natural_frequency_hz": {"type": "number"},
        "stiffness_per_mass": {"type": "number", "description": "1/s^2"},
        "changed": {"type": "boolean", "description": "active set differs from the previous window's"},
        "coefficient_std": {"type": "object", "description": "per equation and term: spread over the ensemble"},
        "inclusion_probability": {"type": "object", "description": "per equation and term: share of the "
                                  "ensemble's models holding the term"},
        "natural_frequency_std_hz": {"type": "number"},
        "amplitude_m": {"type": "number", "description": "sqrt(2) RMS relative displacement over the window"},
    },
}
LEVELS = {"debug": 1, "info": 2, "warning": 3, "error": 4, "fatal": 5}
TOPICS = {"accel": "/rig/accel", "raw": "/rig/raw", "events": "/rig/events", "status": "/rig/status",
          "model": "/rig/model"}


class McapRecorder:
    def __init__(self, path: str | Path, config: Config, *, port: str = "", flush_s: float | None = None,
                 accel_json: bool = False):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fh = open(self.path, "wb")
        self._w = Writer(self._fh, chunk_size=4 * 1024 * 1024, compression=CompressionType.ZSTD)
        self._w.start(profile="", library="shaker-ident daq")
        ids = {}
        for key, schema in (("accel", ACCEL_SCHEMA), ("events", LOG_SCHEMA), ("status", STATUS_SCHEMA),
                            ("model", MODEL_SCHEMA)):
            if key == "accel" and not accel_json:
                continue  # the samples live in /rig/raw alone
            sid = self._w.register_schema(schema["title"], "jsonschema", json.dumps(schema).encode())
            ids[key] = self._w.register_channel(TOPICS[key], "json", sid)
        ids["raw"] = self._w.register_channel(TOPICS["raw"], "application/octet-stream", 0,
                                              metadata={"format": "daq.protocol v1 frames, 24 bytes"})
        self._ch = ids
        text = yaml.safe_dump(config.to_mapping(), sort_keys=False)
        now = time.time_ns()
        self._w.add_metadata("config", {"yaml": text, "source": config.source})
        scales, offsets = config.scales()
        self._w.add_metadata("calibration", {
            f"{name}.{what}": repr(v) for name, sc, off in zip(("base", "tip1", "tip2"), scales, offsets)
            for what, v in (("scale_m_per_s2_per_count", sc), ("offset_m_per_s2", off))})
        self._w.add_metadata("session", {"port": port, "rate_hz": repr(config.daq.rate_hz),
                                         "started_ns": str(now)})
        self._w.add_attachment(now, now, "config.yaml", "application/yaml", text.encode())
        self._flush_s = config.daq.flush_s if flush_s is None else flush_s
        self._last_flush = time.monotonic()
        self._anchor_ns: int | None = None  # host epoch ns at device time 0
        self.accel_json = accel_json
        self._seq = {k: 0 for k in ids}
        self.samples = 0
        self._first_seq: int | None = None
        self._last_seq: int | None = None
        self.closed = False

    def _add(self, key: str, log_ns: int, pub_ns: int, data: bytes) -> None:
        self._w.add_message(self._ch[key], log_time=log_ns, publish_time=pub_ns, data=data,
                            sequence=self._seq[key])
        self._seq[key] = (self._seq[key] + 1) & 0xFFFFFFFF

    def write_raw(self, data: bytes, host_ns: int) -> None:
        self._add("raw", host_ns, host_ns, bytes(data))
        self._maybe_flush()

    def write_block(self, b: SampleBlock) -> None:
        if not len(b):
            return
        if self._anchor_ns is None:
            self._anchor_ns = b.host_ns - int(round(float(b.t_device_s[0]) * 1e9))
        if self.accel_json:
            log_ns = self._anchor_ns + np.rint(b.t_device_s * 1e9).astype(np.int64)
            v = b.values
            for i in range(len(b)):
                msg = (f'{{"seq":{int(b.seq[i])},"t_device":{b.t_device_s[i]:.6f},"base":{v[i, 0]:.6g},'
                       f'"tip1":{v[i, 1]:.6g},"tip2":{v[i, 2]:.6g},"clipped":{"true" if b.clipped[i] else "false"}}}')
                self._add("accel", int(log_ns[i]), b.host_ns, msg.encode())
        if self._first_seq is None:
            self._first_seq = int(b.seq[0])
        self._last_seq = int(b.seq[-1])
        self.samples += len(b)
        self._maybe_flush()

    def write_event(self, e: Event, host_ns: int | None = None, log_ns: int | None = None) -> None:
        ns = time.time_ns() if host_ns is None else host_ns
        log = ns if log_ns is None else log_ns  # the data time an event describes, where it has one
        msg = {"timestamp": {"sec": log // 10**9, "nsec": log % 10**9}, "level": LEVELS.get(e.level, 2),
               "message": e.message, "name": "daq", "file": "", "line": 0, "t": e.t, "kind": e.kind, **e.data}
        self._add("events", log, ns, json.dumps(msg).encode())

    def log_time_ns(self, t_device_s: float) -> int | None:
        """The log time of a sample at this device time (None before the first sample)."""
        return None if self._anchor_ns is None else self._anchor_ns + int(round(t_device_s * 1e9))

    def write_model(self, record: dict, log_ns: int | None = None) -> None:
        """One rolling-window model of one beam (the identification's time series), logged at the data
        time of the window (log_ns) and published now."""
        ns = time.time_ns()
        clean = json.loads(json.dumps(record), parse_constant=lambda c: None)  # NaN and inf as null
        self._add("model", ns if log_ns is None else log_ns, ns, json.dumps(clean).encode())

    def write_status(self, status: dict) -> None:
        ns = time.time_ns()
        self._add("status", ns, ns, json.dumps(status).encode())

    def _maybe_flush(self) -> None:
        if time.monotonic() - self._last_flush >= self._flush_s:
            self.flush()

    def flush(self) -> None:
        """Close the chunk in progress and push it to the OS (survives a killed process)."""
        self._w.flush()
        self._last_flush = time.monotonic()

    def close(self) -> None:
        if self.closed:
            return
        self.closed = True
        if self._first_seq is not None:
            # the recorded range, so that re-decoding /rig/raw gives exactly the samples of /rig/accel
            self._w.add_metadata("samples", {"first_seq": str(self._first_seq), "last_seq": str(self._last_seq),
                                             "count": str(self.samples), "anchor_ns": str(self._anchor_ns)})
        self._w.finish()
        self._fh.close()
