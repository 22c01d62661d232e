"""The shipped Foxglove layout: well formed, and every message path it names exists in our logs.

``fdi_sim/review/foxglove/fdi-sim-layout.json`` is a Foxglove layout (the ``LayoutData`` of
foxglove/studio: ``configById``, a react-mosaic ``layout`` tree, ``globalVariables``,
``userNodes``, ``playbackConfig``). The panel types and their config keys are those of
foxglove/studio (``packages/studio-base/src/panels/index.ts`` and each panel's config type);
message paths follow its grammar (``components/MessagePathSyntax/grammar.ne``): a topic of
``/`` and ``[a-zA-Z0-9_]`` or a double-quoted topic (ours hold ``-``: ``"/fdi/kalman-gust-v1/
statistic".threshold``), then ``.field`` parts.

The paths are checked against the logs of the shipped scenarios as
``tests/flightlog/test_foxglove.py`` flies them (8 s each, the pitch-gyro bias also for 14 s so
its bank alarms and reconfigures): flight paths against every log, a bank member's topics against
every log of a scenario with an ``[fdi]`` table, ``/faults/*`` against every log in which a fault
was injected, the bank's event channels against the bank logs (issue 15, Foxglove bar).
"""
from __future__ import annotations

import json
import re
import sys
import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any, Iterator

import pytest

from fdi_sim.flightlog import EventTopic, FlightLog, VectorTopic, read_log

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests" / "flightlog"))
import test_foxglove as fox  # noqa: E402  (the flown logs are shared with the decoding test)

LAYOUT_RESOURCE = "review/foxglove/fdi-sim-layout.json"
#: built-in panel types of foxglove/studio (packages/studio-base/src/panels/index.ts)
KNOWN_PANEL_TYPES = frozenset({
    "3D", "DiagnosticStatusPanel", "DiagnosticSummary", "ImageViewPanel", "Indicator", "Gauge",
    "Teleop", "map", "Parameters", "Plot", "Publish", "RawMessages", "RosOut", "StateTransitions",
    "Table", "URDFViewer", "TopicGraph", "SourceInfo", "GlobalVariableSliderPanel", "NodePlayground",
    "Tab", "website"})
#: the keys each panel type we use must have (foxglove/studio's PlotConfig / PlotPath,
#: RawMessagesPanelConfig, Table's Config, StateTransitionPath, Tab's config)
REQUIRED_KEYS = {
    "Plot": {"paths", "showLegend", "isSynced", "xAxisVal"},
    "RawMessages": {"topicPath", "diffEnabled", "diffMethod", "diffTopicPath", "showFullMessageForDiff"},
    "Table": {"topicPath"},
    "StateTransitions": {"paths"},
    "Tab": {"activeTabIdx", "tabs"},
}
TIMESTAMP_METHODS = frozenset({"receiveTime", "headerStamp"})
PLOT_X_AXIS = frozenset({"timestamp", "index", "custom", "currentCustom"})

# grammar.ne: topicName -> slashID:+ | quotedID; slashID -> "/" id:?; id -> [a-zA-Z0-9_]:+
_TOPIC_RE = re.compile(r'"(?P<quoted>(?:[^"\\]|\\\\|\\")*)"|(?P<plain>(?:/[a-zA-Z0-9_]*)+)')
_NAME_RE = re.compile(r"\.([a-zA-Z0-9_]+)")


@dataclass(frozen=True)
class MessagePath:
    """One message path a panel names.

    Attributes
    ----------
    panel : str
        Panel id (``"Plot!altitude"``).
    topic : str
        Topic name, unquoted.
    fields : tuple of str
        Field names after the topic (empty for a whole-topic panel).
    """

    panel: str
    topic: str
    fields: tuple[str, ...]


