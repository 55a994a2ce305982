"""The modal baseline as ``discover`` fits a record (its band from a first fit, then the fit in that band), and
what the search works on: the residual on the training rows and the held-out blocks' scale."""

import importlib
from types import SimpleNamespace

import numpy as np

from ident.discovery.signals import prepare

disc = importlib.import_module("ident.discovery.discover")  # the module: the package exports its function
search = importlib.import_module("ident.discovery.search")


def fitted_as_discover(m) -> SimpleNamespace:
    """base, prep, split, warm, residual, rows (training rows where the residual is finite), scale."""
    band, poles0 = disc._fit_modal(m, None, None, None)
    prep = prepare(m, band)
    split = disc._split(prep)
    base = disc._fit_in_band(prep, split, poles0)
    warm = disc._warm(base, prep)
    residual = search.baseline_residual(base, prep, split, warm)
    rows = split.rows("train")
    rows = rows[np.all(np.isfinite(residual[rows]), axis=1)]
    scale = np.maximum(prep.measured[split.rows("test")].std(axis=0), 1e-300)
    return SimpleNamespace(base=base, prep=prep, split=split, warm=warm, residual=residual, rows=rows, scale=scale)
