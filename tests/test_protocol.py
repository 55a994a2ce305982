"""The frame decoder against an independent byte-by-byte reference scanner."""

import binascii
import struct

import numpy as np
import pytest

from daq.protocol import FRAME_LEN, Decoder, crc16_rows, encode

FMT = "<2sBBIQhhhH"


def ref_scan(data: bytes):
    """The obvious scanner: at each byte, a frame if sync, version and CRC (binascii) agree."""
    frames, crc_err, i = [], 0, 0
    used = 0
    while i + FRAME_LEN <= len(data):
        if data[i:i + 3] == b"\xa5\x5a\x01":
            chunk = data[i:i + FRAME_LEN]
            if binascii.crc_hqx(chunk[:22], 0xFFFF) == struct.unpack_from("<H", chunk, 22)[0]:
                _, _, _, seq, t, a, b, c, _ = struct.unpack(FMT, chunk)
                frames.append((seq, t, a, b, c))
                used += FRAME_LEN
                i += FRAME_LEN
                continue
            crc_err += 1
        i += 1
    return frames, crc_err, len(data) - used


def test_crc_is_ccitt_false_check_value():
    row = np.frombuffer(b"123456789", np.uint8)[None]
    assert int(crc16_rows(row)[0]) == 0x29B1 == binascii.crc_hqx(b"123456789", 0xFFFF)


def test_round_trip_and_layout():
    counts = np.array([[1, -2, 3], [32767, -32768, 0]])
    data = encode(np.array([7, 8]), np.array([500, 1000], np.uint64), counts)
    assert len(data) == 2 * FRAME_LEN and data[:3] == b"\xa5\x5a\x01"
    assert struct.unpack(FMT, data[:FRAME_LEN])[3:8] == (7, 500, 1, -2, 3)
    fr = Decoder().feed(data)
    assert fr.seq.tolist() == [7, 8] and fr.counts.tolist() == counts.tolist()


def _corrupt(rng, clean: bytes, n_frames: int) -> bytes:
    arr = bytearray(clean)
    ops = rng.integers(0, 5)
    for _ in range(ops):
        kind = rng.integers(0, 4)
        if kind == 0 and arr:  # flip bits
            arr[rng.integers(0, len(arr))] ^= int(rng.integers(1, 256))
        elif kind == 1 and arr:  # drop a run of bytes
            p = int(rng.integers(0, len(arr)))
            del arr[p:p + int(rng.integers(1, 30))]
        elif kind == 2:  # burst of garbage, sometimes sync-like
            junk = rng.integers(0, 256, int(rng.integers(1, 40)), dtype=np.uint8).tobytes()
            if rng.random() < 0.5:
                junk = b"\xa5\x5a\x01" + junk
            p = int(rng.integers(0, len(arr) + 1))
            arr[p:p] = junk
        else:  # duplicate a frame (replayed bytes)
            k = int(rng.integers(0, n_frames)) * FRAME_LEN
            arr[k:k] = clean[k:k + FRAME_LEN]
    return bytes(arr)


def test_fuzz_100k_corrupted_streams_match_the_reference_exactly():
    rng = np.random.default_rng(12345)
    for case in range(100_000):
        n = int(rng.integers(1, 8))
        seq0 = int(rng.integers(0, 2**32 - 10))
        clean = encode(np.arange(seq0, seq0 + n) % 2**32, rng.integers(0, 2**40, n).astype(np.uint64),
                       rng.integers(-32768, 32768, (n, 3)))
        data = _corrupt(rng, clean, n)
        exp_frames, exp_crc, exp_skip = ref_scan(data)
        dec = Decoder()
        got = []
        pos = 0
        while pos < len(data):  # random split into feeds
            step = int(rng.integers(1, 60))
            fr = dec.feed(data[pos:pos + step])
            got += list(zip(fr.seq.tolist(), fr.t_us.tolist(), *fr.counts.T.tolist()))
            pos += step
        dec.flush()
        assert got == exp_frames, case
        assert dec.counters.crc_errors == exp_crc, case
        assert dec.counters.skipped_bytes == exp_skip, case
        assert dec.counters.frames == len(exp_frames)
        # every frame the corruption did not touch is recovered: its bytes are intact and no
        # other valid frame starts within the 24 bytes before it (which would shadow it)
        valid = [i for i in range(len(data) - FRAME_LEN + 1) if data[i:i + 3] == b"\xa5\x5a\x01"
                 and binascii.crc_hqx(data[i:i + 22], 0xFFFF) == struct.unpack_from("<H", data, i + 22)[0]]
        for k in range(n):
            frame = clean[k * FRAME_LEN:(k + 1) * FRAME_LEN]
            for p in (i for i in valid if data[i:i + FRAME_LEN] == frame):
                if not any(p - FRAME_LEN < q < p for q in valid):
                    assert struct.unpack(FMT, frame)[3:8] in got, case


def test_sequence_gaps_are_counted():
    data = encode(np.array([1, 2, 5, 6, 10]), np.zeros(5, np.uint64), np.zeros((5, 3)))
    dec = Decoder()
    fr = dec.feed(data)
    assert fr.gaps.tolist() == [0, 0, 2, 0, 3]
    assert dec.counters.dropped_frames == 5
    # wrap-around of the 32-bit counter is not a gap
    dec2 = Decoder()
    dec2.feed(encode(np.array([2**32 - 1, 0, 1]), np.zeros(3, np.uint64), np.zeros((3, 3))))
    assert dec2.counters.dropped_frames == 0 and dec2.counters.sequence_resets == 0


def test_decoder_never_raises_on_arbitrary_bytes():
    hyp = pytest.importorskip("hypothesis")
    from hypothesis import given, settings
    from hypothesis import strategies as st

    @settings(max_examples=300, deadline=None)
    @given(st.lists(st.binary(max_size=200), max_size=10))
    def run(chunks):
        dec = Decoder()
        for c in chunks:
            dec.feed(c)
        dec.flush()
        assert dec.counters.skipped_bytes + FRAME_LEN * dec.counters.frames == sum(map(len, chunks))

    del hyp
    run()
