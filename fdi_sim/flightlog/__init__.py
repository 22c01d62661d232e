"""The flight log: one MCAP file per run, written, read back, and repaired after a crash.

Table of contents
-----------------
- :class:`FlightLogWriter` (``writer.py``): ``add_vector_channel`` -> :class:`VectorChannel`
  (float64 rows, CDR + ``ros2msg``), ``add_event_channel`` -> :class:`EventChannel` (JSON +
  JSON Schema), ``add_metadata``, ``flush``, ``close``; flushed once per simulated second.
- :func:`read_log` -> :class:`FlightLog` (``reader.py``): ``topics[topic]`` is a
  :class:`VectorTopic` (numpy column per field), an :class:`EventTopic` (``(t_s, dict)`` events)
  or a :class:`RawTopic`; :func:`log_info` -> :class:`LogInfo` from the summary alone.
- :func:`repair_log` -> :class:`RepairReport` (``repair.py``): rebuild a file cut off by a crash
  or damaged, taking each schema and channel from its intact copy.
- :func:`verify_log` -> :class:`VerifyReport` (``verify.py``): every CRC and index checked, each
  damaged part named (:class:`Problem`).
- ``framing.py``: strict record parsing, a record scan that resynchronises after damage, CRC32
  single-byte error location (shared by verify and repair).
- ``schemas.py``: topic names, schema validation, CDR layout, standard event JSON Schemas.
- ``records.py``: MCAP framing, Message records and chunks laid out with numpy, chunk parsing
  (shared by the writer, the reader and repair).

MCAP libraries are imported only inside this package (STYLE.md rule 2).
"""
from __future__ import annotations

from fdi_sim.flightlog.reader import (
    Event,
    EventTopic,
    FlightLog,
    LogInfo,
    RawTopic,
    TopicData,
    TopicInfo,
    VectorTopic,
    log_info,
    read_log,
)
from fdi_sim.flightlog.repair import RepairReport, repair_log
from fdi_sim.flightlog.schemas import (
    ALARM_JSON_SCHEMA,
    FAILURE_LOG_JSON_SCHEMA,
    FAULT_EVENT_JSON_SCHEMA,
    METADATA_FAULTS,
    METADATA_SCENARIO,
    STATUS_JSON_SCHEMA,
    TOPIC_COMMANDS,
    TOPIC_FAULT_EVENTS,
    TOPIC_FAULTS,
    TOPIC_FDI_ALARMS,
    TOPIC_FDI_FAILURE_LOG,
    TOPIC_OPERATING_POINT,
    TOPIC_SENSORS,
    TOPIC_SENSORS_VALID,
    TOPIC_SIM_STATUS,
    TOPIC_SURFACES,
    TOPIC_TRUTH_STATE,
    EventSchema,
    VectorSchema,
    event_schema,
    fdi_topic,
    vector_schema,
)
from fdi_sim.flightlog.verify import Problem, VerifyReport, verify_log
from fdi_sim.flightlog.writer import EventChannel, FlightLogWriter, VectorChannel

__all__ = [
    "ALARM_JSON_SCHEMA", "FAILURE_LOG_JSON_SCHEMA", "FAULT_EVENT_JSON_SCHEMA", "METADATA_FAULTS",
    "METADATA_SCENARIO", "STATUS_JSON_SCHEMA", "TOPIC_COMMANDS", "TOPIC_FAULTS",
    "TOPIC_FAULT_EVENTS", "TOPIC_FDI_ALARMS", "TOPIC_FDI_FAILURE_LOG", "TOPIC_OPERATING_POINT",
    "TOPIC_SENSORS", "TOPIC_SENSORS_VALID", "TOPIC_SIM_STATUS", "TOPIC_SURFACES",
    "TOPIC_TRUTH_STATE",
    "Event", "EventChannel", "EventSchema", "EventTopic", "FlightLog", "FlightLogWriter", "LogInfo",
    "Problem", "RawTopic", "RepairReport", "TopicData", "TopicInfo", "VectorChannel", "VectorSchema",
    "VectorTopic", "VerifyReport",
    "event_schema", "fdi_topic", "log_info", "read_log", "repair_log", "vector_schema", "verify_log",
]
