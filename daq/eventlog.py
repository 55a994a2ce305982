"""Events sink: one JSON object per line, at least ``t`` (seconds from the start) and ``kind``."""

from __future__ import annotations

import json
import math
from pathlib import Path


def _clean(v):
    """NaN and inf as null (JSON has neither), inside lists and dicts too."""
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {k: _clean(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_clean(x) for x in v]
    return v


class JsonlEvents:
    def __init__(self, path: str | Path):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fh = open(self.path, "w")

    def write(self, event: dict) -> None:
        self._fh.write(json.dumps({k: _clean(v) for k, v in event.items()}) + "\n")
        self._fh.flush()

    def close(self) -> None:
        self._fh.close()
