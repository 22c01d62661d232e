"""repair_log: a real writer process killed with SIGKILL, and truncation at arbitrary offsets."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap.stream_reader import StreamReader

from fdi_sim.errors import LogError
from fdi_sim.flightlog import FlightLogWriter, read_log, repair_log

REPO = Path(__file__).resolve().parents[2]

# The child writes 60 simulated seconds at 120 Hz, far faster than real time, and prints
# "w <t>" after every step and "f <t>" after every flush (then sleeps, so the file grows in
# visible steps). Values are a function of the step, so the parent knows what was written.
CHILD = r"""
import sys, time
import numpy as np
from fdi_sim.flightlog import FlightLogWriter
w = FlightLogWriter(sys.argv[1], metadata={"scenario": {"name": "kill-test", "seed": "3"}}, flush_period_s=1.0)
truth = w.add_vector_channel("/truth/state", "fdi_sim/msg/TruthState", ("t_s", "alpha_rad", "q_radps"))
meas = w.add_vector_channel("/sensors/measurements", "fdi_sim/msg/Meas", ("t_s", "q_meas_radps"))
status = w.add_event_channel("/sim/status", "fdi_sim/msg/Status", {"type": "object", "required": ["status"]})
status.write(0.0, {"status": "start"})
flushed = w.last_flush_t_s
for k in range(120 * 60):
    t = k / 120
    truth.write(t, np.array([0.01 * k, -0.5 * k]))
    meas.write(t, (0.25 * k,))
    if w.last_flush_t_s != flushed:
        flushed = w.last_flush_t_s
        print(f"f {flushed!r}", flush=True)
        time.sleep(0.03)
    print(f"w {t!r}", flush=True)
