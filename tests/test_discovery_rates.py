"""Discovery at the top of the issue's sample-rate range: one record of a force-driven Duffing oscillator
at 20 kHz, and the same record decimated to 2 kHz, give the same answer.

The oscillator is integrated here (RK4 in plain Python on the force's linear interpolation; no ``ident``
code), so the data are not the method's own: x'' + 2 zeta w x' + w^2 x + k3 x^3 = f, displacement out
with 1 % white noise, the force random and low-passed at 150 Hz, the cubic worth 0.3 w^2 x at the linear
response's RMS."""

import re
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
from scipy import signal

from clitools import run_main
from oscillator import rk4
from ident.cli.bench_f16 import SEGMENT, h1_peak
from ident.cli.bench_memory import record
from ident.cli.main import main as ident_main
from ident.discovery import Channel, Measurement, Settings, discover
from ident.discovery.catalogue import CAUSES
from ident.discovery.discover import _set_aside, _split, _warm
from ident.discovery.search import Candidate, FitLevel, _at_fit_level, _refit_at, _scaled
from ident.discovery.signals import prepare, within_budget

FS = 20000.0
W, ZETA = 2 * np.pi * 20.0, 0.02


def _force(fs: float, seconds: float, seed: int):
    """The random force low-passed at 150 Hz, the cubic worth 0.3 w^2 x at its linear response's RMS, and
    the generator (its next draws are the sensor noise)."""
    rng = np.random.default_rng(seed)
    b, a = signal.butter(4, 150 / (fs / 2))
    u = signal.lfilter(b, a, rng.standard_normal(int(seconds * fs)))
    lin = signal.lti([1], [1, 2 * ZETA * W, W * W]).to_discrete(1 / fs, method="bilinear")
    k3 = 0.3 * W * W / signal.lfilter(np.ravel(lin.num), np.ravel(lin.den), u).std() ** 2
    return u, k3, rng


def _integrate(u: np.ndarray, fs: float, k3: float) -> np.ndarray:
    """x of x'' + 2 zeta w x' + w^2 x + k3 x^3 = u from rest, RK4 on the force's linear interpolation."""
    return rk4(u, fs, lambda x, v, f: f - 2 * ZETA * W * v - W * W * x - k3 * x * x * x)[0]


def _duffing(seconds: float = 10.0) -> tuple[np.ndarray, np.ndarray, float]:
    u, k3, rng = _force(FS, seconds, 7)
    x = _integrate(u, FS, k3)
    return u, x + 0.01 * x.std() * rng.standard_normal(u.size), k3


@pytest.fixture(scope="module")
def answers():
    u, x, k3 = _duffing()
    out = {}
    for q in (1, 10):  # 20 kHz as recorded, and every tenth sample (2 kHz)
        m = Measurement(FS / q, Channel("force", "force", u[::q]), (Channel("x", "displacement", x[::q]),))
        out[q] = discover(m)
    return out, k3


def test_a_20_khz_record_and_its_2_khz_decimation_name_the_same_cubic(answers):
    out, k3 = answers
    coefficient = {}
    for q, d in out.items():
        assert [f.label for f in d.findings] == ["cubic_stiffness at x"], (q, d.verdict())
        assert not d.ambiguous[0], (q, [a.label for a in d.ambiguous[0]])
        coefficient[q] = d.findings[0].parameters["coefficient_per_mass"]
    # the sample rate changes nothing the method depends on: the same coefficient within 1 %
    assert coefficient[1] == pytest.approx(coefficient[10], rel=0.01)
    # and it is the integrated oscillator's within 25 % (1.15 x measured: the fitted linear part is the
    # record's, 23.2 Hz where the oscillator's small-amplitude mode is 20 Hz, see the README)
    assert coefficient[1] == pytest.approx(k3, rel=0.25)


