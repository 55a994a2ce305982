"""Bounded inputs: the issue's hanging and crashing inputs refused in one line, then a hypothesis fuzz of
config files and of every command's arguments that counts tracebacks (there must be none)."""

import argparse
import math
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from clitools import run_main
from daq.cli import build_parser as daq_parser
from daq.cli import main as daq_main
from daq.config import MAX_CONFIG_BYTES, load_config
from daq.lines import decoder_for
from daq.sim.device import SimulatedDevice
from ident.cli import parse_split
from ident.cli.main import build_parser as ident_parser
from ident.cli.main import main as ident_main
from replay.cli import build_parser as replay_parser
from replay.cli import main as replay_main

REC = Path(__file__).resolve().parents[1] / "recordings"
FUZZ_SETTINGS = settings(max_examples=300, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
TRACEBACKS = []


def one_line_refusal(code, err, tb, what):
    if tb is not None or "Traceback" in err:
        TRACEBACKS.append(f"{what}: {tb or err}")
    assert tb is None, (what, tb)
    assert code == 2, (what, code, err)
    assert len(err.strip().splitlines()) == 1, (what, err)


ALIAS_BOMB = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{chr(98 + i)}: &{chr(98 + i)} [*{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, "
    f"*{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}]\n" for i in range(8))


@pytest.mark.parametrize("text,match", [
    (ALIAS_BOMB, "aliases|anchors"),
    ("[" * 5000 + "]" * 5000, "nested deeper than 32"),
    ("daq: {reconnect_backoff_s: [-1]}", "daq.reconnect_backoff_s = -1.0 is out of range"),
    ("daq: {give_up_s: -1}", "daq.give_up_s = -1.0 is out of range"),
    ("sensors: {base: {range_m_per_s2: 0}}", "sensors.base.range_m_per_s2 = 0.0 is out of range"),
    ("sensors: {tip1: {adc_bits: 0}}", "sensors.tip1.adc_bits = 0 is out of range"),
    ("sensors: {tip1: {adc_bits: 64}}", "sensors.tip1.adc_bits = 64 is out of range"),
    ("daq: {calibration: {base: {scale_m_per_s2_per_count: 0}}}", "scale_m_per_s2_per_count = 0.0 is out of range"),
    ("daq: {rate_hz: 1e-300}", "daq.rate_hz"),
    ("daq: {rate_hz: .inf}", "daq.rate_hz = inf is not finite"),
    ("rig: {beam1: {mass_kg: 1e400}}", "rig.beam1.mass_kg = inf is not finite"),
    ("excitation: {kicks: [" + ", ".join(["{t_s: 1}"] * 1001) + "]}", "at most 1000"),
])
def test_configs_that_hung_or_crashed_are_refused_in_one_line(tmp_path, text, match):
    cfg = tmp_path / "bad.yaml"
    cfg.write_text(text)
    t0 = time.monotonic()
    code, out, err, tb = run_main(daq_main, ["record", "--sim", "--config", cfg, "--duration", "1",
                                             "-o", tmp_path / "x.mcap"])
    one_line_refusal(code, err, tb, text[:30])
    assert match.split("|")[0] in err or match.split("|")[-1] in err, err
    assert time.monotonic() - t0 < 10  # refused, not expanded (the alias bomb took 88 s to a MemoryError)
    assert not (tmp_path / "x.mcap").exists()


def test_a_config_over_a_mebibyte_is_refused_before_it_is_read(tmp_path):
    cfg = tmp_path / "big.yaml"
    cfg.write_text("# " + "x" * MAX_CONFIG_BYTES + "\n")
    with pytest.raises(ValueError, match=f"at most {MAX_CONFIG_BYTES} bytes"):
        load_config(cfg)
    with pytest.raises(ValueError, match="not a regular file"):
        load_config("/dev/zero")  # would never end
    assert load_config(None).daq.rate_hz == 2000.0


@pytest.mark.parametrize("main,argv", [
    (daq_main, ["record", "--sim", "--duration", "inf"]),  # hung: the device thread died with OverflowError
    (daq_main, ["record", "--sim", "--duration", "nan"]),
    (daq_main, ["record", "--sim", "--duration", "-1"]),
    (daq_main, ["record", "--sim", "--window", "0"]),
    (daq_main, ["record", "--sim", "--window", "2", "--hop", "3"]),
    (daq_main, ["record", "--sim", "--regime-window", "0.1"]),  # shorter than the monitor's hop
    (replay_main, ["{rec}", "--regime-window", "0"]),
    (ident_main, ["batch", "{rec}", "--regimes", "--regime-window", "0.2", "-o", "r.csv"]),
    (daq_main, ["bench", "--regimes", "--regime-window", "0.2"]),
    (daq_main, ["sim", "--duration", "1e400"]),
    (daq_main, ["sim", "--seed", "-4"]),
    (daq_main, ["record", "--sim", "--gaps", "0.003"]),  # two gaps, tip 1 and tip 2
    (daq_main, ["record", "--sim", "--gaps", "0.003,nan"]),
    (daq_main, ["record", "--sim", "--gaps", "0.003,-1"]),
    (daq_main, ["bench", "--regimes", "--cases", "0"]),
    (daq_main, ["bench", "--regimes", "--minutes", "inf"]),
    (replay_main, ["{rec}", "--gaps", "a,b"]),
    (replay_main, ["{rec}", "--rate", "1e-300"]),  # was a traceback
    (replay_main, ["{rec}", "--rate", "inf"]),
    (replay_main, ["{rec}", "--start", "nan"]),
    (replay_main, ["{rec}", "--fs", "0"]),
    (ident_main, ["fit", "{rec}", "--degree", "99"]),
    (ident_main, ["fit", "{rec}", "--start", "-inf"]),
    (ident_main, ["duffing", "--seed", "1e3"]),
])
def test_arguments_out_of_range_are_one_line(main, argv):
    code, out, err, tb = run_main(main, [a.format(rec=REC / "linear.mcap") for a in argv])
    one_line_refusal(code, err, tb, " ".join(argv))


def test_overlapping_train_and_test_are_refused():
    assert parse_split("0:600", "600:1000", 1000) == (slice(0, 600), slice(600, 1000))
    assert parse_split(None, "600:", 1000) == (None, slice(600, 1000))
    for train, test in (("0:700", "600:1000"), (":", "500:700"), ("-400:", "0:700"), ("100:900", "200:300")):
        with pytest.raises(ValueError, match="overlap"):
            parse_split(train, test, 1000)


# ---------------------------------------------------------------------------------------------- fuzz

NUMBERS = st.one_of(st.sampled_from(["inf", "-inf", "nan", "1e400", "1e-300", "-1", "0", "", "abc", "1e308", "0x10",
                                     "3", "0.5", "65536", "-0", "1_000"]),
                    st.floats(allow_nan=True, allow_infinity=True).map(repr),
                    st.integers(-2**70, 2**70).map(str))

VALUES = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-2**80, 2**80), st.floats(allow_nan=True, allow_infinity=True),
              st.text(max_size=8)),
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=6), inner, max_size=3)),
    max_leaves=8)

