"""read_log / log_info: exact round trips, cross-checked against the ``mcap`` reader + struct,
and against files written by the reference ``mcap.writer.Writer`` (indexed, unindexed,
unchunked, big-endian CDR, non-float schemas)."""
from __future__ import annotations

import json
import math
import struct
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import CompressionType, IndexType, Writer

from fdi_sim.errors import LogError
from fdi_sim.flightlog import EventTopic, FlightLogWriter, RawTopic, VectorTopic, log_info, read_log

TRUTH = ("t_s", "alpha_rad", "q_radps", "vt_fps")
STATUS = {"type": "object", "properties": {"status": {"type": "string"}}, "required": ["status"]}


def _write(path: Path, seconds: float = 3.0) -> dict:
    """Truth every step, sensors every 2nd step, a detector channel added at 1.5 s, events."""
    rng = np.random.default_rng(5)
    out: dict = {"/truth/state": [], "/sensors/q": [], "/fdi/parity-v1/residual": [], "/sim/status": []}
    with FlightLogWriter(path, metadata={"scenario": {"name": "reader-demo", "seed": "11", "text": "x = 1"},
                                         "versions": {"numpy": np.__version__}}) as w:
        truth = w.add_vector_channel("/truth/state", "fdi_sim/msg/TruthState", TRUTH)
        sens = w.add_vector_channel("/sensors/q", "fdi_sim/msg/Gyro", ("t_s", "q_meas_radps"))
        status = w.add_event_channel("/sim/status", "fdi_sim/msg/Status", STATUS)
        status.write(0.0, {"status": "start"})
        out["/sim/status"].append((0.0, {"status": "start"}))
        resid = None
        for k in range(int(round(seconds * 120))):
            t = k / 120
            x = rng.standard_normal(3)
            truth.write(t, x)
            out["/truth/state"].append((t, *x))
            if k % 2 == 0:
                sens.write(t, [x[1]])
                out["/sensors/q"].append((t, x[1]))
            if k == 180:
                resid = w.add_vector_channel("/fdi/parity-v1/residual", "fdi_sim/msg/Residual",
                                             ("t_s", "r0", "r1", "statistic", "alarm"))
            if resid is not None:
                r = (x[0], x[2], x[0] ** 2 + x[2] ** 2, float(x[0] ** 2 + x[2] ** 2 > 4.0))
                resid.write(t, r)
                out["/fdi/parity-v1/residual"].append((t, *r))
        status.write(t, {"status": "end", "steps": k + 1})
        out["/sim/status"].append((t, {"status": "end", "steps": k + 1}))
    return out


