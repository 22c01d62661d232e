"""`fdi-sim detect`: registered detectors over a real log, the --json shape, the --out MCAP, bad input."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader

from fdi_sim.cli import main
from fdi_sim.flightlog import FlightLogWriter, read_log, verify_log

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def gyro_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The shipped pitch-gyro-bias scenario, 20 s (onset at 10 s)."""
    log = tmp_path_factory.mktemp("detect") / "gyro.mcap"
    r = subprocess.run([sys.executable, "-m", "fdi_sim.cli", "run", "scenarios/f16_pitch_gyro_bias.toml", "--log",
                        str(log), "--duration", "20", "--quiet"], capture_output=True, text=True, cwd=REPO)
    assert r.returncode == 0, r.stderr
    return log


def test_detect_json_shape_and_out_log(gyro_log: Path, tmp_path: Path) -> None:
    out = tmp_path / "det.mcap"
    r = subprocess.run([sys.executable, "-m", "fdi_sim.cli", "detect", str(gyro_log), "--detector",
                        "kalman-nis-v1:sensor_std=0.01", "--detector", "kalman-mmae-v1:effectiveness=1.0", "--json", "--out", str(out)],
                       capture_output=True, text=True, cwd=REPO)
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    assert rep["aircraft"] == "f16" and rep["rate_hz"] == 20.0
    kal, par = rep["detectors"]
    for key in ("id", "samples", "alarm_samples", "alarm_onsets", "flight_h", "faults"):
        assert key in kal
    assert kal["id"] == "kalman-nis-v1" and kal["samples"] == 20 * 20  # t = 0.05 .. 20 s at 20 Hz
    assert kal["flight_h"] == pytest.approx(20.0 / 3600.0)
    assert kal["alarm_onsets"] <= kal["alarm_samples"] <= kal["samples"]
    (fault,) = kal["faults"]
    assert fault["label"] == "q_radps_bias" and fault["t_onset_s"] == 10.0
    for key in ("first_alarm_s", "isolated_as"):
        assert key in fault
    assert "effectiveness must be in [0, 1)" in par["error"], "a design that fails is reported with its reason"
    # the out file: every input topic with its counts (the in-loop bank's /fdi topics among them),
    # plus the offline detector's statistic and alarms under /fdi/offline
    src, det = read_log(gyro_log), read_log(out)
    assert "/fdi/kalman-gust-v1/statistic" in src.topics  # the shipped scenario flies with its bank
    for topic, n in src.message_counts.items():
        assert det.message_counts[topic] == n, topic
    stat = det.topics["/fdi/offline/kalman-nis-v1/statistic"]
    assert len(stat.t_s) == kal["samples"] and stat.fields == ("t_s", "statistic", "threshold", "alarm", "valid")
    assert int(stat["alarm"].sum()) == kal["alarm_samples"]
    raised = [e for e in det.topics["/fdi/offline/alarms"].events if e.payload["alarm"]]
    assert len(raised) == kal["alarm_onsets"]
    assert verify_log(out).ok
    with open(out, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        assert sum(1 for _ in reader.iter_messages()) == reader.get_summary().statistics.message_count


def test_detect_bad_input(gyro_log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    cases = [
        (["--detector", "kalman-nis-v2"], "did you mean 'kalman-nis-v1'"),
        (["--detector", "kalman-nis-v1:alpah=0.01"], "unknown option 'alpah' (did you mean 'alpha'?)"),
        (["--detector", "kalman-nis-v1", "--rate-hz", "50"], "does not divide the simulation rate 120 Hz"),
        (["--detector", "kalman-nis-v1:alpha"], "is not key=value"),
        ([], "no detector given"),
    ]
    for extra, expected in cases:
        assert main(["detect", str(gyro_log), *extra]) == 2, extra
        err = capsys.readouterr().err
        assert expected.lower() in err.lower(), (extra, err)
    other = tmp_path / "other.mcap"  # an MCAP that `fdi-sim run` did not write
    with FlightLogWriter(other) as w:
        w.add_vector_channel("/x/y", "x/msg/Y", ("t_s", "a_m")).write(0.0, [1.0])
    assert main(["detect", str(other), "--detector", "kalman-nis-v1"]) == 2
    assert "no 'scenario' metadata" in capsys.readouterr().err
    assert main(["detect", str(gyro_log), "--detector", "kalman-nis-v1", "--out", str(gyro_log)]) == 2
    assert "the output is the input log" in capsys.readouterr().err


def test_default_bank_detects_and_isolates_the_gyro_bias(gyro_log: Path) -> None:
    """`--bank default`: the default in-loop bank replayed over the log (the log flew with it, so the
    replay is also compared with its /fdi topics); kalman-gust-v1 and the kinematic attitude check
    both catch the pitch-gyro bias and name q_radps, with no alarm before it."""
    r = subprocess.run([sys.executable, "-m", "fdi_sim.cli", "detect", str(gyro_log), "--bank", "default", "--json"],
                       capture_output=True, text=True, cwd=REPO)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    rep = {d["id"]: d for d in out["detectors"]}
    assert set(rep) == {"kalman-gust-v1", "kinematic-attitude-v1", "kinematic-altitude-v1", "kinematic-airspeed-v1",
                        "kinematic-flow-angles-v1"}
    assert out["identical_to_log"] == {k: True for k in rep}
    for ident in ("kalman-gust-v1", "kinematic-attitude-v1"):
        d = rep[ident]
        (f,) = d["faults"]
        assert d["fault_free_alarm_samples"] == 0, ident
        assert f["first_alarm_s"] is not None and f["delay_s"] < 2.0, (ident, f)
    f = rep["kinematic-attitude-v1"]["faults"][0]
    assert f["isolated_as"] == "q_radps" and f["isolation_correct"]
    # the filter's signatures of a pitch-gyro bias and a pitch-attitude bias are close (the attitude
    # is the gyro's integral): it names one of the two (docs/bank.md, reconfiguration)
    assert rep["kalman-gust-v1"]["faults"][0]["isolated_as"] in ("q_radps", "theta_rad")
