"""An identified model: coefficients with names, printable as equations, serialisable as plain data.

``coefficients[k, i]`` multiplies library term k in the equation of state i
(Xi of paper eq. 5). Models round-trip through JSON or YAML text, never pickle.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np
import yaml

from .library import PolynomialForcingLibrary
from .simulate import Simulation, simulate

FORMAT_VERSION = 1


@dataclass(frozen=True)
class SindyModel:
    library: PolynomialForcingLibrary
    coefficients: np.ndarray  # (n_terms, n_states)

    def __post_init__(self) -> None:
        c = np.asarray(self.coefficients, dtype=float)
        if c.shape != (self.library.n_terms, self.library.n_states):
            raise ValueError(
                f"coefficients shape {c.shape} does not match library "
                f"({self.library.n_terms} terms, {self.library.n_states} states)"
            )
        object.__setattr__(self, "coefficients", c)

    @property
    def state_names(self) -> list[str]:
        return list(self.library.state_names)

    @property
    def term_names(self) -> list[str]:
        return self.library.names

    @property
    def n_active(self) -> int:
        return int(np.count_nonzero(self.coefficients))

    def as_dict(self) -> dict[str, dict[str, float]]:
        """{"x1'": {term: value}} with the non-zero terms only, as the paper's tables list them."""
        out = {}
        for i, s in enumerate(self.state_names):
            out[f"{s}'"] = {
                name: float(self.coefficients[k, i])
                for k, name in enumerate(self.term_names)
                if self.coefficients[k, i] != 0
            }
        return out

    def equations(self, precision: int = 4) -> list[str]:
        eqs = []
        for lhs, terms in self.as_dict().items():
            if not terms:
                eqs.append(f"{lhs} = 0")
                continue
            parts = []
            for name, c in terms.items():
                mag = f"{abs(c):.{precision}f}"
                body = mag if name == "1" else f"{mag} {name}"
                sign = "-" if c < 0 else "+"
                parts.append((sign, body))
            text = ("-" if parts[0][0] == "-" else "") + parts[0][1]
            text += "".join(f" {s} {b}" for s, b in parts[1:])
            eqs.append(f"{lhs} = {text}")
        return eqs

    def table(self) -> list[list[str | float]]:
        """Rows [term, coef for state 1, coef for state 2, ...]: the layout of the paper's Tables 1-7."""
        return [[name, *map(float, self.coefficients[k])] for k, name in enumerate(self.term_names)]

    def simulate(self, x0: np.ndarray, t: np.ndarray, forcing: np.ndarray | None = None, **kw) -> Simulation:
        return simulate(self.library, self.coefficients, x0, t, forcing, **kw)

    # --- plain-data round trip -------------------------------------------------
    def to_dict(self) -> dict:
        return {
            "format_version": FORMAT_VERSION,
            "states": self.state_names,
            "degree": self.library.degree,
            "forcing": self.library.forcing,
            "equations": self.as_dict(),
        }

    @classmethod
    def from_dict(cls, data: dict) -> "SindyModel":
        try:
            states = list(data["states"])
            lib = PolynomialForcingLibrary(len(states), int(data["degree"]), bool(data["forcing"]),
                                           tuple(states))
            eqs = data["equations"]
        except (KeyError, TypeError) as exc:
            raise ValueError(f"not a model file: missing or malformed field {exc}") from None
        names = lib.names
        coefs = np.zeros((lib.n_terms, lib.n_states))
        for i, s in enumerate(states):
            for term, value in (eqs.get(f"{s}'") or {}).items():
                if term not in names:
                    raise ValueError(f"model has unknown term {term!r} for {s}'; the library has {names}")
                coefs[names.index(term), i] = float(value)
        return cls(lib, coefs)

    def dumps(self, fmt: str = "json") -> str:
        if fmt == "json":
            return json.dumps(self.to_dict(), indent=2)
        if fmt in ("yaml", "yml"):
            return yaml.safe_dump(self.to_dict(), sort_keys=False)
        raise ValueError(f"unknown model format {fmt!r}; use json or yaml")

    @classmethod
    def loads(cls, text: str, fmt: str = "json") -> "SindyModel":
        try:
            data = json.loads(text) if fmt == "json" else yaml.safe_load(text)
        except (json.JSONDecodeError, yaml.YAMLError) as exc:
            raise ValueError(f"model text is not valid {fmt}: {exc}") from None
        if not isinstance(data, dict):
            raise ValueError("model text does not hold a mapping")
        return cls.from_dict(data)
