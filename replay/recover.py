"""Rebuild a readable, indexed MCAP file from a truncated or damaged one.

A recording cut by kill -9 or power loss has no summary or footer, and its
last chunk may be partial. We read records in order, keep every schema,
channel, metadata, attachment and every message of every chunk whose CRC
checks out, stop at the first record that is cut or corrupt, and write all
of it again with a proper summary. Only the damaged tail is lost; with the
recorder's one-second chunks that is at most the last second.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from mcap.exceptions import McapError
from mcap.records import Attachment, Channel, Chunk, DataEnd, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader, breakup_chunk
from mcap.writer import CompressionType, Writer


@dataclass
class RecoverReport:
    messages: dict[str, int] = field(default_factory=dict)  # per topic
    chunks: int = 0
    complete: bool = False  # the input had its footer: nothing was missing
    stopped_at: str = ""  # why reading stopped early
    last_log_time_ns: int | None = None

    @property
    def total_messages(self) -> int:
        return sum(self.messages.values())


def recover(src: str | Path, dst: str | Path) -> RecoverReport:
    src, dst = Path(src), Path(dst)
    if src.resolve() == dst.resolve():
        raise ValueError("recover writes a new file: give an output path different from the input")
    try:
        fin = open(src, "rb")
    except FileNotFoundError:
        raise ValueError(f"{src}: no such file") from None
    report = RecoverReport()
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    with fin, open(dst, "wb") as fout:
        w = Writer(fout, compression=CompressionType.ZSTD)
        w.start(profile="", library="shaker-ident replay recover")
        schema_map: dict[int, int] = {0: 0}
        chan_map: dict[int, int] = {}

        def take(rec) -> None:
            if isinstance(rec, Schema):
                schemas[rec.id] = rec
                schema_map[rec.id] = w.register_schema(rec.name, rec.encoding, rec.data)
            elif isinstance(rec, Channel):
                channels[rec.id] = rec
                chan_map[rec.id] = w.register_channel(rec.topic, rec.message_encoding,
                                                      schema_map.get(rec.schema_id, 0), rec.metadata)
            elif isinstance(rec, Message):
                if rec.channel_id not in chan_map:
                    return
                w.add_message(chan_map[rec.channel_id], rec.log_time, rec.data, rec.publish_time, rec.sequence)
                topic = channels[rec.channel_id].topic
                report.messages[topic] = report.messages.get(topic, 0) + 1
                report.last_log_time_ns = max(report.last_log_time_ns or 0, rec.log_time)
            elif isinstance(rec, Metadata):
                w.add_metadata(rec.name, rec.metadata)
            elif isinstance(rec, Attachment):
                w.add_attachment(rec.create_time, rec.log_time, rec.name, rec.media_type, rec.data)

        reader = StreamReader(fin, emit_chunks=True, validate_crcs=True)
        try:
            for rec in reader.records:
                if isinstance(rec, Chunk):
                    inner = breakup_chunk(rec, validate_crc=True)  # all or nothing per chunk
                    report.chunks += 1
                    for r in inner:
                        take(r)
                elif isinstance(rec, (DataEnd, Footer)):
                    report.complete = isinstance(rec, Footer) or report.complete
                    if isinstance(rec, DataEnd):
                        report.complete = True
                        break
                else:
                    take(rec)
        except (McapError, ValueError, EOFError, OSError) as exc:
            report.stopped_at = f"{type(exc).__name__}: {exc}"
        except Exception as exc:  # noqa: BLE001 - a damaged file may fail in any parser branch
            report.stopped_at = f"{type(exc).__name__}: {exc}"
        if not schemas and not channels and not report.chunks:
            fout.close()
            dst.unlink(missing_ok=True)
            raise ValueError(f"{src}: no MCAP data found (not an MCAP file, or cut before its first record)")
        w.finish()
    return report
