"""daq record end to end over a real pty; MCAP read back by independent readers; faults."""

import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest
import serial
import yaml

from clitools import run_main
from daq.cli import main as daq_main
from daq.config import load_config
from daq.driver import Acquisition, ClockEstimator
from daq.protocol import Decoder
from daq.transport import register_url_handler
from replay.formats.mcap import read_recording


def cli(*args, timeout=120, **kw):
    return subprocess.run([sys.executable, "-m", *args], capture_output=True, text=True, timeout=timeout, **kw)


def rerun_cli(*args):
    exe = os.path.join(os.path.dirname(sys.executable), "rerun")
    return subprocess.run([exe, *args], capture_output=True, text=True, timeout=120)


@pytest.fixture(scope="module")
def ten_seconds(tmp_path_factory):
    out = tmp_path_factory.mktemp("rec") / "sim10.mcap"
    proc = cli("daq", "record", "--sim", "--duration", "10", "-o", str(out), "--quiet")
    assert proc.returncode == 0, proc.stderr
    return out, proc


def test_sample_count_no_drops_monotonic(ten_seconds):
    out, _ = ten_seconds
    rec = read_recording(out)
    assert abs(len(rec.seq) - 2000 * 10) <= 1
    assert np.all(np.diff(rec.seq) == 1)  # no drops
    assert np.all(np.diff(rec.t_device) > 0)
    assert rec.rate_hz == pytest.approx(2000.0, rel=1e-6)
    assert not [e for e in rec.events if e["kind"] in ("drop", "crc", "disconnect")]
    assert rec.status[-1]["dropped_frames"] == 0 and rec.status[-1]["crc_errors"] == 0
    cfg = yaml.safe_load(rec.config_yaml)
    assert cfg["daq"]["rate_hz"] == 2000.0 and "beam1" in cfg["rig"]


def test_independent_reader_rerun_mcap(ten_seconds):
    out, _ = ten_seconds
    info = rerun_cli("mcap", "info", str(out))
    assert info.returncode == 0, info.stderr
    assert not any("/rig/accel" in ln for ln in info.stdout.splitlines())  # the samples are the serial bytes
    line = next(ln for ln in info.stdout.splitlines() if "/rig/raw" in ln)
    from mcap.reader import make_reader

    with open(out, "rb") as fh:
        n_raw = sum(1 for _ in make_reader(fh).iter_messages(topics=["/rig/raw"]))
    assert int(line.split()[2]) == n_raw > 0
    check = rerun_cli("mcap", "check", str(out))
    assert check.returncode == 0, check.stdout + check.stderr


def test_at_most_40_bytes_per_sample(ten_seconds):
    out, proc = ten_seconds
    rec = read_recording(out, raw=False)
    assert out.stat().st_size / len(rec.seq) <= 40
    assert f"{out.stat().st_size / len(rec.seq):.1f} bytes per 3-channel sample" in proc.stdout


def test_models_are_stamped_with_their_data_time(ten_seconds):
    """/rig/model: log_time is the device time of the window's last sample (as the samples' log times),
    publish_time when it was computed; each record carries its uncertainty and backbone point."""
    out, _ = ten_seconds
    from mcap.reader import make_reader

    rec = read_recording(out, raw=False)
    with open(out, "rb") as fh:
        msgs = [(m.log_time, m.publish_time) for _, _, m in make_reader(fh).iter_messages(topics=["/rig/model"])]
    assert len(rec.models) == len(msgs) >= 10
    for m, (log_ns, pub_ns) in zip(rec.models, msgs):
        k = int(round(m["t"] * 2000)) - 1  # the window's last sample
        assert log_ns == rec.log_time_ns[k]
        # computed after its data arrived: log_time is the device timeline anchored to the host clock at the
        # first read, so it may lead the host clock by that read's jitter (a fraction of a millisecond seen)
        assert pub_ns >= log_ns - 5_000_000
        assert set(m["coefficient_std"]["v'"]) >= set(m["coefficients"]["v'"])
        assert all(0 <= p <= 1 for eq in m["inclusion_probability"].values() for p in eq.values())
        assert m["amplitude_m"] > 0 and m["natural_frequency_hz"] > 0


