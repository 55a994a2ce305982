"""Characterise before estimating: the restoring-force surface of what the baseline misses, per location.

Masri & Caughey (1979) plot a single-degree-of-freedom system's internal force against displacement and
velocity; its section at zero velocity is the stiffness curve, at zero displacement the damping curve
(Worden & Tomlinson 2001, ch. 7). A multi-mode structure's internal force is not measured, so here the
surface is estimated through the baseline: the missing force at a location is written as
s(z) + d(v), each a piecewise-linear curve (hat functions on ``KNOTS`` points spanning the measured
motion), and the curve values are fitted by least squares to the baseline's residual through the
responses of the baseline to each hat's force (the same regression the catalogue uses, with the curve
free instead of a law). The share of the residual the surface explains says where a nonlinearity sits
(Noel & Kerschen 2017: detection, characterisation, estimation); the curves' shapes say which causes
are plausible, and both are reported:

- a dead zone and then a straight rise: a contact; a smooth S: a cubic (hardening or softening);
- a jump of the damping curve at v = 0: dry friction (a joint also softens: the stiffness curve bends down);
- a damping curve like v |v|: drag.
"""

from __future__ import annotations

import numpy as np

from .baselines import Baseline, Location
from .catalogue import CAUSES, force_series, law_parameters
from .search import force_responses
from .signals import Prepared

KNOTS = 7


def hats(x: np.ndarray, knots: np.ndarray) -> np.ndarray:
    """(n, len(knots)) piecewise-linear hat functions, one per knot (partition of unity inside)."""
    x = np.clip(x, knots[0], knots[-1])
    out = np.zeros((x.size, knots.size))
    idx = np.clip(np.searchsorted(knots, x) - 1, 0, knots.size - 2)
    frac = (x - knots[idx]) / (knots[idx + 1] - knots[idx])
    out[np.arange(x.size), idx] = 1 - frac
    out[np.arange(x.size), idx + 1] += frac
    return out


def _curve_fit(x: np.ndarray, y: np.ndarray, shape: np.ndarray) -> float:
    """Share of a curve's variance one law shape explains (least squares with a straight line beside it:
    the baseline's linear part may be off as well)."""
    X = np.column_stack([shape, x, np.ones_like(x)])
    sol = np.linalg.lstsq(X, y, rcond=None)[0]
    yy = float(np.sum((y - y.mean()) ** 2))
    X0 = np.column_stack([x, np.ones_like(x)])
    sol0 = np.linalg.lstsq(X0, y, rcond=None)[0]
    base = float(np.sum((y - X0 @ sol0) ** 2))
    if yy <= 0 or base <= 0:
        return 0.0
    return max(0.0, 1.0 - float(np.sum((y - X @ sol) ** 2)) / base)


def plausibility(zk: np.ndarray, stiff: np.ndarray, vk: np.ndarray, damp: np.ndarray) -> dict[str, float]:
    """How well each cause's law explains the curve it acts on, beyond a straight line (0 to 1)."""
    zf = np.linspace(zk[0], zk[-1], 61)
    vf = np.linspace(vk[0], vk[-1], 61)
    s = np.interp(zf, zk, stiff)
    d = np.interp(vf, vk, damp)
    top = max(float(np.max(np.abs(zk))), 1e-300)
    out = {
        "cubic_stiffness": _curve_fit(zf, s, zf**3),
        "quadratic_stiffness": _curve_fit(zf, s, zf * np.abs(zf)),
        "contact": max(_curve_fit(zf, s, force_series(CAUSES["contact"].code,
                                                       law_parameters(CAUSES["contact"], {"gap": g * top, "side": sd}),
                                                       zf, np.zeros_like(zf)))
                       for g in (0.3, 0.5, 0.7) for sd in ("both", "positive", "negative")),
        "coulomb_friction": _curve_fit(vf, d, np.tanh(vf / (0.05 * max(float(np.max(np.abs(vk))), 1e-300)))),
        "quadratic_damping": _curve_fit(vf, d, vf * np.abs(vf)),
    }
    out["hysteretic_joint"] = min(out["coulomb_friction"], 1.0) * float(np.polyfit(zf, s, 3)[0] < 0)
    return out


def characterise(baseline: Baseline, prep: Prepared, rows: np.ndarray, residual: np.ndarray,
                 locations: list[Location], scale: np.ndarray) -> dict[str, dict]:
    """Per location: the share of the training residual a free stiffness-plus-damping surface explains,
    its two curves per unit modal mass, and each cause's plausibility from their shapes."""
    target = (residual[rows] / scale).ravel()
    tt = float(target @ target)
    out = {}
    for loc in locations:
        z, v = loc.coordinate(prep)
        gains = baseline.gain_basis(loc)
        zt, vt = float(np.max(np.abs(z[rows]))), float(np.max(np.abs(v[rows])))
        if not gains or tt <= 0 or zt == 0 or vt == 0:
            out[loc.name] = {"explained": 0.0}
            continue
        zk = np.linspace(-zt, zt, KNOTS)
        vk = np.linspace(-vt, vt, KNOTS)
        H = np.hstack([hats(z, zk), hats(v, vk)])
        cols = [force_responses(baseline.model, prep, H[:, j], gains)[rows] / scale[None, :, None]
                for j in range(H.shape[1])]
        X = np.concatenate(cols, axis=2).reshape(rows.size * scale.size, -1)
        try:
            w = np.linalg.lstsq(X, target, rcond=None)[0]
        except np.linalg.LinAlgError:
            out[loc.name] = {"explained": 0.0}
            continue
        explained = max(0.0, 1.0 - float(np.sum((target - X @ w) ** 2)) / tt)
        nb = len(gains)
        curve = np.array([baseline.per_mass(loc, sum(w[j * nb + b] * gains[b] for b in range(nb)))
                          for j in range(H.shape[1])])
        stiff, damp = curve[:KNOTS], curve[KNOTS:]
        out[loc.name] = {"explained": explained,
                         "displacement": zk.tolist(), "stiffness_force_per_mass": stiff.tolist(),
                         "velocity": vk.tolist(), "damping_force_per_mass": damp.tolist(),
                         "plausibility": plausibility(zk, stiff, vk, damp)}
    return out
