"""Rebuild a readable, indexed MCAP file from a truncated or damaged one.

The input is walked with the resynchronising reader (replay.formats.mcap.scan): every record that
adds up is kept, every chunk whose CRC matches, every schema and channel wherever it was found
(first chunk, the copies this tool's recorder writes after every chunk, the summary), every
metadata record and attachment; the damaged regions between them are skipped. A calibration whose
numbers disagree with the config attached (metadata carry no CRC; the attachment does) is written as the
config gives it. A cut (kill -9,
power loss) costs the unfinished chunk, at most the last second; a damaged chunk costs that chunk;
a damaged header costs nothing. The output is written beside its target and renamed when complete
(daq.safeio), never over the input (compared by device and inode) and never over an existing file
without ``force``.

The output says what was lost: metadata ``recovery`` lists the damaged byte ranges of the input and
the sequence numbers lost with them (``lost_seq``: ``a-b`` ranges; from ``/rig/accel`` where the
recording has it, else from the binary frames of ``/rig/raw``, decoded as they are copied), so
``replay info`` tells frames lost to file damage from frames the device dropped.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from mcap.writer import CompressionType, Writer

from daq.protocol import Decoder
from daq.recorder import TOPICS
from daq.safeio import Output, check_outputs, safe_output

from .formats.mcap import Damage, attached_calibration, raw_is_frames, scan


@dataclass
class RecoverReport:
    messages: dict[str, int] = field(default_factory=dict)  # per topic
    chunks: int = 0  # intact chunks kept
    complete: bool = False  # the input had its footer and no damage: nothing was missing
    damage: list[Damage] = field(default_factory=list)
    lost_seq: list[tuple[int, int]] = field(default_factory=list)  # sequence ranges lost to damage
    dropped_messages: int = 0  # messages on channels that no intact record names

    @property
    def total_messages(self) -> int:
        return sum(self.messages.values())


def _accel_seq(data: bytes) -> int | None:
    try:
        return int(json.loads(data)["seq"])
    except (ValueError, KeyError, TypeError):
        return None


def recover(src: str | Path, dst: str | Path, force: bool = False) -> RecoverReport:
    src, dst = Path(src), Path(dst)
    check_outputs([Output("-o", dst)], [src], force)
    s = scan(src)
    report = RecoverReport(complete=s.complete, damage=list(s.damage), chunks=len(s.chunks))
    if not s.channels or not (s.chunks or s.loose):
        raise ValueError(f"{src}: no intact chunk with messages and channels found; nothing to recover")
    accel_ids = s.topic_ids(TOPICS["accel"])
    # a compact recording's samples are the frames of /rig/raw: decode them as they go by to see what was lost
    raw_ids = s.topic_ids(TOPICS["raw"]) if not accel_ids and raw_is_frames(s) else set()
    decoder = Decoder()
    last_raw, raw_off, crossed = None, -1, False  # the last frame's sequence, its chunk, damage since
    damage_starts = sorted(d.offset for d in s.damage)
    with safe_output(dst, inputs=[src], force=force, label="-o") as tmp, open(tmp, "wb") as fout:
        w = Writer(fout, compression=CompressionType.ZSTD)
        w.start(profile="", library="shaker-ident replay recover")
        schema_map = {0: 0}
        for sid, sc in sorted(s.schemas.items()):
            schema_map[sid] = w.register_schema(sc.name, sc.encoding, sc.data)
        chan_map = {}
        for cid, ch in sorted(s.channels.items()):
            if ch.schema_id in schema_map:
                chan_map[cid] = w.register_channel(ch.topic, ch.message_encoding, schema_map[ch.schema_id],
                                                   ch.metadata)
        last, last_off = None, -1  # the last /rig/accel message kept, and its chunk's offset
        for cid, seq, log, pub, data, off in s.messages():
            if cid not in chan_map:
                report.dropped_messages += 1
                continue
            if cid in accel_ids:
                if last is not None and off != last_off and any(last_off < d < off for d in damage_starts):
                    a, b = _accel_seq(last), _accel_seq(data)
                    if a is not None and b is not None and b > a + 1:
                        report.lost_seq.append((a + 1, b - 1))
                last, last_off = data, off
            elif cid in raw_ids:
                if last_raw is not None and off != raw_off and any(raw_off < d < off for d in damage_starts):
                    crossed = True
                fr = decoder.feed(data)
                if len(fr):
                    first = int(fr.seq[0])
                    if crossed and last_raw is not None and first > last_raw + 1:
                        report.lost_seq.append((last_raw + 1, first - 1))
                    crossed = False
                    last_raw = int(fr.seq[-1])
                raw_off = off
            w.add_message(chan_map[cid], log, data, pub, seq)
            topic = s.channels[cid].topic
            report.messages[topic] = report.messages.get(topic, 0) + 1
        # a calibration that disagrees with the config attached is taken from the config (``scan``'s check)
        calibration = (attached_calibration(s) if any(d.what == "calibration metadata" for d in s.damage)
                       else None)
        for name, m in s.metadata:
            if name != "recovery":
                w.add_metadata(name, calibration if name == "calibration" and calibration else m)
        if calibration and not any(name == "calibration" for name, _ in s.metadata):  # (its name was damaged)
            w.add_metadata("calibration", calibration)
        for a in s.attachments:
            w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
        w.add_metadata("recovery", {
            "source": str(src), "intact_chunks": str(len(s.chunks)), "complete": str(s.complete).lower(),
            "damage": ";".join(f"{d.offset}-{d.end}:{d.what}" for d in s.damage),
            "lost_seq": ",".join(f"{a}-{b}" for a, b in report.lost_seq)})
        w.finish()
    return report
