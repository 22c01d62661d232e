"""Message schemas, topic names and wire layout of the fdi-sim flight log.

Two kinds of channel (DESIGN.md, "User-facing contracts"):

* **vector** channels: one message per simulation step holding a fixed tuple of ``float64``
  fields with unit-suffixed names, ``t_s`` first. Messages are CDR (ROS 2 wire format) with a
  ``ros2msg`` schema (``float64 t_s\\nfloat64 alpha_rad\\n...``), so Foxglove and PlotJuggler
  plot every field without any plugin.
* **event** channels: low-rate JSON messages (alarms, failure-log entries, status) with a JSON
  Schema (schema encoding ``jsonschema``, message encoding ``json``).

CDR layout of a vector message (OMG DDS-XTypes 1.3, 7.4.3 / 7.6.2.1.2; the ROS 2 ``cdr``
message encoding): a 4-byte encapsulation header ``00 01 00 00`` (representation identifier
``CDR_LE`` = 0x0001 written big-endian, then two option bytes), then the fields in order.
XCDR1 aligns a ``float64`` to 8 bytes *relative to the end of the header* (the alignment
origin is byte 4), so a struct of ``float64`` only has no padding at all:
``len = 4 + 8 * n_fields``. Every vector message is therefore
``b"\\x00\\x01\\x00\\x00" + values.astype("<f8").tobytes()`` and numpy can build a whole
second of rows in one shot: the last section lays out complete MCAP Message records and
chunks that way (:func:`build_chunk`), for the writer, the reader and repair alike.
"""
from __future__ import annotations

import functools
import json
import math
import re
import struct
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.errors import LogError
from fdi_sim.units import NS_PER_S

# --- encodings ------------------------------------------------------------------------------
#: CDR encapsulation header: representation id CDR_LE (0x0001, big-endian) + options 0x0000
CDR_LE_HEADER: bytes = b"\x00\x01\x00\x00"
#: CDR encapsulation header of big-endian plain CDR (read, never written)
CDR_BE_HEADER: bytes = b"\x00\x00\x00\x00"
MESSAGE_ENCODING_CDR: str = "cdr"
SCHEMA_ENCODING_ROS2MSG: str = "ros2msg"
MESSAGE_ENCODING_JSON: str = "json"
SCHEMA_ENCODING_JSONSCHEMA: str = "jsonschema"

# --- topic names (DESIGN.md: topics by stage) -------------------------------------------------
TOPIC_TRUTH_STATE: str = "/truth/state"
TOPIC_SURFACES: str = "/truth/surfaces"
TOPIC_OPERATING_POINT: str = "/truth/operating_point"
TOPIC_COMMANDS: str = "/commands/pilot"
TOPIC_SENSORS: str = "/sensors/measurements"
TOPIC_FAULTS: str = "/faults/active"
TOPIC_FDI_ALARMS: str = "/fdi/alarms"
TOPIC_FDI_FAILURE_LOG: str = "/fdi/failure_log"
TOPIC_SIM_STATUS: str = "/sim/status"

#: metadata record holding the scenario text, seed and package versions (DESIGN.md)
METADATA_SCENARIO: str = "scenario"

_TOPIC_RE = re.compile(r"^(/[a-z0-9][a-z0-9_\-]*)+$")
# ROS 2 field names: lower case, start with a letter, no "__", no trailing "_" (rosidl rules)
_FIELD_RE = re.compile(r"^[a-z][a-z0-9]*(_[a-z0-9]+)*$")
# ROS 2 type names: package/msg/TypeName
_SCHEMA_RE = re.compile(r"^[a-z][a-z0-9_]*/msg/[A-Z][A-Za-z0-9]*$")
_ROS2MSG_LINE_RE = re.compile(r"^\s*float64\s+([A-Za-z][A-Za-z0-9_]*)\s*(#.*)?$")