def parse_message_path(text: str, panel: str = "?") -> MessagePath:
    """Parse ``text`` by Foxglove's message-path grammar (topic, then ``.name`` parts only).

    Raises
    ------
    ValueError
        If ``text`` is not a whole path of that grammar (slices, filters and modifiers are not
        used by our layout and are refused too).
    """
    m = _TOPIC_RE.match(text)
    if m is None:
        raise ValueError(f"{panel}: {text!r} does not start with a topic")
    topic = m["plain"] if m["plain"] is not None else m["quoted"].replace('\\"', '"').replace("\\\\", "\\")
    pos, fields = m.end(), []
    while pos < len(text):
        part = _NAME_RE.match(text, pos)
        if part is None:
            raise ValueError(f"{panel}: {text!r} is not a Foxglove message path from character {pos} "
                             f"({text[pos:]!r}); a topic holding '-' must be double-quoted")
        fields.append(part[1])
        pos = part.end()
    return MessagePath(panel, topic, tuple(fields))


def _members(log: FlightLog) -> set[str]:
    """The ids of the bank members a log flew (none without a bank)."""
    if "fdi" not in log.metadata:
        return set()
    return {m["id"] for m in json.loads(log.metadata["fdi"]["members"])}


def load_layout() -> dict[str, Any]:
    """The layout shipped as package data."""
    return json.loads((resources.files("fdi_sim") / LAYOUT_RESOURCE).read_text(encoding="utf-8"))


def mosaic_leaves(node: Any, where: str) -> Iterator[str]:
    """Panel ids of a react-mosaic tree (a panel id, or ``{direction, first, second}``)."""
    if isinstance(node, str):
        yield node
        return
    assert isinstance(node, dict), f"{where}: a mosaic node is a panel id or an object, not {node!r}"
    assert node.get("direction") in ("row", "column"), f"{where}: direction {node.get('direction')!r}"
    assert set(node) <= {"direction", "first", "second", "splitPercentage"}, f"{where}: keys {sorted(node)}"
    if "splitPercentage" in node:
        assert 0 < node["splitPercentage"] < 100, f"{where}: splitPercentage {node['splitPercentage']}"
    yield from mosaic_leaves(node["first"], where + ".first")
    yield from mosaic_leaves(node["second"], where + ".second")


def panels_in_view(layout: dict[str, Any]) -> list[str]:
    """Every panel id reachable from the root, through Tab panels' tabs."""
    seen: list[str] = []
    todo = [(layout["layout"], "layout")]
    while todo:
        node, where = todo.pop()
        for pid in mosaic_leaves(node, where):
            assert pid not in seen, f"panel {pid} appears twice"
            seen.append(pid)
            if pid.split("!")[0] == "Tab":
                for i, tab in enumerate(layout["configById"][pid]["tabs"]):
                    todo.append((tab["layout"], f"{pid}.tabs[{i}]"))
    return seen


def message_paths(layout: dict[str, Any]) -> list[MessagePath]:
    """Every message path the layout's panels name."""
    out = []
    for pid, cfg in layout["configById"].items():
        kind = pid.split("!")[0]
        if kind in ("Plot", "StateTransitions"):
            out += [parse_message_path(p["value"], pid) for p in cfg["paths"]]
        elif kind in ("RawMessages", "Table"):
            out.append(parse_message_path(cfg["topicPath"], pid))
    return out


def _fault_injected(stem: str, duration_s: float) -> bool:
    """Whether the shipped scenario ``stem`` injects a fault before ``duration_s``."""
    scenario = tomllib.loads((ROOT / "scenarios" / f"{stem}.toml").read_text())
    return any(f.get("t_start_s", 0.0) < duration_s for f in scenario.get("faults", []))


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, FlightLog]:
    """The shipped scenarios' logs (test_foxglove's), read."""
    return {name: read_log(path) for name, path in fox.shipped_logs(tmp_path_factory).items()
            if name != "detect"}


