"""Write the flight log: one MCAP file per run, flushed about once per simulated second.

Design (measured with ``tests/benchmarks/bench_flightlog.py``): the simulation loop calls
:meth:`VectorChannel.write` ~5 times per 1/120 s step, so a write only checks the time and
appends the row's bytes to a list. Once per ``flush_period_s`` of *simulated* time the rows
of all channels become one MCAP chunk built by numpy in one shot
(:func:`fdi_sim.flightlog.records.build_chunk`: complete Message records interleaved in time
order), compressed, followed by one Message Index record per channel, then ``file.flush()``.
A process killed with SIGKILL therefore loses at most one flush period, and
:func:`fdi_sim.flightlog.repair_log` rebuilds the summary of such a file. ``close()`` writes
Data End, the summary (schemas, channels, statistics, chunk and metadata indexes, summary
offsets) and the footer (MCAP specification, https://mcap.dev/spec, "Summary Section").
"""
from __future__ import annotations

import math
import numbers
import os
import signal
import struct
import threading
import zlib
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Iterator, Mapping, Sequence

import numpy as np
from mcap.opcode import Opcode
from numpy.typing import NDArray

from fdi_sim import __version__ as _FDI_SIM_VERSION
from fdi_sim.errors import LogError
from fdi_sim.flightlog.records import (
    MCAP_MAGIC,
    ChunkPayload,
    RawMessage,
    VectorBlock,
    build_chunk,
    encode_message_index,
)
from fdi_sim.flightlog.schemas import (
    MESSAGE_ENCODING_CDR,
    MESSAGE_ENCODING_JSON,
    SCHEMA_ENCODING_JSONSCHEMA,
    SCHEMA_ENCODING_ROS2MSG,
    EventSchema,
    VectorSchema,
    check_topic,
    event_schema,
    vector_schema,
)
from fdi_sim.units import NS_PER_S

LIBRARY: str = f"fdi-sim {_FDI_SIM_VERSION} flightlog"
#: zstd level: on a one-second chunk of flight data level 1 gives the same size as the
#: library default 3 in ~40 % less time (bench_flightlog.py notes)
ZSTD_LEVEL: int = 1
#: log_time is uint64 ns; keep t_s far below its range (and below 2**53 ns for exact floats)
MAX_T_S: float = 1.0e7

#: the dtype of a fresh float64 array on a little-endian machine (the only one written as is)
_F8_LE = np.dtype("<f8")
_NDARRAY = np.ndarray  # one global lookup instead of two on the write path


def _string(s: str) -> bytes:
    b = s.encode("utf-8")
    return struct.pack("<I", len(b)) + b


def _string_map(m: Mapping[str, str]) -> bytes:
    body = b"".join(_string(k) + _string(v) for k, v in m.items())
    return struct.pack("<I", len(body)) + body


def _record(opcode: int, body: bytes) -> bytes:
    return struct.pack("<BQ", opcode, len(body)) + body


#: the signals that end a run (Ctrl-C, ``kill``/``timeout``/batch schedulers/study engines)
STOP_SIGNALS: tuple[signal.Signals, ...] = (signal.SIGINT, signal.SIGTERM)


