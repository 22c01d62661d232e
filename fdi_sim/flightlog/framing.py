"""Strict MCAP record parsing, a record scan that resynchronises after damage, and CRC32
single-byte error location: the ground shared by :mod:`~fdi_sim.flightlog.verify` and
:mod:`~fdi_sim.flightlog.repair`.

References: MCAP specification (https://mcap.dev/spec), "Records" (opcode u8, record length
u64, body) and each record's field list. Bodies are decoded into the ``mcap`` library's record
dataclasses, but more strictly than its readers do: every string must be UTF-8, every map must
end exactly at its declared length without repeated keys, and the fields must fill the body to
its last byte. A damaged record therefore rarely parses, which is what makes resynchronisation
safe: after a record that does not parse, the scan looks for the next offset where two
consecutive records parse (or one that ends the section exactly).
"""
from __future__ import annotations

import re
import struct
import zlib
from dataclasses import dataclass
from typing import Any

import numpy as np
from mcap.opcode import Opcode
from mcap.records import (
    Attachment,
    AttachmentIndex,
    Channel,
    ChunkIndex,
    DataEnd,
    Footer,
    Header,
    Message,
    Metadata,
    MetadataIndex,
    Schema,
    Statistics,
    SummaryOffset,
)
from numpy.typing import NDArray

from fdi_sim.flightlog.records import RECORD_HEAD_BYTES

#: records allowed in the data section (MCAP spec, "Data Section"); the header only first
DATA_OPCODES: frozenset[int] = frozenset({
    Opcode.SCHEMA, Opcode.CHANNEL, Opcode.MESSAGE, Opcode.CHUNK, Opcode.MESSAGE_INDEX,
    Opcode.ATTACHMENT, Opcode.METADATA, Opcode.DATA_END})
#: records allowed in the summary and summary offset sections (MCAP spec, "Summary Section")
SUMMARY_OPCODES: frozenset[int] = frozenset({
    Opcode.SCHEMA, Opcode.CHANNEL, Opcode.STATISTICS, Opcode.CHUNK_INDEX, Opcode.ATTACHMENT_INDEX,
    Opcode.METADATA_INDEX, Opcode.SUMMARY_OFFSET})
#: a record length above this is implausible (the top three bytes of the u64 are zero below 1 TiB)
MAX_RECORD_BYTES: int = 1 << 40


def opcode_name(opcode: int) -> str:
    """``"CHANNEL"`` for 0x04; ``"0x2a"`` for an opcode the specification does not define."""
    try:
        return Opcode(opcode).name
    except ValueError:
        return f"0x{opcode:02x}"


@dataclass(frozen=True, eq=False)
class MessageIndexRecord:
    """A Message Index record (op 0x07): channel id and (log time [ns], offset [bytes]) rows."""

    channel_id: int
    entries: NDArray[np.uint64]


@dataclass(frozen=True, eq=False)
class ChunkHead:
    """The fields of a Chunk record (op 0x06) without decompressing it.

    ``records_start`` is the file offset of the compressed records [bytes]; ``records_length``
    their length [bytes].
    """

    message_start_time: int
    message_end_time: int
    uncompressed_size: int
    uncompressed_crc: int
    compression: str
    records_start: int
    records_length: int


