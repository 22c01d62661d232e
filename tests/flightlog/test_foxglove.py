"""Foxglove's own libraries decode every topic of our logs exactly as ``read_log`` does.

The shipped scenarios are flown shortened (20 s) through the CLI (the ten with an ``[fdi]`` table
fly the default bank in the loop: ``/fdi/<id>/statistic|residual|estimate``, ``/fdi/alarms``,
``/fdi/failure_log``, ``/fdi/reconfiguration``), the pitch-gyro bias once more (20 s) so the bank
alarms, isolates and reconfigures (those event channels carry payloads), one log is run through
``fdi-sim detect`` (``/fdi/offline/...``), and each log is decoded by
``tools/foxglove/decode.mjs`` with node: ``@mcap/core`` (indexed reader, zstd/lz4 through
``@foxglove/wasm-zstd``/``@foxglove/wasm-lz4``), ``@foxglove/rosmsg`` (ros2msg schema text),
``@foxglove/rosmsg2-serialization`` (CDR) and ``JSON.parse`` + ``ajv`` (JSON channels against
their JSON Schema). Counts, log times and every float64 value (sha256 of the bits) must agree with
:func:`fdi_sim.flightlog.read_log`; event payloads must be equal as dicts (issue 15, Foxglove bar).

The node modules come from the npm registry (``npm ci`` on the committed lock file) the first
time the suite runs; the test is skipped only on a machine without ``node``/``npm``.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fdi_sim.flightlog import (
    STATUS_JSON_SCHEMA,
    EventTopic,
    FlightLog,
    FlightLogWriter,
    VectorTopic,
    read_log,
)

ROOT = Path(__file__).resolve().parents[2]
TOOL = ROOT / "tools" / "foxglove"
DECODE = TOOL / "decode.mjs"
DURATION_S = 20.0  # the length test_scenarios_run and the review tests fly: the same bank designs (a shorter run drops later maneuvers and designs its own bank)
#: every shipped scenario, flown shortened; the dropout variant adds a /sensors/valid topic
SCENARIOS = tuple(sorted(f.stem for f in (ROOT / "scenarios").glob("*.toml")))
#: no shipped scenario has a sensor dropout, so one is added to a shipped file
DROPOUT_FAULT = """
[[faults]]
type = "sensor-dropout-v1"
target = "q_radps"
t_start_s = 2.0
intermittent = { windows_s = [[2.0, 3.0], [5.0, 6.5]] }
"""
DETECTOR = "kalman-nis-v1:sensor_std=0.01"
#: a bank scenario flown long enough for its bank to alarm (11.05 s), log failures and reconfigure (11.5 s)
ALARMED = "f16_pitch_gyro_bias"
ALARMED_S = 20.0
#: the shipped scenarios with an [fdi] table: their logs hold the bank's topics
BANK_SCENARIOS = tuple(name for name in SCENARIOS
                       if "\n[fdi]" in (ROOT / "scenarios" / f"{name}.toml").read_text())


def _node_modules_stale() -> bool:
    marker = TOOL / "node_modules" / ".package-lock.json"  # written by npm ci / npm install
    lock = TOOL / "package-lock.json"
    return not marker.exists() or marker.stat().st_mtime < lock.stat().st_mtime


@pytest.fixture(scope="session")
def node() -> str:
    """Path of ``node``, with tools/foxglove/node_modules installed from the lock file."""
    node_exe, npm_exe = shutil.which("node"), shutil.which("npm")
    if node_exe is None or npm_exe is None:
        pytest.skip("node and npm are not on PATH: the Foxglove decoding check needs Node.js >= 20")
    if _node_modules_stale():
        done = subprocess.run([npm_exe, "ci", "--prefix", str(TOOL), "--no-audit", "--no-fund"],
                              capture_output=True, text=True, timeout=600)
        assert done.returncode == 0, f"npm ci failed:\n{done.stdout}\n{done.stderr}"
    return node_exe


def _cli(*args: str) -> None:
    done = subprocess.run([sys.executable, "-m", "fdi_sim.cli", *args], capture_output=True,
                          text=True, timeout=300, cwd=ROOT)
    assert done.returncode == 0, f"fdi-sim {' '.join(args)} failed:\n{done.stdout}\n{done.stderr}"


#: the shipped logs of this process, flown once (tests/review/test_foxglove_layout.py shares them)
_FLOWN: dict[str, Path] = {}


def shipped_logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The shipped scenarios flown for ``DURATION_S``, the gyro bias for ``ALARMED_S`` (key ``"alarmed"``),
    a dropout variant and a ``detect`` output log; flown once per test session (shared by the xdist
    workers, ``tests/flown_once.py``).

    Parameters
    ----------
    tmp_path_factory : pytest.TempPathFactory
        Where the logs go (a fresh ``foxglove`` folder the first time).

    Returns
    -------
    dict of str to Path
        Scenario stem (or ``"alarmed"``, ``"dropout"``, ``"detect"``) to MCAP path.
    """
    if not _FLOWN:
        from flown_once import flown_once  # tests/flown_once.py: once for the session, across xdist workers

        _FLOWN.update(flown_once(tmp_path_factory, "foxglove", _fly_shipped))
    return dict(_FLOWN)