def test_round_trip_is_exact(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    written = _write(path)
    log = read_log(path)
    assert set(log.topics) == set(written)
    for topic in ("/truth/state", "/sensors/q", "/fdi/parity-v1/residual"):
        data = log.topics[topic]
        assert isinstance(data, VectorTopic)
        np.testing.assert_array_equal(data.as_array(), np.array(written[topic]))
        np.testing.assert_array_equal(data.t_s, [r[0] for r in written[topic]])
        np.testing.assert_array_equal(data.log_time_ns, [round(r[0] * 1e9) for r in written[topic]])
    truth = log.topics["/truth/state"]
    assert truth.fields == TRUTH
    np.testing.assert_array_equal(truth["q_radps"], [r[2] for r in written["/truth/state"]])
    assert not truth["q_radps"].flags.writeable
    with pytest.raises(KeyError, match="alpha_rad"):
        truth["alpha_deg"]
    status = log.topics["/sim/status"]
    assert isinstance(status, EventTopic)
    # event times come from the ns log time: within 0.5 ns of the t_s written
    assert [e.payload for e in status] == [p for _, p in written["/sim/status"]]
    np.testing.assert_allclose(status.t_s, [t for t, _ in written["/sim/status"]], rtol=0, atol=0.5e-9)
    assert status.json_schema == STATUS and status[1].payload["steps"] == 360
    assert log.metadata["scenario"] == {"name": "reader-demo", "seed": "11", "text": "x = 1"}
    assert log.message_counts == {t: len(v) for t, v in written.items()}
    assert log.start_t_s == 0.0 and log.end_t_s == round(359 / 120 * 1e9) / 1e9 == log.duration_s


def test_matches_the_mcap_reader_with_struct(tmp_path: Path) -> None:
    """Independent decode: every message through ``mcap`` iter_messages, unpacked with struct."""
    path = tmp_path / "run.mcap"
    _write(path)
    ref: dict[str, list] = {}
    with open(path, "rb") as f:
        for schema, channel, msg in make_reader(f).iter_messages():
            if channel.message_encoding == "cdr":
                assert msg.data[:4] == b"\x00\x01\x00\x00"
                ref.setdefault(channel.topic, []).append(struct.unpack(f"<{(len(msg.data) - 4) // 8}d", msg.data[4:]))
            else:
                ref.setdefault(channel.topic, []).append((msg.log_time / 1e9, json.loads(msg.data)))
    log = read_log(path)
    for topic, rows in ref.items():
        got = log.topics[topic]
        if isinstance(got, VectorTopic):
            np.testing.assert_array_equal(got.as_array(), np.array(rows))
        else:
            assert got.pairs() == rows  # both sides: log time / 1e9


def _reference_file(path: Path, index_types: IndexType = IndexType.ALL, chunked: bool = True,
                    big_endian: bool = False) -> list[tuple[float, float, float]]:
    """A log written by the reference mcap Writer; 3.6 s, chunks of ~1 kB."""
    rows = []
    with open(path, "wb") as f:
        w = Writer(f, chunk_size=1024, compression=CompressionType.LZ4, index_types=index_types,
                   use_chunking=chunked)
        w.start()
        sid = w.register_schema("fdi_sim/msg/Pair", "ros2msg", b"# a comment\nfloat64 t_s\n\nfloat64 a_m  # metres\nfloat64 b_m\n")
        cid = w.register_channel("/pair", "cdr", sid)
        sid2 = w.register_schema("other/msg/Name", "ros2msg", b"string name\n")
        cid2 = w.register_channel("/name", "cdr", sid2)
        for k in range(432):
            t = k / 120
            row = (t, math.sin(t), -float(k))
            rows.append(row)
            data = (b"\x00\x00\x00\x00" + struct.pack(">3d", *row)) if big_endian else \
                (b"\x00\x01\x00\x00" + struct.pack("<3d", *row))
            w.add_message(cid, round(t * 1e9), data, round(t * 1e9), sequence=k)
            if k % 100 == 0:
                w.add_message(cid2, round(t * 1e9), b"\x00\x01\x00\x00\x04\x00\x00\x00abc\x00", round(t * 1e9))
        w.add_metadata("scenario", {"name": "ref", "seed": "9"})
        w.finish()
    return rows


@pytest.mark.parametrize("index_types, chunked, big_endian", [
    (IndexType.ALL, True, False),                       # message indexes: gather path
    (IndexType.ALL & ~IndexType.MESSAGE, True, False),  # no message indexes: scan path
    (IndexType.ALL, False, False),                      # no chunks at all
    (IndexType.ALL, True, True),                        # big-endian CDR
])
def test_reads_files_of_the_reference_writer(tmp_path: Path, index_types: IndexType, chunked: bool,
                                             big_endian: bool) -> None:
    path = tmp_path / "ref.mcap"
    rows = _reference_file(path, index_types, chunked, big_endian)
    log = read_log(path)
    pair = log.topics["/pair"]
    assert pair.fields == ("t_s", "a_m", "b_m")
    np.testing.assert_array_equal(pair.as_array(), np.array(rows))
    name = log.topics["/name"]
    assert isinstance(name, RawTopic) and len(name) == 5 and name.data[0].endswith(b"abc\x00")
    assert log.metadata == {"scenario": {"name": "ref", "seed": "9"}}


def test_not_an_mcap_file(tmp_path: Path) -> None:
    for name, content in (("notes.txt", b"hello, this is text\n" * 10), ("empty.mcap", b"")):
        path = tmp_path / name
        path.write_bytes(content)
        with pytest.raises(LogError, match="not an MCAP file"):
            read_log(path)
        with pytest.raises(LogError, match="not an MCAP file"):
            log_info(path)
    with pytest.raises(LogError, match="cannot read"):
        read_log(tmp_path / "missing.mcap")


def test_truncated_file_suggests_repair(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    _write(path)
    data = path.read_bytes()
    for cut in (len(data) // 2, len(data) - 1, 20):
        bad = tmp_path / f"cut{cut}.mcap"
        bad.write_bytes(data[:cut])
        with pytest.raises(LogError, match="fdi-sim repair") as err:
            read_log(bad)
        assert "truncated" in str(err.value) and str(bad) in str(err.value)
        with pytest.raises(LogError, match="fdi-sim repair"):
            log_info(bad)


def test_corrupted_chunk_raises_log_error(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    _write(path)
    with open(path, "rb") as f:
        ci = make_reader(f).get_summary().chunk_indexes[1]
    data = bytearray(path.read_bytes())
    data[ci.chunk_start_offset + ci.chunk_length - 40] ^= 0xFF  # inside the compressed records
    path.write_bytes(bytes(data))
    with pytest.raises(LogError, match="corrupted"):
        read_log(path)


def test_log_info_from_the_summary(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    written = _write(path)
    info = log_info(path)
    assert info.scenario_name == "reader-demo" and info.scenario_seed == "11"
    assert info.metadata_names == ("scenario", "versions")
    assert info.message_count == sum(len(v) for v in written.values())
    # one chunk per flush (3 s) and per group of channels written at the same times: truth (120 Hz)
    # and sensors (60 Hz) each second, the detector channel (from 1.5 s) its own in the second
    # second and with the truth in the third: 2 + 3 + 2
    assert info.chunk_count == 7 and info.file_size_bytes == path.stat().st_size
    assert info.duration_s == pytest.approx(359 / 120, abs=1e-9)
    assert {(t.topic, t.schema_name, t.message_count) for t in info.topics} == {
        ("/truth/state", "fdi_sim/msg/TruthState", 360), ("/sensors/q", "fdi_sim/msg/Gyro", 180),
        ("/sim/status", "fdi_sim/msg/Status", 2), ("/fdi/parity-v1/residual", "fdi_sim/msg/Residual", 180)}
    text = info.format()
    assert "reader-demo" in text and "seed: 11" in text and "/fdi/parity-v1/residual" in text
    assert "fdi_sim/msg/Residual" in text and "2.992 s" in text


def test_empty_log_reads(tmp_path: Path) -> None:
    path = tmp_path / "empty.mcap"
    with FlightLogWriter(path, metadata={"scenario": {"name": "nothing"}}) as w:
        w.add_vector_channel("/truth/state", "fdi_sim/msg/TruthState", TRUTH)
    log = read_log(path)
    assert len(log.topics["/truth/state"]) == 0 and log.topics["/truth/state"].fields == TRUTH
    assert log.duration_s == 0.0
    assert log_info(path).message_count == 0


@pytest.mark.slow
def test_300_s_log_loads_in_about_a_second(tmp_path: Path) -> None:
    """DESIGN target: 300 s at 120 Hz x 6 channels (216,000 messages) loads in about a second."""
    path = tmp_path / "long.mcap"
    widths = (29, 6, 6, 8, 12, 8)
    rng = np.random.default_rng(0)
    rows = [rng.standard_normal((36000, w)) for w in widths]
    with FlightLogWriter(path) as w:
        chans = [w.add_vector_channel(f"/c{i}", f"bench/msg/V{i}", ["t_s"] + [f"f{j}" for j in range(n)])
                 for i, n in enumerate(widths)]
        for k in range(36000):
            for c, r in zip(chans, rows):
                c.write(k / 120, r[k])
    t0 = time.perf_counter()
    log = read_log(path)
    elapsed = time.perf_counter() - t0
    assert sum(log.message_counts.values()) == 216000
    np.testing.assert_array_equal(log.topics["/c0"].as_array()[:, 1:], rows[0])
    assert elapsed < 2.0, f"read_log took {elapsed:.2f} s"
