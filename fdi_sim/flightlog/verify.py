"""Check a flight log's integrity: every CRC of the MCAP specification, and every index
against what it indexes (``fdi-sim verify LOG``).

What is checked (MCAP specification, https://mcap.dev/spec):

- the magic at both ends; the Header is the first record; every record parses strictly
  (:func:`fdi_sim.flightlog.framing.parse_body`);
- every chunk: decompressed (zstd, lz4 or none), its uncompressed size and CRC, its records
  fill it exactly, its message start / end times are those of its messages;
- the Data End record's ``data_section_crc``: CRC32 of every byte from the opening magic to the
  Data End record; the footer's ``summary_crc``: CRC32 from the summary start through the
  footer's ``summary_offset_start`` field. The ``mcap`` readers skip both;
- message indexes hold exactly the (log time, offset) of every message of their channel in
  the chunk before them; chunk indexes agree with their chunk (position, length, times,
  compression, sizes, message index positions and length); metadata indexes point at a
  metadata record of their name and length; statistics equal the counts of the data section;
  the summary's schemas and channels equal the data section's copies byte for byte; summary
  offsets describe the summary's groups; the footer points at the summary and its offsets.

Every byte of a file written by :class:`~fdi_sim.flightlog.FlightLogWriter` is covered: the
data section CRC covers the magic and every data record, the summary CRC every summary record
and the footer's fields, and the summary CRC field and the closing magic are compared
themselves. When a CRC fails, :func:`~fdi_sim.flightlog.framing.locate_single_byte_error`
finds the byte a single change would explain and the report names the record holding it.
"""
from __future__ import annotations

import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from mcap.opcode import Opcode

from fdi_sim.errors import LogError
from fdi_sim.flightlog.reader import check_log_file
from fdi_sim.flightlog.framing import (
    DATA_OPCODES,
    SUMMARY_OPCODES,
    Gap,
    Span,
    decompress,
    locate_single_byte_error,
    opcode_name,
    parse_body,
    scan_section,
)
from fdi_sim.flightlog.verify_summary import SummaryChecks
from fdi_sim.flightlog.records import FOOTER_RECORD_BYTES, MCAP_MAGIC, RECORD_HEAD_BYTES, scan_records
from fdi_sim.units import NS_PER_S

#: Data End record: opcode, length, data_section_crc u32
_DATA_END_BYTES = RECORD_HEAD_BYTES + 4
#: topics named in a chunk's part name before "+N more"
_TOPICS_SHOWN = 4


@dataclass(frozen=True)
class Problem:
    """One thing wrong in a log.

    Attributes
    ----------
    part : str
        The damaged part: ``"header"``, ``"chunk at offset N (topics, t_s a..b s)"``,
        ``"message index at offset N (...)"``, ``"metadata record 'scenario'"``,
        ``"channel record 3 (/truth/state) in the data section"``, ``"statistics"``,
        ``"chunk index of the chunk at offset N"``, ``"metadata index 'scenario'"``,
        ``"summary offset record (CHANNEL group)"``, ``"data section (Data End CRC)"``,
        ``"summary section (summary CRC)"``, ``"footer"``, ...
    what : str
        What is wrong.
    offset : int or None
        File offset of the damage or of the damaged record [bytes].
    """

    part: str
    what: str
    offset: int | None = None

    def format(self) -> str:
        """``part: what``."""
        return f"{self.part}: {self.what}"


@dataclass(frozen=True)
class VerifyReport:
    """The result of :func:`verify_log`.

    Attributes
    ----------
    path : Path
    size_bytes : int
    problems : tuple of Problem
        Empty for an intact log.
    checks : tuple of str
        What was verified (CRCs, indexes), for the terminal.
    """

    path: Path
    size_bytes: int
    problems: tuple[Problem, ...]
    checks: tuple[str, ...] = ()

    @property
    def ok(self) -> bool:
        """No problem found."""
        return not self.problems

    def parts(self) -> tuple[str, ...]:
        """The damaged parts, each once, in report order."""
        return tuple(dict.fromkeys(p.part for p in self.problems))

    def format(self) -> str:
        """A terminal report (what ``fdi-sim verify LOG`` prints)."""
        head = f"{self.path}  ({self.size_bytes} bytes): " + (
            "intact" if self.ok else f"DAMAGED, {len(self.problems)} problems")
        lines = [head, "checked: " + "; ".join(self.checks)]
        lines += [f"  {p.format()}" for p in self.problems]
        if not self.ok:
            lines.append(f"rebuild what is intact with `fdi-sim repair {self.path}`")
        return "\n".join(lines)


