"""verify_log on a real log of a short real run: clean, and with one byte flipped anywhere.

The expected part of each position comes from the clean file's record layout, read here with
``records.scan_records`` and the ``mcap`` library's record classes (not with the code under
test). No byte is excluded: the data section CRC covers the opening magic and every data
record, the summary CRC covers every summary record and the footer's fields, and the summary
CRC field and the closing magic are compared directly.
"""
from __future__ import annotations

import io
import zlib
from pathlib import Path

import numpy as np
import pytest
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Metadata, MetadataIndex, Schema, SummaryOffset
from mcap.stream_reader import StreamReader

from fdi_sim.errors import LogError
from fdi_sim.flightlog import read_log, verify_log
from fdi_sim.flightlog.framing import locate_single_byte_error
from fdi_sim.flightlog.records import scan_records

REPO = Path(__file__).resolve().parents[2]
#: flipped positions per part (seeded); every part kind below gets this many
FLIPS_PER_PART = 24


@pytest.fixture(scope="module")
def real_log(tmp_path_factory: pytest.TempPathFactory) -> bytes:
    """A 3 s real F-16 run (JSBSim, the real writer)."""
    from fdi_sim.scenario import load
    from fdi_sim.training import fly
    sc, _ = load(REPO / "scenarios/f16_cruise_doublets.toml").shortened(3.0)
    path = tmp_path_factory.mktemp("verify") / "run.mcap"
    fly(sc, log_path=path)
    return path.read_bytes()


def _layout(data: bytes) -> dict[str, list[tuple[int, int, str]]]:
    """Part kind -> [(start, end, expected part name)] for every record of the clean file."""
    def read(cls, start: int, length: int):  # noqa: ANN001, ANN202
        return cls.read(ReadDataStream(io.BytesIO(data[start:start + length])))

    out: dict[str, list[tuple[int, int, str]]] = {}
    section = "data section"
    out["header"] = [(0, 8, "header")]
    for op, b, n in scan_records(data, 8):
        s, e = b - 9, b + n
        if op == Opcode.HEADER:
            kind, want = "header", "header"
        elif op == Opcode.SCHEMA:
            r = read(Schema, b, n)
            kind, want = f"schema {section}", f"schema record {r.id} ({r.name}) in the {section}"
        elif op == Opcode.CHANNEL:
            r = read(Channel, b, n)
            kind, want = f"channel {section}", f"channel record {r.id} ({r.topic}) in the {section}"
        elif op == Opcode.METADATA:
            r = read(Metadata, b, n)
            kind, want = f"metadata {r.name}", f"metadata record '{r.name}'"
        elif op == Opcode.CHUNK:
            kind, want = "chunk", f"chunk at offset {s} ("
        elif op == Opcode.MESSAGE_INDEX:
            kind, want = "message index", f"message index at offset {s} ("
        elif op == Opcode.DATA_END:
            kind, want, section = "data end", "data section (Data End", "summary"
        elif op == Opcode.STATISTICS:
            kind, want = "statistics", "statistics"
        elif op == Opcode.CHUNK_INDEX:
            kind, want = "chunk index", "chunk index of the chunk at offset"
        elif op == Opcode.METADATA_INDEX:
            kind, want = "metadata index", f"metadata index '{read(MetadataIndex, b, n).name}'"
        elif op == Opcode.SUMMARY_OFFSET:
            g = Opcode(read(SummaryOffset, b, n).group_opcode).name
            kind, want = "summary offset", f"summary offset record ({g} group)"
        elif op == Opcode.FOOTER:
            kind, want, e = "footer", "footer", len(data)  # the closing magic with it
        else:
            raise AssertionError(f"unexpected record {op} in the clean log")
        out.setdefault(kind, []).append((s, e, want))
    return out