def _missing(log: FlightLog, path: MessagePath) -> str | None:
    """Why ``path`` is not in ``log``, or None."""
    if path.topic not in log.topics:
        return f"{log.path.name} has no topic {path.topic}"
    data = log.topics[path.topic]
    if not path.fields:
        return None
    if isinstance(data, VectorTopic):
        if len(path.fields) != 1 or path.fields[0] not in data.fields:
            return f"{log.path.name} {path.topic} has no field {'.'.join(path.fields)} (fields {data.fields})"
        return None
    assert isinstance(data, EventTopic)
    if not data.events:
        return f"{log.path.name} {path.topic} has no events to hold {'.'.join(path.fields)}"
    for event in data.events:
        value: Any = event.payload
        for name in path.fields:
            if not isinstance(value, dict) or name not in value:
                return f"{log.path.name} {path.topic} event at {event.t_s} s has no {'.'.join(path.fields)}"
            value = value[name]
    return None


def test_layout_is_a_foxglove_layout() -> None:
    layout = load_layout()
    assert {"configById", "layout", "globalVariables", "userNodes", "playbackConfig"} <= set(layout)
    assert layout["userNodes"] == {} and isinstance(layout["globalVariables"], dict)
    assert layout["playbackConfig"]["speed"] > 0
    in_view = panels_in_view(layout)
    assert sorted(in_view) == sorted(layout["configById"]), (
        "every panel in the mosaic needs a config and every config a place in the mosaic: "
        f"without config {sorted(set(in_view) - set(layout['configById']))}, "
        f"not shown {sorted(set(layout['configById']) - set(in_view))}")
    for pid, cfg in layout["configById"].items():
        kind, _, suffix = pid.partition("!")
        assert kind in KNOWN_PANEL_TYPES and suffix, f"{pid}: not a Foxglove panel id 'Type!id'"
        assert REQUIRED_KEYS.get(kind, set()) <= set(cfg), f"{pid}: missing {REQUIRED_KEYS[kind] - set(cfg)}"
        if kind == "Plot":
            assert cfg["xAxisVal"] in PLOT_X_AXIS, pid
        if kind in ("Plot", "StateTransitions"):
            assert cfg["paths"], f"{pid}: no paths"
            for p in cfg["paths"]:
                assert p["timestampMethod"] in TIMESTAMP_METHODS, pid
                assert kind != "Plot" or p["enabled"] is True, pid
        if kind == "RawMessages":
            assert cfg["diffMethod"] in ("custom", "previous message"), pid
        if kind == "Tab":
            assert 0 <= cfg["activeTabIdx"] < len(cfg["tabs"]) and all("title" in t for t in cfg["tabs"]), pid


def test_message_path_parser_follows_foxglove_grammar() -> None:
    assert parse_message_path("/truth/state.h_ft") == MessagePath("?", "/truth/state", ("h_ft",))
    assert parse_message_path('"/fdi/kalman-gust-v1/statistic".threshold').topic == \
        "/fdi/kalman-gust-v1/statistic"
    assert parse_message_path("/fdi/alarms").fields == ()
    for bad in ("/fdi/kalman-gust-v1/statistic.threshold", "truth.h_ft", "/truth/state.h_ft[0]",
                "/truth/state.h_ft.@derivative"):
        with pytest.raises(ValueError):
            parse_message_path(bad)


