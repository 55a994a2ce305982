"""The firmware's frame encoder (C, ``daq/firmware/rig_firmware/rigframe.c``) against the Python decoder.

The encoder is compiled with this machine's C compiler into a shared library and driven through ctypes
the way the sketch drives it (``rigframe_stream_sample`` per sample); its bytes, clean and corrupted, are
fed to ``daq.protocol.Decoder`` and compared with the README's reference encoders (byte for byte) and with
the byte-by-byte reference scanner of ``test_protocol`` (frames, CRC failures, skipped bytes, drops). The
sketch itself is compiled for syntax and types only, against a declaration-only stand-in of the
Teensyduino API (``tests/firmware_stubs``): no board was run here.
"""

import binascii
import ctypes
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from daq.firmware import ENCODER_C, ENCODER_H, SKETCH, SKETCH_DIR
from daq.protocol import FRAME_LEN, STATUS_LEN, Decoder, encode, encode_status
from test_protocol import _corrupt, ref_scan, ref_sequence

STUBS = Path(__file__).resolve().parent / "firmware_stubs"
CC = next((p for p in (shutil.which(c) for c in (os.environ.get("CC", "cc"), "gcc", "clang")) if p), None)
CXX = next((p for p in (shutil.which(c) for c in (os.environ.get("CXX", "c++"), "g++", "clang++")) if p), None)
needs_cc = pytest.mark.skipif(CC is None, reason="no C compiler on this machine (cc, gcc or clang): the firmware's "
                                                 "C encoder cannot be compiled and checked")
RATE_MHZ = 2_000_000
DEVICE, SESSION, FW = 0x7E57_1D01, 0x0123_4567_89AB_CDEF, (1, 0)


class Identity(ctypes.Structure):
    _fields_ = [("session_id", ctypes.c_uint64), ("device_id", ctypes.c_uint32), ("rate_mhz", ctypes.c_uint32),
                ("fw_major", ctypes.c_uint8), ("fw_minor", ctypes.c_uint8)]


class Stream(ctypes.Structure):
    _fields_ = [("id", Identity), ("status_counter", ctypes.c_uint32), ("next_status_us", ctypes.c_uint64),
                ("started", ctypes.c_int)]