KEYS = {
    "daq": ["rate_hz", "baudrate", "flush_s", "reconnect_backoff_s", "give_up_s", "calibration", "faults", "format", "lines"],
    "daq.lines": ["delimiter", "columns", "base", "tip1", "tip2", "counter", "time", "clipped", "time_unit_s",
                  "time_wrap", "counter_bits", "max_line_bytes"],
    "daq.faults": ["corrupt_byte_rate", "drop_byte_rate", "garbage_bursts_per_s", "garbage_burst_bytes",
                   "drop_frame_rate", "duplicate_frame_rate", "clock_drift_ppm", "disconnect_at_s", "disconnect_for_s",
                   "restart_at_s", "restart_for_s"],
    "daq.calibration.base": ["scale_m_per_s2_per_count", "offset_m_per_s2", "sensitivity_counts_per_m_per_s2",
                             "sensitivity_mv_per_g", "adc_mv_per_count", "sensor_model", "serial_number", "calibrated"],
    "sensors.tip1": ["gain", "offset_m_per_s2", "noise_rms_m_per_s2", "range_m_per_s2", "adc_bits"],
    "excitation": ["frequency_hz", "amplitude_m_per_s2", "ramp_s", "steps", "kicks", "sweep", "noise_rms_m_per_s2",
                   "noise_band_hz", "seed"],
    "rig.beam1": ["mass_kg", "natural_frequency_hz", "damping_ratio", "gap_pos_m", "gap_neg_m",
                  "stopper_stiffness_n_per_m", "cubic_stiffness_n_per_m3", "coulomb_friction_n"],
    "": ["substeps", "seed", "rig", "sensors", "daq", "excitation"],
}


@st.composite
def configs(draw):
    data: dict = {}
    for _ in range(draw(st.integers(1, 5))):
        section = draw(st.sampled_from(sorted(KEYS)))
        key = draw(st.sampled_from(KEYS[section]))
        node = data
        for part in filter(None, section.split(".")):
            node = node.setdefault(part, {}) if isinstance(node.get(part, {}), dict) else {}
        node[key] = draw(VALUES)
    return data


@FUZZ_SETTINGS
@given(configs())
def test_fuzz_configs_never_traceback(tmp_path_factory, data):
    """Any config is a Config (and the simulated device then runs on it) or a one-line ValueError."""
    cfg = tmp_path_factory.mktemp("cfg") / "fuzz.yaml"
    cfg.write_text(yaml.safe_dump(data))
    try:
        config = load_config(cfg)
    except ValueError as exc:
        assert "\n" not in str(exc)
        return
    except Exception as exc:  # noqa: BLE001
        TRACEBACKS.append(f"config {data}: {type(exc).__name__}: {exc}")
        raise
    with np.errstate(all="ignore"):
        dec = decoder_for(config.daq)  # binary frames or text lines, as the config says
        dec.feed(SimulatedDevice(config, seed=1).frames(40))
    assert dec.counters.frames + dec.counters.crc_errors > 0 or config.daq.faults.drop_frame_rate > 0


