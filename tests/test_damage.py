"""Damaged recordings: a generated corpus through every reading command, and what ``replay recover`` keeps.

The corpus is one real 12 s recording of the simulated rig (one chunk per second; compact: the samples
are the serial bytes of ``/rig/raw``) cut, bit-flipped and zeroed at chosen places: the magic, the header, the first chunk (its opcode, length, data),
chunks in the middle, a chunk's CRC field, the summary, the footer, 4 KiB blocks at the start, in
the middle and at the end, truncations inside and between chunks. Every reading command must end
with exit 0, or exit 2 and one line (never a traceback); a file with damage must be called damaged
and sent to ``replay recover``. What counts as intact comes from an independent reader: the
``mcap`` package's non-seeking ``StreamReader`` on the undamaged original gives every chunk's byte
range and its raw messages; a chunk none of whose bytes were touched is intact, and every sample whose
frame lies wholly in its raw bytes must come back from recover, read again by the ``mcap`` package's
own reader (the frames decoded by daq.protocol, itself checked against a byte-by-byte scanner).
"""

import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Message
from mcap.stream_reader import StreamReader, breakup_chunk

from clitools import run_main
from ident.cli.main import main as ident_main
from daq.protocol import FRAME_LEN, Decoder
from replay.cli import main as replay_main
from replay.formats import read_columns
from replay.formats.mcap import scan

SUMMARY = {}  # figures for the report, printed at the end of the module


def independent_chunks(path: Path) -> list[tuple[int, int, list[int]]]:
    """(start, end, sequence numbers of the frames wholly inside its /rig/raw bytes) of every chunk, from the
    mcap package's stream reader."""
    spans, raw, topics = [], [], {}
    with open(path, "rb") as f:
        reader = StreamReader(f, emit_chunks=True, skip_magic=False)
        start = f.tell()
        for rec in reader.records:
            end = f.tell()
            if isinstance(rec, Chunk):
                lo = sum(len(b) for b in raw)
                for r in breakup_chunk(rec):
                    if isinstance(r, Channel):
                        topics[r.id] = r.topic
                    elif isinstance(r, Message) and topics.get(r.channel_id) == "/rig/raw":
                        raw.append(r.data)
                spans.append((start, end, lo, sum(len(b) for b in raw)))
            start = end
    dec = Decoder()
    fr = [dec.feed(b"".join(raw)), dec.flush()]
    seq = [int(s) for p in fr for s in p.seq]
    ends = [int(e) for p in fr for e in p.end]
    return [(a, b, [s for s, e in zip(seq, ends) if lo <= e - FRAME_LEN and e <= hi]) for a, b, lo, hi in spans]


def independent_samples(path: Path) -> dict[int, tuple]:
    """seq -> (base, tip1, tip2) ADC counts of every frame in the /rig/raw messages (read by the mcap package's
    reader, in file order, decoded by daq.protocol)."""
    with open(path, "rb") as f:
        data = b"".join(m.data for _, _, m in make_reader(f).iter_messages(topics=["/rig/raw"], log_time_order=False))
    dec = Decoder()
    return {int(s): tuple(int(c) for c in counts) for p in (dec.feed(data), dec.flush())
            for s, counts in zip(p.seq, p.counts)}


