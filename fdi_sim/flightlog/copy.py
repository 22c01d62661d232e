"""Write a log again with topics added: offline detection keeps the input's topics beside ``/fdi``.

:func:`write_extended` reads nothing itself: it takes a :class:`FlightLog` (``read_log``) and
new vector and event topics as arrays, and writes one MCAP file through
:class:`FlightLogWriter`, one simulated second at a time in time order (the writer's chunk
layout), so the result reads with ``read_log``, the ``mcap`` tools and Foxglove like any run log.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.errors import LogError
from fdi_sim.flightlog.reader import EventTopic, FlightLog, VectorTopic
from fdi_sim.flightlog.writer import FlightLogWriter


@dataclass(frozen=True, eq=False)
class NewVectorTopic:
    """Rows to add: ``values[i]`` at ``t_s[i]`` [s], fields without ``t_s``."""

    topic: str
    schema_name: str
    fields: tuple[str, ...]
    t_s: NDArray[np.float64]
    values: NDArray[np.float64]


@dataclass(frozen=True)
class NewEventTopic:
    """Events to add: ``(t_s [s], JSON-able dict)`` with their JSON Schema."""

    topic: str
    schema_name: str
    json_schema: Mapping[str, Any]
    events: tuple[tuple[float, Mapping[str, Any]], ...]


def write_extended(log: FlightLog, out: str | Path, vectors: Sequence[NewVectorTopic] = (),
                   events: Sequence[NewEventTopic] = (), metadata: Mapping[str, Mapping[str, str]] | None = None) -> Path:
    """Write ``log``'s topics and metadata plus new topics to ``out``.

    Parameters
    ----------
    log : FlightLog
        The input, as read by :func:`fdi_sim.flightlog.read_log`.
    out : path
        The new file; must not be the input.
    vectors, events : sequences
        Topics to add (names must not clash with the input's).
    metadata : mapping, optional
        Metadata records to add (names must not clash).

    Returns
    -------
    Path

    Notes
    -----
    Vector (CDR) and event (JSON) topics are copied; a topic in another tool's encoding
    (``RawTopic``) is not.
    """
    out = Path(out)
    if out.exists() and Path(log.path).exists() and out.resolve() == Path(log.path).resolve():
        raise LogError(str(out), "the output is the input log; give another --out path")
    clash = [t.topic for t in (*vectors, *events) if t.topic in log.topics]
    clash += [m for m in (metadata or {}) if m in log.metadata]
    if clash:
        raise LogError(str(out), f"{', '.join(clash)} already in the input log {log.path}")
    meta = {**log.metadata, **dict(metadata or {})}
    rows: list[tuple[Any, NDArray[np.float64], NDArray[np.float64]]] = []
    evs: list[tuple[Any, list[tuple[float, Mapping[str, Any]]]]] = []
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise LogError(str(out.parent), f"cannot create the output folder ({exc.strerror})") from None
    # written under a temporary name and moved to `out` only once complete: an interrupted or
    # failed write leaves neither a partial file that reads as complete nor a changed `out`
    tmp = out.with_name(f".{out.name}.partial-{os.getpid()}")
    w = FlightLogWriter(tmp, metadata=meta)
    try:
        _copy(log, w, rows, evs, vectors, events)
        w.close()
        os.replace(tmp, out)
    except BaseException:
        w.abort()
        tmp.unlink(missing_ok=True)
        raise
    return out


def _copy(log: FlightLog, w: FlightLogWriter, rows: list, evs: list, vectors: Sequence[NewVectorTopic],
          events: Sequence[NewEventTopic]) -> None:
    """Write the input topics and the new ones, one flush window at a time, in time order."""
    for name, t in log.topics.items():
        if isinstance(t, VectorTopic):
            ch = w.add_vector_channel(name, t.schema_name, t.fields)
            rows.append((ch, np.asarray(t.t_s, dtype=float), np.asarray(t.data[:, 1:], dtype=float)))
        elif isinstance(t, EventTopic):
            ch = w.add_event_channel(name, t.schema_name, t.json_schema)
            evs.append((ch, [(e.t_s, e.payload) for e in t.events]))
        # a RawTopic (another tool's message encoding) is not copied (write_extended's docstring)
    for v in vectors:
        ch = w.add_vector_channel(v.topic, v.schema_name, ("t_s",) + tuple(v.fields))
        rows.append((ch, np.asarray(v.t_s, dtype=float), np.asarray(v.values, dtype=float).reshape(len(v.t_s), -1)))
    for e in events:
        ch = w.add_event_channel(e.topic, e.schema_name, e.json_schema)
        evs.append((ch, list(e.events)))
    t_end = max([r[1][-1] for r in rows if len(r[1])] + [t for _, es in evs for t, _ in es] + [0.0])
    cursors = [0] * len(rows)
    ecursors = [0] * len(evs)
    for k in range(int(math.floor(t_end)) + 2):  # one flush window at a time, in time order
        hi = float(k + 1)
        for i, (ch, t, vals) in enumerate(rows):
            j0 = cursors[i]
            j1 = int(np.searchsorted(t, hi, side="left"))
            for j in range(j0, j1):
                ch.write(float(t[j]), vals[j])
            cursors[i] = j1
        for i, (ch, es) in enumerate(evs):
            j = ecursors[i]
            while j < len(es) and es[j][0] < hi:
                ch.write(es[j][0], es[j][1])
                j += 1
            ecursors[i] = j
