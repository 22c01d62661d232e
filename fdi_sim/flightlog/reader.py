"""Read a flight log back: numpy arrays per field for vector topics, dicts for events.

The ``mcap`` reader supplies the summary (schemas, channels, statistics, chunk indexes) and
the metadata records; messages are decoded here in bulk. For each chunk the Message Index
records give every message's offset in the decompressed chunk, so all rows of a vector channel
are gathered with one numpy fancy index over a sliding-window view of the chunk and read as
the packed record dtype of :func:`fdi_sim.flightlog.records.message_dtype`: no Python loop per
message. Chunks without message indexes are scanned record by record instead.
"""
from __future__ import annotations

import io
import json
import os
import stat
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator, Union

import numpy as np
from mcap.opcode import Opcode
from numpy.typing import NDArray

from fdi_sim.errors import LogError
from fdi_sim.flightlog.records import (
    FOOTER_RECORD_BYTES,
    MCAP_MAGIC,
    MESSAGE_HEAD,
    RECORD_HEAD_BYTES,
    has_footer,
    message_dtype,
    parse_chunk,
    scan_records,
)
from fdi_sim.flightlog.schemas import (
    CDR_BE_HEADER,
    CDR_LE_HEADER,
    MESSAGE_ENCODING_CDR,
    MESSAGE_ENCODING_JSON,
    METADATA_FAULTS,
    METADATA_SCENARIO,
    SCHEMA_ENCODING_ROS2MSG,
    parse_ros2msg_float64,
)
from fdi_sim.units import NS_PER_S

_READ_ERRORS = (struct.error, ValueError, KeyError, IndexError, UnicodeDecodeError, EOFError)


# --- result objects -----------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class VectorTopic:
    """All messages of one vector channel.

    Attributes
    ----------
    topic, schema_name : str
    fields : tuple of str
        Field names, ``t_s`` first.
    data : NDArray
        Read-only array (n, len(fields)); column ``i`` is ``fields[i]``.
    log_time_ns : NDArray
        MCAP log times [ns], shape (n,).
    """

    topic: str
    schema_name: str
    fields: tuple[str, ...]
    data: NDArray[np.float64]
    log_time_ns: NDArray[np.uint64]

    def __getitem__(self, name: str) -> NDArray[np.float64]:
        """Read-only column of one field (``log.topics["/truth/state"]["alpha_rad"]``)."""
        try:
            return self.data[:, self.fields.index(name)]
        except ValueError:
            raise KeyError(f"{self.topic} has no field {name!r}; fields are {', '.join(self.fields)}") from None

    @property
    def t_s(self) -> NDArray[np.float64]:
        """Times [s] as written (the ``t_s`` field)."""
        return self.data[:, 0]

    def as_array(self) -> NDArray[np.float64]:
        """A writable copy of all fields, shape (n, len(fields)), ``t_s`` in column 0."""
        return np.array(self.data)

    def __len__(self) -> int:
        return int(self.data.shape[0])


@dataclass(frozen=True)
class Event:
    """One event message: time [s] and decoded JSON payload."""

    t_s: float
    payload: dict[str, Any]


@dataclass(frozen=True, eq=False)
class EventTopic:
    """All messages of one JSON event channel, in time order.

    Attributes
    ----------
    topic, schema_name : str
    json_schema : dict
        The channel's JSON Schema.
    events : tuple of Event
    log_time_ns : NDArray
        MCAP log times [ns], shape (n,).
    """

    topic: str
    schema_name: str
    json_schema: dict[str, Any]
    events: tuple[Event, ...]
    log_time_ns: NDArray[np.uint64]

    @property
    def t_s(self) -> NDArray[np.float64]:
        """Event times [s]: log time / 1e9, within 0.5 ns of the ``t_s`` written."""
        return np.array([e.t_s for e in self.events], dtype=np.float64)

    def pairs(self) -> list[tuple[float, dict[str, Any]]]:
        """The events as a list of ``(t_s, payload)``."""
        return [(e.t_s, e.payload) for e in self.events]

    def __iter__(self) -> Iterator[Event]:
        return iter(self.events)

    def __getitem__(self, i: int) -> Event:
        return self.events[i]

    def __len__(self) -> int:
        return len(self.events)


