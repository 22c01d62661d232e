"""Rebuild a flight log cut off by a crash, or damaged (``fdi-sim repair LOG``).

A run killed before :meth:`FlightLogWriter.close` leaves an MCAP file without Data End,
summary and footer, possibly ending inside a chunk. Everything the writer flushed before the
crash is a sequence of complete records (MCAP spec, "Records": opcode, uint64 length, body),
so the file is read from the start record by record (:func:`fdi_sim.flightlog.verify.scan_log`);
the scan ends at the record cut short. After a damaged record the scan resynchronises at the
next offset where records parse again (:func:`fdi_sim.flightlog.framing.scan_section`), so
one bad byte costs one record, not the rest of the file.

Schemas and channels exist twice in a complete file, in the data section and in the summary.
Each is taken from the copy most likely intact: a copy inside a chunk (its CRC checked), then a
section whose CRC (Data End's data_section_crc, the footer's summary_crc) holds, then a section
without a CRC (a cut-off file), then a damaged section; within a rank the data section first.
Every complete Chunk whose size and CRC check out gives its messages back; a new file with
message indexes, summary and footer is written with the same low-level writer as a normal run.
"""
from __future__ import annotations

import io
import json
import struct
from dataclasses import dataclass, field
from pathlib import Path

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Channel, Schema

from fdi_sim.errors import LogError
from fdi_sim.flightlog.reader import check_log_file
from fdi_sim.flightlog.records import (
    MCAP_MAGIC,
    RawMessage,
    build_chunk,
    has_footer,
    scan_records,
)
from fdi_sim.flightlog.schemas import SCHEMA_ENCODING_JSONSCHEMA, SCHEMA_ENCODING_ROS2MSG
from fdi_sim.flightlog.verify import looks_like_mcap, scan_log
from fdi_sim.flightlog.writer import McapFileWriter
from fdi_sim.units import NS_PER_S

#: records that only index or summarize: rebuilt, never copied
_OP_DERIVED = frozenset({Opcode.HEADER, Opcode.MESSAGE_INDEX, Opcode.DATA_END})
#: trust rank of a section by its CRC: holds, not recorded / cut off, fails
_CRC_RANK = {True: 1, None: 2, False: 3}
#: messages per chunk when a file held messages outside chunks
_LOOSE_CHUNK_MESSAGES = 4096
#: what parsing a damaged record raises (UnicodeDecodeError and JSONDecodeError are ValueErrors)
_DAMAGED = (ValueError, struct.error, McapError)


@dataclass(frozen=True)
class RepairReport:
    """What :func:`repair_log` recovered.

    Attributes
    ----------
    src, dst : Path
    messages_recovered : int
    first_t_s, last_t_s : float or None
        Earliest and latest recovered message time [s]; None if no message was recovered.
    message_counts : dict of str to int
        Recovered messages per topic.
    chunks_recovered, chunks_dropped : int
        Complete chunks used / complete chunks rejected (bad size or CRC).
    bytes_total, bytes_used : int
        File size and the end of the last complete record [bytes].
    had_footer : bool
        The source was already complete (repair then simply rewrites it).
    metadata_names : tuple of str
    records_skipped : int
        Complete records that could not be used (attachments, corrupted or unknown records,
        messages of unknown channels, unreadable stretches of bytes).
    source_problems : tuple of str
        What :func:`~fdi_sim.flightlog.verify_log` finds in the source (``part: what``).
    copies_from_summary : tuple of str
        Schemas and channels taken from the summary because the data-section copy is damaged.
    """

    src: Path
    dst: Path
    messages_recovered: int
    first_t_s: float | None
    last_t_s: float | None
    message_counts: dict[str, int] = field(default_factory=dict)
    chunks_recovered: int = 0
    chunks_dropped: int = 0
    bytes_total: int = 0
    bytes_used: int = 0
    had_footer: bool = False
    metadata_names: tuple[str, ...] = ()
    records_skipped: int = 0
    source_problems: tuple[str, ...] = ()
    copies_from_summary: tuple[str, ...] = ()

    def format(self) -> str:
        """A terminal summary (what ``fdi-sim repair LOG`` prints)."""
        span = ("no messages" if self.last_t_s is None
                else f"t = {self.first_t_s:.3f} .. {self.last_t_s:.3f} s")
        lines = [
            f"repaired {self.src} -> {self.dst}",
            f"{'source was complete' if self.had_footer else 'source was cut off'}: used "
            f"{self.bytes_used} of {self.bytes_total} bytes",
            f"recovered {self.messages_recovered} messages ({span}) from {self.chunks_recovered} chunks"
            + (f"; dropped {self.chunks_dropped} damaged chunks" if self.chunks_dropped else "")
            + (f"; skipped {self.records_skipped} records" if self.records_skipped else ""),
        ]
        lines += [f"  {topic}: {n}" for topic, n in self.message_counts.items()]
        lines.append("metadata: " + (", ".join(self.metadata_names) if self.metadata_names else "(none)"))
        if self.copies_from_summary:
            lines.append("taken from the summary (the data-section copy is damaged): "
                         + ", ".join(self.copies_from_summary))
        if self.source_problems:
            lines.append(f"the source has {len(self.source_problems)} problems (fdi-sim verify), first: "
                         + self.source_problems[0])
        return "\n".join(lines)