def test_a_record_over_the_memory_budget_is_decimated_and_names_the_same_cubic(answers, tmp_path):
    """The 20 kHz record against a budget of 50,000 samples x responses (200,000 here): decimated to fit,
    the rate chosen from where the responses carry power, and the same cubic within 1 % of the full-rate
    coefficient; the note says what was done. Through the command, training and test samples that fit
    only once decimated and cut are analysed on that span, and a span that does not fit is refused in
    one line."""
    out, k3 = answers
    u, x, _ = _duffing()
    m = Measurement(FS, Channel("force", "force", u), (Channel("x", "displacement", x),))
    d = discover(m, settings=Settings(max_samples=50_000))
    assert d.prep.n <= 50_000 and d.prep.fs_hz < FS / 10
    assert d.prep.band[1] < 0.45 * d.prep.fs_hz
    assert [f.label for f in d.findings] == ["cubic_stiffness at x"], d.verdict()
    full = out[1].findings[0].parameters["coefficient_per_mass"]
    assert d.findings[0].parameters["coefficient_per_mass"] == pytest.approx(full, rel=0.01)
    assert any(n.startswith("decimated ") and "memory budget" in n for n in d.notes), d.notes
    # a fit record at the same rate is decimated as the analysed one: the baseline's rate is the record's
    half = u.size // 2
    fit = Measurement(FS, Channel("force", "force", u[:half]), (Channel("x", "displacement", x[:half]),))
    low = Measurement(FS, Channel("force", "force", u[half:]), (Channel("x", "displacement", x[half:]),))
    d2 = discover(low, fit_data=fit, settings=Settings(max_samples=50_000))
    step = round(FS / d2.prep.fs_hz)
    assert step > 10 and f"fit data: decimated {step} x to {d2.prep.fs_hz:.6g} Hz" in " ".join(d2.notes), d2.notes

    csv = tmp_path / "duffing.csv"
    np.savetxt(csv, np.column_stack([u, x]), delimiter=",", header="force,x", comments="", fmt="%.9g")
    args = ["discover", csv, "--fs", str(FS), "--excitation", "force:force", "--response", "x:displacement",
            "--max-samples", "7000"]
    code, text, err, tb = run_main(ident_main, args + ["--train", "20000:110000", "--test", "110000:150000"])
    assert code == 0 and tb is None, (err, tb)
    assert "cubic_stiffness at x" in text and "the span around the training and test samples" in text, text
    # 20,000-150,000 is 6.5 s; 7,000 samples at the decimated rate (about 870 Hz) hold about 8 s
    span = re.search(r"analysed ([\d.]+)-([\d.]+) s of 0-10 s", text)
    assert span and float(span[1]) <= 1.0 and float(span[2]) >= 7.5, text
    code, text, err, tb = run_main(ident_main, args + ["--train", "0:150000", "--test", "150000:200000"])
    assert code == 2 and tb is None and len(err.strip().splitlines()) == 1, (err, tb)
    assert "memory budget" in err and "10 s" in err, err
    # --train alone: the held-out samples default to the rest of the record, which does not fit either
    code, text, err, tb = run_main(ident_main, args + ["--train", "0:50000"])
    assert code == 2 and tb is None and len(err.strip().splitlines()) == 1, (err, tb)
    assert "give --test" in err and "memory budget" in err, err


def test_the_span_with_the_widest_range_of_amplitudes_is_the_one_analysed():
    """A minute of a band-limited response at three levels (0.1 for 20 s, 1 for 20 s, 0.3 for 20 s), cut to
    26 s by the budget: the span holds the step from 0.1 to 1, the largest change of level, with both
    levels in it; its notes give the span in the record's seconds."""
    fs = 10000.0
    t = np.arange(int(60 * fs)) / fs
    rng = np.random.default_rng(0)
    u = rng.standard_normal(t.size)
    b, a = signal.butter(2, [8 / (fs / 2), 12 / (fs / 2)], "band")
    y = np.where(t < 20, 0.1, np.where(t < 40, 1.0, 0.3)) * signal.lfilter(b, a, u)
    ex = within_budget(Measurement(fs, Channel("f", "force", u), (Channel("y", "acceleration", y),)), 10_000)
    start, stop = ex.start / fs, ex.stop / fs
    assert ex.measurement.n == 10_000 and ex.measurement.start_s == pytest.approx(start)
    assert start < 20 - 5 and stop > 20 + 5, (start, stop)
    assert ex.notes[-1] == f"analysed {start:.6g}-{stop:.6g} s of 0-60 s to fit the memory budget (the span with " \
                           "the widest range of amplitudes)"
    # a step in the record's last blocks: the span holds it and stays inside the record, a whole budget long
    # (999 samples are no whole number of 20 blocks: the widest span's start, 98, would run 14 past the end)
    fs, n = 100.0, 1083
    u = rng.standard_normal(n)
    b, a = signal.butter(2, [8 / (fs / 2), 12 / (fs / 2)], "band")
    y = np.where(np.arange(n) < n - 60, 0.1, 1.0) * signal.lfilter(b, a, u)
    end = within_budget(Measurement(fs, Channel("f", "force", u), (Channel("y", "acceleration", y),)), 999)
    assert (end.step, end.start, end.stop, end.measurement.n) == (1, 84, 1083, 999)