@dataclass(frozen=True, eq=False)
class RawTopic:
    """Messages of a channel whose schema is neither a flat float64 ros2msg nor JSON."""

    topic: str
    schema_name: str
    message_encoding: str
    log_time_ns: NDArray[np.uint64]
    data: tuple[bytes, ...]

    def __len__(self) -> int:
        return len(self.data)


TopicData = Union[VectorTopic, EventTopic, RawTopic]


@dataclass(frozen=True, eq=False)
class FlightLog:
    """A whole flight log in memory.

    Attributes
    ----------
    path : Path
    topics : dict of str to TopicData
    metadata : dict of str to dict of str to str
    message_counts : dict of str to int
    start_t_s, end_t_s : float
        First and last message log time / 1e9 [s] (0 for an empty log).
    """

    path: Path
    topics: dict[str, TopicData]
    metadata: dict[str, dict[str, str]]
    message_counts: dict[str, int]
    start_t_s: float
    end_t_s: float

    @property
    def duration_s(self) -> float:
        """``end_t_s - start_t_s`` [s]."""
        return self.end_t_s - self.start_t_s


@dataclass(frozen=True)
class TopicInfo:
    """One channel in :class:`LogInfo`."""

    topic: str
    schema_name: str
    message_encoding: str
    message_count: int


@dataclass(frozen=True)
class LogInfo:
    """What the summary of a flight log says, without decoding messages.

    Attributes
    ----------
    path : Path
    file_size_bytes, message_count, chunk_count : int
    start_t_s, end_t_s : float
    topics : tuple of TopicInfo
    metadata_names : tuple of str
    scenario_name, scenario_seed : str or None
        From the ``scenario`` metadata record's ``name`` / ``seed`` keys, if present.
    faults : tuple of dict
        The ``faults`` metadata record's catalogue (label, type, target, params, windows_s [s]).
    """

    path: Path
    file_size_bytes: int
    message_count: int
    chunk_count: int
    start_t_s: float
    end_t_s: float
    topics: tuple[TopicInfo, ...]
    metadata_names: tuple[str, ...]
    scenario_name: str | None = None
    scenario_seed: str | None = None
    faults: tuple[dict, ...] = ()

    @property
    def duration_s(self) -> float:
        """``end_t_s - start_t_s`` [s]."""
        return self.end_t_s - self.start_t_s

    def format(self) -> str:
        """A terminal summary (what ``fdi-sim info LOG`` prints)."""
        lines = [f"{self.path}  ({self.file_size_bytes / 1e6:.2f} MB)"]
        if self.scenario_name is not None or self.scenario_seed is not None:
            lines.append(f"scenario: {self.scenario_name or '?'}   seed: {self.scenario_seed or '?'}")
        lines.append(f"duration: {self.duration_s:.3f} s  (t = {self.start_t_s:.3f} .. {self.end_t_s:.3f} s), "
                     f"{self.message_count} messages in {self.chunk_count} chunks")
        w_topic = max([len("topic")] + [len(t.topic) for t in self.topics])
        w_schema = max([len("schema")] + [len(t.schema_name) for t in self.topics])
        lines.append(f"{'topic':<{w_topic}}  {'schema':<{w_schema}}  {'messages':>9}")
        for t in self.topics:
            lines.append(f"{t.topic:<{w_topic}}  {t.schema_name:<{w_schema}}  {t.message_count:>9d}")
        lines.append("metadata: " + (", ".join(self.metadata_names) if self.metadata_names else "(none)"))
        for f in self.faults:
            w = f.get("windows_s", [])
            open_end = "t_end_s" not in f.get("params", {})
            when = (f"{len(w)} windows from {w[0][0]:g} s" if len(w) > 1 else
                    f"from {w[0][0]:g} s" if open_end else f"[{w[0][0]:g}, {w[0][1]:g}) s") if w else "never"
            lines.append(f"fault:    {f.get('label')}  {f.get('type')} on {f.get('target')}, {when}")
        return "\n".join(lines)