def looks_like_mcap(data: bytes) -> bool:
    """The file opens or ends with the MCAP magic, or opens with it but for one byte."""
    n = len(MCAP_MAGIC)
    if len(data) < n:
        return MCAP_MAGIC.startswith(data) and len(data) > 0
    head_diff = sum(a != b for a, b in zip(data[:n], MCAP_MAGIC))
    return head_diff <= 1 or (len(data) >= 2 * n and data[-n:] == MCAP_MAGIC)


def verify_log(path: str | Path) -> VerifyReport:
    """Check every CRC and every index of a flight log (see the module docstring).

    Parameters
    ----------
    path : str or Path
        An MCAP file.

    Returns
    -------
    VerifyReport
        ``.ok`` False and ``.problems`` naming each damaged part for a damaged or cut-off file.

    Raises
    ------
    LogError
        The file cannot be read, or is not an MCAP file at all (neither end holds the magic).
    """
    p = Path(path)
    check_log_file(p)
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise LogError(str(path), f"cannot read the flight log ({exc.strerror})") from None
    if not looks_like_mcap(data):
        raise LogError(str(p), "not an MCAP file (neither end holds the MCAP magic bytes); "
                       "pass a flight log written by `fdi-sim run`")
    v = scan_log(data, keep_records=False)
    return VerifyReport(p, len(data), tuple(v.problems), tuple(v.checks))


def scan_log(data: bytes, *, keep_records: bool = True) -> _Verifier:
    """Run every check on the bytes of a log; the result also carries what was found
    (``data_spans``, ``sum_spans``, ``chunks`` with their decompressed records,
    ``data_crc_ok``, ``summary_crc_ok``, ``problems``). Package-internal: used by repair.
    ``keep_records=False`` drops each chunk's decompressed records once checked (memory)."""
    v = _Verifier(data)
    v.keep_records = keep_records
    v.run()
    return v


@dataclass
class _Chunk:
    span: Span
    records: bytes | None = None
    messages: dict[int, np.ndarray] = field(default_factory=dict)  # cid -> (n, 2) log, offset
    indexes: list[Span] = field(default_factory=list)  # the Message Index records after it
    part: str = ""
    readable: bool = False  # decompressed, CRC and records checked (``records`` kept on request)