def _fly_shipped(out: Path) -> dict[str, Path]:
    """The logs of :func:`shipped_logs`, flown into ``out``."""
    logs: dict[str, Path] = {}
    jobs = []
    for name in SCENARIOS:
        logs[name] = out / f"{name}.mcap"
        jobs.append((str(ROOT / "scenarios" / f"{name}.toml"), logs[name], DURATION_S))
    dropout = out / "dhc6_intermittent_aoa_dropout.toml"
    dropout.write_text((ROOT / "scenarios" / "dhc6_intermittent_aoa.toml").read_text() + DROPOUT_FAULT)
    logs["dropout"] = out / "dropout.mcap"
    jobs.append((str(dropout), logs["dropout"], DURATION_S))
    logs["alarmed"] = out / "alarmed.mcap"
    jobs.append((str(ROOT / "scenarios" / f"{ALARMED}.toml"), logs["alarmed"], ALARMED_S))
    with ThreadPoolExecutor(max_workers=max(2, os.cpu_count() or 2)) as pool:
        list(pool.map(lambda job: _cli("run", job[0], "--log", str(job[1]), "--duration", str(job[2]),
                                       "--quiet"), jobs))
    logs["detect"] = out / "detect.mcap"
    _cli("detect", str(logs["dropout"]), "--detector", DETECTOR, "--out", str(logs["detect"]))
    return logs


@pytest.fixture(scope="session")
def flown_logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """The logs of :func:`shipped_logs`."""
    return shipped_logs(tmp_path_factory)


def decode(node: str, path: Path, *extra: str) -> dict[str, Any]:
    """Run decode.mjs on ``path``; its JSON output."""
    done = subprocess.run([node, str(DECODE), str(path), *extra], capture_output=True, text=True,
                          timeout=300)
    assert done.returncode == 0, f"decode.mjs {path} failed (exit {done.returncode}):\n{done.stderr}"
    return json.loads(done.stdout)


def _num(v: Any) -> float:
    """A number from decode.mjs (non-finite values arrive as strings)."""
    return float(v)


def _js_min(col: np.ndarray) -> float:
    """decode.mjs's min: ``v < min`` comparisons from +inf, which a NaN never wins (a dropout
    makes a detector's statistic NaN); Infinity for an all-NaN column."""
    finite = col[~np.isnan(col)]
    return float(finite.min()) if finite.size else np.inf


def _js_max(col: np.ndarray) -> float:
    finite = col[~np.isnan(col)]
    return float(finite.max()) if finite.size else -np.inf


def _sha(a: np.ndarray, dtype: str) -> str:
    return hashlib.sha256(np.ascontiguousarray(a, dtype=dtype).tobytes()).hexdigest()