@pytest.fixture(scope="module")
def original(tmp_path_factory):
    folder = tmp_path_factory.mktemp("damage")
    path = folder / "orig.mcap"
    p = subprocess.run([sys.executable, "-m", "daq", "record", "--port", "rig://?seed=7", "--duration", "12", "-o",
                        str(path), "--quiet", "--no-identify"], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    chunks = independent_chunks(path)
    assert not any(c.topic == "/rig/accel" for c in scan(path).channels.values())  # the compact layout
    # every frame is in one chunk but those cut by a chunk's end (the frames past --duration are read too)
    assert len(chunks) >= 11 and 24000 - len(chunks) <= sum(len(c[2]) for c in chunks) <= 24100
    return folder, path, chunks


def corpus(data: bytes, chunks) -> dict[str, tuple[bytes, list[tuple[int, int]]]]:
    """name -> (damaged bytes, damaged byte ranges [a, b) of the original; a cut is the range to the end)."""
    n = len(data)
    c0, c3, c5, c7, c9 = chunks[0], chunks[3], chunks[5], chunks[7], chunks[9]

    def flip(*offsets):
        b = bytearray(data)
        for o in offsets:
            b[o] ^= 0xFF
        return bytes(b), [(o, o + 1) for o in offsets]

    def zero(a, length=4096):
        b = bytearray(data)
        b[a:a + length] = bytes(min(length, n - a))
        return bytes(b), [(a, a + length)]

    def cut(at):
        return data[:at], [(at, n)]

    out = {
        "cut_10pct": cut(n // 10), "cut_inside_chunk7": cut((c7[0] + c7[1]) // 2), "cut_after_chunk9": cut(c9[1] + 5),
        "cut_90pct": cut(9 * n // 10), "cut_before_footer": cut(n - 30),
        "flip_magic": flip(0), "flip_header_opcode": flip(8), "flip_header_length": flip(9), "flip_header_text": flip(30),
        "flip_chunk0_opcode": flip(c0[0]), "flip_chunk0_length": flip(c0[0] + 1), "flip_chunk0_data": flip(c0[0] + 900),
        "flip_200000": flip(200_000), "flip_chunk5_data": flip((c5[0] + c5[1]) // 2),
        "flip_chunk3_crc_field": flip(c3[0] + 9 + 8 + 8 + 8), "flip_summary": flip(n - 300), "flip_footer": flip(n - 15),
        "flip_three_chunks": flip(chunks[2][0] + 777, chunks[6][0] + 5000, chunks[10][1] - 100),
        "zero_start": zero(0), "zero_100k": zero(100_000), "zero_1M": zero(1_000_000 if n > 1_100_000 else n // 2), "zero_end": zero(n - 4096),
        "zero_chunk0": zero(c0[0]),
    }
    both = bytearray(out["zero_chunk0"][0][:c9[1] + 5])  # first chunk gone and no summary: channels from the copies
    out["zero_chunk0_and_cut"] = (bytes(both), [(c0[0], c0[0] + 4096), (c9[1] + 5, n)])
    return out


def intact_seqs(chunks, damaged: list[tuple[int, int]]) -> set[int]:
    return {s for a, b, seqs in chunks if not any(x < b and a < y for x, y in damaged) for s in seqs}


def test_every_reading_command_on_the_damaged_corpus(original):
    folder, path, chunks = original
    data = path.read_bytes()
    truth = independent_samples(path)
    tracebacks, runs, expected_total, recovered_total = [], 0, 0, 0
    for name, (bad, damaged) in corpus(data, chunks).items():
        f = folder / f"{name}.mcap"
        f.write_bytes(bad)
        damage_found = bool(scan(f).problem())
        commands = [(replay_main, ["info", str(f)]),
                    (replay_main, [str(f), "--max", "--no-identify", "--viewer", "none"]),
                    (replay_main, ["export", str(f), "--csv", str(folder / f"{name}.csv")]),
                    (ident_main, ["fit", str(f), "--study", "1", "--duration", "2"])]
        for main, argv in commands:
            code, out, err, tb = run_main(main, argv)
            runs += 1
            if tb or "Traceback" in err:
                tracebacks.append(f"{name}: {argv[0]}: {tb or err}")
                continue
            assert code in (0, 2), (name, argv, code, err)
            if code == 2:
                assert len(err.strip().splitlines()) == 1, (name, argv, err)
            if damage_found:  # called damage, sent to recover; never "drops" or "gaps"
                assert code == 2 and "replay recover" in err and ("unreadable" in err or "cut short" in err), \
                    (name, argv, err)
                assert "drop" not in err and "gap" not in err
        try:  # discover's reader
            read_columns(f, ["base", "tip1", "tip2"])
            assert not damage_found, name
        except ValueError as exc:
            assert damage_found and "replay recover" in str(exc), (name, exc)
        except Exception as exc:  # noqa: BLE001
            tracebacks.append(f"{name}: read_columns: {type(exc).__name__}: {exc}")
        # recover keeps every sample of every intact chunk, and nothing that was not recorded
        fixed = folder / f"{name}.fixed.mcap"
        code, out, err, tb = run_main(replay_main, ["recover", str(f), "-o", str(fixed)])
        runs += 1
        if tb:
            tracebacks.append(f"{name}: recover: {tb}")
            continue
        expect = intact_seqs(chunks, damaged)
        if code == 2:  # nothing recoverable: only if no chunk was intact
            assert expect == set() and len(err.strip().splitlines()) == 1, (name, err)
            continue
        assert code == 0, (name, err)
        got = independent_samples(fixed)
        assert set(got) >= expect, (name, len(expect - set(got)))
        assert all(got[s] == truth[s] for s in got), name  # every recovered sample is the recorded one
        expected_total += len(expect)
        recovered_total += len(expect & set(got))
        # the recovered file reads as a whole file; what was lost is damage, not device drops
        code, out, err, tb = run_main(replay_main, ["info", str(fixed)])
        runs += 1
        assert tb is None and code == 0, (name, err, tb)
        drops = next(line for line in out.splitlines() if line.startswith("drops"))
        assert drops.split()[1] == "0", (name, out)
        if len(got) < len(truth) and not name.startswith("cut") and name != "zero_chunk0_and_cut":
            assert "damage" in out and "frame(s) lost with them" in out, (name, out)
    SUMMARY.update(runs=runs, tracebacks=len(tracebacks), intact=expected_total, recovered=recovered_total,
                   files=len(corpus(data, chunks)))
    print(f"\ndamaged corpus: {SUMMARY['files']} files, {runs} command runs, {len(tracebacks)} tracebacks; "
          f"recover kept {recovered_total} of {expected_total} intact samples")
    assert tracebacks == []
    assert recovered_total == expected_total > 0


def test_the_console_scripts_report_damage_in_one_line(original):
    """The same through the installed commands (a real process: nothing swallowed by the test harness)."""
    folder, path, chunks = original
    data = path.read_bytes()
    bad, _ = corpus(data, chunks)["flip_chunk5_data"]
    f = folder / "console.mcap"
    f.write_bytes(bad)
    for args in (["replay", "info", str(f)], ["ident", "fit", str(f)]):
        p = subprocess.run([sys.executable, "-m", *args], capture_output=True, text=True, timeout=120)
        assert p.returncode == 2 and "Traceback" not in p.stderr
        (line,) = p.stderr.strip().splitlines()
        assert f"chunk at byte {chunks[5][0]} unreadable" in line and "run replay recover" in line


def test_a_changed_digit_in_the_calibration_is_damage_and_recover_takes_the_attached_config(original):
    # metadata records carry no CRC: one digit of tip 1's scale changed (0.0048828125 -> 0.0098828125) had
    # exported tip 1 19 x too large, exit 0, and `replay recover` had called the file whole. The config the
    # recorder attached (an attachment, CRC-checked) gives the scale the counts were recorded under.
    folder, path, _ = original
    data = bytearray(path.read_bytes())
    key = data.find(b"tip1.scale_m_per_s2_per_count")
    at = data.find(b"0.0048828125", key)
    assert key > 0 and 0 < at - key < 40  # the metadata's value, as its map writes it after the key
    data[at + 4] = ord("9")
    bad = folder / "calibration.mcap"
    bad.write_bytes(bytes(data))
    for args in (["info", bad], ["export", bad, "--csv", folder / "calibration.csv"], [bad, "--max", "--no-identify",
                                                                                       "--viewer", "none"]):
        code, out, err, tb = run_main(replay_main, args)
        assert tb is None and code == 2 and len(err.strip().splitlines()) == 1, (args, err)
        assert ("calibration metadata at byte" in err and "tip1.scale_m_per_s2_per_count = 0.0098828125 where the "
                "config attached (CRC-checked) gives 0.0048828125" in err and "run replay recover" in err), err
    assert not (folder / "calibration.csv").exists()
    fixed = folder / "calibration-fixed.mcap"
    code, out, err, tb = run_main(replay_main, ["recover", bad, "-o", fixed])
    assert code == 0 and tb is None, err
    names = ["base", "tip1", "tip2"]
    want, got = read_columns(path, names).matrix(names), read_columns(fixed, names).matrix(names)
    assert got.shape == want.shape and (got == want).all()
    # one changed byte in a key or in the record's name: it had read as no samples at all, and recover as whole
    for what, old, new, said in (("key", b"tip1.scale_m_per_s2_per_count", b"tiX1.scale_m_per_s2_per_count",
                                  "no tip1.scale_m_per_s2_per_count where the config attached"),
                                 ("name", b"\x0b\x00\x00\x00calibration", b"\x0b\x00\x00\x00calibratiXn",
                                  "calibration metadata damaged (no record of it")):
        data = path.read_bytes()
        assert data.count(old) >= 1, what  # (the first: the record itself; the name again in the summary's index)
        bad = folder / f"calibration-{what}.mcap"
        bad.write_bytes(data.replace(old, new, 1))
        code, out, err, tb = run_main(replay_main, ["info", bad])
        assert tb is None and code == 2 and said in err and "run replay recover" in err, (what, err)
        fixed = folder / f"calibration-{what}-fixed.mcap"
        assert run_main(replay_main, ["recover", bad, "-o", fixed])[0] == 0
        got = read_columns(fixed, names).matrix(names)
        assert got.shape == want.shape and (got == want).all(), what
