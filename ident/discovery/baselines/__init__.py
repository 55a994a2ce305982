"""Baselines: the linear models discovery extends, behind one small interface.

A baseline is a ``LinearModel`` (modal coordinates, ``ident.discovery.model``) of how the measured
excitation moves the responses, plus what the search needs to extend it:

- ``locations()``: where an internal force can act: at a response (against the ground or the shaken
  frame) or between two responses (their difference; their sum when neither sign is known);
- ``coordinate_modes(loc)``: the modal coefficients of the coordinate an element there reads;
- ``gain_basis(loc)``: modal gain vectors of a unit force at the location; the search fits one
  coefficient per vector (one when the model has physical units or a driving point is known, one per
  mode otherwise);
- ``per_mass(loc, gain)``: what a unit coefficient acting through ``gain`` is per unit modal mass at the
  location (the dominant mode normalised to 1 there), so coefficients are comparable across baselines;
- ``initial_state(prep, start, stop)``: the modal state at ``start`` from the data (measured states for
  the rig model, least squares on the window for a fitted one);
- ``refit(prep, segments, elements)``: the linear part fitted again with the elements' forces in place
  (a fitted model otherwise keeps the share of a nonlinearity it absorbed); the rig model is given, so
  its refit is itself.

Two baselines implement it: ``rig.RigBaseline`` (the rig model from a YAML) and ``modal.ModalBaseline``
(a modal model fitted to the data).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..catalogue import force_series
from ..model import Element, LinearModel
from ..signals import Prepared


@dataclass(frozen=True)
class Location:
    """A coordinate: a combination of responses (their relative displacements)."""

    name: str
    weights: np.ndarray  # (k,)

    @property
    def responses(self) -> tuple[int, ...]:
        return tuple(int(i) for i in np.flatnonzero(self.weights))

    def coordinate(self, prep: Prepared) -> tuple[np.ndarray, np.ndarray]:
        """Measured displacement and velocity of the coordinate."""
        return prep.zva[0] @ self.weights, prep.zva[1] @ self.weights

    def lz(self, model: LinearModel) -> np.ndarray:
        """Modal coefficients of the coordinate's displacement."""
        return self.weights @ model.C


def default_locations(prep: Prepared, pairs: bool = True) -> list[Location]:
    """Every response, and every pair as a difference (an interface between them); a pair of responses
    whose signs the data could not fix is also searched as a sum."""
    k = len(prep.names)
    known: set[int] = set()
    if prep.base_excited:
        known = set(range(k))
    elif prep.driving_point is not None:
        known = {prep.driving_point}
    out = []
    for j in range(k):
        w = np.zeros(k)
        w[j] = 1.0
        out.append(Location(prep.names[j], w))
    if pairs:
        for j in range(k):
            for i in range(j + 1, k):
                w = np.zeros(k)
                w[j], w[i] = 1.0, -1.0
                out.append(Location(f"{prep.names[j]}-{prep.names[i]}", w))
                if not (j in known and i in known):
                    out.append(Location(f"{prep.names[j]}+{prep.names[i]}", np.abs(w)))
    return out


class Baseline:
    """The interface (see the module's docstring); subclasses hold a ``model`` and say ``causes``."""

    label: str = ""
    model: LinearModel
    causes: tuple[str, ...] = ()

    def locations(self, prep: Prepared) -> list[Location]:
        return default_locations(prep)

    def coordinate_modes(self, loc: Location) -> np.ndarray:
        """Modal coefficients of the coordinate a force at the location reads and acts on."""
        return loc.lz(self.model)

    def gain_basis(self, loc: Location) -> list[np.ndarray]:
        raise NotImplementedError

    def per_mass(self, loc: Location, gain: np.ndarray) -> float:
        raise NotImplementedError

    def physical(self, loc: Location) -> float | None:
        """The coordinate's modal mass [kg] when the model has physical units, else None."""
        return None

    def per_mass_mode_hz(self, loc: Location) -> float | None:
        """The natural frequency of the mode whose modal mass ``per_mass`` divides by, where it is one
        mode's (a modal model: the location's dominant mode), else None."""
        return None

    def basis_signs(self, loc: Location, gains: list[np.ndarray]) -> np.ndarray | None:
        """Per gain of ``gain_basis``, the sign its coefficient takes when a force at the location acts
        on that gain's mode with a positive modal mass; None where the coefficients need not agree (a
        basis of one gain, or a baseline whose gains are physical already)."""
        return None

    def initial_state(self, prep: Prepared, model: LinearModel, start: int, stop: int) -> np.ndarray:
        raise NotImplementedError

    def refit(self, prep: Prepared, segments, elements: tuple[Element, ...]) -> "Baseline":
        return self


def dominant_mode(lz: np.ndarray, poles: np.ndarray) -> int:
    """The mode that moves the coordinate most at its resonance per unit modal input: the largest
    |lz_r| / (zeta_r |lambda_r|)."""
    zeta = -poles.real / np.abs(poles)
    return int(np.argmax(np.abs(lz) / (np.maximum(zeta, 1e-4) * np.abs(poles))))


def element_force(el: Element, prep: Prepared) -> np.ndarray:
    """An element's force along the record: its law on the measured coordinate of its location."""
    if el.weights is None:
        raise ValueError("an element without a location has no measured force")
    return force_series(el.code, el.p, prep.zva[0] @ el.weights, prep.zva[1] @ el.weights)
