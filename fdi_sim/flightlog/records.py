"""MCAP records shared by the writer, the reader and repair: file framing, Message records of
vector channels laid out in bulk with numpy, chunks and their Message Index records.

References: MCAP specification (https://mcap.dev/spec), "Records" (opcode u8, record length
u64, body) and the records named below; opcodes are the ``mcap`` library's :class:`Opcode`.

A Message record (op 0x05) is opcode u8 | record length u64 | channel_id u16 | sequence u32 |
log_time u64 | publish_time u64 | data. For a vector channel the data is the CDR payload of
:mod:`fdi_sim.flightlog.schemas` (``4 + 8 * n_fields`` bytes), so every record of the channel
has the same size ``35 + 8 * n_fields`` and a whole chunk of them is laid out by numpy in
one go (:func:`build_chunk`).
"""
from __future__ import annotations

import functools
import struct
import zlib
from dataclasses import dataclass
from typing import Any, Iterator, Sequence

import numpy as np
from mcap.opcode import Opcode
from numpy.typing import NDArray

from fdi_sim.flightlog.schemas import CDR_LE_HEADER
from fdi_sim.units import NS_PER_S

MCAP_MAGIC: bytes = b"\x89MCAP0\r\n"
#: bytes of a record before its body: opcode u8, length u64
RECORD_HEAD_BYTES: int = 9
#: Footer record: opcode, length, summary_start u64, summary_offset_start u64, summary_crc u32
FOOTER_RECORD_BYTES: int = RECORD_HEAD_BYTES + 8 + 8 + 4
#: bytes of a Message record before its data: opcode, length, channel, sequence, 2 times
MESSAGE_HEAD = struct.Struct("<BQHIQQ")
#: largest decompressed chunk accepted when reading [bytes]
MAX_CHUNK_BYTES: int = 1 << 30


# --- framing -----------------------------------------------------------------------------
def has_footer(data: bytes) -> bool:
    """True if ``data`` (the whole file, or its first 8 and last 37 bytes) ends with a Footer
    record and the closing magic, as a file closed by its writer does."""
    tail = len(MCAP_MAGIC) + FOOTER_RECORD_BYTES
    return (len(data) >= len(MCAP_MAGIC) + tail and data.endswith(MCAP_MAGIC)
            and data[-tail] == Opcode.FOOTER)


def scan_records(buf: bytes | memoryview, start: int = 0) -> Iterator[tuple[int, int, int]]:
    """Yield ``(opcode, body_start, body_length)`` of each complete record from ``start``.

    Stops silently at a record cut short (the caller compares the end position with the size).
    """
    n = len(buf)
    pos = start
    while pos + RECORD_HEAD_BYTES <= n:
        opcode, length = struct.unpack_from("<BQ", buf, pos)
        if pos + RECORD_HEAD_BYTES + length > n:
            return
        yield opcode, pos + RECORD_HEAD_BYTES, length
        pos += RECORD_HEAD_BYTES + length


# --- Message records of vector channels, chunks ----------------------------------------
def message_dtype(n_fields: int) -> np.dtype:
    """Packed dtype of one complete Message record of a vector channel of ``n_fields``."""
    return np.dtype([
        ("opcode", "u1"), ("length", "<u8"), ("channel_id", "<u2"), ("sequence", "<u4"),
        ("log_time_ns", "<u8"), ("publish_time_ns", "<u8"), ("cdr", "u1", (4,)),
        ("values", "<f8", (n_fields,)),
    ])


@dataclass(frozen=True, eq=False)
class VectorBlock:
    """Rows of one vector channel for one chunk.

    Attributes
    ----------
    channel_id : int
    first_sequence : int
        Sequence number of the first row (the channel's message counter).
    t_s : NDArray
        Times [s], shape (n,); blocks of equal times may share one array object.
    values : NDArray
        Values without ``t_s``, shape (n, n_fields - 1).
    """

    channel_id: int
    first_sequence: int
    t_s: NDArray[np.float64]
    values: NDArray[np.float64]


@dataclass(frozen=True)
class RawMessage:
    """One already-encoded message (events, messages recovered by repair); log = publish time [ns]."""

    channel_id: int
    sequence: int
    log_time_ns: int
    data: bytes


