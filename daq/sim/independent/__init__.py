"""daq.sim.independent: a data generator written from physics, apart from ``ident`` (it imports nothing
from it), of higher fidelity than the models the science assumes, so that the science can be judged on
data its own model did not make.

Public API:

- ``discovery_case(seed, family=None, cause=None, twin=False) -> Case``: one structure with one hidden
  cause (cases.FAMILIES, cases.CAUSES), its excitation and instruments, and the truth; ``twin``: the
  same draws run without the effect (truth cause "none", the mirrored effect under ``twin_of``).
- ``regime_case(seed, fs_hz=None, segment_s=(10, 30)) -> Case`` and
  ``steady_case(seed, regime, minutes=10, fs_hz=1000) -> Case``: the two-beam rig with stoppers, for a
  regime monitor (per-sample truth in ``Case.truth_series``).
- ``write_case(case, folder)``: ``case.csv``, ``truth.json`` (and ``truth.csv``), never overwriting.
- ``python -m daq.sim.independent campaign OUT_DIR --cases N --seed S [--family F] [--twins]``.

Modules: beams (finite elements), modal (reduction), elements (nonlinear forces), integrate (compiled
RK4), excitation (signals), sensors (instrument chain), experiment (set-up and run), rig (two-beam rig),
structures (Duffing, chain, clamped-clamped beam), draws (seeded draws, equivalent parameters), cases
(discovery cases), regimes (regime cases), recording (Case, files).
"""

from .cases import CAUSES, FAMILIES, discovery_case
from .recording import Case, write_case
from .regimes import REGIMES, regime_case, steady_case

__all__ = ["CAUSES", "FAMILIES", "REGIMES", "Case", "discovery_case", "regime_case", "steady_case", "write_case"]
