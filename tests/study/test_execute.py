"""Studies flown for real: JSBSim runs on a local Dask cluster, stored, resumed, flown again alone.

Issue 14's bars: a 200-run fault-free DHC-6 study and a 200-run F-16 detection study complete
(short runs); the same study on 1 worker and on 2 gives identical per-run results; any run flies
again alone from its scenario file with `fdi-sim run`; bad input is refused before anything flies.
"""
from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from fdi_sim.errors import StudyError
from fdi_sim.study.execute import TIMING_KEYS, done_runs, fly_study, load_records
from fdi_sim.study.spec import load_study

DHC6_FA = """
kind = "study"
name = "t_dhc6_fa"
scenario = "dhc6_cruise_doublets"
seed = 5
runs = {runs}
duration_s = 20.0
[sample]
"initial.h_ft" = {{ uniform = [5200.0, 6800.0] }}
"initial.vc_kts" = {{ uniform = [118.0, 130.0] }}
"atmosphere.turbulence" = {{ choice = ["light", "moderate"] }}
"atmosphere.wind_speed_kts" = {{ uniform = [0.0, 15.0] }}
"atmosphere.wind_from_deg" = {{ uniform = [0.0, 360.0] }}
"sensors.noise_scale" = {{ normal = [1.0, 0.1], min = 0.6 }}
[bank]
bank = "default"
far_per_h = 0.5
calibration_flights = 6
calibration_duration_s = 60.0
design = {{ point = "grid", turbulence = "moderate", wind_speed_kts = 0.0, noise_scale = 1.0 }}
"""

F16_DET = """
kind = "study"
name = "t_f16_det"
scenario = "f16_cruise_doublets"
seed = 9
runs = {runs}
duration_s = 25.0
[sample]
"initial.h_ft" = {{ uniform = [9000.0, 11000.0] }}
"atmosphere.turbulence" = {{ choice = ["light", "moderate"] }}
[[faults]]
type = "sensor-bias-v1"
target = {{ choice = ["q_radps", "p_radps", "r_radps"] }}
bias_degps = {{ uniform = [0.5, 3.0] }}
t_start_s = {{ uniform = [8.0, 12.0] }}
[[faults]]
type = "sensor-drift-v1"
target = "vc_kts"
drift_ktps = {{ uniform = [0.5, 2.0] }}
t_start_s = {{ uniform = [8.0, 12.0] }}
[[faults]]
type = "actuator-float-v1"
target = "aileron"
tau_s = 0.3
t_start_s = {{ uniform = [8.0, 12.0] }}
[bank]
bank = "default"
calibration_flights = 6
calibration_duration_s = 60.0
design = {{ point = "grid", turbulence = "moderate" }}
"""


def _results(recs: list[dict]) -> list[dict]:
    """Records without how they were flown (wall time, worker): what must not depend on it."""
    return [{k: v for k, v in r.items() if k not in TIMING_KEYS} for r in recs]


@pytest.fixture(scope="module")
def cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("cache")


@pytest.fixture(scope="module")
def env(cache: Path):
    mp = pytest.MonkeyPatch()
    mp.setenv("FDI_SIM_CACHE", str(cache))  # inherited by the cluster's worker processes
    yield
    mp.undo()


def _study(tmp: Path, text: str, runs: int) -> Path:
    p = tmp / f"study_{runs}.toml"
    p.write_text(text.format(runs=runs))
    return p


@pytest.fixture(scope="module")
def dhc6(env, tmp_path_factory: pytest.TempPathFactory):
    tmp = tmp_path_factory.mktemp("dhc6")
    st = load_study(_study(tmp, DHC6_FA, 200))
    t0 = time.perf_counter()
    o = fly_study(st, tmp / "out", workers=2, progress=False)
    return st, o, tmp / "out", time.perf_counter() - t0


@pytest.fixture(scope="module")
def f16(env, tmp_path_factory: pytest.TempPathFactory):
    tmp = tmp_path_factory.mktemp("f16")
    st = load_study(_study(tmp, F16_DET, 200))
    o = fly_study(st, tmp / "out", workers=2, progress=False)
    return st, o, tmp / "out"