def test_rig_url_handler_in_process():
    register_url_handler()
    port = serial.serial_for_url("rig://?seed=4&device_id=0x1234", timeout=0.1)
    dec = Decoder()
    fr = dec.feed(port.read(36 + 24 * 500))  # the status frame at boot, then 500 samples
    assert len(fr) == 500 and dec.counters.crc_errors == 0 and dec.counters.skipped_bytes == 0
    assert fr.seq.tolist() == list(range(500))
    assert len(fr.status) == 1 and fr.status[0].device_id == 0x1234 and fr.status[0].rate_hz == 2000.0
    with pytest.raises(serial.SerialException, match="no option"):
        serial.serial_for_url("rig://?bogus=1")


def test_disconnect_and_reconnect_mid_recording(tmp_path):
    cfg = tmp_path / "rig.yaml"
    cfg.write_text("daq:\n  faults:\n    disconnect_at_s: [3.0]\n    disconnect_for_s: 1.0\n")
    out = tmp_path / "dis.mcap"
    proc = cli("daq", "record", "--sim", "--config", str(cfg), "--duration", "8", "-o", str(out), "--quiet")
    assert proc.returncode == 0, proc.stderr
    rec = read_recording(out)
    kinds = [e["kind"] for e in rec.events]
    assert "disconnect" in kinds and "reconnect" in kinds
    gap = next(e for e in rec.events if e["kind"] == "reconnect")["gap_s"]
    assert 0.9 < gap < 3.0
    jumps = np.diff(rec.seq)
    assert np.count_nonzero(jumps != 1) >= 1  # the hole shows as a sequence gap...
    lost = int(np.sum(jumps[jumps > 1] - 1))
    assert 0.8 * 2000 < lost < 3.0 * 2000  # ...of about the disconnect's length
    assert any(e["kind"] == "drop" for e in rec.events)
    assert rerun_cli("mcap", "check", str(out)).returncode == 0


def test_a_device_that_does_not_come_back_ends_the_recording_and_keeps_what_came_before(tmp_path):
    """--duration counts seconds of samples: a device gone for good (here for 60 s, from 2 s on) had kept the
    recording waiting until Ctrl-C. After ``daq.give_up_s`` it ends, in one line and exit code 2, with the
    2 s received before the loss intact in a recording an independent reader checks."""
    cfg = tmp_path / "rig.yaml"
    cfg.write_text("daq:\n  give_up_s: 1.0\n  faults:\n    disconnect_at_s: [2.0]\n    disconnect_for_s: 60.0\n")
    out = tmp_path / "gone.mcap"
    t0 = time.monotonic()
    proc = cli("daq", "record", "--sim", "--config", str(cfg), "--duration", "8", "-o", str(out), "--quiet",
               "--no-identify", timeout=60)
    assert time.monotonic() - t0 < 40  # not the device's 60 s: it gave up
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr and len(proc.stderr.strip().splitlines()) == 1
    assert "did not come back within 1 s" in proc.stderr and f"what came before is kept in {out}" in proc.stderr
    rec = read_recording(out)
    assert 1.5 * 2000 < rec.seq.size <= 2.2 * 2000  # the 2 s before the loss
    assert np.all(np.diff(rec.seq) == 1)
    kinds = [e["kind"] for e in rec.events]
    assert kinds.index("disconnect") < kinds.index("give_up") and "reconnect" not in kinds
    assert rerun_cli("mcap", "check", str(out)).returncode == 0


def test_a_silent_port_ends_the_recording_after_give_up_s(tmp_path):
    """A port that opens and never sends (a device that hung, the wrong adapter): the recording ends after
    ``daq.give_up_s`` in one line, with an empty but complete recording."""
    master, slave = os.openpty()
    path = os.ttyname(slave)
    try:
        cfg = tmp_path / "rig.yaml"
        cfg.write_text("daq:\n  give_up_s: 1.5\n")
        out = tmp_path / "silent.mcap"
        t0 = time.monotonic()
        proc = cli("daq", "record", "--port", path, "--config", str(cfg), "--duration", "5", "-o",
                   str(out), "--quiet", "--no-identify", timeout=60)
        waited = time.monotonic() - t0
    finally:
        os.close(master)
        os.close(slave)
    assert proc.returncode == 2, proc.stderr
    assert f"nothing arrived from {path} for 1.5 s" in proc.stderr and len(proc.stderr.splitlines()) == 1
    assert waited < 30
    rec = read_recording(out)
    assert rec.seq.size == 0 and any(e["kind"] == "give_up" for e in rec.events)