def assert_same_as_read_log(fox: dict[str, Any], log: FlightLog) -> None:
    """Every topic of ``log`` decoded by Foxglove's stack equals what read_log gives."""
    assert sorted(fox["topics"]) == sorted(log.topics)
    assert fox["message_count"] == sum(log.message_counts.values())
    for topic, data in log.topics.items():
        got = fox["topics"][topic]
        where = f"{log.path.name} {topic}"
        assert got["schema_name"] == data.schema_name, where
        assert got["count"] == len(data) == log.message_counts[topic], where
        assert got["log_time_sha256"] == _sha(data.log_time_ns, "<u8"), f"{where}: log times differ"
        if isinstance(data, VectorTopic):
            assert (got["message_encoding"], got["schema_encoding"]) == ("cdr", "ros2msg"), where
            assert [f["name"] for f in got["fields"]] == list(data.fields), where
            assert {(f["type"], f["isArray"]) for f in got["fields"]} == {("float64", False)}, where
            for name in data.fields:
                col = data[name]
                stats = got["float64"][name]
                assert stats["sha256"] == _sha(col, "<f8"), f"{where}.{name}: float64 values differ"
                # sequential sum in log-time order, as node adds them: exact
                assert _num(stats["sum"]) == sum(col.tolist()) or (
                    math.isnan(_num(stats["sum"])) and math.isnan(sum(col.tolist()))), f"{where}.{name}"
                if len(col):
                    assert _num(stats["min"]) == _js_min(col) and _num(stats["max"]) == _js_max(col), where
            if len(data):
                for end, row in (("first", data.data[0]), ("last", data.data[-1])):  # NaN equals NaN here
                    assert list(got[end]) == list(data.fields), where
                    fox_row = np.array([_num(got[end][k]) for k in data.fields])
                    assert np.array_equal(fox_row, row, equal_nan=True), (where, end)
        else:
            assert isinstance(data, EventTopic), f"{where}: read_log gave {type(data).__name__}"
            assert (got["message_encoding"], got["schema_encoding"]) == ("json", "jsonschema"), where
            assert [int(m["log_time_ns"]) for m in got["messages"]] == data.log_time_ns.tolist(), where
            assert [m["payload"] for m in got["messages"]] == [e.payload for e in data.events], where
            assert got["schema_errors"] == [], f"{where}: ajv rejects messages: {got['schema_errors']}"


LOG_IDS = (*SCENARIOS, "dropout", "alarmed", "detect")


@pytest.mark.parametrize("which", LOG_IDS)
def test_foxglove_decodes_every_topic_like_read_log(node: str, flown_logs: dict[str, Path], which: str) -> None:
    log = read_log(flown_logs[which])
    fox = decode(node, flown_logs[which])
    assert_same_as_read_log(fox, log)
    # the logs hold what this test claims to cover
    assert {"/truth/state", "/sensors/measurements", "/commands/pilot", "/sim/status"} <= set(fox["topics"])
    duration_s = ALARMED_S if which == "alarmed" else DURATION_S
    assert fox["topics"]["/truth/state"]["count"] == round(duration_s * 120) + 1
    if which in BANK_SCENARIOS or which in ("dropout", "alarmed", "detect"):
        # the bank flew in the loop: every member's outputs and the bank's event channels
        members = [m["id"] for m in json.loads(log.metadata["fdi"]["members"])]
        stats = {t for t in fox["topics"] if t.startswith("/fdi/") and t.endswith("/statistic")
                 and not t.startswith("/fdi/offline/")}
        assert len(members) >= 5 and stats == {f"/fdi/{m}/statistic" for m in members}, which
        assert {"/fdi/alarms", "/fdi/failure_log", "/fdi/reconfiguration",
                "/fdi/kalman-gust-v1/residual", "/fdi/kalman-gust-v1/estimate"} <= set(fox["topics"]), which
    if which == "alarmed":
        # Foxglove decodes real alarm, failure-log and reconfiguration payloads, not empty channels
        for topic in ("/fdi/alarms", "/fdi/failure_log", "/fdi/reconfiguration", "/faults/events"):
            assert fox["topics"][topic]["count"] > 0, f"{topic} is empty in the {ALARMED_S} s gyro-bias run"
        actions = [m["payload"]["action"] for m in fox["topics"]["/fdi/reconfiguration"]["messages"]]
        assert actions == ["exclude-and-correct"]
    if which == "dropout":
        valid = log.topics["/sensors/valid"]["q_radps"]
        assert 0.0 in valid and 1.0 in valid
        assert fox["topics"]["/sensors/valid"]["float64"]["q_radps"]["min"] == 0
    if which == "detect":
        # the offline detector's topics beside the in-loop bank's (the scenario flies with its bank)
        assert {"/fdi/offline/kalman-nis-v1/statistic", "/fdi/offline/alarms", "/fdi/alarms",
                "/fdi/kalman-gust-v1/statistic", "/sensors/valid"} <= set(fox["topics"])