def test_dhc6_false_alarm_study_completes(dhc6) -> None:
    st, o, out, wall = dhc6
    recs = load_records(out)
    assert o.complete and o.flown == 200 and o.lost == 0 and not o.interrupted
    assert [r["index"] for r in recs] == list(range(200))
    assert all(r["status"] == "completed" for r in recs), {r["status"] for r in recs}
    assert len({r["seed"] for r in recs}) == 200
    # the sampled values follow their distributions (200 draws)
    h = np.array([r["params"]["initial.h_ft"] for r in recs])
    assert 5200.0 <= h.min() and h.max() <= 6800.0 and abs(h.mean() - 6000.0) < 120.0
    turb = [r["params"]["atmosphere.turbulence"] for r in recs]
    assert 70 < turb.count("moderate") < 130
    # every run has its statistics log and its scenario file
    for r in recs[:5]:
        assert (out / "runs" / r["log"]).stat().st_size > 10_000
        assert (out / "runs" / r["scenario"]).is_file()
    assert sum(r["flight_h"] for r in recs) == pytest.approx(200 * 20.0 / 3600.0)
    assert not recs[0]["faults"] and recs[0]["detectors"][0] == "kalman-gust-v1"


def test_f16_detection_study_completes(f16) -> None:
    st, o, out = f16
    recs = load_records(out)
    assert o.complete and len(recs) == 200
    types = {r["faults"][0]["type"] for r in recs}
    assert types == {"sensor-bias-v1", "sensor-drift-v1", "actuator-float-v1"}
    assert all(r["detections"] for r in recs if r["status"] == "completed")
    detected = [any(d["detected_t_s"] is not None for d in r["detections"]) for r in recs]
    assert np.mean(detected) > 0.5  # the bank sees most of these faults (sizes reach the shipped ones)
    for r in recs:  # no detection before the fault (a first alarm there is a false alarm)
        for d in r["detections"]:
            if d["detected_t_s"] is not None:
                assert d["detected_t_s"] >= d["onset_t_s"] - 1e-9


def test_resume_flies_nothing_twice(dhc6) -> None:
    st, o, out, _ = dhc6
    before = {p.name: p.stat().st_mtime_ns for p in (out / "runs").iterdir()}
    o2 = fly_study(st, out, workers=1, progress=False)
    assert o2.done_before == 200 and o2.flown == 0
    assert {p.name: p.stat().st_mtime_ns for p in (out / "runs").iterdir()} == before


def test_one_worker_equals_two(dhc6, tmp_path: Path) -> None:
    """The first 24 runs on one worker equal the same runs of the 200-run study on two."""
    st, _, out, _ = dhc6
    small = st.with_overrides(runs=24)
    # a smaller run count is the same study (the identity leaves out the count): a new folder
    o = fly_study(small, tmp_path / "one", workers=1, progress=False)
    assert o.flown == 24
    one = _results(load_records(tmp_path / "one"))
    two = _results(load_records(out)[:24])
    assert one == two
    assert {r["worker"] for r in load_records(out)[:24]} != {"local"}
    # and the statistics logs are the same bits
    for i in (0, 7, 23):
        a = (tmp_path / "one" / "runs" / f"{i:06d}.mcap").read_bytes()
        b = (out / "runs" / f"{i:06d}.mcap").read_bytes()
        assert a == b


def test_a_run_flies_again_alone(f16, tmp_path: Path) -> None:
    """`fdi-sim run DIR/runs/N.toml` flies the run again (full log) with the same alarms."""
    from fdi_sim.flightlog import read_log

    _, _, out = f16
    recs = load_records(out)
    r = next(r for r in recs if r["alarms"])
    log = tmp_path / "again.mcap"
    cp = subprocess.run([sys.executable, "-m", "fdi_sim.cli", "run", str(out / "runs" / r["scenario"]), "--log",
                         str(log), "--quiet"], capture_output=True, text=True, timeout=300)
    assert cp.returncode in (0, 1), cp.stderr
    lg = read_log(log)
    assert "/truth/state" in lg.topics  # a normal, full log
    ev = lg.topics["/fdi/alarms"].events
    onsets = sorted((e.payload["detector"], round(e.t_s, 9)) for e in ev
                    if e.payload["alarm"] and e.payload.get("event") != "isolated")
    want = sorted((a["detector"], round(a["onset_t_s"], 9)) for a in r["alarms"])
    assert onsets == want
    stored = read_log(out / "runs" / r["log"])
    for det in r["detectors"]:
        topic = f"/fdi/{det}/statistic"
        np.testing.assert_array_equal(lg.topics[topic]["statistic"], stored.topics[topic]["statistic"])


