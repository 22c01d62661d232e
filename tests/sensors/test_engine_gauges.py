"""The DHC-6 engine gauges: Ng (N1), torque and propeller rpm per engine, as truth and as sensors.

Real JSBSim: short trimmed runs at 5000 ft / 120 KIAS. The gauges measure the engine they are
named after (index i = JSBSim ``engine[i]`` = fault target ``engine_<i>``), with the noise,
resolution and rate of ``aircraft/DHC6/sensors.toml``; sensor faults can target them.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from fdi_sim.aircraft import Aircraft, trim
from fdi_sim.aircraft.properties import ENGINE_SIGNALS, TRUTH_SIGNALS, truth_signals
from fdi_sim.errors import ScenarioError
from fdi_sim.faults.quantities import native_unit
from fdi_sim.flightlog import read_log
from fdi_sim.scenario import from_dict
from fdi_sim.sensors import load_suite
from fdi_sim.training import fly

GAUGES = ("n1_0_pct", "n1_1_pct", "torque_0_ftlb", "torque_1_ftlb", "prop_0_rpm", "prop_1_rpm")
POINT = {"h_ft": 5000.0, "vc_kts": 120.0}
#: horsepower -> ft lbf / s
FTLBPS_PER_HP = 550.0


def _fly(tmp: Path, name: str, *, faults: list[dict] = (), duration_s: float = 6.0, seed: int = 1) -> dict:
    sc = from_dict({"name": name, "aircraft": "DHC6", "duration_s": duration_s, "seed": seed, "initial": POINT,
                    "autopilot": {"altitude": False, "airspeed": False, "lateral": False}, "faults": list(faults)})
    res = fly(sc, log_path=tmp / f"{name}.mcap", progress=False)
    assert res.status == "completed", res.summary.reason
    log = read_log(res.log_path)
    return {"path": res.log_path, "truth": log.topics["/truth/state"], "meas": log.topics["/sensors/measurements"],
            "faults": log.topics.get("/faults/active")}


def test_truth_signals_are_per_aircraft() -> None:
    assert truth_signals("f16") == TRUTH_SIGNALS  # the F-16's truth state is unchanged
    dhc6 = truth_signals("DHC6")
    assert dhc6[:len(TRUTH_SIGNALS)] == TRUTH_SIGNALS  # common indexes do not depend on the aircraft
    assert dhc6[len(TRUTH_SIGNALS):] == ENGINE_SIGNALS["DHC6"] == GAUGES
    assert [native_unit(n) for n in GAUGES] == ["pct", "pct", "ftlb", "ftlb", "rpm", "rpm"]
    assert {s.name for s in load_suite("DHC6")} >= set(GAUGES)
    assert not {s.name for s in load_suite("f16")} & set(GAUGES)


def test_gauges_read_the_engines_at_the_trim() -> None:
    ac = Aircraft("DHC6")
    trim(ac, from_dict({"name": "g", "aircraft": "DHC6", "duration_s": 1.0, "initial": POINT}).operating_point())
    for _ in range(12):
        ac.step()
    got = dict(zip(GAUGES, ac.list_reader(GAUGES)()))
    for i in range(2):
        e = f"propulsion/engine[{i}]/"
        assert got[f"n1_{i}_pct"] == ac[e + "n1"] and 85.0 < got[f"n1_{i}_pct"] < 100.0
        assert got[f"prop_{i}_rpm"] == ac[e + "propeller-rpm"] and 1200.0 < got[f"prop_{i}_rpm"] < 1700.0
        # torque = shaft power / propeller angular speed at steady rpm: 550 P_hp / (2 pi rpm / 60)
        shaft_ftlb = FTLBPS_PER_HP * ac[e + "power-hp"] / (got[f"prop_{i}_rpm"] * 2.0 * math.pi / 60.0)
        assert got[f"torque_{i}_ftlb"] == pytest.approx(shaft_ftlb, rel=1e-3)
        assert 900.0 < got[f"torque_{i}_ftlb"] < 1628.0  # below the PT6A-27 limit


def test_each_gauge_measures_its_own_engine(tmp_path: Path) -> None:
    # left engine (engine_0) flames out at 1 s: its Ng and torque fall, the right engine's do not
    r = _fly(tmp_path, "flameout", faults=[{"type": "engine-flameout-v1", "target": "engine_0", "t_start_s": 1.0}])
    x, y = r["truth"], r["meas"]
    before, late = x["t_s"] < 1.0, x["t_s"] > 5.0
    for name in ("n1_0_pct", "torque_0_ftlb"):
        assert x[name][late].mean() < 0.8 * x[name][before].mean(), name
        assert y[name][late].mean() < 0.8 * y[name][before].mean(), name
    for name in ("n1_1_pct", "torque_1_ftlb"):
        assert x[name][late].mean() > 0.9 * x[name][before].mean(), name


def test_gauge_noise_resolution_and_rate(tmp_path: Path) -> None:
    r = _fly(tmp_path, "noise", duration_s=10.0, seed=4)
    x, y = r["truth"], r["meas"]
    specs = {s.name: s for s in load_suite("DHC6")}
    k = np.arange(len(y["t_s"]))
    for name in GAUGES:
        s = specs[name]
        assert s.rate_hz == 20.0
        sampled = k % 6 == 0  # 20 Hz of the 120 Hz loop: sample, then hold
        held = y[name][~sampled] == y[name][np.flatnonzero(~sampled) // 6 * 6]
        assert held.all(), name
        q = y[name][sampled] / s.quantum
        np.testing.assert_allclose(q, np.round(q), atol=1e-6, err_msg=name)  # on the resolution grid
        err = y[name][sampled] - x[name][sampled]
        # white noise plus uniform rounding error: std = sqrt(sigma^2 + quantum^2 / 12); 200 samples
        want = math.sqrt(s.noise_std ** 2 + s.quantum ** 2 / 12.0)
        assert 0.8 * want < err.std() < 1.2 * want, (name, err.std(), want)
        assert abs(err.mean()) < 4.0 * s.bias_std + 4.0 * want / math.sqrt(err.size), name  # the turn-on offset


def test_sensor_bias_on_ng(tmp_path: Path) -> None:
    fault = {"type": "sensor-bias-v1", "target": "n1_1_pct", "bias_pct": 2.0, "t_start_s": 3.0}
    r = _fly(tmp_path, "bias", faults=[fault], duration_s=6.0)
    x, y, f = r["truth"], r["meas"], r["faults"]
    t = x["t_s"]
    err1 = y["n1_1_pct"] - x["n1_1_pct"]
    err0 = y["n1_0_pct"] - x["n1_0_pct"]
    pre, post = (t > 0.5) & (t < 3.0), t > 3.1  # after the first 20 Hz sample of the fault
    assert err1[post].mean() - err1[pre].mean() == pytest.approx(2.0, abs=0.1)
    assert abs(err0[post].mean() - err0[pre].mean()) < 0.1  # the other engine's gauge is untouched
    np.testing.assert_array_equal(f["n1_1_pct_bias_active"], (t >= 3.0 - 1e-9).astype(float))
    np.testing.assert_allclose(f["n1_1_pct_bias_error"][t >= 3.0 - 1e-9], 2.0, atol=1e-12)


def test_a_gauge_fault_in_a_wrong_unit_names_the_fix() -> None:
    fault = {"type": "sensor-bias-v1", "target": "torque_0_ftlb", "bias_pct": 2.0, "t_start_s": 1.0}
    with pytest.raises(ScenarioError, match="bias_ftlb"):
        from_dict({"name": "u", "aircraft": "DHC6", "duration_s": 2.0, "initial": POINT, "faults": [fault]})


def test_same_seed_same_bytes_with_the_gauges(tmp_path: Path) -> None:
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    a = _fly(tmp_path / "a", "same", duration_s=2.0, seed=9)
    b = _fly(tmp_path / "b", "same", duration_s=2.0, seed=9)
    assert set(GAUGES) <= set(a["meas"].fields) and set(GAUGES) <= set(a["truth"].fields)
    assert Path(a["path"]).read_bytes() == Path(b["path"]).read_bytes()