@dataclass(frozen=True, eq=False)
class ChunkPayload:
    """The uncompressed records of one chunk and what its indexes need.

    Attributes
    ----------
    records : bytes-like
        Concatenated Message records in log-time order.
    message_start_ns, message_end_ns : int
        Earliest and latest log time [ns].
    message_count : int
    index : dict
        channel id -> Message Index entries, shape (n, 2): (log time [ns], offset into
        ``records``) per message, sorted by log time.
    """

    records: bytes | bytearray
    message_start_ns: int
    message_end_ns: int
    message_count: int
    index: dict[int, NDArray[np.uint64]]


def log_time_ns(t_s: NDArray[np.float64]) -> NDArray[np.uint64]:
    """log_time = round(t_s * 1e9) [ns], round half to even like Python's ``round``."""
    return np.rint(np.asarray(t_s, dtype=np.float64) * NS_PER_S).astype(np.uint64)


def vector_records(block: VectorBlock) -> NDArray[Any]:
    """Complete Message records of one :class:`VectorBlock` as a packed structured array."""
    n, n_values = block.values.shape
    rec = np.empty(n, dtype=message_dtype(n_values + 1))
    rec["opcode"] = Opcode.MESSAGE
    rec["length"] = rec.dtype.itemsize - RECORD_HEAD_BYTES
    rec["channel_id"] = block.channel_id
    rec["sequence"] = (np.arange(n, dtype=np.int64) + block.first_sequence) & 0xFFFFFFFF
    log = log_time_ns(block.t_s)
    rec["log_time_ns"] = log
    rec["publish_time_ns"] = log
    rec["cdr"] = np.frombuffer(CDR_LE_HEADER, dtype=np.uint8)
    rec["values"][:, 0] = block.t_s
    rec["values"][:, 1:] = block.values
    return rec


@functools.lru_cache(maxsize=64)
def _step_layout(ids: tuple[int, ...], n_values: tuple[int, ...],
                 n: int) -> tuple[list[NDArray[np.uint8]], NDArray[np.uint8], NDArray[np.int64], int]:
    """Constant parts of ``n`` steps of one Message record per channel, back to back: per
    channel the (n, 11) record start (opcode, record length, channel id), the (n, 4) CDR
    headers, the record offsets (n, channels) in the chunk and the bytes of one step.
    Read-only: shared between calls."""
    starts = []
    prefixes = []
    size = 0
    for cid, nv in zip(ids, n_values):
        starts.append(size)
        length = MESSAGE_HEAD.size - RECORD_HEAD_BYTES + len(CDR_LE_HEADER) + 8 * (nv + 1)
        size += RECORD_HEAD_BYTES + length
        pre = np.frombuffer(struct.pack("<BQH", Opcode.MESSAGE, length, cid), dtype=np.uint8)
        prefixes.append(np.tile(pre, (n, 1)))
    cdr = np.tile(np.frombuffer(CDR_LE_HEADER, dtype=np.uint8), (n, 1))
    offsets = np.arange(n, dtype=np.int64)[:, None] * size + np.array(starts, dtype=np.int64)[None, :]
    for x in (cdr, offsets, *prefixes):
        x.flags.writeable = False
    return prefixes, cdr, offsets, size


def _regular_layout(blocks: list[VectorBlock]) -> tuple[bytearray, NDArray[np.uint64], NDArray[np.int64]] | None:
    """The usual chunk: every channel wrote once per step at the same, sorted times. A step
    is then a fixed-size group of records: the chunk is one ``np.concatenate`` of byte
    columns (n, .) along the rows: per channel the constant record start, the row head shared
    by all channels (sequence, log time, publish time, CDR header, t_s; MESSAGE_HEAD layout)
    and the values. Returns the bytes, the log times (n,) and the record offsets (n,
    channels); None if the chunk is not regular."""
    t0 = blocks[0].t_s
    n = len(t0)
    if not all(b.t_s is t0 or np.array_equal(b.t_s, t0) for b in blocks[1:]):
        return None
    log = log_time_ns(t0)
    if n > 1 and (log[1:] < log[:-1]).any():
        return None
    prefixes, cdr, offsets, step_bytes = _step_layout(
        tuple(b.channel_id for b in blocks), tuple(b.values.shape[1] for b in blocks), n)
    # (n, 1) little-endian numbers viewed as their (n, k) bytes
    log_u1 = log.astype("<u8", copy=False).reshape(n, 1).view(np.uint8)
    t_u1 = np.ascontiguousarray(t0, dtype="<f8").reshape(n, 1).view(np.uint8)
    heads: dict[int, NDArray[np.uint8]] = {}
    columns: list[NDArray[np.uint8]] = []
    for c, b in enumerate(blocks):
        head = heads.get(b.first_sequence)
        if head is None:
            # sequence u32 wraps around (MCAP spec: "sequence" is a uint32 counter)
            seq = np.arange(n, dtype=np.uint32) + np.uint32(b.first_sequence & 0xFFFFFFFF)
            seq_u1 = seq.astype("<u4", copy=False).reshape(n, 1).view(np.uint8)
            head = heads[b.first_sequence] = np.concatenate((seq_u1, log_u1, log_u1, cdr, t_u1), axis=1)
        columns += (prefixes[c], head, np.ascontiguousarray(b.values, dtype="<f8").view(np.uint8))
    buf = bytearray(n * step_bytes)
    np.concatenate(columns, axis=1, out=np.frombuffer(buf, dtype=np.uint8).reshape(n, -1))
    return buf, log, offsets