# --- bad input: refused before anything flies -------------------------------------------------------
def test_empty_distribution_is_refused(tmp_path: Path) -> None:
    p = _study(tmp_path, DHC6_FA.replace('{{ choice = ["light", "moderate"] }}', "{{ choice = [] }}"), 10)
    with pytest.raises(StudyError) as e:
        load_study(p)
    assert str(p) in str(e.value) and "sample.atmosphere.turbulence" in str(e.value) and "empty" in str(e.value)
    p = _study(tmp_path, DHC6_FA.replace("uniform = [5200.0, 6800.0]", "uniform = [6800.0, 5200.0]"), 11)
    with pytest.raises(StudyError, match=r"sample\.initial\.h_ft.*empty"):
        load_study(p)


def test_misspelt_key_and_out_of_range_value_are_named(tmp_path: Path) -> None:
    p = _study(tmp_path, DHC6_FA.replace("duration_s = 20.0", "duration_sec = 20.0"), 12)
    with pytest.raises(StudyError, match="duration_sec"):
        load_study(p)
    p = _study(tmp_path, DHC6_FA.replace("uniform = [5200.0, 6800.0]", "uniform = [100.0, 200.0]"), 13)
    with pytest.raises(StudyError, match=r"sample\.initial\.h_ft"):
        load_study(p)
    p = _study(tmp_path, DHC6_FA.replace("far_per_h = 0.5", "far_per_hour = 0.5"), 14)
    with pytest.raises(StudyError, match=r"bank\.far_per_hour"):
        load_study(p)


def test_unreachable_scheduler_fails_within_seconds(tmp_path: Path) -> None:
    st = load_study(_study(tmp_path, DHC6_FA, 4))
    t0 = time.perf_counter()
    with pytest.raises(StudyError, match="no Dask scheduler answers"):
        fly_study(st, tmp_path / "out", scheduler="tcp://127.0.0.1:9", progress=False)
    assert time.perf_counter() - t0 < 20.0
    assert not done_runs(tmp_path / "out")


def test_folder_of_another_study_is_refused(dhc6, tmp_path: Path) -> None:
    _, _, out, _ = dhc6
    other = load_study(_study(tmp_path, DHC6_FA.replace("seed = 5", "seed = 6"), 200))
    with pytest.raises(StudyError, match="not of 't_dhc6_fa'|would mix"):
        fly_study(other, out, workers=1, progress=False)
    assert len(done_runs(out)) == 200
    other_dur = load_study(_study(tmp_path, DHC6_FA, 200)).with_overrides(duration_s=30.0)
    with pytest.raises(StudyError, match="would mix"):
        fly_study(other_dur, out, workers=1, progress=False)


def test_study_that_needs_more_disk_than_free_is_refused(tmp_path: Path) -> None:
    text = DHC6_FA.replace("[bank]", "[output]\nfull_logs = true\n[bank]").replace("duration_s = 20.0",
                                                                                      "duration_s = 36000.0")
    st = load_study(_study(tmp_path, text, 10_000))
    with pytest.raises(StudyError, match=r"output\.full_logs.*GB"):
        fly_study(st, tmp_path / "out", workers=1, progress=False)
    assert not done_runs(tmp_path / "out")