@pytest.fixture(scope="module")
def lib(tmp_path_factory):
    out = tmp_path_factory.mktemp("cc") / "librigframe.so"
    proc = subprocess.run([CC, "-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-pedantic", "-shared", "-fPIC",
                           "-o", str(out), str(ENCODER_C)], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr
    c = ctypes.CDLL(str(out))
    u8p, i16p = ctypes.POINTER(ctypes.c_uint8), ctypes.POINTER(ctypes.c_int16)
    c.rigframe_crc16.argtypes, c.rigframe_crc16.restype = [u8p, ctypes.c_size_t], ctypes.c_uint16
    c.rigframe_data.argtypes = [u8p, ctypes.c_uint32, ctypes.c_uint64, i16p, ctypes.c_uint8]
    c.rigframe_data.restype = ctypes.c_size_t
    c.rigframe_status.argtypes = [u8p, ctypes.POINTER(Identity), ctypes.c_uint32, ctypes.c_uint64]
    c.rigframe_status.restype = ctypes.c_size_t
    c.rigframe_time_us.argtypes, c.rigframe_time_us.restype = [ctypes.c_uint64, ctypes.c_uint32], ctypes.c_uint64
    c.rigframe_stream_init.argtypes = [ctypes.POINTER(Stream), ctypes.POINTER(Identity)]
    c.rigframe_stream_sample.argtypes = [ctypes.POINTER(Stream), u8p, ctypes.c_uint32, ctypes.c_uint64, i16p,
                                         ctypes.c_uint8]
    c.rigframe_stream_sample.restype = ctypes.c_size_t
    return c


def _identity(rate_mhz=RATE_MHZ, session=SESSION, device=DEVICE):
    return Identity(session, device, rate_mhz, *FW)


def firmware_bytes(c, n_taken, counts, flags, rate_mhz=RATE_MHZ, session=SESSION):
    """What the sketch's loop() sends for the samples taken as ``n_taken`` (samples since boot; a gap is a
    sample the ring lost), in the sketch's order of calls."""
    st = Stream()
    ident = _identity(rate_mhz, session)
    c.rigframe_stream_init(ctypes.byref(st), ctypes.byref(ident))
    buf = (ctypes.c_uint8 * 60)()
    ch = (ctypes.c_int16 * 3)()
    out = bytearray()
    for n, cnt, fl in zip(np.asarray(n_taken).tolist(), np.asarray(counts).tolist(), np.asarray(flags).tolist()):
        ch[0], ch[1], ch[2] = cnt
        k = c.rigframe_stream_sample(ctypes.byref(st), buf, n & 0xFFFFFFFF, c.rigframe_time_us(n, rate_mhz), ch, fl)
        out += bytes(buf[:k])
    return bytes(out)


@needs_cc
def test_crc_is_ccitt_false(lib):
    rng = np.random.default_rng(1)
    data = (ctypes.c_uint8 * 9).from_buffer_copy(b"123456789")
    assert lib.rigframe_crc16(data, 9) == 0x29B1
    for _ in range(500):
        raw = rng.integers(0, 256, int(rng.integers(0, 80)), dtype=np.uint8).tobytes()
        buf = (ctypes.c_uint8 * max(1, len(raw))).from_buffer_copy(raw or b"\0")
        assert lib.rigframe_crc16(buf, len(raw)) == binascii.crc_hqx(raw, 0xFFFF)


@needs_cc
def test_frames_are_byte_identical_to_the_reference_encoders(lib):
    rng = np.random.default_rng(2)
    n = 3000
    seq = np.r_[rng.integers(0, 2**32, n - 2, dtype=np.uint64), [0, 2**32 - 1]]
    t = np.concatenate([rng.integers(0, 2**64 - 1, n - 2, dtype=np.uint64, endpoint=True),
                        np.array([0, 2**64 - 1], np.uint64)])
    counts = np.r_[rng.integers(-32768, 32768, (n - 2, 3)), [[-32768, 32767, 0], [32767, -32768, -1]]]
    flags = rng.integers(0, 256, n)  # the encoder keeps bit 0 only, as daq.protocol.encode does (& 0x7F, bit 0 used)
    buf = (ctypes.c_uint8 * 24)()
    ch = (ctypes.c_int16 * 3)()
    for i in range(n):
        ch[0], ch[1], ch[2] = (int(v) for v in counts[i])
        assert lib.rigframe_data(buf, int(seq[i]), int(t[i]), ch, int(flags[i])) == 24
        want = encode(seq[i:i + 1], t[i:i + 1], counts[i:i + 1], np.array([flags[i] & 1]))
        assert bytes(buf) == want, i
    sbuf = (ctypes.c_uint8 * 36)()
    for i in range(500):
        counter, t_us = int(rng.integers(0, 2**32)), int(rng.integers(0, 2**64, dtype=np.uint64))
        session, device = int(rng.integers(1, 2**64, dtype=np.uint64)), int(rng.integers(0, 2**32))
        rate_mhz, fw = int(rng.integers(1000, 100_000_001)), (int(rng.integers(0, 256)), int(rng.integers(0, 256)))
        ident = Identity(session, device, rate_mhz, *fw)
        assert lib.rigframe_status(sbuf, ctypes.byref(ident), counter, t_us) == 36
        assert bytes(sbuf) == encode_status(counter, t_us, session, device, rate_mhz / 1000.0, fw), i


@needs_cc
def test_device_time_is_n_times_the_period_exactly(lib):
    rng = np.random.default_rng(3)
    for _ in range(2000):
        n = int(rng.integers(0, 2**52, dtype=np.uint64))
        rate = int(rng.integers(1000, 2**32))  # 1 Hz to 4.29 MHz in millihertz
        assert lib.rigframe_time_us(n, rate) == n * 10**9 // rate
    assert lib.rigframe_time_us(2000, RATE_MHZ) == 1_000_000 and lib.rigframe_time_us(1, 3_000_000) == 333


@needs_cc
def test_ten_seconds_of_firmware_output_decode_exactly(lib):
    """20,000 samples at 2 kHz as the sketch sends them, 37 of them lost in the device's ring (sequence
    gaps), one gap spanning a whole second: every frame, every status frame and every gap as sent."""
    rng = np.random.default_rng(4)
    n_all = np.arange(20_037)
    candidates = np.arange(1, 20_000)
    lost = np.sort(rng.choice(candidates[candidates % 2000 != 0], 30, replace=False))  # seconds: below
    lost = np.r_[lost, np.arange(3995, 4002)]  # 4000 (a whole second) is among them: its status frame moves on
    kept = np.setdiff1d(n_all, lost)[:20_000]
    counts = rng.integers(-32768, 32768, (kept.size, 3))
    flags = (rng.random(kept.size) < 0.01).astype(np.uint8)
    data = firmware_bytes(lib, kept, counts, flags)
    # the same stream from the Python reference encoders, assembled by the README's rule
    t_us = kept * 10**9 // RATE_MHZ
    pieces, next_s, status_t = [], 0, []
    for i in range(kept.size):
        if t_us[i] >= next_s:
            pieces.append(encode_status(len(status_t), int(t_us[i]), SESSION, DEVICE, 2000.0, FW))
            status_t.append(int(t_us[i]))
            next_s = (int(t_us[i]) // 1_000_000 + 1) * 1_000_000
        pieces.append(encode(kept[i:i + 1], t_us[i:i + 1].astype(np.uint64), counts[i:i + 1], flags[i:i + 1]))
    assert data == b"".join(pieces)
    dec = Decoder()
    fr = [dec.feed(data[a:a + 4096]) for a in range(0, len(data), 4096)] + [dec.flush()]
    seq = np.concatenate([f.seq for f in fr]).astype(np.int64)
    assert np.array_equal(seq, kept)
    assert np.array_equal(np.concatenate([f.t_us for f in fr]).astype(np.int64), t_us)
    assert np.array_equal(np.concatenate([f.counts for f in fr]), counts)
    assert np.array_equal(np.concatenate([f.flags for f in fr]), flags)
    status = [s for f in fr for s in f.status]
    assert [s.t_us for s in status] == status_t and [s.counter for s in status] == list(range(len(status_t)))
    assert status_t == [0, 1_000_000, 2_001_000] + [k * 1_000_000 for k in range(3, 11)]  # 2.0 s was lost
    assert {(s.session_id, s.device_id, s.rate_hz, s.firmware) for s in status} == {(SESSION, DEVICE, 2000.0, FW)}
    c = dec.counters
    assert (c.frames, c.status_frames, c.crc_errors, c.skipped_bytes, c.dropped_frames) == \
        (20_000, len(status_t), 0, 0, int(kept[-1]) + 1 - 20_000)


@needs_cc
def test_corrupted_firmware_output_agrees_with_the_reference_scanner(lib):
    """2,000 streams from the C encoder (a status frame and 2-40 data frames each), corrupted (flipped bytes,
    cut runs, garbage with and without sync bytes, repeated frames, foreign versions) and fed in random
    pieces: the decoder finds exactly the frames, CRC failures, skipped bytes and drops the reference finds."""
    rng = np.random.default_rng(5)
    agree = 0
    for case in range(2000):
        n = int(rng.integers(2, 41))
        n0 = int(rng.integers(0, 2**33))
        clean = firmware_bytes(lib, n0 + np.arange(n), rng.integers(-32768, 32768, (n, 3)),
                               (rng.random(n) < 0.1).astype(np.uint8), session=int(rng.integers(1, 2**63)))
        body = clean[STATUS_LEN:]  # _corrupt repeats data frames by index: give it the data frames
        data = clean[:STATUS_LEN] + _corrupt(rng, body, n)
        all_frames, exp_status, exp_crc, exp_skip, exp_unknown = ref_scan(data)
        exp_frames, exp_drop, exp_dup, exp_restart = ref_sequence(all_frames)
        dec = Decoder()
        got, status = [], []
        cuts = np.r_[0, np.cumsum(rng.integers(1, 80, len(data)))]
        cuts = cuts[cuts < len(data)].tolist() + [len(data)]
        for fr in [dec.feed(data[a:b]) for a, b in zip(cuts[:-1], cuts[1:])] + [dec.flush()]:
            got += list(zip(fr.seq.tolist(), fr.t_us.tolist(), *fr.counts.T.tolist()))
            status += [(s.counter, s.t_us, s.session_id, s.device_id) for s in fr.status]
        c = dec.counters
        assert got == exp_frames and status == exp_status, case
        assert (c.crc_errors, c.skipped_bytes, c.unknown_version) == (exp_crc, exp_skip, exp_unknown), case
        assert (c.dropped_frames, c.duplicates, c.sequence_resets) == (exp_drop, exp_dup, exp_restart), case
        agree += 1
    assert agree == 2000


@needs_cc
def test_one_flipped_byte_per_damaged_frame_is_one_crc_failure_and_one_drop(lib):
    """Flip one byte (4-23: payload or CRC) in 50 of 2,000 data frames: 50 CRC failures, 50 frames lost,
    every other frame exact."""
    rng = np.random.default_rng(6)
    n = 2000
    counts = rng.integers(-2000, 2000, (n, 3))
    data = bytearray(firmware_bytes(lib, np.arange(n), counts, np.zeros(n, np.uint8)))
    starts = [i for i in range(len(data) - 3) if data[i:i + 3] == b"\xa5\x5a\x01" and not data[i + 3] & 0x80]
    assert len(starts) == n
    hit = np.sort(rng.choice(np.arange(1, n - 1), 50, replace=False))
    for k in hit:
        data[starts[k] + int(rng.integers(4, FRAME_LEN))] ^= int(rng.integers(1, 256))
    dec = Decoder()
    fr = dec.feed(bytes(data))
    dec.flush()
    keep = np.setdiff1d(np.arange(n), hit)
    assert np.array_equal(fr.seq.astype(np.int64), keep) and np.array_equal(fr.counts, counts[keep])
    assert (dec.counters.crc_errors, dec.counters.dropped_frames) == (50, 50)
    assert dec.counters.skipped_bytes == 50 * FRAME_LEN


@pytest.mark.skipif(CXX is None, reason="no C++ compiler on this machine (c++, g++ or clang++): the sketch's syntax "
                                        "cannot be checked")
def test_sketch_compiles_for_syntax_against_a_stand_in_of_the_teensy_api(tmp_path):
    """Syntax and types only: the stand-in declares the Teensyduino calls the sketch uses; it is not the core."""
    proc = subprocess.run([CXX, "-std=gnu++17", "-fsyntax-only", "-Wall", "-Wextra", "-Werror", "-x", "c++",
                           "-I", str(STUBS), "-I", str(SKETCH_DIR), str(SKETCH)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr


def test_the_sketch_folder_ships_in_the_package():
    """An Arduino sketch folder: the .ino named as its folder, the encoder beside it; installed with the package."""
    assert SKETCH.name == SKETCH_DIR.name + ".ino" and ENCODER_C.parent == ENCODER_H.parent == SKETCH_DIR
    text = (Path(__file__).resolve().parents[1] / "pyproject.toml").read_text()
    assert '"daq.firmware" = ["README.md", "rig_firmware/*"]' in text
    assert '#include "rigframe.h"' in SKETCH.read_text()