def test_layout_has_the_standard_panels() -> None:
    layout = load_layout()
    by_panel: dict[str, set[tuple[str, tuple[str, ...]]]] = {}
    for p in message_paths(layout):
        by_panel.setdefault(p.panel, set()).add((p.topic, p.fields))

    def plotted_together(*wanted: tuple[str, str]) -> bool:
        return any(pid.startswith("Plot!") and {(t, (f,)) for t, f in wanted} <= paths
                   for pid, paths in by_panel.items())

    S, C, F = "/truth/state", "/commands/pilot", "/truth/surfaces"
    assert plotted_together((S, "h_ft"), (C, "h_ref_ft")), "altitude + reference"
    assert plotted_together((S, "vc_kts"), (C, "vc_ref_kts")), "airspeed + reference"
    assert plotted_together((S, "phi_rad"), (S, "theta_rad"), (S, "psi_rad")), "attitudes"
    assert plotted_together((S, "p_radps"), (S, "q_radps"), (S, "r_radps")), "rates"
    for surface in ("elevator", "aileron", "rudder"):
        assert plotted_together((F, f"{surface}_pos_rad"), (C, f"{surface}_cmd_norm")), surface
    whole = {(pid.split("!")[0], t) for pid, paths in by_panel.items() for t, f in paths if not f}
    for topic in ("/fdi/alarms", "/fdi/failure_log", "/sim/status", "/faults/events"):
        assert ("RawMessages", topic) in whole, f"no Raw Messages panel for {topic}"
    assert ("Table", "/faults/active") in whole or any(
        pid.startswith("StateTransitions!") and t == "/faults/active" for pid, paths in by_panel.items()
        for t, _ in paths), "no Table / State Transitions panel for /faults/active"


def test_every_path_of_the_layout_exists_in_the_shipped_logs(logs: dict[str, FlightLog]) -> None:
    paths = message_paths(load_layout())
    durations_s = {name: fox.ALARMED_S if name == "alarmed" else fox.DURATION_S for name in logs}
    stems = {name: fox.ALARMED if name == "alarmed" else
             "dhc6_intermittent_aoa" if name == "dropout" else name for name in logs}
    bank_logs = [n for n in logs if stems[n] in fox.BANK_SCENARIOS]
    fault_logs = [n for n in logs if _fault_injected(stems[n], durations_s[n]) or n == "dropout"]
    assert len(bank_logs) >= 10 and "alarmed" in fault_logs and len(logs) == len(fox.SCENARIOS) + 2
    problems, checked = [], 0
    for path in paths:
        if path.topic.startswith("/fdi/"):
            # a member's topics against the logs whose bank has it (engine-gauges-v1: the DHC-6's only)
            member = path.topic.split("/")[2] if path.topic.count("/") >= 3 else None
            against = [n for n in bank_logs if member is None or member in _members(logs[n])]
        elif path.topic.startswith("/faults/"):
            against = fault_logs
        else:
            against = list(logs)
        assert against, f"{path}: no log to check it against"
        for name in against:
            why = _missing(logs[name], path)
            checked += 1
            if why is not None:
                problems.append(f"{path.panel} {path.topic}{''.join('.' + f for f in path.fields)}: {why}")
    assert not problems, "the layout names paths our logs lack:\n" + "\n".join(problems[:40])
    assert checked >= len(paths) * len(fault_logs), checked


def test_layout_plots_every_member_of_the_banks(logs: dict[str, FlightLog]) -> None:
    """Each bank log's members have a statistic-vs-threshold plot, and nothing else is plotted there."""
    from fdi_sim.bank.members import DEFAULT_BANKS

    plotted = {p.topic for p in message_paths(load_layout())
               if p.topic.startswith("/fdi/") and p.topic.endswith("/statistic")}
    # one layout for both aircraft: the union of their default banks, nothing else
    assert plotted == {f"/fdi/{m}/statistic" for bank in DEFAULT_BANKS.values() for m in bank}
    seen = set()
    for name, log in logs.items():
        if "fdi" not in log.metadata:
            continue
        members = _members(log)
        assert {f"/fdi/{m}/statistic" for m in members} <= plotted, name
        seen |= members
    assert {t.split("/")[2] for t in plotted} == seen, "a plotted member flies in none of the shipped logs"
    layout = load_layout()
    for topic in plotted:
        assert any(pid.startswith("Plot!") and {parse_message_path(p["value"]).fields for p in cfg["paths"]
                                                if parse_message_path(p["value"]).topic == topic}
                   >= {("statistic",), ("threshold",)} for pid, cfg in layout["configById"].items()), (
            f"no Plot panel draws {topic} statistic and threshold together")
