"""Calibration: the sine fit against analytic signals, the config's sensitivities, ``daq calibrate`` end to end on
the simulated calibrator (its sensor's gain known, so the sensitivity is known analytically), and the
calibration in a recording's metadata."""

import math

import numpy as np
import pytest
import yaml

from clitools import run_main
from daq.calibration import calibrated_mapping, check_line, fit_sine, sensitivity
from daq.cli import main as daq_main
from daq.config import G_M_PER_S2, load_config, parse_config
from replay.cli import main as replay_main
from replay.formats.mcap import read_recording

FS = 2000.0
LSB = 2 * 160.0 / 2**16  # the simulated sensor's ADC step: +-160 m/s^2 over 16 bits


def calibrator_counts(s_counts_per_ms2, f_hz, n, offset_counts, noise_counts, seed=0, phase=0.7):
    """10 m/s^2 rms at f_hz seen by a channel of known sensitivity: counts, quantised to integers."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / FS
    x = s_counts_per_ms2 * 10.0 * math.sqrt(2) * np.cos(2 * math.pi * f_hz * t + phase) + offset_counts
    return np.rint(x + noise_counts * rng.standard_normal(n))


@pytest.mark.parametrize("f_hz", [159.2, 159.05, 160.1])  # the calibrator on frequency, 0.1 % low, 0.6 % high
def test_sine_fit_recovers_the_analytic_sensitivity(f_hz):
    s_true, offset, noise, n = 123.4, -812.0, 40.0, 20_000  # noise 40 counts rms against a 1,234-count rms line
    fit = fit_sine(calibrator_counts(s_true, f_hz, n, offset, noise), FS)
    sigma = math.sqrt(noise**2 + 1 / 12)  # the noise and the quantisation
    assert fit.frequency_hz == pytest.approx(f_hz, abs=2e-4)
    assert fit.residual_rms == pytest.approx(sigma, rel=0.02)
    # least squares: the amplitude's standard error is sigma sqrt(2 / n): here 0.036 % of the amplitude
    assert abs(sensitivity(fit) - s_true) < 4 * sigma * math.sqrt(2 / n) / (10 * math.sqrt(2))
    assert fit.amplitude_std == pytest.approx(sigma * math.sqrt(2 / n), rel=0.03)
    assert fit.offset == pytest.approx(offset, abs=4 * sigma / math.sqrt(n))
    assert fit.phase_rad == pytest.approx(0.7, abs=1e-3)


def test_sine_fit_refuses_what_is_not_a_calibrator():
    t = np.arange(20_000) / FS
    shaker = 50 * np.sin(2 * math.pi * 12.3 * t) + np.random.default_rng(1).standard_normal(t.size)
    with pytest.raises(ValueError, match=r"no line between 151.2 and 167.2 Hz \(the strongest is at 12.3 Hz\)"):
        fit_sine(shaker, FS)
    with pytest.raises(ValueError, match="fewer than 20 periods"):
        fit_sine(shaker[:200], FS)
    with pytest.raises(ValueError, match="above the Nyquist"):
        fit_sine(shaker, 300.0)
    weak = calibrator_counts(1.0, 159.2, 20_000, 0.0, 30.0)  # a line 6.5 dB under the noise
    with pytest.raises(ValueError, match="dB above the rest"):
        check_line(fit_sine(weak, FS))


def test_config_sensitivities_resolve_to_the_scale():
    cfg = parse_config({"daq": {"calibration": {
        "base": {"sensitivity_mv_per_g": 100.0, "adc_mv_per_count": 3300 / 4096},
        "tip1": {"sensitivity_counts_per_m_per_s2": 215.04, "offset_m_per_s2": -0.3},
        "tip2": {"scale_m_per_s2_per_count": 0.01, "sensor_model": "ADXL1002", "serial_number": "A7"}}}}, "x")
    scales, offsets = cfg.scales()
    # 100 mV/g into 0.806 mV per count: 124.1 counts per g, 12.66 counts per m/s^2
    assert scales == pytest.approx([3300 / 4096 / 100 * G_M_PER_S2, 1 / 215.04, 0.01], rel=1e-12)
    assert offsets == [0.0, -0.3, 0.0]
    meta = cfg.calibration_metadata()
    assert meta["tip2.sensor_model"] == "ADXL1002" and meta["tip2.serial_number"] == "A7"
    assert meta["base.scale_from"] == "sensitivity_mv_per_g" and meta["tip1.sensitivity_counts_per_m_per_s2"] == "215.04"
    for bad, match in [({"scale_m_per_s2_per_count": 1, "sensitivity_counts_per_m_per_s2": 2}, "not both"),
                       ({"sensitivity_mv_per_g": 100}, "go together"), ({"sensitivity_mv_per_g": -1}, "out of range")]:
        with pytest.raises(ValueError, match=match):
            parse_config({"daq": {"calibration": {"tip1": bad}}}, "x")


def test_calibrated_mapping_keeps_the_rest_and_one_scale_source():
    data = {"rig": {"beam1": {"mass_kg": 0.04}}, "daq": {"rate_hz": 2000.0, "calibration": {
        "tip1": {"scale_m_per_s2_per_count": 0.005, "sensor_model": "old", "offset_m_per_s2": 0.1},
        "tip2": {"scale_m_per_s2_per_count": 0.002}}}}
    new = calibrated_mapping(data, "tip1", 200.0, "note", serial="S1")
    assert new["rig"] == data["rig"] and new["daq"]["rate_hz"] == 2000.0
    assert new["daq"]["calibration"]["tip2"] == {"scale_m_per_s2_per_count": 0.002}
    assert new["daq"]["calibration"]["tip1"] == {"sensor_model": "old", "offset_m_per_s2": 0.1, "serial_number": "S1",
                                                 "sensitivity_counts_per_m_per_s2": 200.0, "calibrated": "note"}
    assert data["daq"]["calibration"]["tip1"]["scale_m_per_s2_per_count"] == 0.005  # the input is not changed


def test_daq_calibrate_end_to_end(tmp_path):
    """The simulated calibrator on tip1, whose sensor reads 5 % high with a 0.3 m/s^2 offset and noise: the
    sensitivity written is gain / ADC step = 215.04 counts per m/s^2, the offset -0.3 / 1.05; then tip2 in
    place over rig:// with --force; the calibrated config's sensors appear in a recording and in replay info."""
    start = tmp_path / "rig.yaml"
    start.write_text("# my rig\nsensors:\n  tip1: {gain: 1.05, offset_m_per_s2: 0.3, noise_rms_m_per_s2: 0.05}\n")
    cal = tmp_path / "rig-cal.yaml"
    code, out, err, tb = run_main(daq_main, ["calibrate", "--channel", "tip1", "--config", start, "-o", cal,
                                             "--duration", "2", "--set-offset", "--sensor-model", "PCB 352C33",
                                             "--serial-number", "LW123"])
    assert code == 0 and tb is None, err
    c1 = load_config(cal).daq.calibration.tip1
    assert c1.sensitivity_counts_per_m_per_s2 == pytest.approx(1.05 / LSB, rel=5e-4)  # 215.04
    assert c1.offset_m_per_s2 == pytest.approx(-0.3 / 1.05, abs=0.005)
    assert (c1.sensor_model, c1.serial_number) == ("PCB 352C33", "LW123") and "159.2" in c1.calibrated
    assert start.read_text().startswith("# my rig")  # the input is untouched
    assert load_config(cal).rig.sensors.tip1.gain == 1.05  # the rest of the file kept
    # in place: refused without --force, and nothing changes
    before = cal.read_bytes()
    url = f"rig://?config={cal}&calibrator=tip2"
    code, out, err, tb = run_main(daq_main, ["calibrate", "--port", url, "--channel", "tip2", "--config", cal,
                                             "--duration", "2"])
    assert code == 2 and tb is None and "give --force" in err and cal.read_bytes() == before
    # a channel without a calibrator on it: refused in one line, nothing written
    code, out, err, tb = run_main(daq_main, ["calibrate", "--port", url, "--channel", "base", "--config", cal,
                                             "--force", "--duration", "2"])
    assert code == 2 and tb is None and "no line between" in err and cal.read_bytes() == before
    rec = tmp_path / "cal-run.mcap"
    code, out, err, tb = run_main(daq_main, ["calibrate", "--port", url, "--channel", "tip2", "--config", cal,
                                             "--force", "--duration", "2", "--recording", rec])
    assert code == 0 and tb is None, err
    cfg = load_config(cal)
    assert cfg.daq.calibration.tip2.sensitivity_counts_per_m_per_s2 == pytest.approx(1 / LSB, rel=5e-4)  # 204.8
    assert cfg.daq.calibration.tip1 == c1  # kept as it was
    assert len(read_recording(rec).seq) == 4000
    out_rec = tmp_path / "after.mcap"
    code, out, err, tb = run_main(daq_main, ["record", "--port", f"rig://?config={cal}", "--config", cal, "--duration",
                                             "1", "-o", out_rec, "--quiet", "--no-identify"])
    assert code == 0, err
    meta = read_recording(out_rec).metadata["calibration"]
    assert meta["tip1.sensor_model"] == "PCB 352C33" and meta["tip1.serial_number"] == "LW123"
    assert float(meta["tip1.scale_m_per_s2_per_count"]) == pytest.approx(LSB / 1.05, rel=5e-4)
    code, info, err, _ = run_main(replay_main, ["info", out_rec])
    assert "sensor     tip1: PCB 352C33, SN LW123;" in info and "from sensitivity_counts_per_m_per_s2" in info
    assert yaml.safe_load(read_recording(out_rec).config_yaml)["daq"]["calibration"]["tip1"]["serial_number"] == "LW123"


@pytest.mark.parametrize("argv,match", [
    (["calibrate", "--channel", "tip1", "--duration", "1"], "give -o NEW.yaml"),
    (["calibrate", "--channel", "tip9", "-o", "x.yaml"], "invalid choice"),
    (["calibrate", "--channel", "tip1", "-o", "x.yaml", "--reference-rms", "0"], "out of range"),
    (["calibrate", "--channel", "tip1", "-o", "x.yaml", "--reference-hz", "nan"], "not a finite number"),
])
def test_bad_calibrate_arguments_are_one_line(tmp_path, argv, match):
    code, out, err, tb = run_main(daq_main, argv)
    assert code == 2 and tb is None and len(err.strip().splitlines()) == 1 and match in err, err
