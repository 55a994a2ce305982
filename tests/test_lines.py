"""Text-line devices (daq.lines): the decoder fed bytes, then the driver and recorder over a real pty at 2 kHz
with a writer thread that prints lines the way a sketch does (its own formatting, not daq.lines'), then
``daq record --format lines`` end to end on the simulated line device with a pulled cable."""

import os
import threading
import time
import tty

import numpy as np
import pytest
import yaml
from hypothesis import given, settings
from hypothesis import strategies as st

from clitools import run_main
from daq.cli import main as daq_main
from daq.config import load_config, parse_config
from daq.driver import Acquisition
from daq.lines import LineDecoder, LineFormat, decoder_for
from daq.recorder import McapRecorder
from replay.cli import main as replay_main
from replay.formats import read_samples
from replay.formats.mcap import read_recording

BAUD = 921_600
WIRE_BYTES_PER_S = BAUD / 10  # 8N1: ten bits on the wire per byte


def decode(fmt: LineFormat, data: bytes, rate=2000.0, pieces=None):
    dec = LineDecoder(fmt, rate)
    cuts = [0] + sorted(pieces or []) + [len(data)]
    frames = [dec.feed(data[a:b]) for a, b in zip(cuts[:-1], cuts[1:])] + [dec.flush()]
    cat = {k: np.concatenate([getattr(f, k) for f in frames]) for k in ("seq", "t_us", "counts", "flags", "restart")}
    return cat, dec.counters, dec


def test_header_names_map_columns_and_every_split_gives_the_same_samples():
    fmt = LineFormat(counter="n", time="us", base="b", tip1="t1", tip2="t2")
    text = b"99,1,2\r\nn,us,t2,b,t1\r\n" + b"".join(
        b"%d,%d,%d,%d,%d\r\n" % (k, 500 * k, -k, 2 * k, 3 * k) for k in range(200))
    whole, c, _ = decode(fmt, text)
    assert whole["seq"].tolist() == list(range(200)) and whole["t_us"].tolist() == [500 * k for k in range(200)]
    np.testing.assert_array_equal(whole["counts"], np.column_stack([2 * np.arange(200), 3 * np.arange(200),
                                                                    -np.arange(200)]))
    assert (c.frames, c.malformed_lines, c.text_lines, c.dropped_frames) == (200, 0, 1, 0)
    assert c.skipped_bytes == len(b"99,1,2\r\nn,us,t2,b,t1\r\n")  # the cut first line, the header
    rng = np.random.default_rng(0)
    for _ in range(50):
        cuts = rng.choice(np.arange(1, len(text)), int(rng.integers(1, 60)), replace=False).tolist()
        part, c2, _ = decode(fmt, text, pieces=cuts)
        assert all(np.array_equal(part[k], whole[k]) for k in whole)
        assert (c2.frames, c2.malformed_lines, c2.skipped_bytes) == (c.frames, c.malformed_lines, c.skipped_bytes)


@pytest.mark.parametrize("sep", [b",", b"\t", b" ", b"  \t ", b", "])
def test_comma_tab_and_space_separated_with_a_trailing_delimiter(sep):
    fmt = LineFormat()  # base, tip1, tip2 at positions 0, 1, 2; no counter, no time
    lines = [sep.join(b"%g" % v for v in (1.5 * k, -2e-3 * k, k)) + (sep if k % 2 and sep.strip() else b"")
             for k in range(10)]
    out, c, _ = decode(fmt, b"\n" + b"\r\n".join(lines) + b"\r\n")
    assert c.malformed_lines == 0 and len(out["seq"]) == 10
    np.testing.assert_allclose(out["counts"], [[1.5 * k, -2e-3 * k, k] for k in range(10)], rtol=1e-6)
    assert out["t_us"].tolist() == [500 * k for k in range(10)]  # the line's place at 2 kHz


