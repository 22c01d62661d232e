"""FlightLogWriter: files checked with the reference ``mcap`` reader and with ``struct``.

References: MCAP specification (https://mcap.dev/spec) for records, CRCs and indexes; OMG
DDS-XTypes 1.3 sec. 7.4.3 / 7.6.2.1.2 for the CDR encapsulation header (CDR_LE = 00 01) and
XCDR1 alignment (8 for float64, relative to the end of the 4-byte header).
"""
from __future__ import annotations

import io
import json
import math
import struct
import zlib
from pathlib import Path

import numpy as np
import pytest
import zstandard
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap.records import MessageIndex
from mcap.stream_reader import StreamReader
from mcap.data_stream import RecordBuilder, ReadDataStream

from fdi_sim.errors import LogError
from fdi_sim.flightlog import FlightLogWriter, vector_schema
from fdi_sim.flightlog.records import RawMessage, VectorBlock, build_chunk, encode_message_index, scan_records

TRUTH = ("t_s", "alpha_rad", "q_radps", "vt_fps")
SENS = ("t_s", "q_meas_radps")
ALARM = {"type": "object", "properties": {"detector": {"type": "string"}}, "required": ["detector"]}


def _write_demo(path: Path, seconds: float = 2.5, compression: str | None = "zstd") -> dict:
    """A small log: two vector channels every step, one event channel; returns what was written."""
    rows = {"/truth/state": [], "/sensors/q": []}
    with FlightLogWriter(path, metadata={"scenario": {"name": "demo", "seed": "42"}},
                         compression=compression) as w:
        truth = w.add_vector_channel("/truth/state", "fdi_sim/msg/TruthState", TRUTH)
        sens = w.add_vector_channel("/sensors/q", "fdi_sim/msg/Gyro", SENS)
        alarms = w.add_event_channel("/fdi/alarms", "fdi_sim/msg/Alarm", ALARM)
        for k in range(int(round(seconds * 120))):
            t = k / 120
            x = np.array([0.05 + 0.01 * math.sin(t), 0.1 * math.cos(3 * t), 500.0 + t])
            truth.write(t, x)
            sens.write(t, (x[1] + 0.001 * k,))
            rows["/truth/state"].append((t, *x))
            rows["/sensors/q"].append((t, x[1] + 0.001 * k))
            if k in (7, 130, 250):
                alarms.write(t, {"detector": "parity-v1", "k": k})
    return rows


def _messages(path: Path, log_time_order: bool = False):
    with open(path, "rb") as f:
        return [(ch.topic, m) for _s, ch, m in make_reader(f).iter_messages(log_time_order=log_time_order)]


def test_cdr_layout_decoded_independently_with_struct(tmp_path: Path) -> None:
    """Header 00 01 00 00 (CDR_LE), then the float64 fields packed with no padding (XCDR1
    aligns float64 to 8 from the end of the header, and every field is 8 bytes)."""
    path = tmp_path / "a.mcap"
    rows = _write_demo(path)
    msgs = [m for topic, m in _messages(path) if topic == "/truth/state"]
    assert len(msgs) == len(rows["/truth/state"]) == 300
    for m, row in zip(msgs, rows["/truth/state"]):
        assert m.data[:4] == b"\x00\x01\x00\x00"
        assert len(m.data) == 4 + 8 * len(TRUTH)
        assert struct.unpack("<4d", m.data[4:]) == row
        assert m.log_time == m.publish_time == round(row[0] * 1e9)
    assert [m.sequence for m in msgs] == list(range(300))
    # the bulk encoder agrees with the one-message reference encoder
    schema = vector_schema("fdi_sim/msg/TruthState", TRUTH)
    assert msgs[123].data == schema.encode(rows["/truth/state"][123][0], rows["/truth/state"][123][1:])