w.close()
print("done", flush=True)
"""


@pytest.mark.parametrize("trigger", [("f", 6.0), ("w", 6.5)], ids=["after-flush", "mid-second"])
def test_sigkilled_writer_loses_at_most_one_simulated_second(tmp_path: Path, trigger: tuple[str, float]) -> None:
    """Kill right after a flush, or half a simulated second after one."""
    path = tmp_path / "killed.mcap"
    proc = subprocess.Popen([sys.executable, "-c", CHILD, str(path)], cwd=REPO, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    watchdog = threading.Timer(120.0, proc.kill)
    watchdog.start()
    lines = []
    try:
        for line in proc.stdout:  # type: ignore[union-attr]
            lines.append(line.split())
            if lines[-1][0] == trigger[0] and float(lines[-1][1]) >= trigger[1]:
                os.kill(proc.pid, signal.SIGKILL)
                break
        lines += [line.split() for line in proc.stdout.read().splitlines()]  # type: ignore[union-attr]
        proc.wait()
    finally:
        watchdog.cancel()
    assert proc.returncode == -signal.SIGKILL, proc.stderr.read()  # type: ignore[union-attr]
    assert ["done"] not in lines
    written_t = max(float(x[1]) for x in lines if x[0] == "w")
    flushed_t = max(float(x[1]) for x in lines if x[0] == "f")
    with pytest.raises(LogError, match="fdi-sim repair"):
        read_log(path)
    report = repair_log(path)
    assert report.dst == tmp_path / "killed.repaired.mcap" and not report.had_footer
    assert report.metadata_names == ("scenario",)
    # at most one flush period lost relative to what the child reported writing
    assert written_t - report.last_t_s <= 1.0 + 1e-9
    assert report.last_t_s >= flushed_t - 1 / 120 - 1e-9
    log = read_log(report.dst)
    truth = log.topics["/truth/state"]
    k = np.arange(len(truth))
    np.testing.assert_array_equal(truth.as_array(), np.column_stack([k / 120, 0.01 * k, -0.5 * k]))
    np.testing.assert_array_equal(log.topics["/sensors/measurements"]["q_meas_radps"], 0.25 * k)
    assert log.topics["/sim/status"].pairs() == [(0.0, {"status": "start"})]
    assert log.metadata["scenario"] == {"name": "kill-test", "seed": "3"}
    assert report.messages_recovered == 2 * len(truth) + 1 == sum(log.message_counts.values())
    assert len(truth) % 120 == 0  # whole one-second chunks


def _small_log(path: Path) -> dict[str, np.ndarray]:
    with FlightLogWriter(path, metadata={"scenario": {"name": "cut", "seed": "1"}}, flush_period_s=0.5) as w:
        a = w.add_vector_channel("/truth/state", "fdi_sim/msg/TruthState", ("t_s", "alpha_rad", "q_radps"))
        b = w.add_vector_channel("/sensors/q", "fdi_sim/msg/Gyro", ("t_s", "q_meas_radps"))
        e = w.add_event_channel("/fdi/alarms", "fdi_sim/msg/Alarm", {"type": "object"})
        for k in range(240):
            t = k / 120
            a.write(t, [np.sin(t), np.cos(t)])
            if k % 3 == 0:
                b.write(t, [0.5 * k])
            if k % 50 == 10:
                e.write(t, {"k": k})
    return {topic: d.as_array() for topic, d in read_log(path).topics.items() if hasattr(d, "as_array")}


def _check_repaired_prefix(src: Path, dst: Path, full: dict[str, np.ndarray]) -> int:
    """Repair ``src``; the result is a valid MCAP holding a time prefix of the full log."""
    try:
        report = repair_log(src, dst)
    except LogError:
        return -1
    records = list(StreamReader(open(dst, "rb"), validate_crcs=True).records)  # noqa: SIM115
    assert type(records[-1]).__name__ == "Footer"
    log = read_log(dst)
    for topic, arr in full.items():
        if topic in log.topics:
            got = log.topics[topic].as_array()
            np.testing.assert_array_equal(got, arr[:len(got)])
    assert report.messages_recovered == sum(log.message_counts.values())
    return report.messages_recovered


def test_truncation_at_every_region_of_the_file(tmp_path: Path) -> None:
    src = tmp_path / "full.mcap"
    full = _small_log(src)
    data = src.read_bytes()
    cut = tmp_path / "cut.mcap"
    recovered = []
    offsets = sorted(set(range(0, len(data) + 1, 97)) | {0, 7, 8, 9, 30, len(data) - 1, len(data)})
    for n in offsets:
        cut.write_bytes(data[:n])
        recovered.append(_check_repaired_prefix(cut, tmp_path / "out.mcap", full))
    assert recovered[:2] == [-1, -1]  # no magic / no record: LogError
    assert recovered == sorted(recovered)  # more bytes never recover less
    assert recovered[-1] == 240 + 80 + 5


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.floats(0.0, 1.0), st.one_of(st.none(), st.tuples(st.floats(0.0, 1.0), st.integers(1, 255))))
def test_random_truncation_and_damage_only_raise_log_error(tmp_path: Path, frac: float, flip) -> None:
    src = tmp_path / "full.mcap"
    if not src.exists():
        _small_log(src)
    data = bytearray(src.read_bytes())
    if flip is not None:  # damage one byte somewhere, then cut
        data[int(flip[0] * (len(data) - 1))] ^= flip[1]
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(bytes(data[:int(frac * len(data))]))
    try:
        report = repair_log(cut, tmp_path / "out.mcap")
    except LogError:
        return
    log = read_log(report.dst)
    assert report.messages_recovered == sum(log.message_counts.values())


def test_complete_file_rewrites_identically(tmp_path: Path) -> None:
    src = tmp_path / "full.mcap"
    full = _small_log(src)
    report = repair_log(src)
    assert report.had_footer and report.chunks_dropped == 0
    assert report.message_counts == {"/truth/state": 240, "/sensors/q": 80, "/fdi/alarms": 5}
    log = read_log(report.dst)
    for topic, arr in full.items():
        np.testing.assert_array_equal(log.topics[topic].as_array(), arr)
    with open(src, "rb") as f1, open(report.dst, "rb") as f2:
        a = [(c.topic, m.log_time, m.sequence, m.data) for _, c, m in make_reader(f1).iter_messages()]
        b = [(c.topic, m.log_time, m.sequence, m.data) for _, c, m in make_reader(f2).iter_messages()]
    assert a == b
    text = report.format()
    assert "source was complete" in text and "/sensors/q: 80" in text


def test_damaged_chunk_is_dropped_and_the_rest_kept(tmp_path: Path) -> None:
    src = tmp_path / "full.mcap"
    _small_log(src)
    with open(src, "rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    data = bytearray(src.read_bytes())
    data[chunks[1].chunk_start_offset + chunks[1].chunk_length - 30] ^= 0x55
    src.write_bytes(bytes(data))
    report = repair_log(src)
    assert report.chunks_dropped == 1 and report.chunks_recovered == len(chunks) - 1
    assert "dropped 1 damaged chunks" in report.format()


@pytest.mark.parametrize("complete", [True, False], ids=["complete", "cut-off"])
@pytest.mark.parametrize("encoding", ["ros2msg", "jsonschema"])
def test_schema_with_undecodable_text_comes_from_the_summary_or_is_dropped(
        tmp_path: Path, encoding: str, complete: bool) -> None:
    """Schema records carry no CRC: one whose text is not UTF-8 (or not JSON) is not used. In a
    complete file the summary's intact copy replaces it and nothing is lost; in a file cut off
    before its summary the channels that use it are dropped with their messages."""
    src = tmp_path / "full.mcap"
    _small_log(src)
    data = bytearray(src.read_bytes())
    enc = encoding.encode()
    name = b"fdi_sim/msg/TruthState" if encoding == "ros2msg" else b"fdi_sim/msg/Alarm"
    text = data.index(enc, data.index(name)) + len(enc) + 4  # after the encoding and the u32 length
    data[text] = 0xFF  # never valid in UTF-8
    if not complete:
        with open(tmp_path / "full.mcap", "rb") as f:
            summary_start = make_reader(f).get_summary().chunk_indexes[-1].chunk_start_offset + 1
        data = data[:summary_start]  # cut inside the last chunk: no Data End, no summary
    src.write_bytes(bytes(data))
    report = repair_log(src)
    dropped = "/truth/state" if encoding == "ros2msg" else "/fdi/alarms"
    log = read_log(report.dst)
    if complete:
        sid = 1 if encoding == "ros2msg" else 3
        assert report.copies_from_summary == (f"schema {sid}",)
        assert report.message_counts == {"/truth/state": 240, "/sensors/q": 80, "/fdi/alarms": 5}
        assert dropped in log.topics and "data section" in report.source_problems[0]
    else:
        assert report.records_skipped >= 1 and report.copies_from_summary == ()
        assert dropped not in report.message_counts and dropped not in log.topics
        assert set(log.topics) == set(report.message_counts) and len(log.topics) >= 1


def test_bad_sources_and_destinations(tmp_path: Path) -> None:
    text = tmp_path / "notes.txt"
    text.write_text("not a log\n")
    with pytest.raises(LogError, match="not an MCAP file"):
        repair_log(text)
    with pytest.raises(LogError, match="cannot read"):
        repair_log(tmp_path / "missing.mcap")
    src = tmp_path / "full.mcap"
    _small_log(src)
    with pytest.raises(LogError, match="overwrite"):
        repair_log(src, src)
    with pytest.raises(LogError, match="writable"):
        repair_log(src, tmp_path / "no" / "dir.mcap")


# --- damaged (not cut-off) real logs: repair prefers the intact copy of a record -------------
@pytest.fixture(scope="module")
def run_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 3 s real F-16 run (JSBSim, the real writer)."""
    from fdi_sim.scenario import load
    from fdi_sim.training import fly
    sc, _ = load(REPO / "scenarios/f16_cruise_doublets.toml").shortened(3.0)
    path = tmp_path_factory.mktemp("repair") / "run.mcap"
    fly(sc, log_path=path)
    return path