def test_malformed_lines_are_counted_skipped_and_leave_their_gap():
    fmt = LineFormat()
    good = [b"%d,%d,%d" % (k, k, k) for k in range(20)]
    bad = {3: b"1,2", 7: b"1,2,3,4", 9: b"1,x,3", 12: b"1,nan,3", 14: b"\x00\xff\x10", 15: b"1,1e999,3",
           17: b"4,5," + b"6" * 300}
    lines = [b"3,3"] + [bad.get(k, g) for k, g in enumerate(good)] + [b"DEBUG: buffer overrun", b"19,19,19"]
    out, c, dec = decode(fmt, b"\n".join(lines) + b"\n")
    assert c.malformed_lines == len(bad) and c.text_lines == 1  # the message line is words, not a sample
    assert out["counts"][:, 0].tolist() == [k for k in range(20) if k not in bad] + [19]
    # without a counter the line's place is the sample clock: each unreadable line is one lost sample
    assert c.dropped_frames == len(bad)
    assert "longer than 256 bytes" in dec.last_problem


def test_counter_gaps_wraps_duplicates_and_restarts():
    fmt = LineFormat(counter=0, base=1, tip1=2, tip2=3, counter_bits=16)
    seq = [65530 + k for k in range(6)] + [65536 + 3, 65536 + 3, 65536 + 4, 65536 + 9, 2, 3]
    text = b"x\n" + b"".join(b"%d,1,2,3\n" % (s % 65536) for s in seq)
    out, c, _ = decode(fmt, text)
    assert (c.dropped_frames, c.duplicates, c.sequence_resets) == (3 + 4, 1, 1)  # 65536-65538 and 65541-65544 lost
    assert np.flatnonzero(out["restart"]).tolist() == [len(seq) - 3]  # counter 2 after 65545: the device rebooted
    assert out["t_us"][:3].tolist() == [65530 * 500, 65531 * 500, 65532 * 500]


def test_micros_wrap_is_not_a_restart_and_time_gaps_are_drops():
    fmt = LineFormat(time=0, base=1, tip1=2, tip2=3)
    t = [2**32 - 1000 + 500 * k for k in range(4)] + [2**32 + 2000, 2**32 + 2500]  # wraps; 2 lines lost
    out, c, _ = decode(fmt, b"cut\n" + b"".join(b"%d 1 2 3\n" % (v % 2**32) for v in t))
    assert (c.sequence_resets, c.dropped_frames) == (0, 2)
    assert np.diff(out["t_us"].astype(np.int64)).tolist() == [500, 500, 500, 1500, 500]


def test_a_reopened_port_drops_the_cut_line_and_moves_the_clock_on():
    dec = LineDecoder(LineFormat(), 2000.0)
    a = dec.feed(b"x\n1,1,1\n2,2,2\n3,3")  # "3,3" is cut by the pulled cable
    dec.reopened(0.5)  # 0.5 s later: 1,000 lines were printed meanwhile
    b = dec.feed(b",3\n4,4,4\n5,5,5\n")  # ",3" ends a line the host never saw start: skipped
    assert a.counts[:, 0].tolist() == [1, 2] and b.counts[:, 0].tolist() == [4, 5]
    assert b.seq.tolist() == [1 + 2 + 1000 + 1, 1 + 2 + 1000 + 2]  # 3 (cut), 1,000 printed while away, the cut ",3"
    assert dec.counters.dropped_frames == 1002 and dec.counters.malformed_lines == 0


@settings(max_examples=200, deadline=None, derandomize=True)
@given(st.lists(st.binary(max_size=120), max_size=8), st.sampled_from(["auto", "comma", "tab", "space"]))
def test_arbitrary_bytes_never_raise(chunks, delimiter):
    dec = LineDecoder(LineFormat(delimiter=delimiter, counter=3, time=4), 2000.0)
    for ch in chunks:
        dec.feed(ch)
        dec.feed(b"," + ch + b"\n")
    dec.flush()
    assert dec.counters.bytes_in == sum(2 * len(ch) + 2 for ch in chunks)


