"""Issue 13's bars on the shipped scenarios: every fault scenario, flown with the default bank as
shipped, is detected and isolated by at least one detector with no alarm before the fault; the
default bank raises no alarm on fault-free flights it was not calibrated on (slow)."""
from __future__ import annotations

from pathlib import Path

import pytest

from fdi_sim.scenario import load
from fdi_sim.training import fly
from fdi_sim.study.bank_false_alarms import HELD_OUT_SEEDS, POINTS, study_point

ROOT = Path(__file__).resolve().parents[2]
DEPARTS = {"f16_stuck_elevator"}
FAULT_SCENARIOS = sorted(p.stem for p in (ROOT / "scenarios").glob("*.toml") if load(p).faults)


#: shipped faults the default bank does not isolate at the atlas node (issue 24): none. The DHC-6
#: flameout at 5000 ft / 110 KCAS is designed at the node 4000 ft / 112 kt, where the gust filter names
#: it nx_g instead of the throttle (the two signatures are nearly collinear in a 1 s window: cosines at
#: the alarm nx_g 0.944, throttle 0.940); the engine-gauge check, in the DHC-6 default bank since it
#: allows for the torque limiter, names the engine (test_the_engine_gauges_name_the_flameout).
NOT_ISOLATED_AT_THE_NODE: set[str] = set()


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.xfail(strict=True, reason="isolated wrongly at "
                                                                          "the atlas node: see NOT_ISOLATED_AT_THE_NODE"))
                                  if n in NOT_ISOLATED_AT_THE_NODE else n for n in FAULT_SCENARIOS])
def test_shipped_fault_scenario_detected_and_isolated(tmp_path, name):
    sc = load(ROOT / "scenarios" / f"{name}.toml")
    assert sc.model.fdi.bank == "default"  # shipped with the bank a new user gets
    res = fly(sc, tmp_path, progress=False)
    s = res.summary
    # the F-16 departs without a moving stabilator (the scenario says so): the log ends 'diverged'
    assert res.status == ("diverged" if name in DEPARTS else "completed"), s.reason
    assert not s.fdi_false_alarms, s.format()  # no alarm before the onset (or outside the fault)
    hits = [d for d in s.fdi_detections if d.detected_t_s is not None]
    assert hits, s.format()
    if all(d.target == "airframe" for d in hits):  # icing: no bank has an icing hypothesis
        return
    assert any(d.isolation_correct for d in hits), s.format()
    right = [d for d in hits if d.isolation_correct]
    assert min(d.delay_s for d in right) < 120.0  # the slowest, the pitot drift at 0.1 kt/s, takes 105 s


@pytest.mark.slow
@pytest.mark.parametrize("name", [n for names in POINTS.values() for n in names])
def test_no_false_alarm_on_held_out_fault_free_flights(name):
    """8 held-out seeds x 10 minutes in moderate turbulence per scenario point: no alarm (measured
    with the episode-rate thresholds: 0 in 48 flights, 8.0 h, 0 per h [0, 0.46] against the design 0.1,
    on seeds 301-308, docs/card/bank_false_alarms.json;
    the per-sample thresholds before raised one, DHC-6 approach seed 204, docs/bank.md)."""
    r = study_point(name, HELD_OUT_SEEDS, 600.0, progress=False)
    assert r.statuses == {"completed": len(HELD_OUT_SEEDS)}
    assert r.false_alarms == 0, r.first_alarms


@pytest.mark.slow
def test_gain_scheduling_lowers_the_false_alarms_through_a_climb():
    """f16_climb_accelerate (10 kft / 300 KCAS to 16 kft / 340 KCAS), held-out seeds 201-208: the
    scheduled filter (a design per point, each calibrated at its point) raises fewer alarms than the
    initial point's design alone, through the same kernel and decision."""
    from fdi_sim.study.scheduling import compare

    r = compare("f16_climb_accelerate", progress=False)
    assert len(r.points) >= 3
    assert r.scheduled_onsets < r.single_onsets, r


def test_the_engine_gauges_name_the_flameout(tmp_path) -> None:
    """The DHC-6 flameout as shipped, with the engine-gauge check added (``[[detectors]]``; its
    thresholds trained on the scenario's flights): it names the left engine within 0.5 s of the
    onset (the torque falls by about 1,000 lbf ft in 0.05 s)."""
    import json

    from fdi_sim.scenario.loader import from_dict

    d = json.loads(load(ROOT / "scenarios" / "dhc6_engine_flameout.toml").to_json())
    d["detectors"] = [{"type": "engine-gauges-v1"}]
    s = fly(from_dict(d, source="dhc6_engine_flameout + engine-gauges-v1"), tmp_path, progress=False).summary
    d = next(d for d in s.fdi_detections if d.detector == "engine-gauges-v1")
    assert d.isolation == "engine_0" and d.isolation_correct, s.format()
    assert d.delay_s is not None and d.delay_s < 0.5, s.format()