@pytest.mark.parametrize("compression", ["zstd", "lz4", None])
def test_foxglove_decodes_edge_values_bit_for_bit(node: str, tmp_path: Path, compression: str | None) -> None:
    """A hand-written log with float64 edge cases and odd JSON payloads, known values both ways."""
    path = tmp_path / "edge.mcap"
    values = np.array([-0.0, 5e-324, -2.2250738585072014e-308, 1.7976931348623157e308, math.pi,
                       0.1 + 0.2, -1e-300, 2.0 ** 53 + 1.0])
    events = [{"status": "running", "message": "ünïcødé ✈ \"quoted\" \\ \n"},
              {"status": "completed", "message": ""}]
    with FlightLogWriter(path, compression=compression) as w:
        ch = w.add_vector_channel("/test/edge", "fdi_sim/msg/Edge", ("t_s", "x_m", "y_m"))
        for i, v in enumerate(values):
            ch.write(i * 0.01, [v, -v])
        ev = w.add_event_channel("/sim/status", "fdi_sim/msg/SimStatus", STATUS_JSON_SCHEMA)
        for i, p in enumerate(events):
            ev.write(i * 0.05, p)
    fox = decode(node, path, "--full")
    edge = fox["topics"]["/test/edge"]
    got = np.array([_num(v) for v in edge["float64"]["x_m"]["values"]])
    assert got.tolist() == values.tolist()
    assert edge["float64"]["x_m"]["sha256"] == _sha(values, "<f8")  # -0.0 and subnormals included
    assert edge["float64"]["y_m"]["sha256"] == _sha(-values, "<f8")
    assert [m["payload"] for m in fox["topics"]["/sim/status"]["messages"]] == events
    assert_same_as_read_log(fox, read_log(path))


def test_foxglove_schema_validation_rejects_a_bad_event(node: str, tmp_path: Path) -> None:
    """ajv in decode.mjs is live: a payload outside its channel's JSON Schema is reported."""
    path = tmp_path / "bad_event.mcap"
    schema = {"type": "object", "required": ["status"], "properties": {"status": {"type": "string"}}}
    with FlightLogWriter(path) as w:
        ev = w.add_event_channel("/test/events", "fdi_sim/msg/Test", schema)
        ev.write(0.0, {"status": "ok"})
        ev.write(0.1, {"status": 3})  # the writer does not validate: the reader side must
    errors = decode(node, path)["topics"]["/test/events"]["schema_errors"]
    assert [e["index"] for e in errors] == [1]


def test_decode_refuses_a_file_that_is_not_mcap(node: str, tmp_path: Path) -> None:
    bad = tmp_path / "not.mcap"
    bad.write_bytes(b"this is not an MCAP file at all" * 4)
    done = subprocess.run([node, str(DECODE), str(bad)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 1 and "decode.mjs:" in done.stderr
