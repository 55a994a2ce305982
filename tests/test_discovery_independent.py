"""Discovery on data this project's model did not make: the independent generator (``daq.sim.independent``,
finite-element beams with their own integrator, importing nothing from ``ident``) hides an effect, and
``ident discover`` with a modal baseline fitted to the same record must name it, where it is, with its
size; where nothing is hidden it must find nothing.

The seeds are fixed; ``ident bench discovery`` runs many more (its figures are in the README). Seed 2 is a
two-sided contact near the tip of beam 1 under base excitation at 2 kHz; seed 1 a force-driven rig with
nothing hidden at 2.5 kHz.
"""

import pytest

from ident.cli.bench_discovery import independent_case, judge
from ident.discovery import discover


@pytest.fixture(scope="module")
def cases():
    out = {}
    for seed in (1, 2):
        c = independent_case(seed)
        out[seed] = (c, discover(c.measurement))
    return out


def test_a_hidden_contact_is_named_at_its_beam_with_its_gap(cases):
    c, d = cases[2]
    assert (c.cause, c.location) == ("contact", "tip1")  # what the generator hid (its own record of it)
    v = judge(c, d, 0.0)
    assert v.right and v.extra == 0, d.verdict()
    f = d.findings[0]
    assert f.parameters["gap"] == pytest.approx(c.truth["gap"], rel=0.05)
    assert f.parameters["side"] == c.truth["side"]
    assert f.p_value < 0.05 and d.gain > 0.3 and d.gain_vs_zero > 0


def test_nothing_is_found_where_nothing_is_hidden(cases):
    c, d = cases[1]
    assert c.cause == "none"
    assert d.findings == [] and d.verdict().startswith("nothing found")
