"""The command line: exit codes, messages without tracebacks, and the log commands on real files."""
from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from mcap.reader import make_reader

from fdi_sim.cli import main
from fdi_sim.errors import LogError
from fdi_sim.flightlog import read_log

ROOT = Path(__file__).resolve().parents[1]


def test_run_info_plugins_scenarios(tmp_path: Path, capsys: pytest.CaptureFixture[str], f16_text: str) -> None:
    scn = tmp_path / "s.toml"
    # a detector id nobody registered is refused before anything flies (exit 2, the close id named)
    bad = tmp_path / "bad.toml"
    bad.write_text(f16_text + '[[detectors]]\ntype = "parity-robust-v2"\n')
    assert main(["run", str(bad), "--out", str(tmp_path), "--duration", "3", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "did you mean parity-robust-v1" in err and not list(tmp_path.glob("*.mcap"))
    # one that has runs in the loop (its threshold set on four short training flights)
    fdi = '[fdi]\ncalibration_flights = 4\ncalibration_duration_s = 40.0\n[[detectors]]\ntype = "kinematic-attitude-v1"\n'
    scn.write_text(f16_text + fdi)
    assert main(["run", str(scn), "--out", str(tmp_path), "--duration", "8", "--quiet"]) == 0
    out, err = capsys.readouterr()
    assert "status     completed" in out and "log " in out
    assert "fdi bank   kinematic-attitude-v1" in out and "false alarms: none" in out
    log = next(tmp_path.glob("*.mcap"))
    _check_with_the_mcap_reader(log)
    assert main(["info", str(log)]) == 0
    info = capsys.readouterr().out
    assert "/truth/state" in info and "t_f16" in info and "/fdi/kinematic-attitude-v1/statistic" in info
    assert main(["plugins"]) == 0
    assert "doublet-v1" in capsys.readouterr().out
    assert main(["scenarios"]) == 0
    listing = capsys.readouterr().out
    assert all(p.stem in listing for p in (ROOT / "scenarios").glob("*.toml"))


def _check_with_the_mcap_reader(log: Path) -> None:
    """A real run's log through the standard ``mcap`` reader, CRCs checked: every ros2msg channel
    holds CDR_LE messages of 4 + 8 bytes per ``float64`` line of its schema, every JSON channel
    parses, and the counts agree with the summary and with our reader."""
    counts: dict[str, int] = {}
    with open(log, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        for schema, channel, msg in reader.iter_messages():
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            if schema.encoding == "ros2msg":
                assert channel.message_encoding == "cdr"
                lines = schema.data.decode().splitlines()
                assert all(line.startswith("float64 ") for line in lines)
                assert msg.data[:4] == b"\x00\x01\x00\x00" and len(msg.data) == 4 + 8 * len(lines)
            else:
                assert (schema.encoding, channel.message_encoding) == ("jsonschema", "json")
                assert json.loads(schema.data)["type"] == "object"
                assert isinstance(json.loads(msg.data), dict)
    assert sum(counts.values()) == summary.statistics.message_count > 0
    assert counts == {k: v for k, v in read_log(log).message_counts.items() if v}  # an event topic may be empty


@pytest.mark.parametrize("args,needle", [
    (["run", "scenarios/does_not_exist.toml"], "no such file"),
    (["info", "pyproject.toml"], "not an MCAP"),
])
def test_bad_input_exit_2_one_paragraph(capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch,
                                        args: list[str], needle: str) -> None:
    monkeypatch.chdir(ROOT)
    assert main(args) == 2
    err = capsys.readouterr().err
    assert needle in err and "Traceback" not in err


def test_typo_key_and_untrimmable_point(tmp_path: Path, capsys: pytest.CaptureFixture[str], f16_text: str) -> None:
    bad = tmp_path / "typo.toml"
    bad.write_text(f16_text.replace("h_ft", "hft"))
    assert main(["run", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "typo.toml: initial.hft: unknown key" in err and "h_ft" in err
    dhc = tmp_path / "fast.toml"
    dhc.write_text(f16_text.replace('"f16"', '"DHC6"').replace("h_ft = 10000.0", "h_ft = 5000.0").replace("vt_kts = 400.0", "vc_kts = 150.0"))
    assert main(["run", str(dhc), "--out", str(tmp_path)]) == 2
    assert "cannot trim DHC6" in capsys.readouterr().err


@pytest.mark.parametrize("section,key", [
    ('[sensors]\nsuite = "defualt"', "sensors.suite: no sensor suite 'defualt' for f16"),
    ("[sensors.overrides.alpah_rad]\nnoise_std = 0.1", "sensors.overrides.alpah_rad: no such sensor"),
])
def test_bad_sensor_section_exit_2_before_the_run(tmp_path: Path, capsys: pytest.CaptureFixture[str], f16_text: str,
                                                  section: str, key: str) -> None:
    """A sensor-suite typo escaped as a FileNotFoundError traceback after the trim."""
    bad = tmp_path / "bad.toml"
    bad.write_text(f16_text + section)
    assert main(["run", str(bad), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert f"bad.toml: {key}" in err and "Fix: did you mean" in err and "Traceback" not in err
    assert not list(tmp_path.glob("*.mcap"))  # refused when loaded, before any log is opened


def test_unwritable_output_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str], f16_text: str) -> None:
    scn = tmp_path / "s.toml"
    scn.write_text(f16_text)
    blocker = tmp_path / "file"
    blocker.write_text("x")  # a file where the folder should be: fails even as root
    assert main(["run", str(scn), "--out", str(blocker / "sub")]) == 2
    assert "Traceback" not in capsys.readouterr().err


def test_sigkill_halfway_then_repair(tmp_path: Path, f16_text: str) -> None:
    """Bar: a run killed with SIGKILL halfway is repaired by `fdi-sim repair` and reads back."""
    scn = tmp_path / "long.toml"
    scn.write_text(f16_text.replace("duration_s = 10.0", "duration_s = 600.0"))
    log = tmp_path / "killed.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "fdi_sim.cli", "run", str(scn), "--log", str(log), "--quiet"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.time() + 120
        while time.time() < deadline and (not log.exists() or log.stat().st_size < 400_000):
            time.sleep(0.05)
        assert proc.poll() is None, "the run ended before it could be killed"
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    with pytest.raises(LogError, match="fdi-sim repair"):
        read_log(log)  # no summary: the reader refuses and points at repair
    out = tmp_path / "fixed.mcap"
    assert main(["repair", str(log), "--out", str(out)]) == 0
    rep = read_log(out)
    t = rep.topics["/truth/state"].t_s
    assert t[-1] > 5.0
    # every step present from 0 to the last recovered time: nothing lost but the unflushed tail
    assert len(t) == round(t[-1] * 120) + 1
    statuses = [e.payload["status"] for e in rep.topics["/sim/status"].events]
    assert statuses == ["running"]  # killed: no end record


def test_run_shortened_drops_later_entries(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The README's `fdi-sim run scenarios/dhc6_cruise_doublets.toml --duration S` works for any S:
    maneuvers and faults starting after S are dropped with a note, not refused."""
    scn = Path(__file__).resolve().parents[1] / "scenarios" / "dhc6_cruise_doublets.toml"
    assert main(["run", str(scn), "--out", str(tmp_path), "--duration", "20", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "drops 3 maneuver/fault entries" in err  # the doublets at 20, 35 s and the 3211 at 45 s


def test_info_lists_the_fault_catalogue(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`fdi-sim info` reads the `faults` metadata record the run wrote: label, type, target, onset."""
    scn = ROOT / "scenarios" / "dhc6_airspeed_drift.toml"  # sensor-drift-v1 on vc_kts from t = 10 s, open-ended
    log = tmp_path / "drift.mcap"
    assert main(["run", str(scn), "--log", str(log), "--duration", "11", "--quiet"]) == 0
    capsys.readouterr()
    assert main(["info", str(log)]) == 0
    lines = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("fault:")]
    assert len(lines) == 1 and lines[0].split()[2:] == ["sensor-drift-v1", "on", "vc_kts,", "from", "10", "s"], lines


def test_verify_names_damage_and_exit_codes(tmp_path: Path, f16_text: str, capsys: pytest.CaptureFixture[str]) -> None:
    """`fdi-sim verify`: 0 intact, 1 damaged (the part named), 2 not an MCAP file; `info --check` the same."""
    scn = tmp_path / "s.toml"
    scn.write_text(f16_text.replace("duration_s = 10.0", "duration_s = 3.0"))
    log = tmp_path / "x.mcap"
    assert main(["run", str(scn), "--log", str(log), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["verify", str(log)]) == 0
    assert "intact" in capsys.readouterr().out
    data = bytearray(log.read_bytes())
    data[len(data) // 3] ^= 0x01  # inside a chunk
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    assert main(["verify", str(bad)]) == 1
    out = capsys.readouterr().out
    assert "DAMAGED" in out and "chunk at offset" in out and "fdi-sim repair" in out
    assert main(["info", "--check", str(bad)]) == 1
    assert main(["verify", str(scn)]) == 2
    assert "not an MCAP file" in capsys.readouterr().err