# --- low-level helpers -----------------------------------------------------------------------
def _message_index(data: bytes, offset: int) -> tuple[int, NDArray[np.uint64], NDArray[np.uint64]]:
    """Parse a Message Index record at a file offset: channel id, log times, offsets."""
    opcode, length, cid, n_bytes = struct.unpack_from("<BQHI", data, offset)
    if opcode != Opcode.MESSAGE_INDEX or n_bytes % 16 or n_bytes + 6 > length:
        raise ValueError(f"no message index record at byte {offset}")
    entries = np.frombuffer(data, dtype="<u8", count=n_bytes // 8, offset=offset + 15).reshape(-1, 2)
    return cid, entries[:, 0], entries[:, 1]


def _scan_chunk(records: bytes, start: int = 0) -> dict[int, tuple[NDArray[np.uint64], NDArray[np.uint64]]]:
    """Index the messages of a chunk (or of a whole unchunked file from ``start``) by scanning."""
    found: dict[int, tuple[list[int], list[int]]] = {}
    for opcode, body, _length in scan_records(records, start):
        if opcode == Opcode.MESSAGE:
            cid, _seq, log_ns = struct.unpack_from("<HIQ", records, body)
            logs, offs = found.setdefault(cid, ([], []))
            logs.append(log_ns)
            offs.append(body - RECORD_HEAD_BYTES)
    return {cid: (np.array(lo, dtype=np.uint64), np.array(of, dtype=np.uint64)) for cid, (lo, of) in found.items()}


def _check_framing(path: Path, data: bytes) -> None:
    """Raise LogError for a file that is not MCAP, or an MCAP file without its footer."""
    if len(data) < len(MCAP_MAGIC) or data[:len(MCAP_MAGIC)] != MCAP_MAGIC:
        raise LogError(str(path), "not an MCAP file (it does not start with the MCAP magic bytes); "
                       "pass a flight log written by `fdi-sim run`")
    if not has_footer(data):
        raise LogError(str(path), "the MCAP file is truncated: it has no footer (the run was cut off "
                       f"before the log was closed); rebuild it with `fdi-sim repair {path}`")


def check_log_file(path: str | Path) -> Path:
    """Refuse what is not a regular file before reading it (a link to /dev/zero would never end).

    Raises
    ------
    LogError
        Missing, a folder, a device, a FIFO or a socket (after following links).
    """
    p = Path(path)
    try:
        st = os.stat(p)
    except OSError as exc:
        raise LogError(str(path), f"cannot read the flight log ({exc.strerror})") from None
    if not stat.S_ISREG(st.st_mode):
        kind = "a folder" if stat.S_ISDIR(st.st_mode) else "not a regular file (a device, FIFO or socket)"
        raise LogError(str(path), f"the path is {kind}; pass an MCAP file written by `fdi-sim run`")
    return p


def _read_bytes(path: str | Path) -> tuple[Path, bytes]:
    p = check_log_file(path)
    try:
        return p, p.read_bytes()
    except OSError as exc:
        raise LogError(str(path), f"cannot read the flight log ({exc.strerror})") from None


# --- public API -----------------------------------------------------------------------------
def read_log(path: str | Path) -> FlightLog:
    """Load a whole flight log.

    Parameters
    ----------
    path : str or Path
        An MCAP file written by :class:`~fdi_sim.flightlog.FlightLogWriter` (or repaired).

    Returns
    -------
    FlightLog

    Raises
    ------
    LogError
        Not an MCAP file, truncated (suggests ``fdi-sim repair``), or corrupted.
    """
    p, data = _read_bytes(path)
    _check_framing(p, data)
    from mcap.exceptions import McapError
    from mcap.reader import make_reader
    try:
        reader = make_reader(io.BytesIO(data))
        summary = reader.get_summary()
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        if summary is None:
            raise ValueError("the file has no summary section")
        per_channel: dict[int, list[tuple[bytes, NDArray[np.uint64]]]] = {}
        if not summary.chunk_indexes:  # an unchunked file: messages are top-level records
            for cid, (_log, offs) in _scan_chunk(data, len(MCAP_MAGIC)).items():
                per_channel[cid] = [(data, offs)]
        for ci in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
            opcode, length = struct.unpack_from("<BQ", data, ci.chunk_start_offset)
            if opcode != Opcode.CHUNK:
                raise ValueError(f"no chunk record at byte {ci.chunk_start_offset}")
            start = ci.chunk_start_offset + RECORD_HEAD_BYTES
            body = memoryview(data)[start:start + length]
            records = parse_chunk(body).records
            if ci.message_index_offsets:
                index = {}
                for cid, off in ci.message_index_offsets.items():
                    got, log, offs = _message_index(data, off)
                    if got != cid:
                        raise ValueError(f"message index at byte {off} is for channel {got}, not {cid}")
                    index[cid] = (log, offs)
            else:
                index = _scan_chunk(records)
            for cid, (_log, offs) in index.items():
                if len(offs):
                    per_channel.setdefault(cid, []).append((records, offs))
        topics: dict[str, TopicData] = {}
        for cid, channel in sorted(summary.channels.items()):
            schema = summary.schemas.get(channel.schema_id)
            if channel.topic in topics:
                raise ValueError(f"two channels share the topic {channel.topic!r}")
            topics[channel.topic] = _decode_channel(cid, channel, schema, per_channel.get(cid, []))
    except LogError:
        raise
    except (McapError, *_READ_ERRORS) as exc:
        raise LogError(str(p), f"the MCAP file is corrupted ({exc}); try `fdi-sim repair {p}`") from None
    counts = {t: len(d) for t, d in topics.items()}
    logs = [d.log_time_ns for d in topics.values() if len(d)]
    start_ns = min(int(lo.min()) for lo in logs) if logs else 0
    end_ns = max(int(lo.max()) for lo in logs) if logs else 0
    return FlightLog(path=p, topics=topics, metadata=metadata, message_counts=counts,
                     start_t_s=start_ns / NS_PER_S, end_t_s=end_ns / NS_PER_S)


def _decode_channel(cid: int, channel: Any, schema: Any, parts: list[tuple[bytes, NDArray[np.uint64]]]) -> TopicData:
    """Decode all messages of one channel from (chunk records, offsets) parts."""
    schema_name = schema.name if schema is not None else ""
    fields = None
    if schema is not None and schema.encoding == SCHEMA_ENCODING_ROS2MSG \
            and channel.message_encoding == MESSAGE_ENCODING_CDR:
        fields = parse_ros2msg_float64(schema.data.decode("utf-8"))
    if fields is not None:
        return _decode_vector(cid, channel.topic, schema_name, fields, parts)
    logs: list[int] = []
    payloads: list[bytes] = []
    for records, offs in parts:
        for off in offs.tolist():
            opcode, length, got, _seq, log_ns = struct.unpack_from("<BQHIQ", records, off)
            if opcode != Opcode.MESSAGE or got != cid:
                raise ValueError(f"{channel.topic}: index points at a record that is not its message")
            logs.append(log_ns)
            payloads.append(records[off + MESSAGE_HEAD.size:off + RECORD_HEAD_BYTES + length])
    order = sorted(range(len(logs)), key=logs.__getitem__)
    if channel.message_encoding == MESSAGE_ENCODING_JSON:
        json_schema = json.loads(schema.data) if schema is not None and schema.data else {}
        events = tuple(Event(logs[i] / NS_PER_S, json.loads(payloads[i])) for i in order)
        return EventTopic(channel.topic, schema_name, json_schema, events,
                          np.array([logs[i] for i in order], dtype=np.uint64))
    return RawTopic(channel.topic, schema_name, channel.message_encoding,
                    np.array([logs[i] for i in order], dtype=np.uint64), tuple(payloads[i] for i in order))


def _decode_vector(cid: int, topic: str, schema_name: str, fields: tuple[str, ...],
                   parts: list[tuple[bytes, NDArray[np.uint64]]]) -> VectorTopic:
    """Gather every message of a float64 CDR channel with numpy (see module docstring)."""
    dt = message_dtype(len(fields))
    size = dt.itemsize
    rows = []
    for records, offs in parts:
        buf = np.frombuffer(records, dtype=np.uint8)
        if len(buf) < size or int(offs.max()) > len(buf) - size:
            raise ValueError(f"{topic}: message offsets run past the chunk")
        # row i of the window view is buf[i : i + size]; fancy indexing copies whole records
        win = np.lib.stride_tricks.sliding_window_view(buf, size)
        rows.append(win[offs.astype(np.intp)])
    if rows:
        rec = np.concatenate(rows).view(dt).reshape(-1)
    else:
        rec = np.zeros(0, dtype=dt)
    if len(rec):
        if not (np.all(rec["opcode"] == Opcode.MESSAGE) and np.all(rec["channel_id"] == cid)):
            raise ValueError(f"{topic}: index points at records that are not its messages")
        if not np.all(rec["length"] == size - RECORD_HEAD_BYTES):
            raise ValueError(f"{topic}: messages are not {len(fields)} packed float64 (size mismatch)")
    header = rec["cdr"]
    values = rec["values"]
    le = np.frombuffer(CDR_LE_HEADER, dtype=np.uint8)
    be = np.frombuffer(CDR_BE_HEADER, dtype=np.uint8)
    if len(rec) and not np.all(header == le):
        if np.all(header == be):
            values = values.byteswap()  # plain CDR big-endian: same layout, other byte order
        else:
            raise ValueError(f"{topic}: unsupported CDR encapsulation header {bytes(header[0])!r}")
    log_ns = rec["log_time_ns"].astype(np.uint64)
    if len(log_ns) > 1 and np.any(log_ns[1:] < log_ns[:-1]):
        order = np.argsort(log_ns, kind="stable")
        log_ns, values = log_ns[order], values[order]
    data = np.ascontiguousarray(values, dtype=np.float64)
    data.flags.writeable = False
    log_ns.flags.writeable = False
    return VectorTopic(topic, schema_name, fields, data, log_ns)


def log_info(path: str | Path) -> LogInfo:
    """Summarize a flight log from its summary section only (fast for any size).

    Raises
    ------
    LogError
        As :func:`read_log`.
    """
    p = check_log_file(path)
    from mcap.exceptions import McapError
    from mcap.reader import make_reader
    n_tail = len(MCAP_MAGIC) + FOOTER_RECORD_BYTES
    try:
        size = p.stat().st_size
        with open(p, "rb") as f:
            if size <= len(MCAP_MAGIC) + n_tail:
                ends = f.read()
            else:  # the first 8 and last 37 bytes are all the framing check looks at
                ends = f.read(len(MCAP_MAGIC))
                f.seek(size - n_tail)
                ends += f.read()
    except OSError as exc:
        raise LogError(str(path), f"cannot read the flight log ({exc.strerror})") from None
    _check_framing(p, ends)
    try:
        with open(p, "rb") as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            if summary is None or summary.statistics is None:
                raise ValueError("the file has no summary statistics")
            metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    except (McapError, OSError, *_READ_ERRORS) as exc:
        raise LogError(str(p), f"the MCAP file is corrupted ({exc}); try `fdi-sim repair {p}`") from None
    stats = summary.statistics
    topics = tuple(
        TopicInfo(ch.topic, summary.schemas[ch.schema_id].name if ch.schema_id in summary.schemas else "",
                  ch.message_encoding, int(stats.channel_message_counts.get(cid, 0)))
        for cid, ch in sorted(summary.channels.items()))
    scenario = metadata.get(METADATA_SCENARIO, {})
    empty = stats.message_count == 0
    return LogInfo(
        path=p, file_size_bytes=size, message_count=int(stats.message_count),
        chunk_count=int(stats.chunk_count),
        start_t_s=0.0 if empty else stats.message_start_time / NS_PER_S,
        end_t_s=0.0 if empty else stats.message_end_time / NS_PER_S,
        topics=topics, metadata_names=tuple(metadata),
        scenario_name=scenario.get("name"), scenario_seed=scenario.get("seed"),
        faults=_fault_catalog(metadata),
    )


def _fault_catalog(metadata: dict[str, dict[str, str]]) -> tuple[dict, ...]:
    """The fault catalogue written by the simulation (``faults`` metadata record), if any."""
    try:
        return tuple(json.loads(metadata.get(METADATA_FAULTS, {}).get("catalog", "[]")))
    except (ValueError, TypeError):
        return ()


__all__ = ["Event", "EventTopic", "FlightLog", "LogInfo", "RawTopic", "TopicData", "TopicInfo",
           "VectorTopic", "log_info", "read_log"]
