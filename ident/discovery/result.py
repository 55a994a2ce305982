"""What discovery returns, and its one JSON form."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..jsonsafe import finite
from .baselines import Baseline
from .catalogue import CAUSES
from .model import LinearModel
from .search import Candidate
from .signals import Prepared
from .split import Split

# the test that separates one cause at two places
PLACE = "the same cause at two places: a response on each side of the suspected element, or the excitation moved"


@dataclass(frozen=True)
class Discovery:
    baseline: Baseline
    baseline_test_nrmse: float
    baseline_block_errors: np.ndarray
    extended: LinearModel
    extended_output: tuple
    extended_test_nrmse: float
    extended_block_errors: np.ndarray
    findings: list[Candidate]
    # per finding, the causes the data cannot separate from it (and, for a softening first finding, the
    # mechanism it may be: ``discover._softening_look_alike``)
    ambiguous: list[list[Candidate]]
    candidates: list[Candidate]  # every candidate scored, best gain first
    split: Split
    prep: Prepared
    warm: int
    transients_s: list[float] = field(default_factory=list)
    residual_rms: dict = field(default_factory=dict)
    characterisation: dict = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    @property
    def gain(self) -> float:
        if not self.findings or not self.baseline_test_nrmse > 0:
            return 0.0
        return 1.0 - self.extended_test_nrmse / self.baseline_test_nrmse

    @property
    def gain_vs_zero(self) -> float:
        """1 - NRMSE of the extended model: predicting zero scores 0, a model worse than zero below it."""
        return 1.0 - self.extended_test_nrmse

    def per_mass_mode_hz(self, c: Candidate) -> float | None:
        """The natural frequency of the mode a candidate's per-mass parameters are per modal mass of (its
        own linear part's, else the baseline's dominant mode at its location); None for a baseline in
        physical units (a rig model: per the tip's mass). Where two modes share a location (two coupled
        beams of close frequency), a per-mass coefficient means nothing without it."""
        base = c.baseline or self.baseline
        loc = {x.name: x for x in base.locations(self.prep)}.get(c.location)
        return None if loc is None else base.per_mass_mode_hz(loc)

    def verdict(self) -> str:
        """One line: what was found, or that nothing was, or which causes the data cannot separate."""
        if not self.findings:
            return "nothing found: " + (self.notes[0] if self.notes else "no cause beats the baseline")
        parts = []
        for f, alike in zip(self.findings, self.ambiguous):
            if alike:
                names = " or ".join(options(f, alike)[:3])
                how = (PLACE if all(a.cause == f.cause for a in alike) else separating_test(f, alike))
                parts.append(f"ambiguous: {names} ({how})")
            else:
                parts.append(f"found {f.label} (held-out gain {f.gain:.2f}, p = {f.p_value:.1g})")
        return "; ".join(parts)


def options(first: Candidate, alike: list[Candidate]) -> list[str]:
    """The labels of a finding and its look-alikes, each once (a cause refined and as regressed at one place
    are one answer), the finding's first."""
    return list(dict.fromkeys([first.label] + [a.label for a in alike]))


def separating_test(first: Candidate, alike: list[Candidate]) -> str:
    """The test that tells a finding from its look-alikes: its cause's, or, when it softens and a look-alike
    is the mechanism it then describes (``Cause.softening_mechanism``), the one that tells those two apart."""
    cause = CAUSES[first.cause]
    if softens(first) and any(a.cause == cause.softening_mechanism for a in alike):
        return cause.separates_softening
    return cause.separates_by


def softens(c: Candidate) -> bool:
    """Does the candidate's law soften (its first coefficient negative where the cause names a mechanism
    that softening describes)?"""
    cause = CAUSES[c.cause]
    value = c.parameters.get(cause.coefficients[0].name) if cause.softening_mechanism else None
    return isinstance(value, float) and value < 0


def equation(c: Candidate) -> str:
    text = ", ".join(f"{k} = {v:.4g}" if isinstance(v, float) else f"{k} = {v}" for k, v in c.parameters.items())
    return f"{c.location}: {c.cause} ({text})"


def candidate_json(c: Candidate, fs_hz: float | None = None) -> dict:
    cause = CAUSES[c.cause]
    units = {p.name: p.unit for p in cause.coefficients + cause.shape}
    return finite({"effect": c.cause, "response": c.location, "parameters": c.parameters, "units": units,
                   "physical": c.physical, "gain": c.gain, "gain_over_own_linear_part": c.own_gain,
                   "gain_over_own_linear_part_in_training": c.own_gain_trained,
                   "p_value_over_own_linear_part": c.own_p,
                   "test_nrmse": c.test_nrmse, "p_value": c.p_value,
                   "fit_r2": c.fit_r2, "refined": c.refined, "note": c.note or None})


def to_json(d: Discovery) -> dict:
    """The result in the shape the README documents (``baseline``, ``extended``, ``gain``, ``findings``,
    ``candidates``, ``split``, ``residual_rms``), with what this design adds beside it."""
    prep = d.prep
    model = d.baseline.model
    out = {
        "verdict": d.verdict(),
        "baseline": {"kind": d.baseline.label, "test_nrmse": d.baseline_test_nrmse,
                     "modes": [{"frequency_hz": float(f), "damping_ratio": float(z)}
                               for f, z in zip(model.frequencies_hz, model.damping_ratios)]},
        "extended": {"test_nrmse": d.extended_test_nrmse, "equations": [equation(c) for c in d.findings]},
        "gain": d.gain,
        "gain_vs_zero": d.gain_vs_zero,
        "findings": [{**candidate_json(c), "per_mass_mode_hz": d.per_mass_mode_hz(c),
                      "ambiguous_with": [candidate_json(a) for a in alike]}
                     for c, alike in zip(d.findings, d.ambiguous)],
        "candidates": [candidate_json(c) for c in d.candidates],
        "split": {"blocks": [[s.start, s.stop] for s in d.split.blocks],
                  "held_out": list(d.split.held_out), "excluded": list(d.split.excluded),
                  "train": [[s.start, s.stop] for s in d.split.train],
                  "test": [[s.start, s.stop] for s in d.split.test]},
        # what was analysed: ``split`` counts samples of this (a record over the memory budget is decimated
        # and cut, ``signals.within_budget``; the notes say so), from the record's time ``start_s``
        "analysed": {"fs_hz": prep.fs_hz, "start_s": prep.start_s, "samples": prep.n},
        "band_hz": list(prep.band),
        "signs": {n: int(s) for n, s in zip(prep.names, prep.signs)},
        "sign_notes": prep.sign_notes,
        "transients_s": d.transients_s,
        "residual_rms": d.residual_rms,
        "characterisation": d.characterisation,
        "notes": d.notes,
    }
    return finite(out)