@pytest.mark.parametrize("text,match", [
    ("daq: {format: lines, lines: {base: 1.5}}", "daq.lines.base = 1.5"),
    ("daq: {format: lines, lines: {base: a, columns: [b, c]}}", "'a' is not among daq.lines.columns"),
    ("daq: {format: lines, lines: {counter: 1}}", "name the same column"),
    ("daq: {format: lines, lines: {time: 3, time_unit_s: 0.001}}", "coarser than half the sample period"),
    ("daq: {format: text}", "daq.format = 'text' is not allowed"),
    ("daq: {lines: {tip2: 'has space'}}", "give a column name"),
])
def test_bad_line_configs_are_one_line(tmp_path, text, match):
    cfg = tmp_path / "bad.yaml"
    cfg.write_text(text)
    code, out, err, tb = run_main(daq_main, ["record", "--sim", "--config", cfg, "--duration", "1", "-o",
                                             tmp_path / "x.mcap"])
    assert tb is None and code == 2 and len(err.strip().splitlines()) == 1 and match in err, err
    assert not (tmp_path / "x.mcap").exists()


# ----------------------------------------------------------------------------------------- real pty

def _value(k):
    """What the writer prints for line k: three int16-range numbers (independent of daq.lines)."""
    return (k * 7919) % 60001 - 30000, (k * 104729) % 50001 - 25000, -((k * 31) % 30001)


def _pty_config(tmp_path):
    cfg = tmp_path / "lines.yaml"
    cfg.write_text(yaml.safe_dump({"daq": {
        "format": "lines", "baudrate": BAUD, "rate_hz": 2000.0,
        "lines": {"counter": "seq", "time": "t_us", "base": "base", "tip1": "tip1", "tip2": "tip2"},
        "calibration": {c: {"scale_m_per_s2_per_count": 1.0} for c in ("base", "tip1", "tip2")}}}))
    return load_config(cfg)


def _runs(k):
    """Sorted integers as runs, ``a-b``."""
    cuts = np.flatnonzero(np.diff(k) != 1) + 1
    return ", ".join(f"{r[0]}-{r[-1]}" if r.size > 1 else f"{r[0]}" for r in np.split(k, cuts) if r.size)


def _pty():
    master, slave = os.openpty()
    tty.setraw(slave)
    return master, slave, os.ttyname(slave)