def check_topic(topic: str) -> str:
    """Return ``topic`` if it is a valid flight-log topic, else raise.

    Parameters
    ----------
    topic : str
        ``/stage/name`` path, lower case (``"/truth/state"``, ``"/fdi/parity-robust-v1/residual"``).

    Raises
    ------
    LogError
        If the name is not a lower-case absolute path.
    """
    if not isinstance(topic, str) or not _TOPIC_RE.match(topic):
        raise LogError("<topic>", f"topic {topic!r} is not a lower-case path like '/truth/state' "
                       "(segments of a-z, 0-9, '_' and '-', each after a '/')")
    return topic


def fdi_topic(detector_id: str, name: str) -> str:
    """Topic of one output of one detector: ``/fdi/<detector_id>/<name>``.

    Parameters
    ----------
    detector_id : str
        Registry id of the detector (``"parity-robust-v1"``).
    name : str
        Which output (``"residual"``, ``"decision"``).
    """
    return check_topic(f"/fdi/{detector_id}/{name}")


@dataclass(frozen=True)
class VectorSchema:
    """A ``ros2msg`` schema of ``float64`` fields, ``t_s`` first.

    Attributes
    ----------
    name : str
        ROS 2 type name ``package/msg/TypeName`` (``"fdi_sim/msg/TruthState"``).
    fields : tuple of str
        Field names with unit suffix, ``fields[0] == "t_s"``.
    """

    name: str
    fields: tuple[str, ...]

    @property
    def n_values(self) -> int:
        """Number of values a writer passes per message (fields without ``t_s``)."""
        return len(self.fields) - 1

    @property
    def message_size_bytes(self) -> int:
        """CDR payload size: 4-byte header + 8 bytes per field (no padding, see module doc)."""
        return len(CDR_LE_HEADER) + 8 * len(self.fields)

    def ros2msg(self) -> str:
        """Schema text, one ``float64 <field>`` line per field."""
        return "".join(f"float64 {f}\n" for f in self.fields)

    def encode(self, t_s: float, values: Sequence[float]) -> bytes:
        """CDR payload of one message (reference encoder; the writer encodes in bulk).

        Parameters
        ----------
        t_s : float
            Simulated time [s].
        values : sequence of float
            ``n_values`` values in field order (without ``t_s``).
        """
        if len(values) != self.n_values:
            raise LogError("<schema>", f"{self.name}: {len(values)} values for "
                           f"{self.n_values} fields {self.fields[1:]}")
        return CDR_LE_HEADER + struct.pack(f"<{len(self.fields)}d", t_s, *values)


def vector_schema(name: str, fields: Sequence[str]) -> VectorSchema:
    """Validate and build a :class:`VectorSchema`.

    Parameters
    ----------
    name : str
        ``package/msg/TypeName`` (``"fdi_sim/msg/TruthState"``).
    fields : sequence of str
        Unit-suffixed field names, ``"t_s"`` first, unique, ROS 2 field-name rules
        (lower case, ``[a-z][a-z0-9_]*``, no ``__``, no trailing ``_``).

    Raises
    ------
    LogError
        Naming the offending schema or field and the rule it breaks.
    """
    if not isinstance(name, str) or not _SCHEMA_RE.match(name):
        raise LogError("<schema>", f"schema name {name!r} must look like 'fdi_sim/msg/TruthState' "
                       "(package/msg/CamelCaseType)")
    if isinstance(fields, str):
        raise LogError("<schema>", f"{name}: fields must be a sequence of names, not the string {fields!r}")
    fields = tuple(fields)
    if len(fields) < 2 or fields[0] != "t_s":
        raise LogError("<schema>", f"{name}: fields must start with 't_s' and hold at least one "
                       f"value field, got {fields!r}")
    for f in fields:
        if not isinstance(f, str) or not _FIELD_RE.match(f):
            raise LogError("<schema>", f"{name}: field {f!r} is not a ROS 2 field name "
                           "(lower case letters, digits and single '_', starting with a letter, "
                           "e.g. 'alpha_rad')")
    dup = sorted({f for f in fields if fields.count(f) > 1})
    if dup:
        raise LogError("<schema>", f"{name}: duplicate fields {dup}")
    return VectorSchema(name=name, fields=fields)