def _message_set(path: Path) -> set[tuple[str, int, int, bytes]]:
    with open(path, "rb") as f:
        return {(c.topic, m.log_time, m.sequence, bytes(m.data)) for _, c, m in make_reader(f).iter_messages()}


def _flipped(src: Path, dst: Path, pos: int, xor: int) -> Path:
    data = bytearray(src.read_bytes())
    data[pos] ^= xor
    dst.write_bytes(bytes(data))
    return dst


def test_damaged_data_section_channel_is_taken_from_the_summary(run_log: Path, tmp_path: Path) -> None:
    """Issue 11 item 4: one flipped byte in the data-section channel record of /truth/state used
    to drop the topic ("skipped 2402 records") though the summary holds an intact copy."""
    data = run_log.read_bytes()
    with open(run_log, "rb") as f:
        summary = make_reader(f).get_summary()
    cid = next(c.id for c in summary.channels.values() if c.topic == "/truth/state")
    pos = data.index(b"/truth/state") + 3  # the first copy is the data section's
    assert pos < summary.chunk_indexes[0].chunk_start_offset
    src = _flipped(run_log, tmp_path / "bad.mcap", pos, 0x41)
    report = repair_log(src)
    assert report.copies_from_summary == (f"channel {cid}",)
    assert report.records_skipped == 0 and report.chunks_dropped == 0
    assert any("channel record" in p for p in report.source_problems)
    before, after = read_log(run_log), read_log(report.dst)
    assert set(after.topics) == set(before.topics)
    for topic, d in before.topics.items():
        if hasattr(d, "as_array"):
            np.testing.assert_array_equal(after.topics[topic].as_array(), d.as_array())
    assert _message_set(report.dst) == _message_set(run_log)


