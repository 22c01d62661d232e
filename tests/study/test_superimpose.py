"""Sensor faults superimposed on a logged flight (fdi_sim.study.superimpose), on real JSBSim flights
and real MCAP logs: the empty superimposition is the logged bank bit for bit; a superimposed gyro
bias is detected after its onset only; against the same faults flown in the loop (same seed), the
rows agree bit for bit up to the onset and the fault's draws are the loop's; what cannot be
superimposed is refused by name."""
from __future__ import annotations

import json
import shutil
import tomllib

import numpy as np
import pytest

from fdi_sim.errors import LogError, ScenarioError
from fdi_sim.flightlog import TOPIC_FAULTS, read_log
from fdi_sim.scenario import loads
from fdi_sim.training import fly
from fdi_sim.study.superimpose import loop_fault_rng, superimpose, superimpose_study

SEED = 21
T_ON_S = 20.0
FLIGHT = """
name = "{name}"
aircraft = "f16"
duration_s = 40.0
seed = 21
[initial]
h_ft = 10000.0
vt_kts = 400.0
[atmosphere]
turbulence = "light"
[[maneuvers]]
type = "doublet-v1"
axis = "rudder"
t_start_s = 10.0
amplitude_norm = 0.1
pulse_s = 1.0
{faults}
[fdi]
bank = "default"
calibration_flights = 4
calibration_duration_s = 60.0
"""
GYRO_BIAS = """
[[faults]]
type = "sensor-bias-v1"
target = "q_radps"
bias_degps = 2.0
t_start_s = 20.0
"""
# random windows and noise draws (the fault stream), on a 40 Hz sensor (held between its samples)
ALTIMETER_NOISE = """
[[faults]]
type = "sensor-noise-v1"
target = "h_ft"
noise_std_ft = 0.3
t_start_s = 25.0
intermittent = { duty_cycle = 0.5, mean_dwell_s = 3.0 }
"""
STAT_KEYS = ("t_s", "statistic", "threshold", "exceedance", "alarm", "valid", "isolation", "point")


@pytest.fixture(scope="module")
def flights(tmp_path_factory):
    """A fault-free flight and the same seed flown with the faults in the loop (full logs)."""
    tmp = tmp_path_factory.mktemp("superimpose")
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("FDI_SIM_CACHE", str(tmp / "cache"))  # the calibration (4 x 60 s) once, here
        free = fly(loads(FLIGHT.format(name="t_sup_free", faults="")), tmp, progress=False)
        closed = fly(loads(FLIGHT.format(name="t_sup_closed", faults=GYRO_BIAS + ALTIMETER_NOISE)), tmp,
                     progress=False)
        assert free.status == closed.status == "completed"
        yield free, closed, tmp


def _faults(text: str) -> list[dict]:
    return tomllib.loads(text)["faults"]


def test_no_fault_reproduces_the_logged_bank_bit_for_bit(flights):
    free, _, _ = flights
    r = superimpose(free.log_path, [], np.random.default_rng(0), keep_measurements=True)
    log = read_log(free.log_path)
    assert r.open_loop and "open loop" in r.note and r.format().startswith("OPEN LOOP")
    assert r.detectors == free.summary.fdi_detectors and r.thresholds == free.summary.fdi_thresholds
    for mid in r.detectors:
        tp = log.topics[f"/fdi/{mid}/statistic"]
        for k in STAT_KEYS:
            assert np.array_equal(np.asarray(tp[k], dtype=float), np.asarray(r.traces[mid][k], dtype=float),
                                  equal_nan=True), (mid, k)
    assert r.alarms == free.summary.fdi_alarms and not r.detections
    assert np.array_equal(r.measurements, log.topics["/sensors/measurements"].as_array()[:, 1:])


def test_superimposed_gyro_bias_is_detected_after_its_onset_only(flights):
    free, _, _ = flights
    clean = superimpose(free.log_path, [], np.random.default_rng(0))
    r = superimpose(free.log_path, _faults(GYRO_BIAS), np.random.default_rng(0))
    assert r.faults[0]["windows_s"] == [[T_ON_S, 41.0]]
    att = r.detection("q_radps_bias", "kinematic-attitude-v1")
    assert att.detected_t_s is not None and T_ON_S <= att.detected_t_s < T_ON_S + 2.0
    assert att.isolation == "q_radps" and att.isolation_correct
    assert all(d.detected_t_s is None or d.detected_t_s >= T_ON_S for d in r.detections)
    # before the onset nothing changed: the same alarms as the fault-free replay (in light turbulence
    # the flow-angle check, calibrated on 4 short flights here, alarms on the fault-free flight too)
    assert [a for a in r.alarms if a.onset_t_s < T_ON_S] == [a for a in clean.alarms if a.onset_t_s < T_ON_S]
    for mid in r.detectors:
        before = r.t_s < T_ON_S
        assert np.array_equal(r.traces[mid]["statistic"][before], clean.traces[mid]["statistic"][before], equal_nan=True)
    assert "q_radps_bias" in r.format() and "not fed back" in r.format()
    # the bank's side of a reconfiguration is replayed (decided, listed, never fed back to the pilot)
    assert r.reconfigure and [c["sensor"] for c in r.reconfigurations] == ["q_radps"]
    off = superimpose(free.log_path, _faults(GYRO_BIAS), np.random.default_rng(0), reconfigure=False)
    assert not off.reconfigure and not off.reconfigurations
    assert off.detection("q_radps_bias", "kinematic-attitude-v1") == att