def test_a_line_device_at_2_khz_over_a_real_pty(tmp_path):
    """3 s of a sketch printing ``seq,t_us,base,tip1,tip2`` at 2 kHz (about 30 bytes a line: 60 kB/s, within
    a 921,600-baud line's 92 kB/s), paced against absolute deadlines: 17 lines never printed, 9 garbled, one
    printed twice, a message line. Recorded to MCAP through the driver and recorder of the binary path."""
    cfg = _pty_config(tmp_path)
    master, slave, path = _pty()
    lost = {101, 102, 103, 777, 1500, 2222, 2223, 2600, 3000, 3001, 3002, 3003, 3004, 4000, 4100, 4200, 4321}
    garbled = {50: b"50,25000,1,2\r\n", 300: b"300,150000,12,-x,4\r\n", 1200: b"\x13\x37garbage\x00,1,2,3,4,5\r\n",
               1800: b"1800,900000,3.5.1,2,3\r\n", 2500: b"2500,1250000,,2,3\r\n", 3500: b"3500;1750000;1;2;3\r\n",
               3600: b"3600,1800000,1,2,3,4\r\n", 4500: b"4500,2250000,1,2,3\r\n"[:9] + b"\r\n",
               4600: b"4600,2300000,nan,1,2\r\n"}
    opened, done = threading.Event(), threading.Event()
    written = {"bytes": 0, "t0": 0.0, "t1": 0.0}

    def line(k):
        if k in garbled:
            return garbled[k]
        return b"%d,%d,%d,%d,%d\r\n" % (k, 500 * k, *_value(k))

    def writer():
        opened.wait(10)
        out = [b"34,5\r\nseq,t_us,base,tip1,tip2\r\n"]  # the tail of a line printed before we listened; the header
        t0 = time.monotonic()
        written["t0"] = t0
        k = 0
        while k < 2000 * 3.3 and not done.is_set():
            due = int((time.monotonic() - t0) * 2000) + 1
            while k < due:
                if k not in lost:
                    out.append(line(k))
                if k == 2000:
                    out.append(line(k))  # a sample printed twice (a retried print)
                    out.append(b"WARN adc overrun\r\n")
                k += 1
            data = b"".join(out)
            try:
                sent = os.write(master, data)
            except BlockingIOError:  # the pty's buffer is full (the reader is behind, on a busy machine):
                sent = 0  # keep it for the next tick; breaking off here left the reader waiting forever
            written["bytes"] += sent
            written["t1"] = time.monotonic()
            out = [data[sent:]]  # what did not fit goes first at the next tick
            time.sleep(0.005 - (time.monotonic() - t0) % 0.005)  # next 5 ms tick on the absolute grid
        while out[0] and not done.is_set():  # a device goes on printing: what a full buffer held still goes out
            try:
                out = [out[0][os.write(master, out[0]):]]
            except BlockingIOError:
                time.sleep(0.005)

    blocks = []
    acq = Acquisition(path, cfg, on_block=blocks.append)
    rec = McapRecorder(tmp_path / "lines.mcap", cfg, port=path)
    events = []
    acq.on_raw, acq.on_status = rec.write_raw, rec.write_device
    acq.on_event = lambda e: (events.append(e), rec.write_event(e))
    acq.on_block = lambda b: (blocks.append(b), rec.write_block(b))
    os.set_blocking(master, False)
    th = threading.Thread(target=writer, daemon=True)
    th.start()
    watchdog = threading.Timer(120.0, acq.stop)  # samples that never come fail the test, not hang it
    watchdog.start()
    try:
        acq.run(duration_s=3.0, opened=opened)
        rec.write_status(acq.status())
        rec.close()
    finally:
        watchdog.cancel()
        done.set()
        th.join(10)
        os.close(master)
        os.close(slave)
    seq = np.concatenate([b.seq for b in blocks]).astype(np.int64)
    want = np.array([k for k in range(6000) if k not in lost and k not in garbled])
    missing = np.setdiff1d(want, seq)
    assert np.array_equal(seq, want), (  # what went missing, and what the driver said about it
        f"{missing.size} lines missing ({_runs(missing)}), {np.setdiff1d(seq, want).size} extra; "
        f"status {acq.status()}; events {[(e.kind, e.message) for e in events if e.kind != 'drop']}")
    values = np.concatenate([b.values for b in blocks])
    np.testing.assert_array_equal(values, np.array([_value(k) for k in want], float))  # scale 1: as printed
    np.testing.assert_array_equal(np.rint(np.concatenate([b.t_device_s for b in blocks]) * 1e6), want * 500)
    st = acq.status()
    assert st["dropped_frames"] == len(lost) + len(garbled) and st["malformed_lines"] == len(garbled)
    assert (st["duplicates"], st["text_lines"], st["reconnects"], st["crc_errors"]) == (1, 2, 0, 0)
    wire = written["bytes"] / (written["t1"] - written["t0"])
    assert wire < WIRE_BYTES_PER_S  # the lines fit the 921,600-baud line they stand for
    host = np.array([b.host_t for b in blocks])
    rate = (len(seq) - len(blocks[0])) / (host[-1] - host[0])
    print(f"\npaced: {rate:.0f} lines/s delivered over the pty ({wire:.0f} bytes/s on the wire, "
          f"{100 * wire / WIRE_BYTES_PER_S:.0f} % of 921,600 baud)")
    assert rate == pytest.approx(2000, rel=0.05)
    rec_back = read_recording(tmp_path / "lines.mcap")
    assert np.array_equal(rec_back.seq, want) and rec_back.status[-1]["malformed_lines"] == len(garbled)
    np.testing.assert_allclose(rec_back.values, values, rtol=1e-6)
    assert {e["kind"] for e in rec_back.events} >= {"start", "drop", "malformed", "duplicate", "stop"}