def test_schemas_and_channels_are_plottable(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    _write_demo(path)
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    by_topic = {c.topic: c for c in summary.channels.values()}
    truth = by_topic["/truth/state"]
    assert truth.message_encoding == "cdr"
    schema = summary.schemas[truth.schema_id]
    assert (schema.name, schema.encoding) == ("fdi_sim/msg/TruthState", "ros2msg")
    assert schema.data.decode() == "float64 t_s\nfloat64 alpha_rad\nfloat64 q_radps\nfloat64 vt_fps\n"
    alarm = by_topic["/fdi/alarms"]
    assert alarm.message_encoding == "json"
    a_schema = summary.schemas[alarm.schema_id]
    assert a_schema.encoding == "jsonschema" and json.loads(a_schema.data) == ALARM


def test_summary_statistics_and_crcs(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    _write_demo(path)
    data = path.read_bytes()
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        meta = list(reader.iter_metadata())
    stats = summary.statistics
    assert stats.message_count == 603 and stats.chunk_count == 3 and stats.metadata_count == 1
    assert stats.message_start_time == 0 and stats.message_end_time == round(299 / 120 * 1e9)
    counts = {summary.channels[c].topic: n for c, n in stats.channel_message_counts.items()}
    assert counts == {"/truth/state": 300, "/sensors/q": 300, "/fdi/alarms": 3}
    assert [(m.name, m.metadata) for m in meta] == [("scenario", {"name": "demo", "seed": "42"})]
    # chunk, data-section CRCs checked by the reference stream reader
    records = list(StreamReader(io.BytesIO(data), validate_crcs=True).records)
    assert type(records[-1]).__name__ == "Footer"
    # summary CRC recomputed here: crc32 of summary section + footer fields before the CRC
    footer = records[-1]
    crc = zlib.crc32(data[footer.summary_start:len(data) - 8 - 4])
    assert crc == footer.summary_crc


def test_summary_offsets_name_their_groups(tmp_path: Path) -> None:
    """Each Summary Offset record (MCAP spec, op 0x0E) spans a run of records of its opcode,
    and the groups tile the summary section up to the offsets themselves."""
    path = tmp_path / "a.mcap"
    _write_demo(path)
    data = path.read_bytes()
    summary_start, offset_start = struct.unpack_from("<QQ", data, len(data) - 8 - 20)
    groups = []
    for opcode, start, length in scan_records(data[:len(data) - 8 - 29], offset_start):
        assert opcode == 0x0E
        groups.append(struct.unpack_from("<BQQ", data, start))
    assert [g[0] for g in groups] == [0x03, 0x04, 0x0B, 0x08, 0x0D]
    pos = summary_start
    for opcode, group_start, group_length in groups:
        assert group_start == pos
        ops = {op for op, _, _ in scan_records(data[:group_start + group_length], group_start)}
        assert ops == {opcode}
        pos += group_length
    assert pos == offset_start


def test_message_indexes_point_at_their_messages(tmp_path: Path) -> None:
    """Every Message Index entry, parsed by ``mcap``, names the offset of a Message record of
    its channel and time in the chunk decompressed here with zstandard."""
    path = tmp_path / "a.mcap"
    _write_demo(path)
    data = path.read_bytes()
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    n_indexed = 0
    for ci in summary.chunk_indexes:
        body = data[ci.chunk_start_offset + 9:ci.chunk_start_offset + ci.chunk_length]
        usize = struct.unpack_from("<Q", body, 16)[0]
        clen = struct.unpack_from("<I", body, 28)[0]
        packed = body[32 + clen + 8:]
        chunk = zstandard.ZstdDecompressor().decompress(packed, max_output_size=usize)
        starts = {}
        for opcode, start, length in scan_records(chunk):
            assert opcode == 0x05
            cid, _seq, log = struct.unpack_from("<HIQ", chunk, start)
            starts[start - 9] = (cid, log)
        assert set(ci.message_index_offsets) == {c for c, _ in starts.values()}
        for cid, off in ci.message_index_offsets.items():
            stream = ReadDataStream(io.BytesIO(data[off + 9:]))
            assert data[off] == 0x07
            idx = MessageIndex.read(stream)
            assert idx.channel_id == cid
            assert [t for t, _ in idx.records] == sorted(t for t, _ in idx.records)
            assert {o for _, o in idx.records} == {o for o, (c, _) in starts.items() if c == cid}
            for log, o in idx.records:
                assert starts[o] == (cid, log)
            n_indexed += len(idx.records)
    assert n_indexed == 603


def test_messages_are_in_time_order_in_the_file(tmp_path: Path) -> None:
    """File order = log time order (what ``mcap doctor`` checks); events after the vector
    messages of their step."""
    path = tmp_path / "a.mcap"
    _write_demo(path)
    msgs = _messages(path, log_time_order=False)
    times = [m.log_time for _, m in msgs]
    assert times == sorted(times)
    i = next(i for i, (topic, _) in enumerate(msgs) if topic == "/fdi/alarms")
    assert [topic for topic, _ in msgs[i - 2:i + 1]] == ["/truth/state", "/sensors/q", "/fdi/alarms"]
    assert json.loads(msgs[i][1].data) == {"detector": "parity-v1", "k": 7}


def test_flush_follows_simulated_time(tmp_path: Path) -> None:
    """Chunks hold [0, 1), [1, 2), ... s of simulated time and reach the disk when a write
    crosses the boundary, before close()."""
    path = tmp_path / "a.mcap"
    w = FlightLogWriter(path, flush_period_s=1.0)
    ch = w.add_vector_channel("/truth/state", "fdi_sim/msg/TruthState", TRUTH)
    on_disk = []
    for k in range(2 * 120 + 1):
        ch.write(k / 120, [0.0, 0.0, 0.0])
        chunks = [(op, s) for op, s, _ in scan_records(path.read_bytes(), 8) if op == 0x06]
        on_disk.append(len(chunks))
    assert on_disk[119] == 0 and on_disk[120] == 1 and on_disk[239] == 1 and on_disk[240] == 2
    assert w.last_flush_t_s == 2.0
    w.close()
    with open(path, "rb") as f:
        ranges = [(c.message_start_time, c.message_end_time) for c in make_reader(f).get_summary().chunk_indexes]
    assert ranges == [(0, round(119 / 120 * 1e9)), (10**9, round(239 / 120 * 1e9)), (2 * 10**9, 2 * 10**9)]


def test_an_event_alone_crossing_a_window_flushes(tmp_path: Path) -> None:
    """Events go through the same time check as vector rows: one written past the window
    boundary first puts the buffered messages on disk as a chunk."""
    path = tmp_path / "a.mcap"
    w = FlightLogWriter(path, flush_period_s=1.0)
    ev = w.add_event_channel("/sim/status", "fdi_sim/msg/Status", {"type": "object"})
    ev.write(0.2, {"k": 0})
    ev.write(0.9, {"k": 1})
    assert not [op for op, _, _ in scan_records(path.read_bytes(), 8) if op == 0x06]
    ev.write(1.5, {"k": 2})
    assert [op for op, _, _ in scan_records(path.read_bytes(), 8) if op == 0x06] == [0x06]
    assert w.last_flush_t_s == 1.5
    w.close()
    with open(path, "rb") as f:
        ranges = [(c.message_start_time, c.message_end_time) for c in make_reader(f).get_summary().chunk_indexes]
    assert ranges == [(2 * 10**8, 9 * 10**8), (15 * 10**8, 15 * 10**8)]


def test_late_start_and_gaps_keep_whole_second_windows(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    with FlightLogWriter(path, flush_period_s=0.5) as w:
        ch = w.add_vector_channel("/x/y", "fdi_sim/msg/X", ("t_s", "a_m"))
        for t in (100.2, 100.3, 100.6, 103.0, 103.1):
            ch.write(t, [t])
    with open(path, "rb") as f:
        ranges = [(c.message_start_time / 1e9, c.message_end_time / 1e9)
                  for c in make_reader(f).get_summary().chunk_indexes]
    assert ranges == [(100.2, 100.3), (100.6, 100.6), (103.0, 103.1)]


def test_identical_inputs_give_identical_files(tmp_path: Path) -> None:
    a, b = tmp_path / "a.mcap", tmp_path / "b.mcap"
    _write_demo(a)
    _write_demo(b)
    assert a.read_bytes() == b.read_bytes()


@pytest.mark.parametrize("compression", ["zstd", "lz4", None])
def test_every_compression_reads_back_the_same(tmp_path: Path, compression: str | None) -> None:
    ref = tmp_path / "ref.mcap"
    path = tmp_path / "c.mcap"
    _write_demo(ref, compression="zstd")
    _write_demo(path, compression=compression)
    assert [(t, m.data, m.log_time) for t, m in _messages(path)] == \
        [(t, m.data, m.log_time) for t, m in _messages(ref)]


def test_value_types_give_the_same_payload(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    base = np.array([1.5, -2.0, 3.25])
    variants = [base, tuple(base), list(base), [1.5, -2, 3.25], np.array([[1.5, 9], [-2.0, 9], [3.25, 9]])[:, 0],
                base.astype(np.float32), base.astype(">f8"), (np.float64(1.5), -2.0, 3.25)]
    with FlightLogWriter(path) as w:
        ch = w.add_vector_channel("/truth/state", "fdi_sim/msg/TruthState", TRUTH)
        for k, v in enumerate(variants):
            ch.write(k * 0.01, v)
    payloads = {m.data[12:] for _, m in _messages(path)}
    assert payloads == {struct.pack("<3d", 1.5, -2.0, 3.25)}


def test_buffered_rows_are_copies(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    x = np.zeros(3)
    with FlightLogWriter(path) as w:
        ch = w.add_vector_channel("/truth/state", "fdi_sim/msg/TruthState", TRUTH)
        for k in range(5):
            x[:] = k
            ch.write(k * 0.01, x)  # the caller reuses its buffer
    assert [struct.unpack_from("<d", m.data, 12)[0] for _, m in _messages(path)] == [0.0, 1.0, 2.0, 3.0, 4.0]


def test_close_is_idempotent_and_runs_in_finally(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    with pytest.raises(RuntimeError, match="boom"):
        with FlightLogWriter(path) as w:
            ch = w.add_vector_channel("/truth/state", "fdi_sim/msg/TruthState", TRUTH)
            ch.write(0.0, [1.0, 2.0, 3.0])
            raise RuntimeError("boom")
    w.close()
    w.close()
    assert w.closed
    assert len(_messages(path)) == 1
    with pytest.raises(LogError, match="closed"):
        ch.write(1.0, [1.0, 2.0, 3.0])
    with pytest.raises(LogError, match="closed"):
        w.add_metadata("late", {"a": "b"})


@pytest.mark.parametrize("bad", ["no_such_dir/run.mcap", "."])
def test_unwritable_path_names_the_path(tmp_path: Path, bad: str) -> None:
    target = tmp_path / bad
    with pytest.raises(LogError) as err:
        FlightLogWriter(target)
    assert str(target) in str(err.value) and "writable" in str(err.value)


@pytest.mark.parametrize("t_s", [float("nan"), -0.1, float("inf"), "1.0", None])
def test_bad_times_raise(tmp_path: Path, t_s: object) -> None:
    with FlightLogWriter(tmp_path / "a.mcap") as w:
        ch = w.add_vector_channel("/truth/state", "fdi_sim/msg/TruthState", TRUTH)
        with pytest.raises(LogError, match="t_s"):
            ch.write(t_s, [1.0, 2.0, 3.0])  # type: ignore[arg-type]
        ev = w.add_event_channel("/sim/status", "fdi_sim/msg/Status", {"type": "object"})
        with pytest.raises(LogError, match="t_s"):
            ev.write(t_s, {})  # type: ignore[arg-type]


@pytest.mark.parametrize("values", [[1.0, 2.0], [1.0, 2.0, 3.0, 4.0], 1.0, ["a", "b", "c"], np.zeros((3, 1)),
                                    (1.0, 2.0), ("a", "b", "c"), np.zeros(4)])
def test_wrong_values_raise_with_the_fields(tmp_path: Path, values: object) -> None:
    with FlightLogWriter(tmp_path / "a.mcap") as w:
        ch = w.add_vector_channel("/truth/state", "fdi_sim/msg/TruthState", TRUTH)
        with pytest.raises(LogError, match="alpha_rad"):
            ch.write(0.0, values)


@pytest.mark.parametrize("topic, name, fields, match", [
    ("truth/state", "fdi_sim/msg/T", TRUTH, "topic"),
    ("/truth/state", "TruthState", TRUTH, "schema name"),
    ("/truth/state", "fdi_sim/msg/T", ("alpha_rad", "t_s"), "t_s"),
    ("/truth/state", "fdi_sim/msg/T", ("t_s",), "value field"),
    ("/truth/state", "fdi_sim/msg/T", ("t_s", "Alpha"), "ROS 2 field name"),
    ("/truth/state", "fdi_sim/msg/T", ("t_s", "a__b"), "ROS 2 field name"),
    ("/truth/state", "fdi_sim/msg/T", ("t_s", "a_m", "a_m"), "duplicate"),
    ("/truth/state", "fdi_sim/msg/T", "t_s", "sequence"),
])
def test_bad_channel_definitions_raise(tmp_path: Path, topic: str, name: str, fields: object, match: str) -> None:
    with FlightLogWriter(tmp_path / "a.mcap") as w:
        with pytest.raises(LogError, match=match):
            w.add_vector_channel(topic, name, fields)  # type: ignore[arg-type]


def test_topics_unique_and_schemas_shared_or_distinct(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    with FlightLogWriter(path) as w:
        w.add_vector_channel("/sensors/a", "fdi_sim/msg/Gyro", SENS)
        w.add_vector_channel("/sensors/b", "fdi_sim/msg/Gyro", SENS)
        with pytest.raises(LogError, match="already has a channel"):
            w.add_vector_channel("/sensors/a", "fdi_sim/msg/Gyro", SENS)
        with pytest.raises(LogError, match="already defined differently"):
            w.add_vector_channel("/sensors/c", "fdi_sim/msg/Gyro", ("t_s", "p_radps"))
    with open(path, "rb") as f:
        s = make_reader(f).get_summary()
    assert len(s.schemas) == 1 and len({c.schema_id for c in s.channels.values()}) == 1


@pytest.mark.parametrize("payload, match", [
    ({"k": 1}, "required"),
    ({"detector": "x", "v": float("nan")}, "JSON"),
    ({"detector": "x", "v": object()}, "JSON"),
    (["detector"], "dict"),
])
def test_bad_event_payloads_raise(tmp_path: Path, payload: object, match: str) -> None:
    with FlightLogWriter(tmp_path / "a.mcap") as w:
        ev = w.add_event_channel("/fdi/alarms", "fdi_sim/msg/Alarm", ALARM)
        with pytest.raises(LogError, match=match):
            ev.write(0.0, payload)  # type: ignore[arg-type]


def test_event_payload_numpy_values_become_json(tmp_path: Path) -> None:
    path = tmp_path / "a.mcap"
    with FlightLogWriter(path) as w:
        ev = w.add_event_channel("/fdi/alarms", "fdi_sim/msg/Alarm", ALARM)
        ev.write(0.5, {"detector": "x", "stat": np.float64(2.5), "n": np.int64(3), "on": np.bool_(True),
                       "r": np.array([1.0, 2.0])})
    assert json.loads(_messages(path)[0][1].data) == {"detector": "x", "stat": 2.5, "n": 3, "on": True, "r": [1.0, 2.0]}


@pytest.mark.parametrize("kwargs, match", [
    ({"flush_period_s": 0.0}, "flush_period_s"), ({"flush_period_s": float("nan")}, "flush_period_s"),
    ({"compression": "gzip"}, "compression"), ({"metadata": {"scenario": {"seed": 3}}}, "strings"),
    ({"metadata": {"": {}}}, "non-empty"), ({"metadata": {"scenario": "text"}}, "dict"),
])
def test_bad_writer_options_raise(tmp_path: Path, kwargs: dict, match: str) -> None:
    with pytest.raises(LogError, match=match):
        FlightLogWriter(tmp_path / "a.mcap", **kwargs)


def test_metadata_names_unique(tmp_path: Path) -> None:
    with FlightLogWriter(tmp_path / "a.mcap", metadata={"scenario": {"name": "x"}}) as w:
        w.add_metadata("versions", {"numpy": np.__version__})
        with pytest.raises(LogError, match="already written"):
            w.add_metadata("scenario", {"seed": "1"})


def test_message_index_encoding_matches_mcap() -> None:
    entries = np.array([[5, 0], [17, 100], [17, 250]], dtype=np.uint64)
    rb = RecordBuilder()
    MessageIndex(channel_id=3, records=[(5, 0), (17, 100), (17, 250)]).write(rb)
    assert encode_message_index(3, entries) == rb.end()


def _decode_chunk(payload) -> dict[int, list[tuple[int, int, bytes]]]:
    """Messages of a built chunk by channel: (log time, sequence, data), scanned with struct."""
    out: dict[int, list[tuple[int, int, bytes]]] = {}
    offsets = {}
    for opcode, start, length in scan_records(bytes(payload.records)):
        assert opcode == 0x05
        cid, seq, log, pub = struct.unpack_from("<HIQQ", payload.records, start)
        assert pub == log
        out.setdefault(cid, []).append((log, seq, bytes(payload.records[start + 22:start + length])))
        offsets[start - 9] = (cid, log)
    for cid, entries in payload.index.items():  # the index names every message once
        assert sorted((int(o), offsets[int(o)]) for _, o in entries) == \
            sorted((o, v) for o, v in offsets.items() if v[0] == cid)
        assert all(offsets[int(o)][1] == int(log) for log, o in entries)
    return out


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.integers(1, 4), st.lists(st.integers(0, 40), min_size=0, max_size=12)),
                min_size=1, max_size=4, unique_by=lambda c: c[0]),
       st.lists(st.integers(0, 40), max_size=4), st.booleans())
def test_build_chunk_against_one_message_encoder(chans, event_ticks, same_times) -> None:
    """Both layouts (regular steps and general sort) and event splicing give, per channel,
    exactly the messages the reference encoder makes, in time order, correctly indexed."""
    rng = np.random.default_rng(len(chans))
    if same_times:
        ticks = chans[0][1]
        chans = [(cid, ticks) for cid, _ in chans]
    blocks, expected = [], {}
    for cid, ticks in chans:
        width = cid + 1
        t = np.array(ticks, dtype=np.float64) / 120
        vals = rng.standard_normal((len(t), width))
        blocks.append(VectorBlock(cid, 7 * cid, t, vals))
        schema = vector_schema("fdi_sim/msg/T", ("t_s",) + tuple(f"v{i}_m" for i in range(width)))
        msgs = [(round(t[i] * 1e9), 7 * cid + i, schema.encode(t[i], vals[i])) for i in range(len(t))]
        expected[cid] = sorted(msgs, key=lambda m: m[0])
    raws = [RawMessage(9, i, round(k / 120 * 1e9), b'{"k":%d}' % k) for i, k in enumerate(event_ticks)]
    expected[9] = sorted([(r.log_time_ns, r.sequence, r.data) for r in raws], key=lambda m: m[0])
    expected = {c: m for c, m in expected.items() if m}
    payload = build_chunk(blocks, raws)
    got = _decode_chunk(payload)
    assert got == expected
    all_logs = [m[0] for msgs in expected.values() for m in msgs]
    assert payload.message_count == len(all_logs)
    if all_logs:
        assert (payload.message_start_ns, payload.message_end_ns) == (min(all_logs), max(all_logs))
    file_order = [struct.unpack_from("<Q", payload.records, s + 6)[0] for _, s, _ in scan_records(bytes(payload.records))]
    assert file_order == sorted(file_order)


def test_regular_chunks_wrap_sequences_and_own_their_bytes() -> None:
    """The per-second layout (shared, cached constant parts): u32 sequences wrap, any float
    layout of the values is written as little-endian float64, chunks of other lengths reuse
    nothing of an earlier payload's bytes."""
    from fdi_sim.flightlog.records import _regular_layout
    rng = np.random.default_rng(3)
    firsts = {1: 2**32 - 2, 2: 5, 3: 2**32 + 3}
    schemas = {cid: vector_schema("fdi_sim/msg/T", ("t_s",) + tuple(f"v{i}_m" for i in range(cid + 1)))
               for cid in firsts}
    payloads, expected = [], []
    for n in (5, 3, 5):
        t = (np.arange(n) + 10 * len(payloads)) / 120
        wide = rng.standard_normal((n, 8))
        vals = {1: wide[:, ::4].astype(">f8"), 2: wide[:, :3].astype(np.float32).astype(np.float64), 3: wide[:, 1:5]}
        blocks = [VectorBlock(cid, firsts[cid], t, vals[cid]) for cid in firsts]
        assert _regular_layout(blocks) is not None
        payloads.append(build_chunk(blocks))
        expected.append({cid: [(round(t[i] * 1e9), (firsts[cid] + i) & 0xFFFFFFFF,
                                schemas[cid].encode(t[i], np.asarray(vals[cid][i], dtype=np.float64)))
                               for i in range(n)] for cid in firsts})
    for payload, exp in zip(payloads, expected):
        assert _decode_chunk(payload) == exp
