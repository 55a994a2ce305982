"""JSON-ready values: what every writer of this project's JSON and JSON lines passes its records through.

JSON has no NaN or infinity (``json.dumps`` writes the bare tokens ``NaN`` and ``Infinity``, which strict
readers such as Foxglove's or ``jq`` refuse), and numpy scalars are not serialisable: non-finite numbers
become null, numpy scalars Python ones, keys strings, tuples lists, inside dicts and lists at any depth.
"""

from __future__ import annotations

import math

import numpy as np


def finite(v):
    """``v`` with non-finite floats as None and numpy scalars and arrays as Python values."""
    if isinstance(v, (float, np.floating)):
        v = float(v)
        return v if math.isfinite(v) else None
    if isinstance(v, np.bool_):
        return bool(v)
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.ndarray):
        return finite(v.tolist())
    if isinstance(v, dict):
        return {str(k): finite(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [finite(x) for x in v]
    return v