def _general_layout(blocks: list[VectorBlock]) -> tuple[bytes, NDArray[np.uint64], NDArray[np.int64], list[NDArray[np.int64]]]:
    """Any chunk: stable sort of all rows by (log time, block), whole records copied into
    place. Returns the bytes, file-order log times and offsets, and each block's positions."""
    recs = [vector_records(b) for b in blocks]
    all_log = np.concatenate([r["log_time_ns"] for r in recs])
    blk = np.concatenate([np.full(len(r), c, dtype=np.int64) for c, r in enumerate(recs)])
    order = np.lexsort((blk, all_log))
    sizes = np.array([r.dtype.itemsize for r in recs], dtype=np.int64)
    size_sorted = sizes[blk[order]]
    voff = np.concatenate(([0], np.cumsum(size_sorted)[:-1])).astype(np.int64)
    inv = np.empty_like(order)
    inv[order] = np.arange(len(order))
    out = np.empty(int(size_sorted.sum()), dtype=np.uint8)
    positions, start = [], 0
    for c, r in enumerate(recs):
        pos = inv[start:start + len(r)]
        start += len(r)
        s = int(sizes[c])
        # writable overlapping window view: row i is out[i : i + s]; the targets don't overlap
        win = np.lib.stride_tricks.as_strided(out, shape=(len(out) - s + 1, s), strides=(1, 1))
        win[voff[pos]] = r.view(np.uint8).reshape(len(r), s)
        positions.append(pos)
    return out.tobytes(), all_log[order], voff, positions


def _entries(log: NDArray[Any], offsets: NDArray[Any]) -> NDArray[np.uint64]:
    e = np.empty((len(log), 2), dtype="<u8")
    e[:, 0] = log
    e[:, 1] = offsets
    return e