def parse_ros2msg_float64(text: str) -> tuple[str, ...] | None:
    """Field names of a ``ros2msg`` schema made only of ``float64`` fields, else None.

    Comments and blank lines are ignored. Any other type (or a constant) returns None: the
    reader then keeps that channel's messages as raw bytes.
    """
    fields: list[str] = []
    for line in text.splitlines():
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        if stripped.startswith("=" * 10):  # dependent-type separator: not a flat schema
            return None
        m = _ROS2MSG_LINE_RE.match(stripped)
        if m is None:
            return None
        fields.append(m.group(1))
    return tuple(fields) if fields else None


@dataclass(frozen=True)
class EventSchema:
    """A JSON Schema for an event channel.

    Attributes
    ----------
    name : str
        Schema name (``"fdi_sim/msg/Alarm"``).
    json_text : str
        The JSON Schema, serialized canonically (sorted keys), as stored in the log.
    required : tuple of str
        Keys every payload must hold (the schema's ``"required"`` list).
    """

    name: str
    json_text: str
    required: tuple[str, ...]

    @property
    def json_schema(self) -> dict[str, Any]:
        """The JSON Schema as a dict (a fresh copy)."""
        return json.loads(self.json_text)

    def encode(self, payload: Mapping[str, Any]) -> bytes:
        """Canonical JSON of one payload: sorted keys, no spaces, no NaN (invalid JSON).

        numpy scalars and arrays are converted with ``.item()`` / ``.tolist()``.
        """
        if not isinstance(payload, Mapping):
            raise LogError("<event>", f"{self.name}: payload must be a dict, got {type(payload).__name__}")
        missing = [k for k in self.required if k not in payload]
        if missing:
            raise LogError("<event>", f"{self.name}: payload lacks required keys {missing}")
        try:
            text = json.dumps(payload, sort_keys=True, separators=(",", ":"),
                              allow_nan=False, default=_json_default)
        except (TypeError, ValueError) as exc:
            raise LogError("<event>", f"{self.name}: payload is not JSON-serializable ({exc}); "
                           "use str, int, float (finite), bool, None, lists and dicts") from None
        return text.encode("utf-8")