def test_the_memory_benchmark_runs_both_ways_and_finds_the_structures_modes():
    """``ident bench memory`` on a short record: both runs (in processes of their own) find the two modes
    the record was made with (12 and 31 Hz, within 1 %), say nothing is found on a linear record, and the
    ratios line is printed."""
    proc = subprocess.run([sys.executable, "-m", "ident", "bench", "memory", "--duration", "12", "--fs", "1000"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    runs = [line for line in proc.stdout.splitlines() if "--max-samples" in line]
    assert len(runs) == 2 and "ratios, within the budget / as recorded: peak memory" in proc.stdout, proc.stdout
    for line in runs:
        modes = [float(f) for f in re.search(r"modes ([\d., ]+) Hz", line)[1].split(", ")]
        assert modes == pytest.approx([12.0, 31.0], rel=0.01) and "nothing found" in line, line


def test_a_clipped_sensor_is_found_in_a_record_decimated_to_fit_the_budget():
    """A linear two-mode record (``ident bench memory``'s, made with scipy's lfilter) whose first
    accelerometer clips at 0.6 of its peak (2 % of its samples at the rail), 30 s at 5 kHz, against a budget
    of a quarter: decimation smooths the flat tops away, so the clipping is read off the record as
    recorded; it is the finding, at the rail's value."""
    fs = 5000.0
    u, y1, y2 = record(30, fs)
    rail = 0.6 * float(np.abs(y1).max())
    m = Measurement(fs, Channel("force", "force", u), (Channel("a1", "acceleration", np.clip(y1, -rail, rail)),
                                                       Channel("a2", "acceleration", y2)))
    d = discover(m, settings=Settings(max_samples=75_000))
    assert d.prep.fs_hz < fs and any(n.startswith("decimated 2 x") for n in d.notes), d.notes
    assert [f.label for f in d.findings] == ["clipping at a1"] and not d.ambiguous[0], d.verdict()
    assert d.findings[0].parameters["range"] == pytest.approx(rail, rel=1e-9)


def _duffing_levels(fs=2000.0, seconds=20.0, low=0.2):
    """The Duffing oscillator of ``_duffing`` (same w, zeta, cubic worth 0.3 w^2 x at the high level's linear
    RMS), integrated at ``fs`` under one random force at two levels: (force, x) at ``low`` x and at 1 x."""
    u, k3, rng = _force(fs, seconds, 3)
    out = []
    for scale in (low, 1.0):
        y = _integrate(scale * u, fs, k3)
        out.append((scale * u, y + 0.01 * y.std() * rng.standard_normal(u.size)))
    return out, k3


@pytest.fixture(scope="module")
def two_levels():
    (lo, hi), k3 = _duffing_levels()
    meas = [Measurement(2000.0, Channel("force", "force", u), (Channel("x", "displacement", x),)) for u, x in (lo, hi)]
    return meas, k3, discover(meas[1], fit_data=meas[0])


def test_with_a_low_level_fit_record_the_cubic_holds_at_both_levels_and_what_breaks_the_low_one_is_said(two_levels):
    """``discover(high, fit_data=low)`` on a Duffing oscillator at two force levels (0.2 and 1): the cubic is
    named, its coefficient within 25 % of the oscillator's; candidates that predict the low level's held-out
    blocks materially worse are set aside with the figures (and no candidate within the gain floor of the
    baseline there is)."""
    _, k3, d = two_levels
    assert [f.label for f in d.findings] == ["cubic_stiffness at x"], d.verdict()
    assert d.findings[0].parameters["coefficient_per_mass"] == pytest.approx(k3, rel=0.25)
    aside = [c for c in d.candidates if c.note.startswith("breaks the fit record")]
    assert aside, [c.note for c in d.candidates]
    for c in aside:
        figures = re.search(r"(\d+)% worse than the baseline \(NRMSE ([\d.e+-]+) against ([\d.e+-]+)", c.note)
        worse, mine, base = figures.groups()
        assert c.p_value == 1.0 and float(mine) > 1.03 * float(base) and int(worse) >= 3, c.note


def test_a_refinement_with_a_fit_record_keeps_only_versions_that_hold_at_its_level(two_levels):
    """``search._at_fit_level``, the refinement's rule at the fit record's level: the named cubic holds there
    (the oscillator's own law), the same cubic 100 times stronger does not (at the low level, a fifth of the
    force, its force is about four times what the true cubic's is at the high level), and a version that
    adds nothing to the baseline holds by construction; ``_refit_at`` keeps a linear part refitted there
    only where it simulates that record better."""
    meas, k3, d = two_levels
    cubic = d.findings[0]
    prep_f = prepare(meas[0], d.prep.band)
    fit = FitLevel(prep_f, (slice(prep_f.edge, prep_f.n - prep_f.edge),), _split(prep_f), _warm(d.baseline, prep_f))
    loc = next(loc for loc in d.baseline.locations(prep_f) if loc.name == cubic.location)
    at_fit = _at_fit_level(fit, loc, d.baseline, Settings())
    shape = {p.name: cubic.parameters[p.name] for p in CAUSES[cubic.cause].shape}
    assert at_fit.error(cubic) <= at_fit.limit
    strong = _scaled(cubic, cubic.baseline or d.baseline, loc, np.full(len(cubic.elements), np.log(100.0)), shape)
    assert at_fit.error(strong) > 2 * at_fit.limit
    nothing = replace(cubic, baseline=None, elements=(), output=())
    assert at_fit.error(nothing) == pytest.approx(at_fit.limit / (1 + Settings().gain_floor), rel=1e-12)
    refitted = _refit_at(fit, d.baseline, strong, at_fit)
    assert at_fit.error(refitted) <= at_fit.error(strong)
    assert _at_fit_level(None, loc, d.baseline, Settings()).limit == np.inf


def test_the_best_candidate_the_fit_record_set_aside_is_said_when_it_gains_more_than_the_answer():
    note = "breaks the fit record: it predicts that record's held-out blocks 34% worse than the baseline"
    joint = Candidate("hysteretic_joint", "A2", {}, gain=0.75, note=note)
    cubic = Candidate("cubic_stiffness", "A1+A3", {}, gain=0.29)
    other = Candidate("contact", "A3", {}, gain=0.5, note=note)
    assert _set_aside([joint, other, cubic], [cubic]) == [
        f"hysteretic_joint at A2 (held-out gain 0.75 on this record) was set aside: {note}"]
    assert _set_aside([joint, cubic], []) != [] and _set_aside([replace(joint, gain=0.2), cubic], [cubic]) == []
    assert _set_aside([cubic], [cubic]) == []


def test_the_f16_benchmark_reads_a_resonance_peak_as_the_analytic_frf_has_it(tmp_path):
    """``bench_f16.h1_peak`` on a mode at 7.3 Hz (damping ratio 0.02) driven by white force at 400 Hz, as the F-16's
    records are sampled: the peak of the accelerance s^2 / (s^2 + 2 zeta w s + w^2) lies at w / sqrt(1 - 2 zeta^2)
    with height 1 / (2 zeta sqrt(1 - zeta^2)). With segments of 32,768 samples (0.012 Hz lines) the estimate
    finds it within 0.05 Hz and 1.5 %; with the bench's 8,192 (0.05 Hz, against the mode's half-power bandwidth
    2 zeta f0 = 0.29 Hz) the Hann window's resolution lowers the peak by up to 7 %, as it does for every column
    the bench compares. ``ident bench f16`` on a folder without the records says so in one line (exit 2)."""
    fs, f0, zeta = 400.0, 7.3, 0.02
    w = 2 * np.pi * f0
    num, den, _ = signal.cont2discrete(([1.0, 0.0, 0.0], [1.0, 2 * zeta * w, w * w]), 1 / fs, method="bilinear")
    u = np.random.default_rng(5).standard_normal(int(900 * fs))
    y = signal.lfilter(np.ravel(num), den, u)
    f_true, h_true = f0 / np.sqrt(1 - 2 * zeta**2), 1 / (2 * zeta * np.sqrt(1 - zeta**2))
    f_pk, h_pk = h1_peak(u, y, fs, nperseg=4 * SEGMENT)
    # within 0.05 Hz, a sixth of the half-power bandwidth: the top is flat to 2 % there, and the estimate's scatter
    # over its 21 segments picks the line (seeds 5-7: 7.275-7.300 Hz)
    assert f_pk == pytest.approx(f_true, abs=0.05) and h_pk == pytest.approx(h_true, rel=0.015)
    f_pk, h_pk = h1_peak(u, y, fs)
    assert f_pk == pytest.approx(f_true, abs=fs / SEGMENT) and 0.93 * h_true < h_pk < h_true
    code, _, err, tb = run_main(ident_main, ["bench", "f16", "--data", tmp_path])
    assert code == 2 and tb is None and "not the F-16 benchmark's folder" in err and err.count("\n") == 1, err
    code, _, err, tb = run_main(ident_main, ["bench", "memory", "--data", tmp_path])
    assert code == 2 and tb is None and "it is for ident bench f16" in err, err
