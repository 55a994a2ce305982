"""Discovery on one of the independent generator's cases, asserted to name its cause: shared by the files
that each hold one case per test (``test_discovery_independent_*.py``)."""

import pytest

from daq.sim.independent.cases import discovery_case
from ident.cli.bench_discovery import independent_case, judge
from ident.discovery import discover


def named_right(seed: int, family: str | None = None):
    """Discovery on the generator's case ``seed`` (of ``family``, if given), asserted to name its cause at the
    right place with no false extra finding; the generated case, the case as measured, the discovery and its
    verdict."""
    generated = discovery_case(seed, family)
    c = independent_case(seed, generated)
    d = discover(c.measurement)
    v = judge(c, d, 0.0)
    assert v.right and v.extra == 0, d.verdict()
    return generated, c, d, v


def cubic_found(seed: int, rel: float, family: str | None = None):
    """``named_right`` for a cubic, its coefficient per modal mass asserted within ``rel`` of the generator's
    one-mode equivalent; the discovery and that equivalent."""
    generated, _, d, _ = named_right(seed, family)
    eq = generated.truth["equivalent"]
    assert d.findings[0].parameters["coefficient_per_mass"] == pytest.approx(eq["k3_per_mass"], rel=rel)
    return d, eq
