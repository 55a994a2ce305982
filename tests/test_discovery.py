"""Discovery: hidden effects in simulated rig data, found from the data and the nominal model only."""

import json
import subprocess
import sys

import numpy as np
import pytest

from daq.sim.hidden import HIDDEN, hidden_case, nominal_params
from ident.discovery import (HELD_OUT, N_BLOCKS, Candidate, best_contact, contact_shape, discover,
                             interleaved_split, simplest_of_best)


@pytest.fixture(scope="module")
def results():
    """Two seeded cases per effect of the catalogue and two with nothing hidden: parameters, beam and
    excitation (steps, sweep or noise) drawn at random; 30 dB sensor noise."""
    out = []
    for seed, effect in enumerate(HIDDEN * 2):
        c = hidden_case(seed, effect=effect)
        out.append((c, discover(c.values, c.fs_hz, c.nominal)))
    return out


def test_cases_cover_the_catalogue_and_none(results):
    assert {c.effect for c, _ in results} == set(HIDDEN)


def test_effect_and_response_named_right(results):
    right = 0
    for c, d in results:
        top = d.findings[0] if d.findings else None
        named = top.effect if top else "none"
        right += named == c.effect and (c.effect == "none" or top.response == f"tip{c.beam}")
    assert right >= 19, right  # the target, 95 % (the 40-case benchmark: 40 of 40)


def test_nothing_found_when_nothing_is_hidden(results):
    nones = [d for c, d in results if c.effect == "none"]
    assert len(nones) >= 2
    assert all(d.findings == [] for d in nones)


def test_parameters_and_gains(results):
    for c, d in results:
        if c.effect == "none" or not d.findings or d.findings[0].effect != c.effect:
            continue
        f = d.findings[0]
        key = "gap" if c.effect == "contact" else next(iter(c.truth))
        err = abs(f.parameters[key] / c.truth[key] - 1)
        if c.effect == "contact":
            assert f.parameters["side"] == c.truth["side"]
            assert err < 0.05, (c, f.parameters)  # the bound; 40-case benchmark: median 0.3 %, max 4.6 %
        elif c.effect == "sensor_offset":
            assert abs(f.parameters[key] - c.truth[key]) < 0.1 * abs(c.truth[key]) + 0.05, (f.parameters, c.truth)
        else:
            assert err < 0.05, (c.effect, err)  # benchmark: at most 0.8 % (sensor gain)
        assert f.gain > 0.15  # the extended model beats the baseline on held-out data