class _Cursor:
    """Read little-endian fields from one record body; every read is bounds-checked."""

    def __init__(self, body: bytes | memoryview, base: int = 0) -> None:
        self.b = body
        self.p = 0
        self.base = base  # file offset of the body, for ChunkHead.records_start

    def take(self, n: int) -> bytes:
        if n < 0 or self.p + n > len(self.b):
            raise ValueError(f"a field runs {self.p + n - len(self.b)} bytes past the record end")
        out = bytes(self.b[self.p:self.p + n])
        self.p += n
        return out

    def u(self, fmt: str) -> int:
        size = struct.calcsize(fmt)
        (v,) = struct.unpack("<" + fmt, self.take(size))
        return int(v)

    def string(self) -> str:
        return self.take(self.u("I")).decode("utf-8")

    def str_map(self) -> dict[str, str]:
        n = self.u("I")
        end = self.p + n
        if end > len(self.b):
            raise ValueError("a map runs past the record end")
        out: dict[str, str] = {}
        while self.p < end:
            k, v = self.string(), self.string()
            if k in out:
                raise ValueError(f"map key {k!r} repeated")
            out[k] = v
        if self.p != end:
            raise ValueError("a map's entries overrun its declared length")
        return out

    def int_map(self, key: str, value: str) -> dict[int, int]:
        n = self.u("I")
        width = struct.calcsize("<" + key + value)
        if n % width:
            raise ValueError(f"map length {n} is not a multiple of its entry size {width}")
        out: dict[int, int] = {}
        for _ in range(n // width):
            k, v = self.u(key), self.u(value)
            if k in out:
                raise ValueError(f"map key {k} repeated")
            out[k] = v
        return out

    def done(self) -> None:
        if self.p != len(self.b):
            raise ValueError(f"{len(self.b) - self.p} bytes left over after the last field")


def parse_body(opcode: int, body: bytes | memoryview, base: int = 0) -> Any:
    """Decode one record body strictly.

    Parameters
    ----------
    opcode : int
    body : bytes-like
        The record without its opcode and length.
    base : int
        File offset of ``body`` [bytes] (for :class:`ChunkHead`).

    Returns
    -------
    The ``mcap`` record dataclass, or :class:`ChunkHead` / :class:`MessageIndexRecord`.

    Raises
    ------
    ValueError
        The body does not hold exactly the record's fields, or a string is not UTF-8.
    """
    c = _Cursor(body, base)
    rec: Any
    if opcode == Opcode.HEADER:
        rec = Header(profile=c.string(), library=c.string())
    elif opcode == Opcode.SCHEMA:
        sid, name, enc = c.u("H"), c.string(), c.string()
        rec = Schema(id=sid, name=name, encoding=enc, data=c.take(c.u("I")))
    elif opcode == Opcode.CHANNEL:
        cid, sid, topic, enc = c.u("H"), c.u("H"), c.string(), c.string()
        rec = Channel(id=cid, schema_id=sid, topic=topic, message_encoding=enc, metadata=c.str_map())
    elif opcode == Opcode.MESSAGE:
        cid, seq, log, pub = c.u("H"), c.u("I"), c.u("Q"), c.u("Q")
        rec = Message(channel_id=cid, sequence=seq, log_time=log, publish_time=pub, data=c.take(len(body) - 22))
    elif opcode == Opcode.CHUNK:
        start, end, usize, crc = c.u("Q"), c.u("Q"), c.u("Q"), c.u("I")
        comp = c.string()
        n = c.u("Q")
        rec = ChunkHead(start, end, usize, crc, comp, base + c.p, n)
        c.take(n)
    elif opcode == Opcode.MESSAGE_INDEX:
        cid, n = c.u("H"), c.u("I")
        if n % 16:
            raise ValueError(f"message index entries' length {n} is not a multiple of 16")
        raw = c.take(n)
        rec = MessageIndexRecord(cid, np.frombuffer(raw, dtype="<u8").reshape(-1, 2))
    elif opcode == Opcode.METADATA:
        rec = Metadata(name=c.string(), metadata=c.str_map())
    elif opcode == Opcode.ATTACHMENT:
        log, create, name, media = c.u("Q"), c.u("Q"), c.string(), c.string()
        rec = Attachment(log_time=log, create_time=create, name=name, media_type=media, data=c.take(c.u("Q")))
        crc = c.u("I")
        # attachment crc: CRC32 of every field before it (MCAP spec, "Attachment"); 0 = none
        if crc != 0 and zlib.crc32(bytes(body[:c.p - 4])) != crc:
            raise ValueError("attachment CRC mismatch")
    elif opcode == Opcode.DATA_END:
        rec = DataEnd(data_section_crc=c.u("I"))
    elif opcode == Opcode.STATISTICS:
        fields = [c.u(f) for f in "QHIIIIQQ"]
        rec = Statistics(message_count=fields[0], schema_count=fields[1], channel_count=fields[2],
                         attachment_count=fields[3], metadata_count=fields[4], chunk_count=fields[5],
                         message_start_time=fields[6], message_end_time=fields[7],
                         channel_message_counts=c.int_map("H", "Q"))
    elif opcode == Opcode.CHUNK_INDEX:
        start, end, off, length = c.u("Q"), c.u("Q"), c.u("Q"), c.u("Q")
        mio = c.int_map("H", "Q")
        rec = ChunkIndex(message_start_time=start, message_end_time=end, chunk_start_offset=off,
                         chunk_length=length, message_index_offsets=mio, message_index_length=c.u("Q"),
                         compression=c.string(), compressed_size=c.u("Q"), uncompressed_size=c.u("Q"))
    elif opcode == Opcode.METADATA_INDEX:
        rec = MetadataIndex(offset=c.u("Q"), length=c.u("Q"), name=c.string())
    elif opcode == Opcode.ATTACHMENT_INDEX:
        rec = AttachmentIndex(offset=c.u("Q"), length=c.u("Q"), log_time=c.u("Q"), create_time=c.u("Q"),
                              data_size=c.u("Q"), name=c.string(), media_type=c.string())
    elif opcode == Opcode.SUMMARY_OFFSET:
        rec = SummaryOffset(group_opcode=c.u("B"), group_start=c.u("Q"), group_length=c.u("Q"))
    elif opcode == Opcode.FOOTER:
        rec = Footer(summary_start=c.u("Q"), summary_offset_start=c.u("Q"), summary_crc=c.u("I"))
    else:
        raise ValueError(f"opcode {opcode_name(opcode)} is not a record of the MCAP specification")
    c.done()
    return rec


def decompress(data: bytes | memoryview, head: ChunkHead) -> bytes:
    """The records of a chunk, CRC-checked (a stored CRC of 0 means "not computed").

    Raises
    ------
    ValueError
        Unknown compression, data that does not decompress, wrong size or CRC mismatch.
    """
    packed = bytes(data[head.records_start:head.records_start + head.records_length])
    try:
        if head.compression == "zstd":
            import zstandard
            # the stored size bounds the output; zstd frames normally carry their content size
            out = zstandard.ZstdDecompressor().decompress(packed, max_output_size=min(head.uncompressed_size, 1 << 30))
        elif head.compression == "lz4":
            import lz4.frame
            out = lz4.frame.decompress(packed)
        elif head.compression == "":
            out = packed
        else:
            raise ValueError(f"unsupported chunk compression {head.compression!r}")
    except Exception as exc:  # zstandard.ZstdError, lz4's RuntimeError: damaged data
        if isinstance(exc, ValueError) and "unsupported" in str(exc):
            raise
        raise ValueError(f"the records do not decompress ({type(exc).__name__}: {exc})") from None
    if len(out) != head.uncompressed_size:
        raise ValueError(f"the records decompress to {len(out)} bytes, the chunk says {head.uncompressed_size}")
    if head.uncompressed_crc != 0 and zlib.crc32(out) != head.uncompressed_crc:
        raise ValueError(f"uncompressed CRC mismatch (computed 0x{zlib.crc32(out):08x}, "
                         f"stored 0x{head.uncompressed_crc:08x})")
    return out


# --- scanning with resynchronisation ---------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Span:
    """One record found by :func:`scan_section`.

    Attributes
    ----------
    opcode : int
    start, end : int
        File offsets of the opcode byte and one past the record [bytes].
    record : object or None
        The parsed body (:func:`parse_body`), None if it does not parse.
    error : str
        Why the body does not parse ("" if it does).
    reframed : bool
        The record's own opcode or length byte was wrong: it was recognised from its body
        between two intact records (``opcode`` is then the recognised one).
    """

    opcode: int
    start: int
    end: int
    record: Any = None
    error: str = ""
    reframed: bool = False


@dataclass(frozen=True)
class Gap:
    """Bytes ``[start, end)`` that hold no recognisable record (damage) [bytes]; ``reason``
    says what was wrong at ``start``."""

    start: int
    end: int
    reason: str


def _head(data: bytes | memoryview, pos: int, end: int, allowed: frozenset[int]) -> tuple[int, int] | None:
    """(opcode, record end) if a record of an allowed opcode fits in ``[pos, end)``."""
    if pos + RECORD_HEAD_BYTES > end:
        return None
    opcode, length = struct.unpack_from("<BQ", data, pos)
    if opcode not in allowed or length > MAX_RECORD_BYTES or pos + RECORD_HEAD_BYTES + length > end:
        return None
    return opcode, pos + RECORD_HEAD_BYTES + length


def _parsed(data: bytes | memoryview, pos: int, end: int, allowed: frozenset[int]) -> Span | None:
    h = _head(data, pos, end, allowed)
    if h is None:
        return None
    try:
        rec = parse_body(h[0], data[pos + RECORD_HEAD_BYTES:h[1]], pos + RECORD_HEAD_BYTES)
    except (ValueError, struct.error):
        return None
    return Span(h[0], pos, h[1], rec)


def _plausible_start(data: bytes | memoryview, pos: int, end: int, allowed: frozenset[int]) -> bool:
    """A record parses at ``pos`` and either ends the section or is followed by one that parses."""
    s = _parsed(data, pos, end, allowed)
    return s is not None and (s.end == end or _parsed(data, s.end, end, allowed) is not None)


def _candidates(allowed: frozenset[int]) -> re.Pattern[bytes]:
    # an opcode byte, then a u64 length whose top three bytes are zero (length < 1 TiB)
    ops = b"".join(re.escape(bytes([o])) for o in sorted(allowed))
    return re.compile(b"(?=[" + ops + b"].....\x00\x00\x00)", re.DOTALL)


def resync(data: bytes | memoryview, pos: int, end: int, allowed: frozenset[int]) -> int:
    """The first offset >= ``pos`` where a plausible record starts, else ``end``."""
    buf = data if isinstance(data, bytes) else bytes(data)
    for m in _candidates(allowed).finditer(buf, pos, end):
        if _plausible_start(buf, m.start(), end, allowed):
            return m.start()
    return end


def _reframe(data: bytes | memoryview, start: int, stop: int, allowed: frozenset[int]) -> Span | None:
    """A record whose opcode or length byte is damaged: the body ``[start + 9, stop)`` parses
    as exactly one allowed record type."""
    body = data[start + RECORD_HEAD_BYTES:stop]
    found = []
    for op in sorted(allowed):
        try:
            found.append(Span(op, start, stop, parse_body(op, body, start + RECORD_HEAD_BYTES), reframed=True))
        except (ValueError, struct.error):
            pass
    # any 22 bytes or more read as a Message: it counts only if nothing else fits
    strict = [f for f in found if f.opcode != Opcode.MESSAGE]
    if strict:
        return strict[0] if len(strict) == 1 else None
    return found[0] if found else None


def scan_section(data: bytes | memoryview, start: int, end: int, allowed: frozenset[int],
                 *, first: int | None = None, cut_off_ok: bool = False) -> tuple[list[Span], list[Gap], int]:
    """Read the records of ``[start, end)``, resynchronising after damage.

    Parameters
    ----------
    data : bytes-like
        The whole file.
    start, end : int
        Section bounds [bytes].
    allowed : frozenset of int
        Opcodes that may occur in the section.
    first : int, optional
        An opcode allowed only as the first record (the Header).
    cut_off_ok : bool
        The section may end inside a record (a file cut off by a crash): the incomplete last
        record ends the scan without a :class:`Gap`.

    Returns
    -------
    spans : list of Span
        Records in file order (a record whose length is intact but whose body does not
        parse is a Span with ``record=None``).
    gaps : list of Gap
    stop : int
        Where the scan ended: ``end``, or the start of the cut-off last record [bytes].
    """
    spans: list[Span] = []
    gaps: list[Gap] = []
    pos = start
    while pos < end:
        ops = allowed | {first} if (first is not None and pos == start) else allowed
        h = _head(data, pos, end, ops)
        if h is not None:
            body = data[pos + RECORD_HEAD_BYTES:h[1]]
            try:
                spans.append(Span(h[0], pos, h[1], parse_body(h[0], body, pos + RECORD_HEAD_BYTES)))
                pos = h[1]
                continue
            except (ValueError, struct.error) as exc:
                if h[1] == end or _plausible_start(data, h[1], end, allowed):
                    # the length is right (the next record is where it says): the body is damaged
                    spans.append(Span(h[0], pos, h[1], None, str(exc)))
                    pos = h[1]
                    continue
                reason = f"{opcode_name(h[0])} record does not parse ({exc}) and no record follows it"
        elif pos + RECORD_HEAD_BYTES <= end:
            opcode, length = struct.unpack_from("<BQ", data, pos)
            if opcode not in ops:
                reason = f"opcode {opcode_name(opcode)} is not allowed here"
            else:
                reason = f"{opcode_name(opcode)} record length {length} runs past the section end {end}"
        else:
            reason = f"{end - pos} bytes left, too few for a record"
        q = resync(data, pos + 1, end, allowed)
        if q == end and cut_off_ok:
            return spans, gaps, pos
        fixed = _reframe(data, pos, q, ops) if q > pos + RECORD_HEAD_BYTES else None
        if fixed is not None:
            spans.append(fixed)
        else:
            gaps.append(Gap(pos, q, reason))
        pos = q
    return spans, gaps, end


# --- CRC32 single-byte error location --------------------------------------------------------
def _crc_table() -> list[int]:
    table = []
    for i in range(256):
        r = i
        for _ in range(8):
            r = (r >> 1) ^ (0xEDB88320 if r & 1 else 0)
        table.append(r)
    return table


_TABLE = _crc_table()
# the top byte of the reflected table is a permutation of 0..255 (that makes a step invertible)
_TOP_INV = {t >> 24: i for i, t in enumerate(_TABLE)}


def _zero_step_inverse(r: int) -> int:
    """Undo one zero byte of the reflected CRC register step r' = (r >> 8) ^ T[r & 0xff]."""
    i = _TOP_INV[r >> 24]
    return (((r ^ _TABLE[i]) << 8) & 0xFFFFFFFF) | i


def _zero_step(r: int) -> int:
    return (r >> 8) ^ _TABLE[r & 0xFF]


def _linear_tables(fn: Any) -> list[list[int]]:
    """Byte tables of a GF(2)-linear map on 32-bit words: fn(x) = XOR of T[j][byte j of x]."""
    basis = [fn(1 << k) for k in range(32)]
    tables = []
    for j in range(4):
        t = [0] * 256
        for b in range(1, 256):
            low = b & -b
            t[b] = t[b ^ low] ^ basis[8 * j + low.bit_length() - 1]
        tables.append(t)
    return tables


def locate_single_byte_error(stored_crc: int, computed_crc: int, length: int, *, max_hits: int = 4) -> list[int]:
    """Offsets where changing one byte of a ``length``-byte message explains a CRC32 mismatch.

    CRC32 is linear: for two messages of equal length, crc(a) ^ crc(b) depends only on
    e = a ^ b. One changed byte v at offset p gives the syndrome S = M^(L-1-p) T[v], with T
    the CRC table and M one zero-byte step of the register. The search is baby-step giant-step:
    the baby table holds M^i T[v] for i < m and every v; the giant steps walk M^(-g m) S.
    About m 255 + L / m steps, m = sqrt(L / 255): 0.1 s for 100 MB.

    Parameters
    ----------
    stored_crc, computed_crc : int
        The CRC in the file and the CRC of the bytes as they are.
    length : int
        Bytes covered by the CRC [bytes].
    max_hits : int
        Stop after this many candidates.

    Returns
    -------
    list of int
        Candidate offsets from the start of the covered bytes, nearest the end first; empty
        if no single changed byte explains the difference (then the damage is larger, or in
        the stored CRC itself). For L below 2**21 bytes a second candidate is rare
        (probability about 255 L / 2**32) but possible: say "most likely".
    """
    syndrome = stored_crc ^ computed_crc
    if syndrome == 0 or length <= 0:
        return []
    m = max(1, int((length / 255) ** 0.5))
    baby: dict[int, list[int]] = {}
    for v in range(1, 256):
        r = _TABLE[v]
        for i in range(m):
            baby.setdefault(r, []).append(i)
            r = _zero_step(r)

    def back_m(x: int) -> int:
        for _ in range(m):
            x = _zero_step_inverse(x)
        return x

    t0, t1, t2, t3 = _linear_tables(back_m)
    hits: list[int] = []
    s = syndrome
    g = 0
    while g * m < length:
        for i in baby.get(s, ()):  # s = M^i T[v]  =>  k = g m + i
            k = g * m + i
            if k < length:
                hits.append(length - 1 - k)
        if len(hits) >= max_hits:
            break
        s = t0[s & 0xFF] ^ t1[(s >> 8) & 0xFF] ^ t2[(s >> 16) & 0xFF] ^ t3[s >> 24]
        g += 1
    return sorted(set(hits), reverse=True)[:max_hits]


__all__ = ["DATA_OPCODES", "SUMMARY_OPCODES", "ChunkHead", "Gap", "MessageIndexRecord", "Span",
           "decompress", "locate_single_byte_error", "opcode_name", "parse_body", "resync",
           "scan_section"]