def test_lines_per_second_the_host_reads_from_a_pty(tmp_path):
    """Capacity: 60,000 lines written as fast as the pty takes them; the driver must read and decode them
    several times faster than a 921,600-baud line can carry them (about 3,000 such lines a second)."""
    cfg = _pty_config(tmp_path)
    master, slave, path = _pty()
    n = 60_000
    text = b"seq,t_us,base,tip1,tip2\r\n" + b"".join(b"%d,%d,%d,%d,%d\r\n" % (k, 500 * k, *_value(k)) for k in range(n))
    per_line = len(text) / n
    opened = threading.Event()
    got = [0]
    times = []

    def writer():
        opened.wait(10)
        view = memoryview(b"0,0,0\r\n" + text)
        while view:
            k = os.write(master, view[:65536])
            view = view[k:]

    acq = Acquisition(path, cfg)

    def on_block(b):
        got[0] += len(b)
        times.append((time.monotonic(), got[0]))
        if got[0] >= n:
            acq.stop()

    acq.on_block = on_block
    th = threading.Thread(target=writer, daemon=True)
    th.start()
    try:
        timer = threading.Timer(30, acq.stop)
        timer.start()
        acq.run(opened=opened)
        timer.cancel()
    finally:
        th.join(10)
        os.close(master)
        os.close(slave)
    assert got[0] == n and acq.status()["malformed_lines"] == 0 and acq.status()["dropped_frames"] == 0
    (t0, n0), (t1, n1) = times[0], times[-1]
    rate = (n1 - n0) / (t1 - t0)
    ceiling = WIRE_BYTES_PER_S / per_line
    print(f"\ncapacity: {rate:.0f} lines/s read and decoded from a pty ({per_line:.1f} bytes a line; a 921,600-baud "
          f"line carries {ceiling:.0f} of them a second)")
    assert rate > 2 * ceiling


# -------------------------------------------------------------------------------------- daq record

def test_daq_record_format_lines_on_the_simulated_line_device_with_a_pulled_cable(tmp_path):
    """``daq record --format lines`` without a port: the simulated rig prints lines on a real pty; its cable is
    pulled at 1 s for 0.4 s; the recording counts the lines lost meanwhile, replays, and plays."""
    cfg = tmp_path / "sim-lines.yaml"
    cfg.write_text(yaml.safe_dump({"daq": {"lines": {"counter": "seq", "time": "t_us", "base": "base",
                                                     "tip1": "tip1", "tip2": "tip2"},
                                           "faults": {"disconnect_at_s": [1.0], "disconnect_for_s": 0.4}}}))
    out = tmp_path / "sim-lines.mcap"
    code, text, err, tb = run_main(daq_main, ["record", "--format", "lines", "--baud", "921600", "--config", cfg,
                                              "--duration", "2.5", "-o", out, "--quiet", "--no-identify"])
    assert code == 0 and tb is None, err
    assert "malformed lines" in text and "1 reconnects" in text
    rec = read_recording(out)
    assert yaml.safe_load(rec.config_yaml)["daq"]["format"] == "lines"
    kinds = [e["kind"] for e in rec.events]
    assert "disconnect" in kinds and "reconnect" in kinds
    gap = int(np.max(np.diff(rec.seq)))
    assert 0.4 * 2000 <= gap - 1 <= 2.0 * 2000  # the lines printed while the cable was out, as a drop
    assert rec.status[-1]["dropped_frames"] >= gap - 1
    s = read_samples(out)
    assert s.fs_hz == pytest.approx(2000.0) and len(s.t) == rec.seq[-1] - rec.seq[0] + 1  # the gap filled
    scales, _ = parse_config({}, "defaults").scales()
    dec = decoder_for(parse_config(yaml.safe_load(rec.config_yaml), "recorded config").daq)
    fr = dec.feed(rec.raw)  # the raw bytes decode to the recorded samples where the link was whole
    first = np.searchsorted(fr.seq, rec.seq[0])
    k = int(np.argmax(np.diff(rec.seq) > 1))
    np.testing.assert_allclose(fr.counts[first:first + k + 1] * scales, rec.values[:k + 1], rtol=1e-5, atol=1e-5)
    code, info, err, _ = run_main(replay_main, ["info", out])
    assert code == 0 and "0 malformed lines, 1 reconnects" in info, info + err