@dataclass
class _Recovered:
    schemas: dict[int, tuple[str, str, bytes]] = field(default_factory=dict)
    channels: dict[int, tuple[int, str, str, dict[str, str]]] = field(default_factory=dict)
    metadata: list[tuple[str, dict[str, str]]] = field(default_factory=list)
    chunks: list[list[RawMessage]] = field(default_factory=list)
    chunks_dropped: int = 0
    skipped: int = 0
    had_footer: bool = False
    bytes_used: int = len(MCAP_MAGIC)
    problems: tuple[str, ...] = ()
    from_summary: list[str] = field(default_factory=list)
    # candidate copies: id -> [(rank, order, body)], the best rank wins
    schema_copies: dict[int, list[tuple[int, int, memoryview, str]]] = field(default_factory=dict)
    channel_copies: dict[int, list[tuple[int, int, memoryview, str]]] = field(default_factory=dict)


def repair_log(src: str | Path, dst: str | Path | None = None, *, compression: str | None = "zstd") -> RepairReport:
    """Rebuild a cut-off (or complete) flight log into a proper MCAP file.

    Parameters
    ----------
    src : str or Path
        The damaged log.
    dst : str or Path, optional
        Output; default ``<stem>.repaired.mcap`` next to ``src``.
    compression : {"zstd", "lz4", None}
        Chunk compression of the output.

    Returns
    -------
    RepairReport

    Raises
    ------
    LogError
        ``src`` unreadable, not MCAP, holding nothing recoverable, or ``dst`` unwritable.
    """
    src_p = Path(src)
    dst_p = Path(dst) if dst is not None else src_p.with_name(src_p.stem + ".repaired.mcap")
    check_log_file(src_p)
    try:
        data = src_p.read_bytes()
    except OSError as exc:
        raise LogError(str(src), f"cannot read the flight log ({exc.strerror})") from None
    if dst_p.resolve() == src_p.resolve():
        raise LogError(str(src), "repair would overwrite its own input; give another destination")
    if data[:len(MCAP_MAGIC)] != MCAP_MAGIC:
        if len(data) < len(MCAP_MAGIC) and MCAP_MAGIC.startswith(data):
            raise LogError(str(src), "the file was cut off inside the MCAP magic: nothing to recover")
        if len(data) <= len(MCAP_MAGIC) or not looks_like_mcap(data):
            raise LogError(str(src), "not an MCAP file (it does not start with the MCAP magic bytes)")
    rec = _scan(data)
    if not rec.channels and not rec.metadata:
        raise LogError(str(src), f"nothing to recover: no complete channel or metadata record in the "
                       f"first {rec.bytes_used} of {len(data)} bytes")
    return _write(src_p, dst_p, data, rec, compression)


