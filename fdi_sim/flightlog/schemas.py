"""Message schemas, topic names and CDR payloads of the fdi-sim flight log.

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
second of rows in one shot (:func:`fdi_sim.flightlog.records.build_chunk`).
"""
from __future__ import annotations

import json
import math
import re
import struct
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

from fdi_sim.errors import LogError

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
TOPIC_FAULT_EVENTS: str = "/faults/events"
TOPIC_SENSORS_VALID: str = "/sensors/valid"
TOPIC_FDI_ALARMS: str = "/fdi/alarms"
TOPIC_FDI_FAILURE_LOG: str = "/fdi/failure_log"
TOPIC_SIM_STATUS: str = "/sim/status"

#: metadata record holding the scenario text, seed and package versions (DESIGN.md)
METADATA_SCENARIO: str = "scenario"
#: metadata record holding the fault catalogue (key ``catalog``: JSON list, one dict per fault)
METADATA_FAULTS: str = "faults"

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
def _object_schema(title: str, required: list[str], **properties: dict[str, Any]) -> dict[str, Any]:
    """A JSON Schema of an object with the given properties."""
    return {"type": "object", "title": title, "properties": properties, "required": required}


_DETECTOR_ID = {"type": "string", "description": "registry id of the detector"}

#: ``/fdi/alarms``: one message each time a detector's alarm changes state
ALARM_JSON_SCHEMA: dict[str, Any] = _object_schema(
    "fdi-sim alarm transition", ["detector", "alarm"],
    detector=_DETECTOR_ID,
    alarm={"type": "boolean", "description": "new alarm state"},
    statistic={"type": "number", "description": "test statistic at the transition"},
    threshold={"type": "number", "description": "alarm threshold"},
    isolation={"type": ["string", "null"], "description": "isolated hypothesis, if any"},
    event={"type": "string", "description": "\"isolated\": the alarm's isolation changed (the in-loop bank)"},
)

#: ``/fdi/failure_log``: time of occurrence, duration and nature of each failure
#: (Miller & Ribbens 2003, the failure log of FIG. 4)
FAILURE_LOG_JSON_SCHEMA: dict[str, Any] = _object_schema(
    "fdi-sim failure-log entry", ["hypothesis", "onset_t_s"],
    hypothesis={"type": "string", "description": "failed component (signal name)"},
    detector=_DETECTOR_ID,
    onset_t_s={"type": "number", "description": "time of occurrence [s]"},
    duration_s={"type": ["number", "null"], "description": "duration [s], null while active"},
    kind={"type": "string", "description": "what failed: sensor, or actuator (name)"},
    nature={"type": "string", "description": "persistent, or intermittent (more than one onset so far)"},
    event={"type": "string", "description": "onset or end"},
    ongoing={"type": "boolean", "description": "the entry was still on when the flight ended"},
)

#: ``/sim/status``: run status (start, trim done, end, diverged)
STATUS_JSON_SCHEMA: dict[str, Any] = _object_schema(
    "fdi-sim run status", ["status"],
    status={"type": "string"},
    message={"type": "string"},
)

#: ``/faults/events``: the fault catalogue at t = 0, then each onset and clear of a fault window
FAULT_EVENT_JSON_SCHEMA: dict[str, Any] = _object_schema(
    "fdi-sim fault event", ["event"],
    event={"type": "string", "enum": ["catalog", "onset", "clear"]},
    label={"type": "string", "description": "fault label (prefix of its fields on /faults/active)"},
    type={"type": "string", "description": "registry id of the fault"},
    target={"type": "string", "description": "surface, throttle, engine_<i>, sensor name or airframe"},
    faults={"type": "array", "description": "catalog: every fault with its parameters and on-windows [s]"},
)
