"""Events sink: one JSON object per line, at least ``t`` (seconds from the start) and ``kind``.

Written as ``NAME.part`` and renamed to ``NAME`` when closed (daq.safeio.PartFile): a crash leaves
the ``.part`` with every line written so far (each line is flushed).
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path

from ident.jsonsafe import finite

from .safeio import PartFile


class JsonlEvents:
    def __init__(self, path: str | Path, *, force: bool = False, inputs: Iterable = (), label: str = "--events"):
        self.path = Path(path)
        self._out = PartFile(self.path, inputs=inputs, force=force, label=label, mode="w")
        self._fh = self._out.file

    def write(self, event: dict) -> None:
        self._fh.write(json.dumps(finite(event), default=str) + "\n")
        self._fh.flush()

    def close(self) -> Path:
        return self._out.commit()

    def abort(self) -> None:
        """Nothing worth keeping was written: remove the ``.part``."""
        self._out.abort()