def test_the_disk_check_log_sizes_are_what_a_run_writes(tmp_path: Path) -> None:
    """The bytes per flight hour the disk check and the help texts use (spec.STATISTICS_BYTES_PER_H,
    spec.FULL_LOG_BYTES_PER_H) against one flown 60-s DHC-6 run with the default bank: each size must
    cover the measured one within the check's margin (never refuse too little) and not exceed it
    2-fold (never refuse a study that fits)."""
    from fdi_sim.study.execute import DISK_MARGIN
    from fdi_sim.units import S_PER_H
    from fdi_sim.study.spec import FULL_LOG_BYTES_PER_H, STATISTICS_BYTES_PER_H

    measured_bytes_per_h = {}
    for full, budget_bytes_per_h in ((False, STATISTICS_BYTES_PER_H), (True, FULL_LOG_BYTES_PER_H)):
        text = DHC6_FA.replace("duration_s = 20.0", "duration_s = 60.0")
        if full:
            text = text.replace("[bank]", "[output]\nfull_logs = true\n[bank]")
        (tmp_path / str(full)).mkdir()
        st = load_study(_study(tmp_path / str(full), text, 1))
        out = tmp_path / f"out_{full}"
        fly_study(st, out, workers=1, progress=False)
        (log,) = (out / "runs").glob("*.mcap")
        bytes_per_h = log.stat().st_size / (st.model.duration_s / S_PER_H)
        measured_bytes_per_h[full] = bytes_per_h
        assert bytes_per_h <= budget_bytes_per_h * DISK_MARGIN, (full, bytes_per_h, budget_bytes_per_h)
        assert budget_bytes_per_h <= 2.0 * bytes_per_h, (full, bytes_per_h, budget_bytes_per_h)
    assert measured_bytes_per_h[True] > 10 * measured_bytes_per_h[False]


def test_cli_json(dhc6, tmp_path: Path) -> None:
    """`fdi-sim study --json` on a finished study: the statistics as one JSON object."""
    st, _, out, _ = dhc6
    cp = subprocess.run([sys.executable, "-m", "fdi_sim.cli", "study", st.source, "--out", str(out), "--json",
                         "--quiet", "--no-report"], capture_output=True, text=True, timeout=300)
    assert cp.returncode == 0, cp.stderr
    s = json.loads(cp.stdout)
    assert s["runs"] == 200 and s["flight_h"] == pytest.approx(200 * 20 / 3600)
    ids = [d["id"] for d in s["detectors"]]
    assert "kalman-gust-v1" in ids
    for d in s["detectors"]:
        for k in ("false_alarms", "far_per_h", "far_per_h_ci", "p_detect", "delay_s_median", "delay_s_p95", "confusion"):
            assert k in d
        lo, hi = d["far_per_h_ci"]
        assert lo <= d["far_per_h"] <= hi
    recs = load_records(out)
    for d in s["detectors"]:
        assert d["false_alarms"] == sum(1 for r in recs for a in r["false_alarms"] if a["detector"] == d["id"])