def test_discover_command_on_a_recording(tmp_path):
    """A recording of a rig with a hidden cubic stiffness on beam 2; the user's model has none."""
    truth = tmp_path / "truth.yaml"
    truth.write_text("rig:\n  beam1: {gap_pos_m: .inf, gap_neg_m: .inf}\n"
                     "  beam2: {gap_pos_m: .inf, gap_neg_m: .inf, cubic_stiffness_n_per_m3: 3.0e6}\n"
                     "excitation:\n  amplitude_m_per_s2: 1.0\n  ramp_s: 1.0\n"
                     "  steps: [{t_s: 8, amplitude_m_per_s2: 2.5}, {t_s: 16, amplitude_m_per_s2: 1.5}]\n")
    nominal = tmp_path / "nominal.yaml"
    nominal.write_text("rig:\n  beam1: {gap_pos_m: .inf, gap_neg_m: .inf}\n  beam2: {gap_pos_m: .inf, "
                       "gap_neg_m: .inf}\n")
    rec = tmp_path / "hidden.mcap"
    p = subprocess.run([sys.executable, "-m", "daq", "record", "--port", f"rig://?config={truth}", "--config",
                        str(truth), "--duration", "24", "-o", str(rec), "--quiet", "--no-identify"],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    out = tmp_path / "d.json"
    p = subprocess.run([sys.executable, "-m", "ident", "discover", str(rec), "--model", str(nominal), "--json",
                        str(out), "--report", str(tmp_path / "rep")], capture_output=True, text=True, timeout=300)
    assert p.returncode == 0, p.stderr
    js = json.loads(out.read_text())
    assert js["findings"][0]["effect"] == "cubic_stiffness" and js["findings"][0]["response"] == "tip2"
    assert js["findings"][0]["parameters"]["coefficient_per_mass"] == pytest.approx(3.0e6 / 0.04, rel=0.1)
    assert js["gain"] == pytest.approx(1 - js["extended"]["test_nrmse"] / js["baseline"]["test_nrmse"])
    assert js["gain"] > 0.5
    for fig in ("residual_portraits.png", "baseline_extended_measured.png", "ranking.png"):
        assert (tmp_path / "rep" / fig).read_bytes()[:4] == b"\x89PNG", fig


@pytest.mark.parametrize("args,match", [
    (["--train", "5"], "START:STOP"),
    (["--train", "0:50"], "at least 100"),
    (["--model", "/nonexistent.yaml"], "model file not found"),
])
def test_bad_arguments_are_one_line_exit_2(tmp_path, args, match):
    from pathlib import Path

    rec = Path(__file__).resolve().parents[1] / "recordings" / "linear.mcap"
    model = tmp_path / "m.yaml"
    model.write_text("{}\n")
    base = ["--model", str(model)] if "--model" not in args else []
    p = subprocess.run([sys.executable, "-m", "ident", "discover", str(rec), *base, *args], capture_output=True,
                       text=True, timeout=120)
    assert p.returncode == 2
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and match in lines[0]


def test_bad_data():
    with pytest.raises(ValueError, match="NaN"):
        discover(np.full((50000, 3), np.nan), 2000.0, nominal_params())
    with pytest.raises(ValueError, match="too few"):
        discover(np.zeros((100, 3)), 2000.0, nominal_params())


def test_linear_baseline_path_finds_friction_and_nothing_when_nothing_is_hidden():
    """The generic path (a linear baseline fitted on the training segment): weaker than the rig path."""
    from ident.linear_discovery import discover_linear

    c = hidden_case(11, effect="coulomb_friction")
    d = discover_linear(c.values[:, 0], c.values[:, 1:], ["tip1", "tip2"], ["acceleration"] * 2,
                        "base_acceleration", c.fs_hz)
    assert d.findings[0]["effect"] == "coulomb_friction" and d.findings[0]["response"] == f"tip{c.beam}"
    assert d.findings[0]["parameters"]["force_per_mass"] == pytest.approx(c.truth["force_per_mass"], rel=0.15)
    assert d.extended_test_nrmse < d.baseline_test_nrmse
    c0 = hidden_case(1, effect="none")
    d0 = discover_linear(c0.values[:, 0], c0.values[:, 1:], ["tip1", "tip2"], ["acceleration"] * 2,
                         "base_acceleration", c0.fs_hz)
    assert d0.findings == []


def test_one_sided_gap_is_corrected_for_the_mean_integration_removes():
    """A stopper at +g hit by motion whose mean is z0: integration gives z - z0, the nominal model's
    spring on it adds -w^2 z0 to the residual. The fit with a constant returns g; without, g - z0."""
    rng = np.random.default_rng(5)
    w2, k, g, z0 = 5000.0, 1e5, 0.9e-3, 0.3e-3
    z_true = 1e-3 * np.sin(np.linspace(0, 200, 40_000)) + z0
    z_meas = z_true - z_true.mean()
    d = -k * contact_shape(z_true, g, "positive") - w2 * z_true.mean() + rng.normal(0, 0.5, z_true.size)
    side, gap, stiff, _ = best_contact(z_meas, d, n_grid=400, linear_per_mass=w2)
    assert side == "positive" and gap == pytest.approx(g, rel=0.01) and stiff == pytest.approx(k, rel=0.05)
    _, naive, _, _ = best_contact(z_meas, d, n_grid=400, sides=("positive",))
    assert naive == pytest.approx(g - z0, rel=0.05)  # a third short of the stopper


def test_default_split_interleaves_blocks_over_the_whole_record():
    n, edge = 80_000, 1000
    train, test = interleaved_split(n, edge)
    segs = sorted(train + test, key=lambda s: s.start)
    assert segs[0].start == edge and segs[-1].stop == n - edge
    assert all(a.stop == b.start for a, b in zip(segs, segs[1:]))  # disjoint, no gaps
    held = sum(s.stop - s.start for s in test) / (n - 2 * edge)
    assert held == pytest.approx(len(HELD_OUT) / N_BLOCKS, abs=1e-3)
    assert test[0].start < 0.35 * n and test[-1].stop == n - edge  # spread over the record
    assert interleaved_split(n, edge, slice(0, 30_000), None) == ((slice(edge, 30_000),), (slice(48_000, n - edge),))


def test_more_parameters_must_buy_more_than_the_tolerance():
    def cand(effect, gain, parameters):
        return Candidate(effect, "tip1", parameters, nominal_params(), 0.0, gain=gain)
    contact = {"gap": 1e-3, "side": "both", "stiffness_per_mass": 1e4}
    cubic = {"coefficient_per_mass": 1e7}
    assert simplest_of_best([cand("contact", 0.90, contact), cand("cubic_stiffness", 0.89, cubic)]).effect == \
        "cubic_stiffness"
    assert simplest_of_best([cand("contact", 0.95, contact), cand("cubic_stiffness", 0.90, cubic)]).effect == "contact"
    assert simplest_of_best([]) is None