def test_against_the_same_faults_flown_in_the_loop(flights, capsys):
    free, closed, _ = flights
    faults = _faults(GYRO_BIAS + ALTIMETER_NOISE)
    r = superimpose(free.log_path, faults, loop_fault_rng(SEED), keep_measurements=True)
    cl = read_log(closed.log_path)
    # the loop's fault stream: the same random windows
    assert [f["windows_s"] for f in r.faults] == [f["windows_s"] for f in json.loads(cl.metadata["faults"]["catalog"])]
    # the measurement rows equal the closed loop's up to the onset, bit for bit; after it the flights part
    y_cl = cl.topics["/sensors/measurements"].as_array()[:, 1:]
    t = cl.topics["/sensors/measurements"].t_s
    assert np.array_equal(r.measurements[t < T_ON_S], y_cl[t < T_ON_S])
    assert not np.array_equal(r.measurements[t >= T_ON_S], y_cl[t >= T_ON_S])
    # the same fault physics: the noise samples added to the altimeter (faulty - healthy, held at
    # 40 Hz) are the loop's, to the rounding of adding them to a different altitude
    ft = cl.topics[TOPIC_FAULTS]
    i = r.fault_truth_fields.index("h_ft_noise_error")
    assert np.any(r.fault_truth[:, i] != 0.0)
    assert np.allclose(r.fault_truth[:, i], ft["h_ft_noise_error"], rtol=0.0, atol=1e-9)
    i = r.fault_truth_fields.index("q_radps_bias_error")
    assert np.allclose(r.fault_truth[t >= T_ON_S, i], np.radians(2.0), rtol=1e-12)
    # the bank's statistics agree before the onset too (same rows, same commands)
    for mid in r.detectors:
        tp = cl.topics[f"/fdi/{mid}/statistic"]
        before = r.t_s < T_ON_S
        assert np.array_equal(r.traces[mid]["statistic"][before], np.asarray(tp["statistic"])[before], equal_nan=True)
    # both detect the bias; the delays are reported, not asserted equal (open loop lacks the pilot's reaction)
    closed_det = {d.detector: d for d in closed.summary.fdi_detections if d.fault == "q_radps_bias"}
    with capsys.disabled():
        print("\nq_radps +2 deg/s at 20 s: detection delay [s], open loop (superimposed) vs closed loop (flown)")
        for mid in r.detectors:
            o, c = r.detection("q_radps_bias", mid), closed_det[mid]
            print(f"  {mid:26} open {o.delay_s if o.delay_s is None else round(o.delay_s, 2)!s:>6} ({o.isolation})"
                  f"   closed {c.delay_s if c.delay_s is None else round(c.delay_s, 2)!s:>6} ({c.isolation})")
    for d in (r.detection("q_radps_bias", "kinematic-attitude-v1"), closed_det["kinematic-attitude-v1"]):
        assert d.detected_t_s is not None and d.isolation == "q_radps"


@pytest.mark.parametrize("entry, family", [
    ({"type": "actuator-stuck-v1", "target": "elevator", "t_start_s": 20.0}, "actuator"),
    ({"type": "engine-flameout-v1", "target": "engine_0", "t_start_s": 20.0}, "engine"),
    ({"type": "icing-v1", "target": "airframe", "eta_final": 0.1, "t_start_s": 20.0}, "airframe"),
])
def test_faults_that_change_the_flight_are_refused_by_name(flights, entry, family):
    free, _, _ = flights
    ok = _faults(GYRO_BIAS)[0]
    with pytest.raises(ScenarioError) as e:
        superimpose(free.log_path, [ok, entry], np.random.default_rng(0))
    msg = str(e.value)
    assert e.value.key == "faults[1].type" and entry["type"] in msg and repr(entry["target"]) in msg
    assert f"{family} fault" in msg and "open-loop" in msg and "fdi-sim run" in msg


def test_bad_input_is_refused(flights):
    free, closed, _ = flights
    rng = np.random.default_rng(0)
    with pytest.raises(ScenarioError, match=r"faults\[0\]\.target"):  # the loader's check: not in the suite
        superimpose(free.log_path, [{**_faults(GYRO_BIAS)[0], "target": "q_rad"}], rng)
    with pytest.raises(ScenarioError, match="starts at 50"):  # after the logged flight's end
        superimpose(free.log_path, [{**_faults(GYRO_BIAS)[0], "t_start_s": 50.0}], rng)
    with pytest.raises(LogError, match="its flight had faults"):  # not healthy measurements to corrupt
        superimpose(closed.log_path, _faults(GYRO_BIAS), rng)
    with pytest.raises(ValueError, match="bank must be one of"):
        superimpose(free.log_path, [], rng, bank="mine")


def test_superimpose_study_replays_every_full_log(flights, tmp_path):
    free, _, _ = flights
    runs = tmp_path / "runs"
    runs.mkdir()
    shutil.copy(free.log_path, runs / "000003.mcap")
    (runs / "000003.json").write_text(json.dumps({"index": 3, "seed": SEED, "status": "completed",
                                                  "log": "000003.mcap", "faults": []}))
    (runs / "000004.json").write_text(json.dumps({"index": 4, "seed": 5, "status": "completed", "log": None,
                                                  "faults": []}))
    s = superimpose_study(tmp_path, _faults(GYRO_BIAS), np.random.default_rng(1))
    assert s.open_loop and [i for i, _ in s.results] == [3] and s.skipped == ((4, "no log kept"),)
    one = superimpose(free.log_path, _faults(GYRO_BIAS), np.random.default_rng(0))
    assert s.results[0][1].detections == one.detections  # a bias draws nothing: any stream gives the same
    assert s.detection_rate("kinematic-attitude-v1") == (1, 1) and len(s.delays_s("kinematic-attitude-v1")) == 1
    with pytest.raises(ScenarioError, match="actuator fault"):
        superimpose_study(tmp_path, [{"type": "actuator-stuck-v1", "target": "elevator", "t_start_s": 1.0}],
                          np.random.default_rng(1))
