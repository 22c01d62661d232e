"""The summary half of :func:`fdi_sim.flightlog.verify_log`: the summary's records, the footer,
the summary CRC, and the summary against the data section (schemas and channels byte for
byte, statistics, chunk indexes, metadata indexes, summary offsets).

A mixin of the verifier in ``verify.py``: it reads the verifier's state (``data``,
``data_spans``, ``chunks``, ``metadata_d``, the CRC results) and adds problems with ``add``.
"""
from __future__ import annotations

import struct
from typing import Any

from mcap.opcode import Opcode

from fdi_sim.flightlog.framing import SUMMARY_OPCODES, Span, opcode_name, parse_body, scan_section
from fdi_sim.flightlog.records import FOOTER_RECORD_BYTES, RECORD_HEAD_BYTES
from fdi_sim.units import NS_PER_S


class SummaryChecks:
    """Summary checks of the verifier (mixin; see the module docstring)."""

    data: bytes
    problems: list[Any]
    checks: list[str]

    def _scan_summary(self, start: int, footer_pos: int) -> None:
        """Read the summary's records (before the data section, whose damage they help name)."""
        spans, gaps, _ = scan_section(self.data, start, footer_pos, SUMMARY_OPCODES)
        self.sum_spans, self.sum_gaps = spans, gaps
        (off,) = struct.unpack_from("<Q", self.data, footer_pos + RECORD_HEAD_BYTES + 8)
        firsts = [s.start for s in spans if s.opcode == Opcode.SUMMARY_OFFSET and s.record is not None]
        self.offset_start = off if start < off < footer_pos else (firsts[0] if firsts else None)
        self.groups = [(s.record.group_opcode, s.record.group_start, s.record.group_start + s.record.group_length)
                       for s in spans if s.opcode == Opcode.SUMMARY_OFFSET and s.record is not None]
        # what the summary's indexes say starts where: (offset, opcode, index record)
        exp = self._expected = []
        for s in spans:
            r = s.record
            if s.opcode == Opcode.CHUNK_INDEX and r is not None:
                exp.append((r.chunk_start_offset, Opcode.CHUNK, r))
                for cid, off in r.message_index_offsets.items():
                    exp.append((off, Opcode.MESSAGE_INDEX, (cid, r.chunk_start_offset)))
            elif s.opcode == Opcode.METADATA_INDEX and r is not None:
                exp.append((r.offset, Opcode.METADATA, r))

    def _expected_part(self, offset: int, opcode: int, what: Any) -> str:
        """The name of the record the summary indexes at ``offset``."""
        if opcode == Opcode.CHUNK:
            return (f"chunk at offset {offset} (t_s {what.message_start_time / NS_PER_S:.3f}.."
                    f"{what.message_end_time / NS_PER_S:.3f})")
        if opcode == Opcode.MESSAGE_INDEX:
            return (f"message index at offset {offset} (channel {what[0]} {self.topics.get(what[0], '?')}) "
                    f"of the chunk at offset {what[1]}")
        return f"metadata record '{what.name}'"

    def _group_at(self, offset: int) -> int | None:
        for op, a, b in self.groups:
            if a <= offset < b:
                return op
        return None

    def _summary_part(self, s: Span, ordinal: int) -> str:
        """Name a summary record by the group the summary offsets put it in (its own opcode
        may be the damaged byte), then by its fields."""
        op = s.opcode if s.record is not None else (self._group_at(s.start) or s.opcode)
        if s.record is None and self.offset_start is not None and s.start >= self.offset_start:
            op = Opcode.SUMMARY_OFFSET  # the footer says the summary offsets are here
        r = s.record if s.opcode == op else None
        if op in (Opcode.SCHEMA, Opcode.CHANNEL):
            return self._part_of(Span(op, s.start, s.end, r), "summary")
        if op == Opcode.STATISTICS:
            return "statistics"
        if op == Opcode.CHUNK_INDEX:
            off = self.chunks[ordinal].span.start if ordinal < len(self.chunks) else (
                r.chunk_start_offset if r is not None else None)
            return f"chunk index of the chunk at offset {off}" if off is not None else f"chunk index {ordinal}"
        if op == Opcode.METADATA_INDEX:
            names = [self.meta_names.get(m.start, "?") for m in self.metadata_d]
            name = names[ordinal] if ordinal < len(names) else (r.name if r is not None else "?")
            return f"metadata index '{name}'"
        if op == Opcode.SUMMARY_OFFSET:
            if r is None:
                return f"summary offset record at offset {s.start}"
            # the group it points at names it (its group_opcode may be the damaged byte)
            at = [g[0] for g in self._actual_groups() if g[1] == r.group_start]
            return f"summary offset record ({opcode_name(at[0] if at else r.group_opcode)} group)"
        return f"{opcode_name(op)} record at offset {s.start} in the summary"

    def _actual_groups(self) -> list[tuple[int, int, int]]:
        """(opcode, start, end) of each run of records of one opcode in the summary."""
        actual: list[list[int]] = []
        for s in self.sum_spans:
            if s.opcode == Opcode.SUMMARY_OFFSET:
                continue
            if actual and actual[-1][0] == s.opcode and actual[-1][2] == s.start:
                actual[-1][2] = s.end
            else:
                actual.append([s.opcode, s.start, s.end])
        return [(a, b, c) for a, b, c in actual]

    def _check_summary(self, start: int, footer_pos: int) -> None:
        d = self.data
        ordinals: dict[int, int] = {}
        self.summary_named: list[tuple[Span, str]] = []
        for s in self.sum_spans:
            op = s.opcode if s.record is not None else (self._group_at(s.start) or s.opcode)
            if s.record is None and self.offset_start is not None and s.start >= self.offset_start:
                op = Opcode.SUMMARY_OFFSET
            k = ordinals[op] = ordinals.get(op, -1) + 1
            part = self._summary_part(s, k)
            self.summary_named.append((s, part))
            self.parts.append((s.start, s.end, part))
            if s.record is None:
                self.add(part, f"does not parse as {opcode_name(s.opcode)} ({s.error})", s.start)
            if s.reframed:
                self.add(part, "the record's opcode or length field is damaged", s.start)
        for g in self.sum_gaps:
            op = self._group_at(g.start)
            part = (self._summary_part(Span(op, g.start, g.end), 0) if op is not None
                    else f"summary section at offset {g.start}")
            self.parts.append((g.start, g.end, part))
            self.add(part, f"{g.reason}; bytes {g.start}..{g.end} hold no readable record", g.start)
        # the footer: opcode, length, where the summary and its offsets start, the summary CRC
        head = d[footer_pos:footer_pos + RECORD_HEAD_BYTES]
        if head != bytes([Opcode.FOOTER]) + (20).to_bytes(8, "little"):
            self.add("footer", f"record head {head.hex()} at offset {footer_pos}, expected opcode FOOTER, length 20",
                     footer_pos)
        foot = parse_body(Opcode.FOOTER, d[footer_pos + RECORD_HEAD_BYTES:footer_pos + FOOTER_RECORD_BYTES])
        if foot.summary_start != start:
            self.add("footer", f"summary_start {foot.summary_start}, the summary starts at {start} (after Data End)",
                     footer_pos)
        offs = [s.start for s in self.sum_spans if s.opcode == Opcode.SUMMARY_OFFSET]
        want = offs[0] if offs else 0
        if foot.summary_offset_start != want:
            self.add("footer", f"summary_offset_start {foot.summary_offset_start}, the summary offsets start at {want}",
                     footer_pos)
        body_end = max([s.end for s in self.sum_spans if s.opcode != Opcode.SUMMARY_OFFSET], default=start)
        if offs and offs[0] < body_end:
            self.add("summary offsets", "summary offset records are not all after the summary's other records", offs[0])
        if self.summary_crc is None:
            self.checks.append("summary CRC not recorded (0)")
        else:
            covered = footer_pos + RECORD_HEAD_BYTES + 16  # through summary_offset_start
            self.checks.append("summary CRC")
            if not self.summary_crc_ok:
                self._located("summary section (summary CRC)", *self.summary_crc, start, covered,
                              covered, "footer's summary")
        # the groups the summary offsets describe are the groups the summary holds
        real = set(self._actual_groups())
        for s, part in self.summary_named:
            if s.opcode == Opcode.SUMMARY_OFFSET and s.record is not None:
                r = s.record
                g = (r.group_opcode, r.group_start, r.group_start + r.group_length)
                if g not in real:
                    self.add(part, f"says the {opcode_name(g[0])} group is bytes {g[1]}..{g[2]}; the summary holds "
                             + ", ".join(f"{opcode_name(a)} {b}..{c}" for a, b, c in sorted(real, key=lambda x: x[1])),
                             s.start)
        described = {(op, a, b) for op, a, b in self.groups}
        for g in sorted(real - described, key=lambda x: x[1]):
            self.add("summary offsets", f"no summary offset record for the {opcode_name(g[0])} group at bytes "
                     f"{g[1]}..{g[2]}", g[1])
        self.checks.append("summary offsets, footer")

    # -- the summary against the data section ---------------------------------------------------
    def _blame(self, data_part: str, summary_part: str, what: str, offset: int | None) -> None:
        """Report a disagreement between a data-section record and its summary counterpart on
        the side whose CRC fails (both if neither or both fail)."""
        if self.data_crc_ok is False and self.summary_crc_ok is not False:
            self.add(data_part, what + " (the data section CRC fails, the summary CRC holds)", offset)
        elif self.summary_crc_ok is False and self.data_crc_ok is not False:
            self.add(summary_part, what + " (the summary CRC fails, the data section CRC holds)", offset)
        else:
            self.add(data_part, what, offset)
            self.add(summary_part, what, offset)

    def _cross_checks(self) -> None:
        summary = {Opcode.SCHEMA: {}, Opcode.CHANNEL: {}}
        for s, part in self.summary_named:
            if s.opcode in summary and s.record is not None:
                summary[s.opcode].setdefault(s.record.id, (s, part))
        for op, data_copies, kind in ((Opcode.SCHEMA, self.schemas_d, "schema"), (Opcode.CHANNEL, self.channels_d, "channel")):
            summ = summary[op]
            for rid in sorted(set(data_copies) | set(summ)):
                ds, ss = data_copies.get(rid), summ.get(rid)
                ref = ds if ds is not None else ss[0]
                d_part = self._part_of(Span(op, ref.start, ref.end, ref.record), "data section")
                s_part = self._part_of(Span(op, ref.start, ref.end, ref.record), "summary")
                if ds is None:
                    self._blame(d_part, s_part, f"the summary holds {kind} {rid}, the data section has no readable copy",
                                ss[0].start)
                elif ss is None:
                    self._blame(d_part, s_part, f"the data section holds {kind} {rid}, the summary has no readable copy",
                                ds.start)
                elif bytes(self._body(ds)) != bytes(self._body(ss[0])):
                    self._blame(d_part, s_part, f"the data-section copy (offset {ds.start}) and the summary copy "
                                f"(offset {ss[0].start}) differ", ds.start)
        self._check_statistics()
        self._check_chunk_indexes()
        self._check_metadata_indexes()
        self.checks.append("indexes against the data section")

    def _data_complete(self) -> bool:
        return (not self.data_gaps and all(s.record is not None for s in self.data_spans)
                and all(c.readable for c in self.chunks))

    def _check_statistics(self) -> None:
        stats = [(s, p) for s, p in self.summary_named if s.opcode == Opcode.STATISTICS and s.record is not None]
        if len(stats) != 1:
            if not any(p == "statistics" for p in (q.part for q in self.problems)):
                self.add("statistics", f"{len(stats)} readable Statistics records in the summary, expected 1")
            return
        s, _ = stats[0]
        r = s.record
        if not self._data_complete():
            self.checks.append("statistics not compared (the data section is damaged)")
            return
        counts: dict[int, int] = {}
        logs: list[int] = []
        for c in self.chunks:
            for cid, e in c.messages.items():
                counts[cid] = counts.get(cid, 0) + len(e)
                logs += [int(e[:, 0].min()), int(e[:, 0].max())]
        for cid, times in self.loose.items():
            counts[cid] = counts.get(cid, 0) + len(times)
            logs += [min(times), max(times)]
        want = {
            "message_count": sum(counts.values()), "schema_count": len(self.schemas_d),
            "channel_count": len(self.channels_d),
            "attachment_count": sum(1 for x in self.data_spans if x.opcode == Opcode.ATTACHMENT),
            "metadata_count": len(self.metadata_d), "chunk_count": len(self.chunks),
            "message_start_time": min(logs) if logs else 0, "message_end_time": max(logs) if logs else 0,
        }
        bad = [f"{k} {getattr(r, k)} (the data section: {v})" for k, v in want.items() if getattr(r, k) != v]
        got = {k: v for k, v in r.channel_message_counts.items() if v}
        if got != {k: v for k, v in counts.items() if v}:
            bad.append(f"channel_message_counts {got} (the data section: {counts})")
        if bad:
            self.add("statistics", "; ".join(bad), s.start)

    def _check_chunk_indexes(self) -> None:
        idx = [(s, p) for s, p in self.summary_named if s.opcode == Opcode.CHUNK_INDEX and s.record is not None]
        if len(idx) != len(self.chunks) and not self.data_gaps:
            self._blame("data section", "chunk index", f"{len(self.chunks)} chunks, {len(idx)} readable chunk indexes",
                        None)
        for (s, part), c in zip(idx, self.chunks):
            h, r = c.span.record, s.record
            if h is None:
                continue
            mi = [m for m in c.indexes if m.record is not None]
            want = {
                "chunk_start_offset": c.span.start, "chunk_length": c.span.end - c.span.start,
                "message_start_time": h.message_start_time, "message_end_time": h.message_end_time,
                "compression": h.compression, "compressed_size": h.records_length,
                "uncompressed_size": h.uncompressed_size,
                "message_index_offsets": {m.record.channel_id: m.start for m in mi},
                "message_index_length": (c.indexes[-1].end - c.indexes[0].start) if c.indexes else 0,
            }
            bad = [f"{k} {getattr(r, k)} (the chunk: {v})" for k, v in want.items() if getattr(r, k) != v]
            if bad:
                self._blame(c.part or self._chunk_part(c.span, None), part, "; ".join(bad), s.start)

    def _check_metadata_indexes(self) -> None:
        idx = [(s, p) for s, p in self.summary_named if s.opcode == Opcode.METADATA_INDEX and s.record is not None]
        by_offset = {m.start: m for m in self.metadata_d}
        for s, part in idx:
            r = s.record
            m = by_offset.get(r.offset)
            if m is None:
                self._blame(f"metadata record '{r.name}'", part,
                            f"the index points at offset {r.offset}, where no readable metadata record starts", s.start)
                continue
            if r.length != m.end - m.start or m.record is None or m.record.name != r.name:
                name = m.record.name if m.record is not None else "?"
                self._blame(self._metadata_part(m), part, f"the index says '{r.name}', {r.length} bytes; the record "
                            f"at offset {r.offset} is '{name}', {m.end - m.start} bytes", s.start)
        indexed = {s.record.offset for s, _ in idx}
        for m in self.metadata_d:
            if m.start not in indexed:
                self._blame(self._metadata_part(m), "metadata index", f"no metadata index points at the record at "
                            f"offset {m.start}", m.start)
