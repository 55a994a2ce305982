"""MCAP recorder sink: every sample (as the raw bytes), events, status and models, crash-safe.

Channels (JSON schema encoding, readable by Foxglove and PlotJuggler):

- ``/rig/raw`` (no schema, ``application/octet-stream``): the serial bytes
  exactly as read: for a binary-frame device the record of the samples (about
  16 bytes per sample with zstd), decoded again by every reader
  (replay.formats.mcap) with the ``calibration`` metadata and the ``samples``
  metadata (first_seq, last_seq, count, anchor_ns); log_time = publish_time =
  host read time.
- ``/rig/accel`` (``rig.Accel``): one message per frame with scalar fields
  ``seq``, ``t_device`` [s], ``base``, ``tip1``, ``tip2`` [m/s^2], ``clipped``,
  plottable as is in Foxglove and PlotJuggler (about 44 more bytes per sample).
  Written only with ``accel_json=True`` (``daq record --accel-json``), for
  imports (no serial bytes) and for text-line devices (``daq.format: lines``:
  a line has no checksum, so the decoded values are the record; the lines
  stay in ``/rig/raw`` beside them). ``log_time`` is the sample's place on the
  timeline (device time, re-anchored at a device restart), anchored to the
  host clock at the first read: the last frame it delivered arrived then, so
  a first read that drained a full port buffer does not push every time
  into the future (the anchor is also in the ``samples``
  metadata, so readers give raw-decoded samples the same times);
  ``publish_time`` is when the host read the bytes that carried it.
- ``/rig/events`` (``foxglove.Log``): drops, CRC failures, disconnects,
  reconnects, regime changes; with our fields ``t`` and ``kind`` added.
- ``/rig/status`` (``rig.Status``): counters and clock estimates once a second.
- ``/rig/model`` (``rig.Model``): every rolling window's model per beam: equations,
  coefficients with their ensemble spread and inclusion probability, active set, integration
  NRMSE, natural frequency (and spread) and displacement amplitude (the backbone). ``log_time``
  is the data time of the window's last sample (on the timeline, anchored as the samples), so
  models line up with the data they fit; ``publish_time`` is when the model was computed.
  Regime and model-change events on ``/rig/events`` are stamped the same way.
- ``/rig/device`` (``rig.Device``): every status frame of the device (device id, session id,
  firmware, protocol, rate, counter, device time): who was recorded, and each boot.

The resolved config is stored as metadata ``config`` (YAML text) and as the
attachment ``config.yaml``; the calibration (scale and offset per channel, and the sensors' model, serial
number and sensitivity where the config gives them) as metadata ``calibration``.

Crash safety: the file is written as ``NAME.part`` and renamed to ``NAME`` when
closed (daq.safeio.PartFile), so a crash leaves a ``.part`` and never a half-written
``NAME``. Chunks are zstd-compressed and closed every ``flush_s`` (1 s) of host time
or of samples, whichever comes first, so after kill -9 or power loss at most the last
second is missing and ``replay recover`` rebuilds an indexed file from the rest.
After every chunk the schema and channel records are written again (top level, about
1.5 kB): a recovery that loses the header, the first chunk and the summary still
knows every channel.
"""

from __future__ import annotations

import json
import time
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import yaml
from mcap.data_stream import RecordBuilder
from mcap.records import Channel, Schema
from mcap.writer import CompressionType, Writer

from ident.jsonsafe import finite

from .config import Config
from .driver import Event, SampleBlock
from .protocol import Status
from .safeio import PartFile

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
DEVICE_SCHEMA = {
    "type": "object",
    "title": "rig.Device",
    "properties": {
        "device_id": {"type": "string", "description": "unit id, hex"},
        "session_id": {"type": "string", "description": "random per boot, hex"},
        "firmware": {"type": "string"},
        "protocol": {"type": "integer"},
        "rate_hz": {"type": "number"},
        "counter": {"type": "integer", "description": "status frames since boot"},
        "t_device": {"type": "number", "description": "device clock [s] since boot"},
    },
}
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
          "model": "/rig/model", "device": "/rig/device"}
RAW_LINES = "text lines (daq.lines), as the config's daq.lines says"  # /rig/raw of a text-line device
CHUNK_BYTES = 64 * 1024 * 1024  # chunks are closed by time (flush_s), this only bounds a runaway one