@contextmanager
def signals_deferred() -> Iterator[None]:
    """Hold SIGINT and SIGTERM while a block writes records; deliver them after it.

    A KeyboardInterrupt raised between ``file.write`` and the position update, or after a
    channel's rows were taken and before their chunk was written, used to leave a file whose
    footer pointed 9,675 bytes early or a summary counting rows that were never written
    (issue 11). The block runs to its end; a signal that arrived meanwhile is then passed to the
    handler that was installed before (so Ctrl-C still raises, just not inside a record). Only
    the main thread receives Python signal handlers; elsewhere this does nothing. Cost: four
    ``signal.signal`` calls, once per flush (about once per simulated second).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held: list[int] = []
    before = {s: signal.getsignal(s) for s in STOP_SIGNALS}
    for s in STOP_SIGNALS:
        signal.signal(s, lambda signum, _frame: held.append(signum))
    try:
        yield
    finally:
        for s, h in before.items():
            signal.signal(s, h if h is not None else signal.SIG_DFL)
        for signum in held[:1]:  # one delivery is enough: the handler decides what it means
            h = before[signal.Signals(signum)]
            if callable(h):
                h(signum, None)
            elif h == signal.SIG_DFL:
                signal.raise_signal(signum)


class McapFileWriter:
    """Low-level MCAP file writer: records in, a valid indexed file out.

    Used by :class:`FlightLogWriter` and by repair. Schemas, channels and metadata are
    written to the data section as they come (so a cut-off file keeps them); messages go in
    chunks given as :class:`ChunkPayload`.

    Parameters
    ----------
    path : str or Path
        Output file (created or truncated).
    compression : {"zstd", "lz4", None}
        Chunk compression.
    """

    def __init__(self, path: str | Path, compression: str | None = "zstd") -> None:
        self.path = Path(path)
        if compression not in ("zstd", "lz4", None, ""):
            raise LogError(str(path), f"compression {compression!r} is not one of 'zstd', 'lz4', None")
        self._compression = compression or ""
        if self._compression == "zstd":
            import zstandard
            self._compress = zstandard.ZstdCompressor(level=ZSTD_LEVEL).compress
        elif self._compression == "lz4":
            import lz4.frame
            self._compress = lz4.frame.compress
        else:
            self._compress = bytes
        try:
            self._f = open(self.path, "wb")  # noqa: SIM115 - closed in finish()/abort()
        except OSError as exc:
            raise LogError(str(path), f"cannot open the flight log for writing ({exc.strerror}); "
                           "choose a writable output directory") from None
        self._pos = 0
        self._crc = 0
        self._schemas: dict[int, bytes] = {}
        self._channels: dict[int, bytes] = {}
        self._chunk_indexes: list[bytes] = []
        self._metadata_indexes: list[bytes] = []
        self._counts: dict[int, int] = {}
        self._n_messages = 0
        self._start_ns: int | None = None
        self._end_ns = 0
        self._open = True
        try:
            self._write(MCAP_MAGIC)
            self._write(_record(Opcode.HEADER, _string("") + _string(LIBRARY)))
        except OSError as exc:
            self.abort()
            raise LogError(str(path), f"cannot write the flight log ({exc})") from None

    # -- data section ----------------------------------------------------------------------
    def _write(self, data: bytes) -> None:
        self._f.write(data)
        self._pos += len(data)
        self._crc = zlib.crc32(data, self._crc)

    def add_schema(self, schema_id: int, name: str, encoding: str, data: bytes) -> None:
        """Write a Schema record (op 0x03)."""
        rec = _record(Opcode.SCHEMA, struct.pack("<H", schema_id) + _string(name) + _string(encoding)
                      + struct.pack("<I", len(data)) + data)
        self._schemas[schema_id] = rec
        self._write(rec)

    def add_channel(self, channel_id: int, schema_id: int, topic: str, message_encoding: str,
                    metadata: Mapping[str, str] | None = None) -> None:
        """Write a Channel record (op 0x04)."""
        rec = _record(Opcode.CHANNEL, struct.pack("<HH", channel_id, schema_id) + _string(topic)
                      + _string(message_encoding) + _string_map(metadata or {}))
        self._channels[channel_id] = rec
        self._counts.setdefault(channel_id, 0)
        self._write(rec)

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """Write a Metadata record (op 0x0C) and remember its index."""
        rec = _record(Opcode.METADATA, _string(name) + _string_map(data))
        self._metadata_indexes.append(_record(
            Opcode.METADATA_INDEX, struct.pack("<QQ", self._pos, len(rec)) + _string(name)))
        self._write(rec)

    def write_chunk(self, payload: ChunkPayload) -> None:
        """Write one Chunk record and its Message Index records (nothing if empty)."""
        if payload.message_count == 0:
            return
        raw = payload.records
        packed = self._compress(raw)
        cname = self._compression.encode()
        head = struct.pack("<QQQI", payload.message_start_ns, payload.message_end_ns, len(raw),
                           zlib.crc32(raw)) + struct.pack("<I", len(cname)) + cname + struct.pack("<Q", len(packed))
        chunk_start = self._pos
        self._write(struct.pack("<BQ", Opcode.CHUNK, len(head) + len(packed)) + head)
        self._write(packed)
        chunk_length = self._pos - chunk_start
        index_start = self._pos
        # the Message Index records in one write; offsets: channel id, file position of its record
        records = []
        offsets = b""
        pos = index_start
        for cid, entries in payload.index.items():
            rec = encode_message_index(cid, entries)
            records.append(rec)
            offsets += struct.pack("<HQ", cid, pos)
            pos += len(rec)
            self._counts[cid] = self._counts.get(cid, 0) + len(entries)
        self._write(b"".join(records))
        self._chunk_indexes.append(_record(Opcode.CHUNK_INDEX, struct.pack(
            "<QQQQI", payload.message_start_ns, payload.message_end_ns, chunk_start, chunk_length,
            len(offsets)) + offsets + struct.pack("<Q", self._pos - index_start) + _string(self._compression)
            + struct.pack("<QQ", len(packed), len(raw))))
        self._n_messages += payload.message_count
        if self._start_ns is None or payload.message_start_ns < self._start_ns:
            self._start_ns = payload.message_start_ns
        self._end_ns = max(self._end_ns, payload.message_end_ns)

    def flush(self) -> None:
        """Push everything written so far to the operating system (survives SIGKILL)."""
        self._f.flush()

    def move_to(self, path: str | Path) -> None:
        """Rename the open file to ``path`` (atomic on one file system; replaces ``path``)."""
        os.replace(self.path, path)
        self.path = Path(path)

    # -- summary and footer ----------------------------------------------------------------
    def finish(self) -> None:
        """Write Data End, the summary section, the footer and the closing magic; close."""
        if not self._open:
            return
        with signals_deferred():
            self._finish()

    def _finish(self) -> None:
        try:
            self._write(_record(Opcode.DATA_END, struct.pack("<I", self._crc)))
            summary_start = self._pos
            groups: list[tuple[int, bytes]] = [
                (Opcode.SCHEMA, b"".join(self._schemas[k] for k in sorted(self._schemas))),
                (Opcode.CHANNEL, b"".join(self._channels[k] for k in sorted(self._channels))),
                (Opcode.STATISTICS, self._statistics()),
                (Opcode.CHUNK_INDEX, b"".join(self._chunk_indexes)),
                (Opcode.METADATA_INDEX, b"".join(self._metadata_indexes)),
            ]
            summary = b""
            offsets = b""
            for opcode, data in groups:
                if data:
                    offsets += _record(Opcode.SUMMARY_OFFSET, struct.pack(
                        "<BQQ", opcode, summary_start + len(summary), len(data)))
                    summary += data
            offset_start = summary_start + len(summary)
            summary += offsets
            # Footer: summary_start, summary_offset_start, summary_crc; the CRC covers the
            # summary section and the footer fields before it (MCAP spec, "Footer")
            footer_head = struct.pack("<BQQQ", Opcode.FOOTER, 20, summary_start, offset_start)
            crc = zlib.crc32(footer_head, zlib.crc32(summary))
            self._f.write(summary + footer_head + struct.pack("<I", crc) + MCAP_MAGIC)
            self._f.flush()
        finally:
            self._open = False
            self._f.close()

    def _statistics(self) -> bytes:
        # channels with messages only, as the reference writers do
        counts = b"".join(struct.pack("<HQ", k, n) for k, n in sorted(self._counts.items()) if n)
        return _record(Opcode.STATISTICS, struct.pack(
            "<QHIIIIQQI", self._n_messages, len(self._schemas), len(self._channels), 0,
            len(self._metadata_indexes), len(self._chunk_indexes), self._start_ns or 0, self._end_ns,
            len(counts)) + counts)

    def abort(self) -> None:
        """Close the file without a footer (after an I/O error)."""
        if self._open:
            self._open = False
            try:
                self._f.close()
            except OSError:
                pass


class VectorChannel:
    """A vector channel of a :class:`FlightLogWriter`; get one from ``add_vector_channel``."""

    __slots__ = ("_w", "topic", "schema", "channel_id", "_t", "_b", "_shape", "_pack", "_seq", "_last_t_s")

    def __init__(self, writer: FlightLogWriter, topic: str, schema: VectorSchema, channel_id: int) -> None:
        self._w = writer
        self.topic = topic
        self.schema = schema
        self.channel_id = channel_id
        self._t: list[float] = []
        self._b: list[bytes] = []
        self._shape = (schema.n_values,)
        self._pack = struct.Struct(f"<{schema.n_values}d").pack
        self._seq = 0
        self._last_t_s: float | None = None

    @property
    def fields(self) -> tuple[str, ...]:
        """Field names, ``t_s`` first."""
        return self.schema.fields

    @property
    def rows_written(self) -> int:
        """Rows written so far (flushed or still buffered)."""
        return self._seq + len(self._t)

    @property
    def last_t_s(self) -> float | None:
        """Time of the last row written [s], or None before the first."""
        return self._t[-1] if self._t else self._last_t_s

    def write(self, t_s: float, values: Any) -> None:
        """Log one row.

        Parameters
        ----------
        t_s : float
            Simulated time [s], finite, >= 0; log_time = publish_time = round(t_s * 1e9) ns.
        values : 1-D float array or sequence
            ``len(fields) - 1`` values in field order, without ``t_s``. Copied. A fresh
            float64 array, a tuple or a list of floats take the fast path.
        """
        # the common cases inline (a time in the current flush window; a fresh float64 array
        # or a tuple of floats); everything else, and every error, through the general checks
        try:
            in_window = 0.0 <= t_s < self._w._hi_t_s
        except TypeError:
            in_window = False
        if not in_window:
            self._w._admit_time(t_s, self.topic)
        kind = type(values)
        if kind is tuple or kind is list:
            try:
                b = self._pack(*values)
            except (struct.error, TypeError):
                b = self._values_slow_path(values)
        elif kind is _NDARRAY and values.dtype is _F8_LE and values.shape == self._shape:
            b = values.tobytes()
        else:
            b = self._values_slow_path(values)
        self._t.append(t_s)
        self._b.append(b)

    def write_rows(self, t_s: NDArray[np.float64], values: NDArray[np.float64]) -> None:
        """Log several rows at once (a detector block): ``t_s`` (N,) increasing [s], ``values``
        (N, len(fields) - 1) float64. The same messages as N calls of :meth:`write`; rows inside the
        current flush window go in as one buffer (a block that crosses the window's end is split
        there, the flush happening where :meth:`write` would do it)."""
        n = len(t_s)
        if n == 0:
            return
        v = values
        if not (type(v) is _NDARRAY and v.dtype is _F8_LE and v.shape == (n,) + self._shape and v.flags.c_contiguous):
            v = np.ascontiguousarray(values, dtype="<f8")
            if v.shape != (n,) + self._shape:
                raise LogError(str(self._w.path), f"{self.topic}: write_rows() needs (N, {self.schema.n_values}) "
                               f"values for {self.schema.fields[1:]} (without t_s), got {v.shape}")
        t = t_s.tolist() if type(t_s) is _NDARRAY else [float(x) for x in t_s]
        w = self._w
        if 0.0 <= t[0] and t[-1] < w._hi_t_s:  # the common case: the whole block in the flush window
            self._t.extend(t)
            self._b.append(v.tobytes())
            return
        i = 0
        while i < n:
            if not (0.0 <= t[i] < w._hi_t_s):
                w._admit_time(t[i], self.topic)  # checks the time; flushes when it leaves the window
            hi = w._hi_t_s
            j = i + 1
            while j < n and t[j] < hi:
                j += 1
            self._t.extend(t[i:j])
            self._b.append(v[i:j].tobytes())
            i = j

    def _values_slow_path(self, values: Any) -> bytes:
        if not isinstance(values, np.ndarray):
            try:
                return self._pack(*values)
            except (struct.error, TypeError):
                pass
        try:
            arr = np.asarray(values, dtype=np.float64)
        except (TypeError, ValueError):
            arr = None
        if arr is None or arr.shape != self._shape:
            got = getattr(arr, "shape", type(values).__name__)
            raise LogError(str(self._w.path), f"{self.topic}: write() needs {self.schema.n_values} "
                           f"float values for {self.schema.fields[1:]} (without t_s), got {got}")
        return arr.astype("<f8").tobytes()

    def _take(self, t_s: NDArray[np.float64]) -> VectorBlock:
        """Hand the buffered rows over as a block; ``t_s`` is ``self._t`` as an array [s]."""
        n = len(self._t)
        values = np.frombuffer(b"".join(self._b), dtype="<f8").reshape(n, self.schema.n_values)
        block = VectorBlock(self.channel_id, self._seq, t_s, values)
        self._seq += n
        self._last_t_s = self._t[-1]
        self._t = []
        self._b = []
        return block


class EventChannel:
    """An event (JSON) channel of a :class:`FlightLogWriter`; get one from ``add_event_channel``."""

    __slots__ = ("_w", "topic", "schema", "channel_id", "_seq")

    def __init__(self, writer: FlightLogWriter, topic: str, schema: EventSchema, channel_id: int) -> None:
        self._w = writer
        self.topic = topic
        self.schema = schema
        self.channel_id = channel_id
        self._seq = 0

    def write(self, t_s: float, payload: Mapping[str, Any]) -> None:
        """Log one event at simulated time ``t_s`` [s]; ``payload`` is a JSON-able dict."""
        w = self._w
        w._admit_time(t_s, self.topic)  # events are rare: always the full check
        try:
            data = self.schema.encode(payload)
        except LogError as exc:
            raise LogError(str(w.path), f"{self.topic}: {exc.problem}") from None
        w._pending_raw.append(RawMessage(self.channel_id, self._seq, int(round(float(t_s) * NS_PER_S)), data))
        self._seq += 1


class FlightLogWriter:
    """Write one run's MCAP flight log (context manager).

    Parameters
    ----------
    path : str or Path
        Output file; opened (created or truncated) at once, so an unwritable path fails
        before the simulation starts.
    metadata : dict of str to dict of str to str, optional
        Metadata records written first (``{"scenario": {"name": ..., "seed": ..., "text": ...}}``).
    flush_period_s : float
        Simulated time between flushes to disk [s]: a crash loses at most this much.
    compression : {"zstd", "lz4", None}
        Chunk compression.

    Raises
    ------
    LogError
        Unwritable path, bad metadata, bad period or compression.

    Examples
    --------
    >>> with FlightLogWriter("run.mcap", metadata={"scenario": {"name": "demo"}}) as log:  # doctest: +SKIP
    ...     truth = log.add_vector_channel("/truth/state", "fdi_sim/msg/TruthState",
    ...                                    ("t_s", "alpha_rad", "q_radps"))
    ...     truth.write(0.0, [0.05, 0.0])
    """

    def __init__(self, path: str | Path, *, metadata: Mapping[str, Mapping[str, str]] | None = None,
                 flush_period_s: float = 1.0, compression: str | None = "zstd") -> None:
        self.path = Path(path)
        try:
            period_ok = math.isfinite(flush_period_s) and flush_period_s > 0.0
        except TypeError:
            period_ok = False
        if not period_ok:
            raise LogError(str(path), f"flush_period_s = {flush_period_s!r} must be a finite time > 0 s")
        self.flush_period_s = float(flush_period_s)
        records = [(name, _check_metadata(str(path), name, data)) for name, data in (metadata or {}).items()]
        self._file = McapFileWriter(self.path, compression)
        self._closed = False
        self._hi_t_s = self.flush_period_s
        self._last_flush_t_s = 0.0
        self._schemas: dict[str, tuple[int, object]] = {}
        self._channels: dict[str, VectorChannel | EventChannel] = {}
        self._vector: list[VectorChannel] = []
        self._pending_raw: list[RawMessage] = []
        self._metadata_names: set[str] = set()
        try:
            for name, data in records:
                self._metadata(name, data)
            self._file.flush()
        except OSError as exc:
            self._file.abort()
            raise LogError(str(path), f"cannot write the flight log ({exc})") from None

    # -- context manager -------------------------------------------------------------------
    def __enter__(self) -> FlightLogWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- channels --------------------------------------------------------------------------
    def add_vector_channel(self, topic: str, schema_name: str, fields: Sequence[str]) -> VectorChannel:
        """Add a channel of float64 rows (CDR, ``ros2msg`` schema).

        Parameters
        ----------
        topic : str
            ``/stage/name`` (``"/truth/state"``).
        schema_name : str
            ``package/msg/Type`` (``"fdi_sim/msg/TruthState"``); channels may share a schema
            if they also share its fields.
        fields : sequence of str
            Unit-suffixed names, ``"t_s"`` first.
        """
        schema = self._wrap(vector_schema, schema_name, fields)
        sid = self._schema_id(schema, SCHEMA_ENCODING_ROS2MSG, schema.ros2msg().encode())
        cid = self._new_channel(topic, sid, MESSAGE_ENCODING_CDR)
        ch = VectorChannel(self, topic, schema, cid)
        self._channels[topic] = ch
        self._vector.append(ch)
        return ch

    def add_event_channel(self, topic: str, schema_name: str, json_schema: Mapping[str, Any]) -> EventChannel:
        """Add a low-rate JSON channel with a JSON Schema (``jsonschema`` / ``json``)."""
        schema = self._wrap(event_schema, schema_name, json_schema)
        sid = self._schema_id(schema, SCHEMA_ENCODING_JSONSCHEMA, schema.json_text.encode())
        cid = self._new_channel(topic, sid, MESSAGE_ENCODING_JSON)
        ch = EventChannel(self, topic, schema, cid)
        self._channels[topic] = ch
        return ch

    def _wrap(self, factory: Any, *args: Any) -> Any:
        self._check_open()
        try:
            return factory(*args)
        except LogError as exc:
            raise LogError(str(self.path), exc.problem) from None

    def _schema_id(self, schema: VectorSchema | EventSchema, encoding: str, data: bytes) -> int:
        known = self._schemas.get(schema.name)
        if known is not None:
            if known[1] != schema:
                raise LogError(str(self.path), f"schema {schema.name!r} is already defined differently; "
                               "give the new layout its own schema name")
            return known[0]
        sid = len(self._schemas) + 1
        self._io(self._file.add_schema, sid, schema.name, encoding, data)
        self._schemas[schema.name] = (sid, schema)
        return sid

    def _new_channel(self, topic: str, schema_id: int, encoding: str) -> int:
        try:
            check_topic(topic)
        except LogError as exc:
            raise LogError(str(self.path), exc.problem) from None
        if topic in self._channels:
            raise LogError(str(self.path), f"topic {topic!r} already has a channel; use that channel")
        cid = len(self._channels) + 1
        self._io(self._file.add_channel, cid, schema_id, topic, encoding)
        return cid

    # -- metadata, flush, close ------------------------------------------------------------
    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        """Write a metadata record now (``name`` unique in the file, values strings)."""
        self._check_open()
        self._metadata(name, _check_metadata(str(self.path), name, data))
        self._io(self._file.flush)

    def _metadata(self, name: str, data: dict[str, str]) -> None:
        if name in self._metadata_names:
            raise LogError(str(self.path), f"metadata record {name!r} was already written; "
                           "put all its keys in one record")
        self._metadata_names.add(name)
        self._io(self._file.add_metadata, name, data)

    def flush(self) -> None:
        """Write everything buffered as one chunk and push it to the operating system."""
        self._check_open()
        t_max = self._write_pending()
        if t_max is not None:
            self._last_flush_t_s = max(self._last_flush_t_s, t_max)

    @property
    def last_flush_t_s(self) -> float:
        """Simulated time [s] of the last flush: the time of the write that crossed a flush
        boundary (or the latest time flushed by :meth:`flush`). Every message written before
        that flush is in the operating system's hands, so it survives a SIGKILL."""
        return self._last_flush_t_s

    def move_to(self, path: str | Path) -> None:
        """Rename the log file to ``path`` while it stays open (replacing a file there).

        :func:`fdi_sim.sim.run` writes a new log under a temporary name next to its final path
        and moves it there only once the run is trimmed and flying, so a run that fails to start
        leaves an existing log at that path untouched.
        """
        self._check_open()
        try:
            self._file.move_to(path)
        except OSError as exc:
            raise LogError(str(path), f"cannot move the new log here ({exc.strerror})") from None
        self.path = Path(path)

    @property
    def closed(self) -> bool:
        """True after :meth:`close`."""
        return self._closed

    def close(self) -> None:
        """Flush, write the summary and footer, close. Idempotent; safe in ``finally``."""
        if self._closed:
            return
        self._closed = True
        self._hi_t_s = -math.inf  # every later write takes the slow path and raises
        try:
            self._write_pending()
            self._io(self._file.finish)
        finally:
            self._file.abort()  # no-op after a clean finish

    def abort(self) -> None:
        """Close the file as it is, without flushing the buffers or writing a summary."""
        self._closed = True
        self._hi_t_s = -math.inf
        self._file.abort()

    # -- internals -------------------------------------------------------------------------
    def _check_open(self) -> None:
        if self._closed:
            raise LogError(str(self.path), "the flight log is closed; open a new FlightLogWriter")

    def _io(self, fn: Any, *args: Any) -> None:
        try:
            fn(*args)
        except OSError as exc:
            self._closed = True
            self._hi_t_s = -math.inf
            self._file.abort()
            raise LogError(str(self.path), f"write failed ({exc}); the file was left without "
                           "its summary: run `fdi-sim repair` on it") from None

    @property
    def window_end_s(self) -> float:
        """End of the current flush window [s]: the first write at or after it flushes. A caller
        writing a block of rows on several channels writes every channel's rows before it first,
        so that each chunk holds the same times on every channel (the regular, fast layout)."""
        return self._hi_t_s

    def _admit_time(self, t_s: Any, topic: str) -> None:
        """Check the time of a write; flush first if it leaves the current flush window.

        :meth:`VectorChannel.write` calls this only for times outside the window.
        """
        self._check_open()
        if not isinstance(t_s, numbers.Real):
            raise LogError(str(self.path), f"{topic}: t_s = {t_s!r} is not a number")
        t = float(t_s)
        if not (0.0 <= t < MAX_T_S):
            raise LogError(str(self.path), f"{topic}: t_s = {t_s!r} must be finite, >= 0 s and "
                           f"< {MAX_T_S:g} s")
        if t >= self._hi_t_s:
            self._write_pending()
            self._last_flush_t_s = t
            k = math.floor(t / self.flush_period_s) + 1
            while k * self.flush_period_s <= t:
                k += 1
            self._hi_t_s = k * self.flush_period_s

    def _write_pending(self) -> float | None:
        """Write the buffered messages as one chunk, flush; return their latest time [s].

        Signals are held for the whole of it: rows taken from the buffers are always written.
        """
        with signals_deferred():
            return self._write_pending_now()

    def _write_pending_now(self) -> float | None:
        # channels written at the same times form a group: their times are converted once and
        # shared, which lets build_chunk recognise the regular layout by identity. Each group is
        # its own chunk (the 120 Hz topics and a 20 Hz detector bank would otherwise share one
        # irregular chunk and take the general layout, 3-4 times slower); every channel stays in
        # one chunk per flush, so its messages stay in time order.
        groups: list[tuple[list[float], NDArray[np.float64], list[VectorBlock]]] = []
        for ch in self._vector:
            if ch._t:
                for times, t_s, blocks in groups:
                    if ch._t == times:
                        break
                else:
                    times, t_s, blocks = ch._t, np.array(ch._t, dtype=np.float64), []
                    groups.append((times, t_s, blocks))
                blocks.append(ch._take(t_s))
        raws, self._pending_raw = self._pending_raw, []
        t_max = None
        if not groups and raws:
            groups = [([], np.zeros(0), [])]
        for i, (_, _, blocks) in enumerate(groups):
            payload = build_chunk(blocks, raws if i == 0 else ())  # the events with the first group
            end = payload.message_end_ns / NS_PER_S
            t_max = end if t_max is None else max(t_max, end)
            self._io(self._file.write_chunk, payload)
        self._io(self._file.flush)
        return t_max


def _check_metadata(path: str, name: Any, data: Any) -> dict[str, str]:
    """Validate one metadata record: a non-empty name and a dict of str to str."""
    if not isinstance(name, str) or not name:
        raise LogError(path, f"metadata name {name!r} must be a non-empty string")
    if not isinstance(data, Mapping):
        raise LogError(path, f"metadata {name!r} must be a dict of str to str, got {type(data).__name__}")
    bad = [k for k, v in data.items() if not isinstance(k, str) or not isinstance(v, str)]
    if bad:
        raise LogError(path, f"metadata {name!r}: keys and values must be strings (convert with str()); "
                       f"offending keys {bad!r}")
    return dict(data)