def test_clean_log_verifies_and_the_mcap_reader_agrees(real_log: bytes, tmp_path: Path) -> None:
    path = tmp_path / "clean.mcap"
    path.write_bytes(real_log)
    report = verify_log(path)
    assert report.ok, report.format()
    assert {"data section CRC", "summary CRC"} <= set(report.checks)
    assert "intact" in report.format()
    records = list(StreamReader(io.BytesIO(real_log), validate_crcs=True).records)
    assert type(records[-1]).__name__ == "Footer"
    assert read_log(path).message_counts["/truth/state"] == 361


def test_every_part_kind_is_present(real_log: bytes) -> None:
    """The sweep below covers each part the MCAP writer produces (a change in the writer that
    adds a record kind must extend the sweep)."""
    assert set(_layout(real_log)) == {
        "header", "schema data section", "channel data section", "metadata scenario",
        "metadata versions", "chunk", "message index", "data end", "schema summary",
        "channel summary", "statistics", "chunk index", "metadata index", "summary offset", "footer"}


@pytest.mark.parametrize("kind", [
    "header", "schema data section", "channel data section", "metadata scenario", "metadata versions",
    "chunk", "message index", "data end", "schema summary", "channel summary", "statistics",
    "chunk index", "metadata index", "summary offset", "footer"])
def test_one_flipped_byte_is_found_and_its_part_named(real_log: bytes, tmp_path: Path, kind: str) -> None:
    records = _layout(real_log)[kind]
    positions = [(p, want) for s, e, want in records for p in range(s, e)]
    rng = np.random.default_rng(zlib.crc32(kind.encode()))  # seeded per part kind
    pick = rng.choice(len(positions), size=min(FLIPS_PER_PART, len(positions)), replace=False)
    path = tmp_path / "flipped.mcap"
    for i in pick.tolist():
        pos, want = positions[i]
        data = bytearray(real_log)
        data[pos] ^= int(rng.integers(1, 256))
        path.write_bytes(bytes(data))
        report = verify_log(path)
        assert not report.ok, f"flip at {pos} ({want}) went unnoticed"
        assert any(want in part for part in report.parts()), (pos, want, report.format())


def test_small_parts_flipped_at_every_byte(real_log: bytes, tmp_path: Path) -> None:
    """Header (with the magic) and footer (with the closing magic), every byte, one bit."""
    lay = _layout(real_log)
    path = tmp_path / "flipped.mcap"
    for s, e, want in lay["header"] + lay["footer"]:
        for pos in range(s, e):
            data = bytearray(real_log)
            data[pos] ^= 0x10
            path.write_bytes(bytes(data))
            report = verify_log(path)
            assert any(want in part for part in report.parts()), (pos, report.format())


def test_cut_off_and_foreign_files(real_log: bytes, tmp_path: Path) -> None:
    path = tmp_path / "cut.mcap"
    path.write_bytes(real_log[:len(real_log) // 2])
    report = verify_log(path)
    assert not report.ok and "footer" in report.parts()
    assert "fdi-sim repair" in report.format()
    text = tmp_path / "notes.mcap"
    text.write_text("a text file, not a log\n")
    with pytest.raises(LogError, match="not an MCAP file"):
        verify_log(text)
    with pytest.raises(LogError, match="cannot read"):
        verify_log(tmp_path / "missing.mcap")


def test_crc_locates_a_single_changed_byte() -> None:
    """CRC32's linearity: the syndrome of one changed byte gives its offset back."""
    rng = np.random.default_rng(5)
    for length in (1, 7, 4096, 300_000):
        buf = bytearray(rng.integers(0, 256, length, dtype=np.uint8).tobytes())
        crc = zlib.crc32(buf)
        for _ in range(5):
            pos, v = int(rng.integers(length)), int(rng.integers(1, 256))
            buf[pos] ^= v
            assert pos in locate_single_byte_error(crc, zlib.crc32(buf), length)
            buf[pos] ^= v
    assert locate_single_byte_error(crc, crc, length) == []