class McapRecorder:
    """The live MCAP sink. ``path`` is the final name; until :meth:`close` the data is in ``path.part``.

    ``inputs`` and ``force`` are checked as daq.safeio.check_outputs does (the command checks them
    first; this repeats the check at the rename). ``accel_json``: also the samples as JSON on
    ``/rig/accel`` (always so for a text-line device, whose raw lines are no checksummed record).
    """

    def __init__(self, path: str | Path, config: Config, *, port: str = "", flush_s: float | None = None,
                 force: bool = False, inputs: Iterable[str | Path | None] = (), accel_json: bool = False):
        self.accel_json = accel_json or config.daq.format != "frames"
        self.path = Path(path)
        self._out = PartFile(self.path, inputs=inputs, force=force, label="-o")
        self._fh = self._out.file
        self._w = Writer(self._fh, chunk_size=CHUNK_BYTES, compression=CompressionType.ZSTD)
        self._w.start(profile="", library="shaker-ident daq")
        ids = {}
        self._records: list = []  # schema and channel records, repeated after every chunk
        for key, schema in (("accel", ACCEL_SCHEMA), ("events", LOG_SCHEMA), ("status", STATUS_SCHEMA),
                            ("model", MODEL_SCHEMA), ("device", DEVICE_SCHEMA)):
            if key == "accel" and not self.accel_json:
                continue  # the samples live in /rig/raw alone
            data = json.dumps(schema).encode()
            sid = self._w.register_schema(schema["title"], "jsonschema", data)
            ids[key] = self._w.register_channel(TOPICS[key], "json", sid)
            self._records += [Schema(id=sid, name=schema["title"], encoding="jsonschema", data=data),
                              Channel(id=ids[key], topic=TOPICS[key], message_encoding="json", schema_id=sid,
                                      metadata={})]
        raw_meta = {"format": "daq.protocol v1 frames: 24-byte data frames, 36-byte status frames"
                    if config.daq.format == "frames" else RAW_LINES}
        ids["raw"] = self._w.register_channel(TOPICS["raw"], "application/octet-stream", 0, metadata=raw_meta)
        self._records.append(Channel(id=ids["raw"], topic=TOPICS["raw"], message_encoding="application/octet-stream",
                                     schema_id=0, metadata=raw_meta))
        self._ch = ids
        text = yaml.safe_dump(config.to_mapping(), sort_keys=False)
        now = time.time_ns()
        self._w.add_metadata("config", {"yaml": text, "source": config.source})
        self._w.add_metadata("calibration", config.calibration_metadata())
        self._w.add_metadata("session", {"port": port, "rate_hz": repr(config.daq.rate_hz),
                                         "started_ns": str(now)})
        self._w.add_attachment(now, now, "config.yaml", "application/yaml", text.encode())
        self._flush_s = config.daq.flush_s if flush_s is None else flush_s
        self._flush_samples = max(1, int(self._flush_s * config.daq.rate_hz))
        self._since_flush = 0
        self._last_flush = time.monotonic()
        self._anchor_ns: int | None = None  # host epoch ns at timeline 0 (the log time of the first sample)
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
        """Samples; log time = the host time of the first sample + the timeline (monotonic across restarts)."""
        if not len(b):
            return
        if self._anchor_ns is None:
            # the read that delivered the first block arrived with its last frame: that frame is "now"
            self._anchor_ns = b.host_ns - int(round(float(b.t_s[-1]) * 1e9))
        if self.accel_json:
            log_ns = self._anchor_ns + np.rint(np.asarray(b.t_s) * 1e9).astype(np.int64)
            v = b.values
            for i in range(len(b)):
                msg = (f'{{"seq":{int(b.seq[i])},"t_device":{b.t_device_s[i]:.6f},"base":{v[i, 0]:.6g},'
                       f'"tip1":{v[i, 1]:.6g},"tip2":{v[i, 2]:.6g},"clipped":{"true" if b.clipped[i] else "false"}}}')
                self._add("accel", int(log_ns[i]), b.host_ns, msg.encode())
        if self._first_seq is None:
            self._first_seq = int(b.seq[0])
        self._last_seq = int(b.seq[-1])
        self.samples += len(b)
        self._since_flush += len(b)
        self._maybe_flush()

    def write_device(self, status: Status, host_ns: int) -> None:
        """One status frame of the device."""
        self._add("device", host_ns, host_ns, json.dumps(status.as_dict()).encode())

    def write_event(self, e: Event, host_ns: int | None = None, log_ns: int | None = None) -> None:
        ns = time.time_ns() if host_ns is None else host_ns
        log = ns if log_ns is None else log_ns  # the data time an event describes, where it has one
        msg = {"timestamp": {"sec": log // 10**9, "nsec": log % 10**9}, "level": LEVELS.get(e.level, 2),
               "message": e.message, "name": "daq", "file": "", "line": 0, "t": e.t, "kind": e.kind, **e.data}
        self._add("events", log, ns, json.dumps(finite(msg)).encode())

    def log_time_ns(self, t_s: float) -> int | None:
        """The log time of a sample at this place on the timeline (``SampleBlock.t_s``; None before the first
        sample)."""
        return None if self._anchor_ns is None else self._anchor_ns + int(round(t_s * 1e9))

    def write_model(self, record: dict, log_ns: int | None = None) -> None:
        """One rolling-window model of one beam (the identification's time series), logged at the data
        time of the window (log_ns) and published now."""
        ns = time.time_ns()
        self._add("model", ns if log_ns is None else log_ns, ns, json.dumps(finite(record)).encode())

    def write_status(self, status: dict) -> None:
        ns = time.time_ns()
        self._add("status", ns, ns, json.dumps(status).encode())

    def _maybe_flush(self) -> None:
        if self._since_flush >= self._flush_samples or time.monotonic() - self._last_flush >= self._flush_s:
            self.flush()

    def flush(self) -> None:
        """Close the chunk in progress and push it to the OS (survives a killed process); then repeat the
        schema and channel records, so every chunk has them close by."""
        self._w.flush()
        rb = RecordBuilder()
        for r in self._records:
            r.write(rb)
        self._fh.write(rb.end())
        self._fh.flush()
        self._last_flush = time.monotonic()
        self._since_flush = 0

    def abort(self) -> None:
        """Remove the ``.part`` of a recording that never started."""
        self.closed = True
        self._out.abort()

    def close(self) -> Path:
        """Finish the file (summary, footer) and rename ``NAME.part`` to ``NAME``; returns ``NAME``."""
        if self.closed:
            return self.path
        self.closed = True
        if self._first_seq is not None:
            # the recorded frames are the first ``count`` data frames that decoding /rig/raw gives; anchor_ns
            # is the log time of the first (readers stamp raw-decoded samples as /rig/accel would be)
            self._w.add_metadata("samples", {"first_seq": str(self._first_seq), "last_seq": str(self._last_seq),
                                             "count": str(self.samples), "anchor_ns": str(self._anchor_ns)})
        self._w.finish()
        return self._out.commit()