def event_schema(name: str, json_schema: Mapping[str, Any]) -> EventSchema:
    """Validate and build an :class:`EventSchema`.

    Parameters
    ----------
    name : str
        Schema name, ``package/msg/Type`` like vector schemas.
    json_schema : dict
        A JSON Schema object (``{"type": "object", "properties": {...}, "required": [...]}``).
    """
    if not isinstance(name, str) or not _SCHEMA_RE.match(name):
        raise LogError("<schema>", f"schema name {name!r} must look like 'fdi_sim/msg/Alarm' "
                       "(package/msg/CamelCaseType)")
    if not isinstance(json_schema, Mapping) or json_schema.get("type") != "object":
        raise LogError("<schema>", f"{name}: json_schema must be a dict with \"type\": \"object\"")
    required = json_schema.get("required", [])
    if not isinstance(required, (list, tuple)) or not all(isinstance(k, str) for k in required):
        raise LogError("<schema>", f"{name}: json_schema 'required' must be a list of key names")
    try:
        text = json.dumps(json_schema, sort_keys=True, separators=(",", ":"), allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise LogError("<schema>", f"{name}: json_schema is not plain JSON ({exc})") from None
    return EventSchema(name=name, json_text=text, required=tuple(required))


def _json_default(obj: Any) -> Any:
    """Convert numpy scalars/arrays for ``json.dumps``; anything else is an error."""
    item = getattr(obj, "item", None)
    tolist = getattr(obj, "tolist", None)
    if tolist is not None and getattr(obj, "ndim", 0) > 0:
        return tolist()
    if item is not None:
        value = item()
        if isinstance(value, float) and not math.isfinite(value):
            raise ValueError(f"non-finite value {value}")
        return value
    raise TypeError(f"object of type {type(obj).__name__} is not JSON serializable")


# --- JSON Schemas of the standard event channels ----------------------------------------------
#: ``/fdi/alarms``: one message each time a detector's alarm changes state
ALARM_JSON_SCHEMA: dict[str, Any] = {
    "type": "object",
    "title": "fdi-sim alarm transition",
    "properties": {
        "detector": {"type": "string", "description": "registry id of the detector"},
        "alarm": {"type": "boolean", "description": "new alarm state"},
        "statistic": {"type": "number", "description": "test statistic at the transition"},
        "threshold": {"type": "number", "description": "alarm threshold"},
        "isolation": {"type": ["string", "null"], "description": "isolated hypothesis, if any"},
    },
    "required": ["detector", "alarm"],
}

#: ``/fdi/failure_log``: time of occurrence, duration and nature of each failure
#: (Miller & Ribbens 2003, the failure log of FIG. 4)
FAILURE_LOG_JSON_SCHEMA: dict[str, Any] = {
    "type": "object",
    "title": "fdi-sim failure-log entry",
    "properties": {
        "hypothesis": {"type": "string", "description": "failed component (signal name)"},
        "detector": {"type": "string", "description": "registry id of the detector"},
        "onset_t_s": {"type": "number", "description": "time of occurrence [s]"},
        "duration_s": {"type": ["number", "null"], "description": "duration [s], null while active"},
        "kind": {"type": "string", "description": "nature of the failure"},
    },
    "required": ["hypothesis", "onset_t_s"],
}

#: ``/sim/status``: run status (start, trim done, end, diverged)
STATUS_JSON_SCHEMA: dict[str, Any] = {
    "type": "object",
    "title": "fdi-sim run status",
    "properties": {
        "status": {"type": "string"},
        "message": {"type": "string"},
    },
    "required": ["status"],
}


# --- wire layout: MCAP Message records and chunks (used by writer, reader and repair) -------
# A Message record (MCAP spec, "Message", op 0x05) is opcode u8 | record length u64 |
# channel_id u16 | sequence u32 | log_time u64 | publish_time u64 | data. For a vector
# channel the data is the CDR payload above, so every record of the channel has the same size
# 35 + 8 * n_fields and a whole chunk of them is one packed numpy structured array.
MCAP_MAGIC: bytes = b"\x89MCAP0\r\n"
OP_MESSAGE: int = 0x05
OP_MESSAGE_INDEX: int = 0x07
#: bytes of a Message record before its data: opcode, length, channel, sequence, 2 times
MESSAGE_HEAD = struct.Struct("<BQHIQQ")


def message_dtype(n_fields: int) -> np.dtype:
    """Packed dtype of one complete Message record of a vector channel of ``n_fields``."""
    return np.dtype([
        ("opcode", "u1"), ("length", "<u8"), ("channel_id", "<u2"), ("sequence", "<u4"),
        ("log_time", "<u8"), ("publish_time", "<u8"), ("cdr", "u1", (4,)),
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
        Times [s], shape (n,); blocks of one step share the same array object.
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
    rec["opcode"] = OP_MESSAGE
    rec["length"] = rec.dtype.itemsize - 9
    rec["channel_id"] = block.channel_id
    rec["sequence"] = (np.arange(n, dtype=np.int64) + block.first_sequence) & 0xFFFFFFFF
    log = log_time_ns(block.t_s)
    rec["log_time"] = log
    rec["publish_time"] = log
    rec["cdr"] = np.frombuffer(CDR_LE_HEADER, dtype=np.uint8)
    rec["values"][:, 0] = block.t_s
    rec["values"][:, 1:] = block.values
    return rec


#: per-row fields shared by every channel of a step: sequence, log time, publish time, CDR
#: header, t_s (bytes 11..43 of each Message record)
_ROW_HEAD = np.dtype([("sequence", "<u4"), ("log_time", "<u8"), ("publish_time", "<u8"),
                      ("cdr", "V4"), ("t_s", "<f8")])


@functools.lru_cache(maxsize=64)
def _step_layout(ids: tuple[int, ...], n_values: tuple[int, ...]) -> tuple[np.dtype, bytes, NDArray[np.int64]]:
    """One time step holding one Message record per channel, back to back: its dtype (the
    variable parts only), its bytes with the constant parts filled, each record's offset."""
    names: list[str] = []
    formats: list[Any] = []
    offsets: list[int] = []
    template = b""
    starts = []
    for c, (cid, nv) in enumerate(zip(ids, n_values)):
        base = len(template)
        starts.append(base)
        names += [f"h{c}", f"v{c}"]
        formats += [_ROW_HEAD, ("<f8", (nv,))]
        offsets += [base + 11, base + 43]
        template += struct.pack("<BQH", OP_MESSAGE, 34 + 8 * nv, cid) + bytes(32 + 8 * nv)
    dtype = np.dtype({"names": names, "formats": formats, "offsets": offsets, "itemsize": len(template)})
    return dtype, template, np.array(starts, dtype=np.int64)


def _row_heads(t_s: NDArray[np.float64], log: NDArray[np.uint64], first_sequence: int) -> NDArray[Any]:
    head = np.empty(len(t_s), dtype=_ROW_HEAD)
    head["sequence"] = (np.arange(len(t_s), dtype=np.int64) + first_sequence) & 0xFFFFFFFF
    head["log_time"] = log
    head["publish_time"] = log
    head["cdr"] = np.void(CDR_LE_HEADER)
    head["t_s"] = t_s
    return head


def _regular_layout(blocks: list[VectorBlock]) -> tuple[bytearray, NDArray[np.uint64], NDArray[np.int64]] | None:
    """The usual chunk: every channel wrote once per step at the same, sorted times. A step
    is then a fixed-size group of records and the chunk one structured array, filled with
    two copies per channel. Returns the bytes, the log times (n,) and the record offsets
    (n, channels); None if the chunk is not regular."""
    t0 = blocks[0].t_s
    n = len(t0)
    if not all(b.t_s is t0 or (len(b.t_s) == n and np.array_equal(b.t_s, t0)) for b in blocks):
        return None
    log = log_time_ns(t0)
    if np.any(log[1:] < log[:-1]):
        return None
    dtype, template, starts = _step_layout(tuple(b.channel_id for b in blocks),
                                           tuple(b.values.shape[1] for b in blocks))
    buf = bytearray(template * n)
    comb = np.frombuffer(buf, dtype=dtype)
    heads: dict[int, NDArray[Any]] = {}
    for c, b in enumerate(blocks):
        if b.first_sequence not in heads:
            heads[b.first_sequence] = _row_heads(t0, log, b.first_sequence)
        comb[f"h{c}"] = heads[b.first_sequence]
        comb[f"v{c}"] = b.values
    offsets = np.arange(n, dtype=np.int64)[:, None] * len(template) + starts[None, :]
    return buf, log, offsets


def _general_layout(blocks: list[VectorBlock]) -> tuple[bytes, NDArray[np.uint64], NDArray[np.int64], list[NDArray[np.int64]]]:
    """Any chunk: stable sort of all rows by (log time, block), whole records copied into
    place. Returns the bytes, file-order log times and offsets, and each block's positions."""
    recs = [vector_records(b) for b in blocks]
    all_log = np.concatenate([r["log_time"] for r in recs])
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
        index = {b.channel_id: _entries(log, offs[:, c]) for c, b in enumerate(blocks)}
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
    rbytes = [MESSAGE_HEAD.pack(OP_MESSAGE, 22 + len(raws[i].data), raws[i].channel_id,
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
    return struct.pack("<BQHI", OP_MESSAGE_INDEX, 2 + 4 + len(body), channel_id, len(body)) + body
