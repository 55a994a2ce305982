"""Events sink: one JSON object per line, at least ``t`` (seconds from the start) and ``kind``.

Written as ``NAME.part`` and renamed to ``NAME`` when closed (daq.safeio.PartFile): a crash leaves
the ``.part`` with every line written so far (each line is flushed).
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable
from pathlib import Path

from .safeio import PartFile


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
    def __init__(self, path: str | Path, *, force: bool = False, inputs: Iterable = (), label: str = "--events"):
        self.path = Path(path)
        self._out = PartFile(self.path, inputs=inputs, force=force, label=label, mode="w")
        self._fh = self._out.file

    def write(self, event: dict) -> None:
        self._fh.write(json.dumps({k: _clean(v) for k, v in event.items()}, default=str) + "\n")
        self._fh.flush()

    def close(self) -> Path:
        return self._out.commit()

    def abort(self) -> None:
        """Nothing worth keeping was written: remove the ``.part``."""
        self._out.abort()
