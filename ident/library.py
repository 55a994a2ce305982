"""Candidate-function library: polynomials of the states plus the forcing as one column.

Paper eq. (7): Theta(X, F) = [1, X, X^P2, ..., X^Pp, F]. The forcing is appended
as a single extra column; it is *not* multiplied into the polynomial terms
(which is what pysindy does with a control input ``u`` by default).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import combinations_with_replacement

import numpy as np


def _term_name(powers: tuple[int, ...], state_names: list[str]) -> str:
    parts = []
    for name, p in zip(state_names, powers):
        if p == 1:
            parts.append(name)
        elif p > 1:
            parts.append(f"{name}^{p}")
    return " ".join(parts) if parts else "1"


@dataclass(frozen=True)
class PolynomialForcingLibrary:
    """Polynomial terms up to ``degree`` of ``n_states`` states, then ``F`` (if ``forcing``).

    Terms are ordered by total degree, then lexicographically like the paper's
    tables: ``1, x1, x2, x1^2, x1 x2, x2^2, x1^3, ..., F``.
    """

    n_states: int
    degree: int = 3
    forcing: bool = True
    state_names: tuple[str, ...] | None = None
    powers: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.n_states < 1:
            raise ValueError(f"n_states must be >= 1, got {self.n_states}")
        if not 0 <= self.degree <= 7:
            raise ValueError(f"polynomial degree must be in 0..7, got {self.degree}")
        names = self.state_names or tuple(f"x{i + 1}" for i in range(self.n_states))
        if len(names) != self.n_states:
            raise ValueError(f"{len(names)} state names given for {self.n_states} states")
        object.__setattr__(self, "state_names", tuple(names))
        rows = []
        for d in range(self.degree + 1):
            for combo in combinations_with_replacement(range(self.n_states), d):
                rows.append(np.bincount(np.array(combo, dtype=int), minlength=self.n_states))
        powers = np.array(rows, dtype=np.int64).reshape(-1, self.n_states)
        object.__setattr__(self, "powers", powers)

    @property
    def n_terms(self) -> int:
        return self.powers.shape[0] + int(self.forcing)

    @property
    def names(self) -> list[str]:
        cached = self.__dict__.get("_names")
        if cached is None:  # frozen: store past __setattr__, once
            cached = tuple(_term_name(tuple(p), list(self.state_names)) for p in self.powers)
            cached += ("F",) if self.forcing else ()
            object.__setattr__(self, "_names", cached)
        return list(cached)

    def transform(self, x: np.ndarray, f: np.ndarray | None = None) -> np.ndarray:
        """Evaluate the library: ``x`` (..., n_states), ``f`` (...) -> (..., n_terms).

        Works on any leading batch shape, which is what lets the simulator
        integrate many candidate models at once.
        """
        x = np.asarray(x, dtype=float)
        if x.shape[-1] != self.n_states:
            raise ValueError(f"library built for {self.n_states} states, data has {x.shape[-1]}")
        # Integer powers by repeated products (exact, 0**0 == 1), each state's powers computed once and each
        # term the product of its states' powers in state order: the numbers of the multiply-in-place over
        # the ones it replaced (a factor 1 is exact), without boolean-mask assignments (three times slower)
        pows = []
        for j in range(self.n_states):
            col = x[..., j]
            acc = [None, col]  # acc[p] = col^p as (((col) col) col); p = 0 is skipped below
            for _ in range(2, int(self.powers[:, j].max(initial=0)) + 1):
                acc.append(acc[-1] * col)
            pows.append(acc)
        if self.forcing and f is None:
            raise ValueError("this library has a forcing column F: pass the forcing signal")
        theta = np.empty(x.shape[:-1] + (self.n_terms,))
        for k, pk in enumerate(self.powers.tolist()):
            term = None
            for j, p in enumerate(pk):
                if p:
                    term = pows[j][p] if term is None else term * pows[j][p]
            theta[..., k] = 1.0 if term is None else term
        if self.forcing:
            theta[..., -1] = np.asarray(f, dtype=float)  # broadcast over the states' leading shape
        return theta