def test_shipped_studies_load_and_share_designs() -> None:
    """Every shipped study is valid, and its runs need few bank designs (grid nodes), not one each."""
    from fdi_sim.scenario.shipped import list_studies
    from fdi_sim.study.spec import design_groups

    studies = list(list_studies())
    assert len(studies) >= 5
    for entry in studies:
        path = getattr(entry, "path", entry)
        st = load_study(path)
        n = min(st.n_runs, 300)
        groups, _ = design_groups([st.run_scenario(i)[0] for i in range(n)])
        # a design per grid node of the sampled envelope, shared by the runs in it: at most one per
        # 6 runs, or one per node of the widest shipped envelope (the DHC-6 atlas's 2-8 kft x 95-135
        # KCAS: 44 nodes of 2000 ft x 4 kt); one design per run would be 300
        assert len(groups) <= max(n // 6, 44), (st.name, len(groups), n)


def test_replay_at_the_study_threshold_gives_the_runs_alarms(dhc6, f16) -> None:
    """Re-scoring the stored statistics at the runs' own thresholds and rule gives exactly the
    alarm episodes the bank raised in the loop, on both 200-run studies."""
    from fdi_sim.study.rescore import check_replay

    n_alarms = 0
    for _, _, out, *_ in (dhc6, f16):
        recs = load_records(out)
        n_alarms += sum(len(r["alarms"]) for r in recs)
        assert check_replay(recs, out) == []
    # something to compare: the detection study's faults (the fault-free study may raise none: with
    # the episode-rate thresholds its 200 short runs measured 0)
    assert n_alarms > 0


@pytest.mark.parametrize("target", [10.0, 40.0])
@pytest.mark.parametrize("detector", ["kalman-gust-v1", "bank", "kinematic-attitude-v1"])
def test_threshold_calibrated_on_half_gives_the_target_on_the_other_half(dhc6, detector: str, target: float) -> None:
    """Issue 14's self-consistency bar: a threshold set to a target false-alarm rate on the even
    runs gives on the odd runs the rate the calibration predicts: the ratio of the held-out rate to
    the calibration half's, with its exact conditional interval scaled by the per-run dispersion,
    holds 1.

    Why not the held-out interval alone (``target_inside``): measured on this study (session 9), at
    10 per h the calibration rests on 4 alarms per half, and the attitude check's alarms come from
    the runs with the largest sampled sensor noise (noise_scale >= 1.05: 18 of 20 alarms at the
    even-half scale, none below 0.95; turbulence light or moderate made no difference). Calibrated
    on the even runs, the odd ones gave 15 (36 per h [15.9, 70.0]); calibrated on the odd runs, the
    even ones gave 1: the halves differ by their noisiest runs, and the threshold carries the
    calibration half's sampling error. 40 per h puts about 16 alarms in each half."""
    from fdi_sim.study.calibration import check_calibration

    _, _, out, _ = dhc6
    recs = load_records(out)
    chk = check_calibration(recs, out, detector, target)
    print(f"{detector}: target {target} per h: scale {chk.calibration.scale:.3f} on the even runs "
          f"({chk.calibration_false_alarms} alarms); odd runs {chk.false_alarms} in {chk.exposure_h:.3f} h = "
          f"{chk.far_per_h:.2f} per h [{chk.far_per_h_ci[0]:.2f}, {chk.far_per_h_ci[1]:.2f}]; ratio {chk.rate_ratio:.2f} "
          f"[{chk.rate_ratio_ci[0]:.2f}, {chk.rate_ratio_ci[1]:.2f}]")
    assert chk.calibration_false_alarms <= target * chk.calibration.exposure_h  # the calibration met its target
    assert chk.calibration_false_alarms >= 0.5 * target * chk.calibration.exposure_h  # and rests on alarms
    assert chk.ratio_check == "consistent", chk


@pytest.mark.parametrize("detector", ["kalman-gust-v1", "kinematic-attitude-v1"])
def test_tail_calibration_on_half_is_not_beaten_on_the_other_half(dhc6, detector: str) -> None:
    """The calibration a thresholds file uses (``tail_calibrate_threshold``: the episode peaks'
    tail at its 95 % bound) at a target the half's count cannot resolve by itself (10 per h on
    0.55 h: 5.5 alarms, below the 10 an empirical level needs, so the tail is extrapolated): the
    held-out rate is not significantly above the target, and the two halves agree."""
    from fdi_sim.study.calibration import check_calibration, tail_calibrate_threshold

    _, _, out, _ = dhc6
    recs = load_records(out)
    target = 10.0
    cal = tail_calibrate_threshold([r for r in recs if r["index"] % 2 == 0], out, detector, target,
                                   np.random.default_rng(1))
    chk = check_calibration(recs, out, detector, target, calibration=cal)
    print(f"{detector}: {cal.method}; scale {cal.scale:.3f}, even {cal.false_alarms} alarms, odd "
          f"{chk.false_alarms} in {chk.exposure_h:.3f} h = {chk.far_per_h:.2f} per h "
          f"[{chk.far_per_h_ci[0]:.2f}, {chk.far_per_h_ci[1]:.2f}]")
    assert cal.method.startswith("episode tail") and "GPD" in cal.method  # extrapolated, not the count
    assert chk.calibration_false_alarms == cal.false_alarms  # the check counts what the calibration counted
    assert chk.far_per_h_ci[0] <= target, chk
    assert chk.ratio_check == "consistent", chk