@FUZZ_SETTINGS
@given(st.text(max_size=300))
def test_fuzz_config_text_never_tracebacks(tmp_path_factory, text):
    cfg = tmp_path_factory.mktemp("cfg") / "text.yaml"
    cfg.write_bytes(text.encode("utf-8", "surrogatepass"))  # lone surrogates make bytes that are not UTF-8
    try:
        load_config(cfg)
    except ValueError as exc:
        assert "\n" not in str(exc)
    except Exception as exc:  # noqa: BLE001
        TRACEBACKS.append(f"config text {text!r}: {type(exc).__name__}: {exc}")
        raise


NUMERIC_OPTIONS = [
    (daq_parser, ["record", "--sim"], ["--duration", "--window", "--hop", "--baud", "--regime-window"]),
    (daq_parser, ["calibrate", "--channel", "tip1"], ["--duration", "--reference-rms", "--reference-hz", "--baud"]),
    (daq_parser, ["sim"], ["--duration", "--seed", "--device-id"]),
    (daq_parser, ["bench"], ["--seconds", "--cases", "--seed", "--minutes"]),
    (replay_parser, ["play", "x.mcap"], ["--rate", "--start", "--duration", "--window", "--hop", "--fs",
                                         "--regime-window"]),
    (replay_parser, ["import", "x.csv", "-o", "y.mcap"], ["--fs"]),
    (ident_parser, ["fit", "x.mcap"], ["--start", "--duration", "--degree", "--dimension", "--delay", "--fs"]),
    (ident_parser, ["duffing"], ["--seed", "--workers"]),
    (ident_parser, ["batch", "x.mcap", "--fit", "-o", "r.csv"], ["--start", "--duration", "--fs", "--workers",
                                                                 "--regime-window"]),
    (ident_parser, ["bench", "batch"], ["--duration", "--recordings", "--seed", "--cases", "--workers"]),
]


@FUZZ_SETTINGS
@given(st.sampled_from(range(len(NUMERIC_OPTIONS))), st.data())
def test_fuzz_numeric_options_are_checked_when_parsed(which, data):
    """Every numeric option: a finite value in range, or exit 2 with one line."""
    build, base, options = NUMERIC_OPTIONS[which]
    argv = list(base)
    for opt in data.draw(st.lists(st.sampled_from(options), min_size=1, max_size=3, unique=True)):
        argv += [opt, data.draw(NUMBERS)]

    def parse(args):
        ns = build().parse_args(args)
        for opt in options:
            v = getattr(ns, {"--fs": "fs_hz"}.get(opt, opt.lstrip("-").replace("-", "_")))
            for x in v if isinstance(v, list) else [v]:
                assert x is None or math.isfinite(x), (args, x)
        return 0

    code, out, err, tb = run_main(parse, argv)
    if tb:
        TRACEBACKS.append(f"{argv}: {tb}")
    assert tb is None and code in (0, 2), (argv, code, err)
    if code == 2:
        assert len(err.strip().splitlines()) == 1


@FUZZ_SETTINGS
@given(st.lists(st.tuples(st.sampled_from(["--start", "--duration", "--window", "--hop", "--fs", "--rate"]), NUMBERS),
                max_size=3, unique_by=lambda x: x[0]))
def test_fuzz_replay_runs_never_traceback(tmp_path_factory, opts):
    """The whole replay command on a short CSV with fuzzed numbers: it plays, or refuses in one line."""
    folder = tmp_path_factory.mktemp("play")
    csv = folder / "short.csv"
    if not csv.exists():
        rng = np.random.default_rng(0)
        np.savetxt(csv, rng.standard_normal((3000, 3)), delimiter=",", header="base,tip1,tip2", comments="")
    argv = [csv, "--no-identify", "--viewer", "none"]
    for opt, val in opts:
        argv += [opt, val]
    if "--rate" not in dict(opts):
        argv.append("--max")
    elif "--duration" not in dict(opts):
        argv += ["--duration", "0.01"]  # paced playback: keep it short
    if "--fs" not in dict(opts):
        argv += ["--fs", "2000"]
    code, out, err, tb = run_main(replay_main, argv)
    if tb:
        TRACEBACKS.append(f"replay {argv}: {tb}")
    assert tb is None and code in (0, 2), (argv, code, err)
    if code == 2:
        assert len(err.strip().splitlines()) == 1, err


def test_zz_fuzz_tally():
    """Runs after the fuzz tests of this module: the count the issue asks for."""
    print(f"\nfuzz of configs and arguments: {len(TRACEBACKS)} tracebacks")
    assert TRACEBACKS == []


def test_the_regime_window_option_starts_at_the_monitors_hop():
    """One range for --regime-window in record, replay, batch and the bench: from the monitor's hop."""
    from ident.cli import REGIME_WINDOW
    from ident.live.regimes import RegimeConfig

    assert REGIME_WINDOW(str(RegimeConfig.hop_s)) == RegimeConfig.hop_s
    with pytest.raises(argparse.ArgumentTypeError):
        REGIME_WINDOW(str(0.99 * RegimeConfig.hop_s))
