"""A cause regressed with its equivalent linearisation taken out (``search.regressions`` given
``search.spring_damper_responses``).

A modal baseline fitted to a record holds each nonlinearity's equivalent stiffness and damping at the
record's amplitudes; regressed on that baseline's residual alone, a drag comes out too small, since the part
of it the baseline already damps is not in the residual. Regressed together with a spring and a damper at
the same coordinate, the damper takes that part out again and the drag comes out whole.

The data are not the method's own: a one-mode oscillator with drag, x'' + 2 zeta w x' + w^2 x + c2 x'|x'|
= f, integrated here (RK4 in plain Python on the force's linear interpolation; no ``ident`` code),
displacement out with 1 % white noise, the force random and low-passed at 40 Hz. The drag's equivalent
viscous damping at the velocity's RMS is 1.5 times the linear one. For a Gaussian velocity of RMS s, the
least-squares viscous equivalent of c2 v|v| is c2 E|v|^3 / E v^2 = 2 sqrt(2 / pi) c2 s: the compensation's
damper is checked against that (analytic) value."""

import importlib

import numpy as np
import pytest
from scipy import signal

from discovery_fit import fitted_as_discover
from oscillator import rk4

from ident.discovery import Channel, Measurement

disc = importlib.import_module("ident.discovery.discover")
search = importlib.import_module("ident.discovery.search")

FS, SECONDS = 1000.0, 40.0
W, ZETA = 2 * np.pi * 12.0, 0.01


def _integrate(u: np.ndarray, c2: float) -> tuple[np.ndarray, np.ndarray]:
    """x and v of x'' + 2 zeta w x' + w^2 x + c2 v|v| = u from rest (RK4, force linearly interpolated)."""
    return rk4(u, FS, lambda x, v, f: f - 2 * ZETA * W * v - W * W * x - c2 * v * abs(v))


@pytest.fixture(scope="module")
def drag():
    rng = np.random.default_rng(11)
    b, a = signal.butter(4, 40 / (FS / 2))
    u = signal.lfilter(b, a, rng.standard_normal(int(SECONDS * FS)))
    _, v_lin = _integrate(u, 0.0)
    s = float(v_lin.std())
    c2 = 1.5 * 2 * ZETA * W / (2 * np.sqrt(2 / np.pi) * s)  # its equivalent damping 1.5 x the linear one
    x, v = _integrate(u, c2)
    m = Measurement(FS, Channel("force", "force", u), (Channel("x", "displacement",
                                                                   x + 0.01 * x.std() * rng.standard_normal(u.size)),))
    f = fitted_as_discover(m)
    base, prep, split, warm, residual, rows, scale = f.base, f.prep, f.split, f.warm, f.residual, f.rows, f.scale
    loc = next(loc for loc in base.locations(prep) if loc.name == "x")
    lin = search.spring_damper_responses(base, prep, rows, loc, scale)
    plain, comp = search.regressions(base, prep, rows, residual, loc, "quadratic_damping", scale, compensate=lin)
    return c2, float(v.std()), plain, comp, (base, loc, prep, split, warm, scale)


def test_the_compensated_regression_gives_the_drag_the_plain_one_misses(drag):
    c2, _, plain, comp, _ = drag
    found = comp.parameters["coefficient_per_mass"]
    assert found == pytest.approx(c2, rel=0.10), (found, c2)  # measured: 91.4 against 87.3 (4.7 %)
    # the plain regression sees only what the fitted damping left: 1.8, a fiftieth of the drag
    assert plain.parameters["coefficient_per_mass"] < 0.1 * c2, (plain.parameters, c2)


def test_the_compensation_is_the_drags_equivalent_damping_taken_out(drag):
    c2, s, _, comp, _ = drag
    equivalent = 2 * np.sqrt(2 / np.pi) * c2 * s  # the least-squares viscous equivalent (Gaussian velocity)
    # measured: -1.58 /s against -1.64 /s
    assert comp.parameters["compensation_damping_per_mass"] == pytest.approx(-equivalent, rel=0.10)
    # the spring takes out only what the drag does not do: no stiffness worth a percent of the mode's
    assert abs(comp.parameters["compensation_stiffness_per_mass"]) < 0.01 * W * W
    assert comp.order == search.CAUSES["quadratic_damping"].order + 2
    assert search.compensation(comp) == comp.elements[-2:] and not search.compensation(search.replace(comp, parameters={}))


def test_the_refinement_scales_the_drag_with_its_spring_and_damper_and_keeps_their_laws(drag):
    # the second step refines what leads by simulation (``discover``), as the first step does: the cause's
    # elements and its spring and damper scaled together, each keeping its law
    c2, _, _, comp, (base, loc, prep, split, warm, scale) = drag
    bound = search.simulation_bound(prep)
    segs = search.busiest(prep, split, loc.weights, search.Settings().refine_blocks)
    before = search.train_error(base, comp, prep, segs, warm, scale, bound)
    ref = search.refine(comp, base, loc, prep, split, warm, scale, bound, search.Settings(), joint=False)
    assert ref.refined and ref.train_nrmse <= before
    assert [el.code for el in ref.elements] == [el.code for el in comp.elements]
    assert all(np.array_equal(a.p, b.p) for a, b in zip(ref.elements[-2:], comp.elements[-2:]))
    assert set(ref.parameters) == set(comp.parameters) and search.compensation(ref) == ref.elements[-2:]
    assert np.sign(ref.parameters["compensation_damping_per_mass"]) == -1
    # the drag itself stays where the regression put it, within 10 % of the integrated oscillator's
    assert ref.parameters["coefficient_per_mass"] == pytest.approx(c2, rel=0.10), (ref.parameters, c2)