class _Verifier(SummaryChecks):
    """The state of one check; ``run`` fills ``problems`` and ``checks``."""

    def __init__(self, data: bytes) -> None:
        self.data = data
        self.keep_records = True
        self.problems: list[Problem] = []
        self.checks: list[str] = []
        self.topics: dict[int, str] = {}
        self.schema_names: dict[int, str] = {}
        self.meta_names: dict[int, str] = {}  # metadata record offset -> name
        self.sum_spans: list[Span] = []
        self.sum_gaps: list[Gap] = []
        self.groups: list[tuple[int, int, int]] = []
        self._expected: list[tuple[int, int, Any]] = []
        self.offset_start: int | None = None
        self.data_crc: tuple[int, int] | None = None  # (stored, computed)
        self.summary_crc: tuple[int, int] | None = None
        self.parts: list[tuple[int, int, str]] = []  # (start, end, part) for CRC location
        self.data_crc_ok: bool | None = None
        self.summary_crc_ok: bool | None = None

    def add(self, part: str, what: str, offset: int | None = None) -> None:
        self.problems.append(Problem(part, what, offset))

    # -- layout ----------------------------------------------------------------------------
    def run(self) -> None:
        d = self.data
        n = len(d)
        if d[:len(MCAP_MAGIC)] != MCAP_MAGIC:
            self.add("header (leading magic)", f"the first 8 bytes are {d[:8]!r}, not the MCAP magic", 0)
        footer_pos = n - len(MCAP_MAGIC) - FOOTER_RECORD_BYTES
        tail_ok = n >= 2 * len(MCAP_MAGIC) + FOOTER_RECORD_BYTES and d[-len(MCAP_MAGIC):] == MCAP_MAGIC
        footer_like = footer_pos > len(MCAP_MAGIC) and d[footer_pos] == Opcode.FOOTER
        complete = tail_ok or footer_like or self._data_end_at(footer_pos - _DATA_END_BYTES) is not None
        data_end = self._find_data_end(footer_pos) if complete else None
        if not complete or data_end is None:
            self._check_data_section(len(MCAP_MAGIC), n, cut_off=True)
            self.add("footer", f"missing: the file ends at byte {n} without Data End, summary and "
                     "footer (cut off by a crash, or never closed)", n)
            return
        if not tail_ok:
            self.add("footer (closing magic)", f"the last 8 bytes are {d[-8:]!r}, not the MCAP magic", n - 8)
        self.parts.append((footer_pos, n, "footer"))
        self._scan_summary(data_end + _DATA_END_BYTES, footer_pos)
        self._crcs(data_end, footer_pos)
        self._check_data_section(len(MCAP_MAGIC), data_end, cut_off=False)
        self._check_data_crc(data_end)
        self._check_summary(data_end + _DATA_END_BYTES, footer_pos)
        self._cross_checks()

    def _data_end_at(self, pos: int) -> int | None:
        if pos < len(MCAP_MAGIC) or pos + _DATA_END_BYTES > len(self.data):
            return None
        ok = self.data[pos] == Opcode.DATA_END and self.data[pos + 1:pos + 9] == (4).to_bytes(8, "little")
        return pos if ok else None

    def _find_data_end(self, footer_pos: int) -> int | None:
        """The Data End record: where the footer's summary_start says, else the last record
        with Data End's opcode and length 4 that a summary record or the footer follows."""
        d = self.data
        try:
            foot = parse_body(Opcode.FOOTER, d[footer_pos + RECORD_HEAD_BYTES:footer_pos + FOOTER_RECORD_BYTES])
            at = self._data_end_at(foot.summary_start - _DATA_END_BYTES)
            if at is not None:
                return at
        except ValueError:
            pass
        pattern = bytes([Opcode.DATA_END]) + (4).to_bytes(8, "little")
        pos = d.rfind(pattern, 0, footer_pos)
        while pos >= len(MCAP_MAGIC):
            nxt = pos + _DATA_END_BYTES
            if nxt == footer_pos or d[nxt] in SUMMARY_OPCODES:
                return pos
            pos = d.rfind(pattern, 0, pos)
        # the Data End record itself is damaged: the summary starts at the footer's word
        # if that is plausible, else there is no telling where the data section ends
        try:
            start = foot.summary_start
            if len(MCAP_MAGIC) + _DATA_END_BYTES <= start <= footer_pos:
                self.add("data section (Data End record)", f"no Data End record before the summary at offset {start}",
                         start - _DATA_END_BYTES)
                return start - _DATA_END_BYTES
        except UnboundLocalError:
            pass
        return None

    # -- data section ------------------------------------------------------------------------
    def _check_data_section(self, start: int, end: int, *, cut_off: bool) -> None:
        d = self.data
        spans, gaps, stop = scan_section(d, start, end, DATA_OPCODES, first=Opcode.HEADER, cut_off_ok=cut_off)
        if cut_off and stop < end:
            self.add("data section", f"cut off inside a record at offset {stop}", stop)
        self.data_spans, self.data_gaps = spans, gaps
        self._names()
        self.schemas_d: dict[int, Span] = {}
        self.channels_d: dict[int, Span] = {}
        self.metadata_d: list[Span] = []
        self.chunks: list[_Chunk] = []
        self.loose: dict[int, list[int]] = {}
        if not spans or spans[0].opcode != Opcode.HEADER or spans[0].start != start:
            self.add("header", f"the first record (offset {start}) is not a readable Header record", start)
            self.parts.append((0, spans[0].start if spans else end, "header"))
        else:
            self.parts.append((0, spans[0].end, "header"))
            if spans[0].record is None:
                self.add("header", f"does not parse ({spans[0].error})", start)
            elif spans[0].reframed:
                self.add("header", "its opcode or length field is damaged (its body reads as a Header "
                         "between the magic and the next intact record)", start)
        chunk: _Chunk | None = None
        expected_at = {e[0]: e for e in self._expected} if self.summary_crc_ok is not False else {}
        for s in spans[1:] if spans and spans[0].opcode == Opcode.HEADER else spans:
            if s.opcode != Opcode.MESSAGE_INDEX:
                chunk = None
            exp = expected_at.get(s.start)
            if exp is not None and exp[1] != s.opcode:
                # the summary indexes another record here: its opcode byte is the damaged one
                part = self._expected_part(*exp)
                self.parts.append((s.start, s.end, part))
                self.add(part, f"the summary indexes a {opcode_name(exp[1])} record at offset {s.start}; "
                         f"the record there has opcode {opcode_name(s.opcode)}", s.start)
                continue
            if s.opcode == Opcode.HEADER:
                self.add("header", f"a second Header record at offset {s.start}", s.start)
            elif s.opcode == Opcode.SCHEMA:
                self._copy(self.schemas_d, s, "data section")
            elif s.opcode == Opcode.CHANNEL:
                self._copy(self.channels_d, s, "data section")
            elif s.opcode == Opcode.METADATA:
                self.metadata_d.append(s)
                self.parts.append((s.start, s.end, self._metadata_part(s)))
                if s.record is None:
                    self.add(self._metadata_part(s), f"does not parse ({s.error})", s.start)
            elif s.opcode == Opcode.CHUNK:
                chunk = self._chunk(s)
                self.chunks.append(chunk)
            elif s.opcode == Opcode.MESSAGE_INDEX:
                self._message_index(s, chunk)
            elif s.opcode == Opcode.MESSAGE:
                self.parts.append((s.start, s.end, f"message record at offset {s.start}"))
                if s.record is not None:
                    self.loose.setdefault(s.record.channel_id, []).append(s.record.log_time)
            elif s.opcode == Opcode.DATA_END:
                self.add("data section (Data End record)", f"a Data End record at offset {s.start} "
                         "before the end of the data section", s.start)
            else:
                self.parts.append((s.start, s.end, f"{opcode_name(s.opcode)} record at offset {s.start}"))
            if s.reframed:
                self.add(self.part_at(s.start), "the record's opcode or length field is damaged (its body "
                         "reads as this record between two intact ones)", s.start)
        for g in gaps:
            self._gap(g, "data section")
        self.checks.append(f"{len(self.chunks)} chunk CRCs")

    def _crcs(self, data_end: int, footer_pos: int) -> None:
        """The stored and computed data section and summary CRCs (0 stored: not recorded)."""
        d = self.data
        (stored,) = struct.unpack_from("<I", d, data_end + RECORD_HEAD_BYTES)
        if stored:
            self.data_crc = (stored, zlib.crc32(memoryview(d)[:data_end]))
            self.data_crc_ok = self.data_crc[0] == self.data_crc[1]
        (stored,) = struct.unpack_from("<I", d, footer_pos + RECORD_HEAD_BYTES + 16)
        if stored:
            covered = footer_pos + RECORD_HEAD_BYTES + 16  # through summary_offset_start
            self.summary_crc = (stored, zlib.crc32(memoryview(d)[data_end + _DATA_END_BYTES:covered]))
            self.summary_crc_ok = self.summary_crc[0] == self.summary_crc[1]

    def _names(self) -> None:
        """Topic, schema and metadata names for the report, from the copy most likely intact:
        a section whose CRC holds first, then one without a CRC, then a damaged one."""
        rank = {True: 0, None: 1, False: 2}
        sources = sorted([(rank[self.data_crc_ok], 0, self.data_spans), (rank[self.summary_crc_ok], 1, self.sum_spans)],
                         key=lambda x: x[:2])
        meta_data = {s.start: s.record.name for s in self.data_spans
                     if s.opcode == Opcode.METADATA and s.record is not None}
        meta_index = {s.record.offset: s.record.name for s in self.sum_spans
                      if s.opcode == Opcode.METADATA_INDEX and s.record is not None}
        for _, which, spans in sources:
            for s in spans:
                if s.record is None or s.reframed:
                    continue
                if s.opcode == Opcode.CHANNEL:
                    self.topics.setdefault(s.record.id, s.record.topic)
                elif s.opcode == Opcode.SCHEMA:
                    self.schema_names.setdefault(s.record.id, s.record.name)
            for off, name in (meta_data if which == 0 else meta_index).items():
                self.meta_names.setdefault(off, name)

    def _copy(self, table: dict[int, Span], s: Span, section: str) -> None:
        part = self._part_of(s, section)
        self.parts.append((s.start, s.end, part))
        if s.record is None:
            self.add(part, f"does not parse ({s.error})", s.start)
            return
        if s.record.id in table and bytes(self._body(table[s.record.id])) != bytes(self._body(s)):
            self.add(part, f"two different records with id {s.record.id} in the {section}", s.start)
        table.setdefault(s.record.id, s)

    def _body(self, s: Span) -> memoryview:
        return memoryview(self.data)[s.start + RECORD_HEAD_BYTES:s.end]

    def _part_of(self, s: Span, section: str = "data section") -> str:
        """The part name of a record (by its opcode, id and name)."""
        rec = s.record
        rid = rec.id if rec is not None and hasattr(rec, "id") else int.from_bytes(
            self.data[s.start + 9:s.start + 11], "little")
        if s.opcode == Opcode.HEADER:
            return "header"
        if s.opcode == Opcode.SCHEMA:
            return f"schema record {rid} ({self.schema_names.get(rid, '?')}) in the {section}"
        if s.opcode == Opcode.CHANNEL:
            return f"channel record {rid} ({self.topics.get(rid, '?')}) in the {section}"
        if s.opcode == Opcode.METADATA:
            return self._metadata_part(s)
        if s.opcode == Opcode.CHUNK:
            return self._chunk_part(s, None)
        return f"{opcode_name(s.opcode)} record at offset {s.start}"

    def _metadata_part(self, s: Span) -> str:
        name = self.meta_names.get(s.start)
        return f"metadata record '{name}'" if name is not None else f"metadata record at offset {s.start}"

    def _chunk_part(self, s: Span, cids: Any) -> str:
        head = s.record
        if not cids:  # unreadable: the channels its chunk index lists
            cids = [c for e in self._expected if e[0] == s.start and e[1] == Opcode.CHUNK
                    for c in e[2].message_index_offsets]
        topics = [self.topics.get(c, f"channel {c}") for c in sorted(cids)]
        shown = ", ".join(topics[:_TOPICS_SHOWN]) + (f" +{len(topics) - _TOPICS_SHOWN} more"
                                                     if len(topics) > _TOPICS_SHOWN else "")
        span = (f"t_s {head.message_start_time / NS_PER_S:.3f}..{head.message_end_time / NS_PER_S:.3f}"
                if head is not None else "times unreadable")
        return f"chunk at offset {s.start} ({shown or 'channels unknown'}, {span})"

    def _chunk(self, s: Span) -> _Chunk:
        c = _Chunk(s)
        if s.record is None:
            part = self._chunk_part(s, None)
            self.add(part, f"does not parse ({s.error})", s.start)
            self.parts.append((s.start, s.end, part))
            c.part = part
            return c
        head = s.record
        problem = ""
        try:
            c.records = decompress(self.data, head)
        except ValueError as exc:
            problem = str(exc)
        if c.records is not None:
            found: dict[int, list[tuple[int, int]]] = {}
            end = 0
            for opcode, body, length in scan_records(c.records):
                end = body + length
                if opcode == Opcode.MESSAGE:
                    if length < 22:
                        problem = f"a message record at {body - 9} is too short"
                        break
                    cid, _seq, log = struct.unpack_from("<HIQ", c.records, body)
                    found.setdefault(cid, []).append((log, body - RECORD_HEAD_BYTES))
                elif opcode not in (Opcode.SCHEMA, Opcode.CHANNEL):
                    problem = f"holds a {opcode_name(opcode)} record at {body - 9}"
            if not problem and end != len(c.records):
                problem = f"its records stop at byte {end} of {len(c.records)}"
            c.messages = {cid: np.array(sorted(v), dtype=np.uint64).reshape(-1, 2) for cid, v in found.items()}
            logs = [int(a[:, 0].min()) for a in c.messages.values()] + [int(a[:, 0].max()) for a in c.messages.values()]
            if not problem and logs and (min(logs), max(logs)) != (head.message_start_time, head.message_end_time):
                problem = (f"message_start_time / message_end_time {head.message_start_time} / "
                           f"{head.message_end_time} ns, its messages span {min(logs)} / {max(logs)} ns")
        part = self._chunk_part(s, c.messages.keys())
        c.part = part
        c.readable = c.records is not None
        if not self.keep_records:
            c.records = None
        self.parts.append((s.start, s.end, part))
        if problem:
            self.add(part, problem, s.start)
        return c

    def _message_index(self, s: Span, chunk: _Chunk | None) -> None:
        rec = s.record
        cid = rec.channel_id if rec is not None else int.from_bytes(self.data[s.start + 9:s.start + 11], "little")
        owner = f" of the chunk at offset {chunk.span.start}" if chunk is not None else ""
        part = f"message index at offset {s.start} (channel {cid} {self.topics.get(cid, '?')}){owner}"
        self.parts.append((s.start, s.end, part))
        if rec is None:
            self.add(part, f"does not parse ({s.error})", s.start)
            return
        if chunk is None:
            self.add(part, "follows no chunk", s.start)
            return
        chunk.indexes.append(s)
        if not chunk.readable:
            return
        want = chunk.messages.get(cid)
        got = rec.entries
        if want is None:
            self.add(part, f"the chunk holds no message of channel {cid}", s.start)
        elif got.shape != want.shape or not np.array_equal(got[np.lexsort((got[:, 1], got[:, 0]))], want):
            self.add(part, f"{len(got)} entries do not match the chunk's {len(want)} messages of channel "
                     f"{cid} (log time, offset)", s.start)

    def _gap(self, g: Gap, section: str) -> None:
        expected = [self._expected_part(*e) for e in self._expected if g.start <= e[0] < g.end]
        op = self.data[g.start]
        if expected:
            part = expected[0]
        elif op in (Opcode.SCHEMA, Opcode.CHANNEL, Opcode.METADATA, Opcode.CHUNK) or (op == Opcode.HEADER and g.start == 8):
            part = "header" if op == Opcode.HEADER else self._part_of(Span(op, g.start, g.end))
        else:
            part = f"{section} at offset {g.start}"
        self.parts.append((g.start, g.end, part))
        self.add(part, f"{g.reason}; bytes {g.start}..{g.end} hold no readable record", g.start)

    def _check_data_crc(self, data_end: int) -> None:
        self.parts.append((data_end, data_end + _DATA_END_BYTES, "data section (Data End record)"))
        if self.data_crc is None:
            self.checks.append("data section CRC not recorded (0)")
            return
        self.checks.append("data section CRC")
        stored, computed = self.data_crc
        if self.data_crc_ok:
            return
        self._located("data section (Data End CRC)", stored, computed, 0, data_end,
                      data_end + RECORD_HEAD_BYTES, "Data End")

    def _located(self, part: str, stored: int, computed: int, start: int, end: int, crc_at: int,
                 what: str) -> None:
        """Report a CRC mismatch over ``[start, end)`` and the part a one-byte change explains."""
        hits = [start + h for h in locate_single_byte_error(stored, computed, end - start)]
        diff = stored ^ computed
        field_hit = sum(1 for k in range(4) if (diff >> (8 * k)) & 0xFF) == 1
        where = []
        for h in hits:
            where.append(f"offset {h} ({self.part_at(h)})")
        text = (f"CRC32 of bytes {start}..{end} is 0x{computed:08x}, the {what} record holds 0x{stored:08x}")
        if where:
            text += "; a single changed byte at " + " or ".join(where) + " would explain it"
        if field_hit:
            text += "; or the stored CRC itself is damaged (one byte differs)"
        self.add(part, text, hits[0] if hits else crc_at)
        named = {p.part for p in self.problems}
        if field_hit and not hits:
            self.add(self.part_at(crc_at), f"its stored {what} CRC differs from the computed one in one byte", crc_at)
        if len(hits) == 1 and self.part_at(hits[0]) not in named:
            self.add(self.part_at(hits[0]), f"byte {hits[0]} differs from what the {what} CRC covers "
                     "(located from the CRC difference)", hits[0])

    def part_at(self, offset: int) -> str:
        best = None
        for a, b, p in self.parts:
            if a <= offset < b and (best is None or b - a < best[1] - best[0]):
                best = (a, b, p)
        return best[2] if best else f"byte {offset}"


__all__ = ["Problem", "VerifyReport", "looks_like_mcap", "verify_log"]