def build_chunk(blocks: Sequence[VectorBlock], raws: Sequence[RawMessage] = ()) -> ChunkPayload:
    """Lay out the Message records of one chunk in log-time order and index them.

    Parameters
    ----------
    blocks : sequence of VectorBlock
        At most one per channel. Rows are interleaved by time (ties: block order).
    raws : sequence of RawMessage
        Already-encoded messages (any order); spliced in after vector messages of equal time.
    """
    blocks = [b for b in blocks if len(b.t_s)]
    regular = _regular_layout(blocks) if blocks else None
    if regular is not None and not raws:  # the per-second fast path
        buf, log, offs = regular
        # all channels' entries in one array: [c, i] = (log time, offset) of step i's record
        e = np.empty((len(blocks), len(log), 2), dtype="<u8")
        e[:, :, 0] = log
        e[:, :, 1] = offs.T
        index = {b.channel_id: e[c] for c, b in enumerate(blocks)}
        return ChunkPayload(buf, int(log[0]), int(log[-1]), len(log) * len(blocks), index)
    if regular is not None:
        vbytes: bytes | bytearray = regular[0]
        k = len(blocks)
        vlog, voff = np.repeat(regular[1], k), regular[2].ravel()
        positions = [np.arange(len(regular[1]), dtype=np.int64) * k + c for c in range(k)]
    elif blocks:
        vbytes, vlog, voff, positions = _general_layout(blocks)
    else:
        vbytes, vlog, voff, positions = b"", np.zeros(0, np.uint64), np.zeros(0, np.int64), []
    n_vec = len(vlog)
    order = sorted(range(len(raws)), key=lambda i: raws[i].log_time_ns)
    rlog = np.array([raws[i].log_time_ns for i in order], dtype=np.uint64)
    rbytes = [MESSAGE_HEAD.pack(Opcode.MESSAGE, 22 + len(raws[i].data), raws[i].channel_id,
                                raws[i].sequence & 0xFFFFFFFF, raws[i].log_time_ns,
                                raws[i].log_time_ns) + raws[i].data for i in order]
    rsize = np.array([len(b) for b in rbytes], dtype=np.int64)
    ins = np.searchsorted(vlog, rlog, side="right")
    voff_ext = np.append(voff, len(vbytes)).astype(np.int64)
    view = memoryview(vbytes)
    pieces: list[Any] = []
    prev = 0
    for j, i in enumerate(ins.tolist()):
        pieces += [view[voff_ext[prev]:voff_ext[i]], rbytes[j]]
        prev = i
    pieces.append(view[voff_ext[prev]:])
    records = b"".join(pieces)
    # vector message k moves by the sizes of the raw messages inserted before it
    inc = np.zeros(n_vec + 1, dtype=np.int64)
    np.add.at(inc, ins, rsize)
    voff = voff + np.cumsum(inc)[:n_vec]
    roff = voff_ext[ins] + np.concatenate(([0], np.cumsum(rsize)[:-1])).astype(np.int64)
    parts: dict[int, list[tuple[NDArray[Any], NDArray[Any]]]] = {}
    for b, pos in zip(blocks, positions):
        parts.setdefault(b.channel_id, []).append((vlog[pos], voff[pos]))
    rch = np.array([raws[i].channel_id for i in order], dtype=np.int64)
    for cid in np.unique(rch).tolist():
        sel = rch == cid
        parts.setdefault(int(cid), []).append((rlog[sel], roff[sel]))
    index = {}
    for cid in sorted(parts):
        log = np.concatenate([p[0] for p in parts[cid]])
        off = np.concatenate([p[1] for p in parts[cid]])
        o = np.lexsort((off, log))  # a channel written out of time order gets sorted entries
        index[cid] = _entries(log[o], off[o])
    all_log = np.concatenate([vlog, rlog])
    if len(all_log) == 0:
        return ChunkPayload(b"", 0, 0, 0, {})
    return ChunkPayload(records, int(all_log.min()), int(all_log.max()), len(all_log), index)


def encode_message_index(channel_id: int, entries: NDArray[np.uint64]) -> bytes:
    """One Message Index record (op 0x07): channel_id u16, entries' byte length u32, then
    (log_time u64, offset u64) per message, offsets from the start of the chunk's records."""
    body = np.ascontiguousarray(entries, dtype="<u8").tobytes()
    return struct.pack("<BQHI", Opcode.MESSAGE_INDEX, 2 + 4 + len(body), channel_id, len(body)) + body


# --- reading chunks -----------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class ChunkData:
    """A decoded Chunk record (MCAP spec, "Chunk", op 0x06)."""

    message_start_ns: int
    message_end_ns: int
    compression: str
    records: bytes


def parse_chunk(body: bytes | memoryview, check_crc: bool = True) -> ChunkData:
    """Decode the body of a Chunk record and decompress its records.

    Raises
    ------
    ValueError
        Truncated body, unknown compression, wrong size or CRC mismatch.
    """
    start_ns, end_ns, usize, crc, clen = struct.unpack_from("<QQQII", body, 0)
    pos = 32
    compression = bytes(body[pos:pos + clen]).decode("utf-8")
    pos += clen
    (rlen,) = struct.unpack_from("<Q", body, pos)
    pos += 8
    packed = bytes(body[pos:pos + rlen])
    if len(packed) != rlen or usize > MAX_CHUNK_BYTES:
        raise ValueError("chunk record is cut short or its sizes are implausible")
    try:
        if compression == "zstd":
            import zstandard
            records = zstandard.ZstdDecompressor().decompress(packed, max_output_size=usize)
        elif compression == "lz4":
            import lz4.frame
            records = lz4.frame.decompress(packed)
        elif compression == "":
            records = packed
        else:
            raise ValueError(f"unsupported chunk compression {compression!r}")
    except Exception as exc:  # zstandard.ZstdError, lz4's RuntimeError: damaged data
        raise ValueError(f"chunk does not decompress ({exc})") from None
    if len(records) != usize:
        raise ValueError(f"chunk decompressed to {len(records)} bytes, expected {usize}")
    if check_crc and crc != 0 and zlib.crc32(records) != crc:
        raise ValueError("chunk CRC mismatch")
    return ChunkData(start_ns, end_ns, compression, records)