def _stream(body: memoryview) -> ReadDataStream:
    return ReadDataStream(io.BytesIO(bytes(body)))


def _keep_schema(rec: _Recovered, body: memoryview) -> None:
    """Record a Schema record (the first of an id wins); raise if its text is damaged."""
    s = Schema.read(_stream(body))
    # schema records outside chunks carry no CRC: a damaged text schema must not reach the repaired file
    if s.encoding in (SCHEMA_ENCODING_ROS2MSG, SCHEMA_ENCODING_JSONSCHEMA):
        text = bytes(s.data).decode("utf-8")
        if s.encoding == SCHEMA_ENCODING_JSONSCHEMA:
            json.loads(text)
    rec.schemas.setdefault(s.id, (s.name, s.encoding, bytes(s.data)))


def _keep_channel(rec: _Recovered, body: memoryview) -> None:
    """Record a Channel record (the first of an id wins)."""
    c = Channel.read(_stream(body))
    rec.channels.setdefault(c.id, (c.schema_id, c.topic, c.message_encoding, dict(c.metadata)))


def _scan(data: bytes) -> _Recovered:
    """Collect every usable record: the data section read with resynchronisation, the
    summary's copies of schemas and channels, and the chunks whose CRC holds."""
    rec = _Recovered()
    v = scan_log(data)
    rec.problems = tuple(p.format() for p in v.problems)
    rec.had_footer = has_footer(data)
    data_rank, summary_rank = _CRC_RANK[v.data_crc_ok], _CRC_RANK[v.summary_crc_ok]
    spans = v.data_spans
    chunked = any(s.opcode == Opcode.CHUNK for s in spans)
    loose: list[RawMessage] = []
    rec.skipped = len(v.data_gaps)
    chunk_records = {c.span.start: c.records for c in v.chunks}
    for order, s in enumerate(spans):
        rec.bytes_used = max(rec.bytes_used, s.end)
        body = memoryview(data)[s.start + 9:s.end]
        if s.opcode == Opcode.CHUNK:
            records = chunk_records.get(s.start)
            try:
                if records is None:
                    raise ValueError("damaged chunk")
                rec.chunks.append(_chunk_messages(records, rec))
            except _DAMAGED:
                rec.chunks_dropped += 1
        elif s.record is None:
            rec.skipped += 1
        elif s.opcode == Opcode.SCHEMA:
            rec.schema_copies.setdefault(s.record.id, []).append((data_rank, order, body, "data"))
        elif s.opcode == Opcode.CHANNEL:
            rec.channel_copies.setdefault(s.record.id, []).append((data_rank, order, body, "data"))
        elif s.opcode == Opcode.METADATA:
            rec.metadata.append((s.record.name, dict(s.record.metadata)))
        elif s.opcode == Opcode.MESSAGE and not chunked:
            # in a chunked file a stray Message record is more likely a damaged index record
            m = s.record
            loose.append(RawMessage(m.channel_id, m.sequence, m.log_time, bytes(m.data)))
        elif s.opcode not in _OP_DERIVED:  # attachments and stray records are not carried over
            rec.skipped += 1
    if v.sum_spans:
        rec.bytes_used = max(rec.bytes_used, v.sum_spans[0].start)
    for order, s in enumerate(v.sum_spans, start=len(spans)):
        body = memoryview(data)[s.start + 9:s.end]
        if s.record is not None and s.opcode == Opcode.SCHEMA:
            rec.schema_copies.setdefault(s.record.id, []).append((summary_rank, order, body, "summary"))
        elif s.record is not None and s.opcode == Opcode.CHANNEL:
            rec.channel_copies.setdefault(s.record.id, []).append((summary_rank, order, body, "summary"))
    for sid, copies in sorted(rec.schema_copies.items()):
        _choose(rec, copies, _keep_schema, f"schema {sid}")
    for cid, copies in sorted(rec.channel_copies.items()):
        _choose(rec, copies, _keep_channel, f"channel {cid}")
    for i in range(0, len(loose), _LOOSE_CHUNK_MESSAGES):
        rec.chunks.append(loose[i:i + _LOOSE_CHUNK_MESSAGES])
    return rec