def test_damaged_header_length_loses_nothing(run_log: Path, tmp_path: Path) -> None:
    """Issue 11 item 4: a flipped byte in the header's length made repair report "nothing to
    recover" on a file that read_log reads."""
    src = _flipped(run_log, tmp_path / "bad.mcap", 8 + 1 + 2, 0x41)  # record length, byte 2
    assert read_log(src).message_counts == read_log(run_log).message_counts
    report = repair_log(src)
    assert report.chunks_dropped == 0
    assert report.metadata_names == tuple(read_log(run_log).metadata)
    assert _message_set(report.dst) == _message_set(run_log)
    assert read_log(report.dst).metadata == read_log(run_log).metadata


def test_single_byte_flips_in_the_data_section_keep_every_intact_chunk(run_log: Path, tmp_path: Path) -> None:
    """Seeded sweep: the repaired file reads with read_log and with the mcap reader (CRCs
    checked), holds only original messages, every message of every chunk the flip missed,
    every topic (the summary copies stand in), and every metadata record the flip missed."""
    data = run_log.read_bytes()
    with open(run_log, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        meta_spans = [(mi.offset, mi.offset + mi.length) for mi in summary.metadata_indexes]
    data_end = int.from_bytes(data[-8 - 29 + 9:-8 - 29 + 17], "little") - 13  # footer summary_start - Data End
    chunks = sorted((c.chunk_start_offset, c.chunk_start_offset + c.chunk_length, c.message_start_time,
                     c.message_end_time) for c in summary.chunk_indexes)
    assert all(a[3] < b[2] for a, b in zip(chunks, chunks[1:]))  # disjoint time ranges
    original = _message_set(run_log)
    topics = {c.topic for c in summary.channels.values()}
    rng = np.random.default_rng(11)
    positions = rng.integers(0, data_end, 30).tolist() + [int(rng.integers(a, a + 48)) for a, *_ in chunks]
    for pos in positions:
        src = _flipped(run_log, tmp_path / "bad.mcap", pos, int(rng.integers(1, 256)))
        report = repair_log(src, tmp_path / "out.mcap")
        records = list(StreamReader(open(report.dst, "rb"), validate_crcs=True).records)  # noqa: SIM115
        assert type(records[-1]).__name__ == "Footer"
        log = read_log(report.dst)
        got = _message_set(report.dst)
        assert got <= original, pos
        hit = [(a, b, t0, t1) for a, b, t0, t1 in chunks if a <= pos < b]
        lost = {m for m in original - got}
        assert all(hit and hit[0][2] <= m[1] <= hit[0][3] for m in lost), (pos, len(lost))
        assert set(log.topics) == topics, pos
        if not any(a <= pos < b for a, b in meta_spans):
            assert log.metadata == metadata, pos
        assert report.messages_recovered == len(got) == sum(log.message_counts.values())