def test_give_up_s_0_waits_for_a_silent_port_until_stopped(tmp_path):
    """``give_up_s: 0`` is the unattended run that outlasts any outage: silence past every bound the tests use
    stops nothing, and stop() (Ctrl-C's path) ends it without an error."""
    master, slave = os.openpty()
    try:
        cfg = tmp_path / "rig.yaml"
        cfg.write_text("daq:\n  give_up_s: 0\n")
        acq = Acquisition(os.ttyname(slave), load_config(cfg))
        run = threading.Thread(target=acq.run, args=(5.0,))
        run.start()
        time.sleep(2.0)
        assert run.is_alive() and acq.error is None
        acq.stop()
        run.join(timeout=10)
        assert not run.is_alive() and acq.error is None and acq.samples == 0
    finally:
        os.close(master)
        os.close(slave)


def test_kill_9_then_recover_loses_at_most_one_second(tmp_path):
    out = tmp_path / "killed.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "daq", "record", "--sim", "-o", str(out)],
                            stderr=subprocess.PIPE, stdout=subprocess.DEVNULL)
    reported = 0
    buf = b""
    deadline = time.time() + 60
    while reported < 8000 and time.time() < deadline:
        ch = os.read(proc.stderr.fileno(), 256)
        if not ch:
            break
        buf += ch
        parts = buf.replace(b"\r", b"\n").split(b"\n")
        for p in parts:
            tok = p.split()
            if tok and tok[0].isdigit() and len(tok) > 1 and tok[1] == b"samples":
                reported = max(reported, int(tok[0]))
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=10)
    assert reported >= 8000
    part = tmp_path / "killed.mcap.part"
    assert not out.exists() and part.exists()  # never a half-written killed.mcap: the data is in the .part
    with pytest.raises(ValueError, match="cut short.*replay recover"):
        read_recording(part)
    fixed = tmp_path / "fixed.mcap"
    r = cli("replay", "recover", str(part), "-o", str(fixed))
    assert r.returncode == 0, r.stderr
    rec = read_recording(fixed)
    assert len(rec.seq) >= reported - 2000  # at most the last second (2000 samples) lost
    assert np.all(np.diff(rec.seq) == 1)
    assert rerun_cli("mcap", "check", str(fixed)).returncode == 0


def test_sigterm_finishes_the_file(tmp_path):
    out = tmp_path / "term.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "daq", "record", "--sim", "-o", str(out), "--quiet"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    part = tmp_path / "term.mcap.part"
    deadline = time.monotonic() + 120  # kernels compile before the port opens: slow on a cold cache
    while not part.exists() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.1)
    assert part.exists(), proc.stderr.read() if proc.poll() is not None else "no .part within 120 s"
    time.sleep(3)  # about 6,000 samples recorded
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(timeout=20) == 0
    rec = read_recording(out)  # readable without recovery: summary and footer written
    assert len(rec.seq) > 2000


@pytest.mark.parametrize("text,match", [
    (None, "config file not found"),
    ("rig: {beam1: {mass_kg: heavy}}", "rig.beam1.mass_kg must be a number"),
    ("rig: {beam1: {mass_kg: nan}}", "rig.beam1.mass_kg must be a number"),
    ("rig: {beam3: {}}", "unknown key 'rig.beam3'"),
    ("rigg: {beam1: {}}", "unknown key 'rigg'; allowed: rig, excitation, sensors, substeps, seed, daq"),
    ("daq: {rate_hz: 1000}\ndaq: {rate_hz: 2000}", "key 'daq' given twice"),
    ("? [a, b]\n: 1\n", "not valid YAML"),  # an unhashable key (the duplicate check had raised a TypeError)
    ("daq: {rate_hz: -5}", "daq.rate_hz = -5.0 is out of range"),
    ("rig: [unclosed", "not valid YAML"),
])
def test_bad_config_is_one_line_naming_file_and_key(tmp_path, text, match):
    cfg = tmp_path / "bad.yaml"
    if text is not None:
        cfg.write_text(text)
    # through main() in this process (daq's entry point in a process of its own: test_safe_writes, a wrong port)
    code, _, err, tb = run_main(daq_main, ["record", "--sim", "--config", cfg, "--duration", "1", "-o",
                                           tmp_path / "x.mcap"])
    lines = err.strip().splitlines()
    assert tb is None and code == 2 and len(lines) == 1, (code, err, tb)
    assert str(cfg) in lines[0] and match in lines[0]
    assert not (tmp_path / "x.mcap").exists()


