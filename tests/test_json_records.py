"""Every JSON the tool writes is strict JSON: a NaN or an infinity in an event, a model record or a
discovery result is written as null (``json.dumps`` alone writes the bare tokens ``NaN`` and ``Infinity``,
which Foxglove, ``jq`` and other strict readers refuse), and numpy scalars are written as numbers."""

import json

import numpy as np
import pytest
from mcap.reader import make_reader

from daq.config import load_config
from daq.driver import Event
from daq.eventlog import JsonlEvents
from daq.recorder import McapRecorder
from ident.jsonsafe import finite


def strict(raw: bytes | str):
    def refuse(token):
        raise ValueError(f"not JSON: {token}")
    return json.loads(raw, parse_constant=refuse)


def test_finite_maps_non_finite_numbers_to_null_at_any_depth():
    v = {"a": float("nan"), 1: [np.float32(np.inf), (np.int64(3), np.bool_(True))], "b": np.array([1.5, -np.inf])}
    assert finite(v) == {"a": None, "1": [None, [3, True]], "b": [1.5, None]}
    assert json.dumps(finite(v)) == '{"a": null, "1": [null, [3, true]], "b": [1.5, null]}'


def test_mcap_events_and_models_with_nan_are_strict_json(tmp_path):
    path = tmp_path / "r.mcap"
    rec = McapRecorder(path, load_config(None))
    rec.write_event(Event(0.5, "regime_start", "free", data={"confidence": float("nan"), "p": [np.float64(0.2), np.inf]}))
    rec.write_model({"beam": 1, "stiffness": np.float64(12.5), "spread": float("nan")}, log_ns=10**9)
    rec.close()
    with open(path, "rb") as fh:
        msgs = {ch.topic: strict(m.data) for _, ch, m in make_reader(fh).iter_messages()}
    event = next(v for k, v in msgs.items() if k.endswith("events"))
    model = next(v for k, v in msgs.items() if k.endswith("model"))
    assert event["confidence"] is None and event["p"] == [pytest.approx(0.2), None] and event["kind"] == "regime_start"
    assert model == {"beam": 1, "stiffness": 12.5, "spread": None}


def test_jsonl_events_with_nan_are_strict_json(tmp_path):
    out = JsonlEvents(tmp_path / "e.jsonl")
    out.write({"t": np.float64(1.25), "kind": "model", "k": float("inf"), "terms": {"x": np.float32(0.5)}})
    out.close()
    line = (tmp_path / "e.jsonl").read_text().splitlines()[0]
    assert strict(line) == {"t": 1.25, "kind": "model", "k": None, "terms": {"x": 0.5}}