def _choose(rec: _Recovered, copies: list[tuple[int, int, memoryview, str]], keep: object, name: str) -> None:
    """Keep the best-ranked copy that passes its checks (``keep`` raises for a bad one)."""
    for _rank, _order, body, where in sorted(copies, key=lambda c: c[:2]):
        try:
            keep(rec, body)  # type: ignore[operator]
        except _DAMAGED:
            continue
        if where == "summary" and not any(c[3] == "data" and bytes(c[2]) == bytes(body) for c in copies):
            rec.from_summary.append(name)
        return
    rec.skipped += 1


def _chunk_messages(records: bytes, rec: _Recovered) -> list[RawMessage]:
    """Messages (and schemas/channels) inside one decompressed chunk; raise if malformed."""
    out: list[RawMessage] = []
    end = 0
    view = memoryview(records)
    for opcode, start, length in scan_records(view):
        end = start + length
        if opcode == Opcode.MESSAGE:
            if length < 22:  # channel u16, sequence u32, log and publish time u64
                raise ValueError("message record too short")
            cid, seq, log_ns = struct.unpack_from("<HIQ", records, start)
            out.append(RawMessage(cid, seq, log_ns, records[start + 22:end]))
        elif opcode == Opcode.SCHEMA:
            _keep_schema(rec, view[start:end])
        elif opcode == Opcode.CHANNEL:
            _keep_channel(rec, view[start:end])
    if end != len(records):
        raise ValueError("chunk records do not fill the chunk")
    return out


def _write(src: Path, dst: Path, data: bytes, rec: _Recovered, compression: str | None) -> RepairReport:
    """Write the recovered records as a complete MCAP file."""
    usable = {cid: ch for cid, ch in rec.channels.items() if ch[0] == 0 or ch[0] in rec.schemas}
    out = McapFileWriter(dst, compression)
    counts: dict[str, int] = {}
    n_total, first_ns, last_ns, skipped = 0, None, None, rec.skipped
    try:
        for sid in sorted({ch[0] for ch in usable.values() if ch[0] != 0}):
            out.add_schema(sid, *rec.schemas[sid])
        for cid, (sid, topic, encoding, meta) in sorted(usable.items()):
            out.add_channel(cid, sid, topic, encoding, meta)
            counts[topic] = 0
        for name, meta in rec.metadata:
            out.add_metadata(name, meta)
        for msgs in rec.chunks:
            keep = [m for m in msgs if m.channel_id in usable]
            skipped += len(msgs) - len(keep)
            if not keep:
                continue
            out.write_chunk(build_chunk([], keep))
            for m in keep:
                counts[usable[m.channel_id][1]] += 1
            lo = min(m.log_time_ns for m in keep)
            hi = max(m.log_time_ns for m in keep)
            first_ns = lo if first_ns is None else min(first_ns, lo)
            last_ns = hi if last_ns is None else max(last_ns, hi)
            n_total += len(keep)
        out.finish()
    except OSError as exc:
        out.abort()
        raise LogError(str(dst), f"cannot write the repaired log ({exc})") from None
    return RepairReport(
        src=src, dst=dst, messages_recovered=n_total,
        first_t_s=None if first_ns is None else first_ns / NS_PER_S,
        last_t_s=None if last_ns is None else last_ns / NS_PER_S,
        message_counts=counts,
        chunks_recovered=sum(1 for c in rec.chunks if c),
        chunks_dropped=rec.chunks_dropped, bytes_total=len(data), bytes_used=rec.bytes_used,
        had_footer=rec.had_footer, metadata_names=tuple(name for name, _ in rec.metadata),
        records_skipped=skipped, source_problems=rec.problems, copies_from_summary=tuple(rec.from_summary),
    )


__all__ = ["RepairReport", "repair_log"]