def test_clock_estimator_recovers_offset_and_drift():
    rng = np.random.default_rng(0)
    est = ClockEstimator()
    t_dev = np.linspace(0, 100, 2000)
    host = 5.0 + (1 + 150e-6) * t_dev + rng.uniform(0, 2e-4, t_dev.size)  # latency jitter
    for a, b in zip(t_dev, host):
        est.update(a, b)
    offset, ppm = est.estimate()
    assert ppm == pytest.approx(150, abs=3)
    assert offset == pytest.approx(5.0, abs=2e-5)  # the quickest reads' latency, not the mean's


def test_clock_estimator_holds_its_drift_when_a_busy_host_reads_late():
    # 3 s at 200 reads a second, the device 3000 ppm fast (-2991 ppm host seconds per device second);
    # reads are late by up to 0.5 ms, and for half a second of every second a busy host reads them late
    # by a latency that climbs to 40 ms: a line through the points follows the climb, the line under
    # them does not
    rng = np.random.default_rng(1)
    t_dev = np.arange(600) / 200.0
    busy = np.where((t_dev % 1.0) > 0.5, 0.08 * ((t_dev % 1.0) - 0.5), 0.0)
    host = 2.0 + t_dev / 1.003 + rng.uniform(0, 5e-4, t_dev.size) + busy
    est = ClockEstimator()
    for a, b in zip(t_dev, host):
        est.update(a, b)
    offset, ppm = est.estimate()
    expected = (1 / 1.003 - 1) * 1e6
    assert ppm == pytest.approx(expected, abs=30)
    assert offset == pytest.approx(2.0, abs=1e-4)
    slope = np.polyfit(t_dev, host, 1)[0]  # least squares: what the estimator used to say
    assert abs((slope - 1) * 1e6 - expected) > 500


@pytest.mark.parametrize("which", ["-o", "--config"])
def test_a_folder_where_a_file_belongs_is_named_as_one(tmp_path, which):
    # -o . had said "PosixPath('.') has an empty name", --config DIR "[Errno 21] Is a directory: 3"
    argv = ["record", "--sim", "--duration", "1"]
    argv += ["-o", "."] if which == "-o" else ["--config", tmp_path, "-o", tmp_path / "x.mcap"]
    code, _, err, tb = run_main(daq_main, argv)
    want = f"{tmp_path}: a folder; give a YAML config file" if which == "--config" else ". is a folder; give a file name"
    assert tb is None and code == 2 and err.strip() == f"daq record: error: {want}", err
    assert list(tmp_path.iterdir()) == []


def test_a_full_disk_stops_the_recording_in_one_line_that_says_where_the_samples_are(tmp_path):
    # a file-size limit stands in for a full disk (both are a write's OSError): the error had followed the status
    # line on its own line's end ("restartsdaq record: error: [Errno 27] File too large"), naming no file
    import resource

    def limited():
        # about 13 s of a 2 kHz recording; twice the largest file numba's cache writes when it compiles (274 kB)
        resource.setrlimit(resource.RLIMIT_FSIZE, (600_000, 600_000))

    out = tmp_path / "full.mcap"
    p = subprocess.run([sys.executable, "-m", "daq", "record", "--port", "rig://?seed=4", "--duration", "60", "-o",
                        str(out), "--no-identify"], preexec_fn=limited, capture_output=True, timeout=300, cwd=tmp_path)
    err = p.stderr.decode()
    assert p.returncode == 2 and "Traceback" not in err, err
    last = err.rstrip("\n").split("\n")[-1]  # (status lines end in \r; the error starts a line of its own)
    part = tmp_path / "full.mcap.part"
    assert last == (f"daq record: error: recording stopped: File too large; what came before is in {part}: recover "
                    f"it with `replay recover {part} -o {out}`"), err
    fixed = tmp_path / "fixed.mcap"
    assert subprocess.run([sys.executable, "-m", "replay", "recover", str(part), "-o", str(fixed)],
                          capture_output=True, timeout=120).returncode == 0
    assert len(read_recording(fixed).seq) > 10 * 2000  # the seconds before the limit
