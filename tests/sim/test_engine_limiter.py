"""The engine-gauge check near the DHC-6's torque limiter, on real JSBSim flights.

The envelope development study (seed 15102) gave the check 11 false alarms in 29.6 h, all near full
power: the model's IELU torque limiter latches on one engine and not the other
(fdi_sim.detectors.engine_gauges). These development flights (seeds 910-913, fdi_sim/seeds.py:
130 KIAS at 3,500 ft in severe air, the autopilot's lever near full travel) put the check near the
limit half of the time; seed 911 is the one whose engines the limiter pulled furthest apart. The
check's statistic runs offline over each flight's logged gauges, as `fdi-sim detect` runs it."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from fdi_sim.detectors.engine_gauges import GAUGES, HYPOTHESES, EngineGaugeStream, make_engine_gauges
from fdi_sim.detectors.kinematic import MeasurementSet
from fdi_sim.detectors.samples import log_samples
from fdi_sim.detectors.stream import BlockOutputs
from fdi_sim.flightlog import read_log
from fdi_sim.scenario.loader import from_dict
from fdi_sim.training import fly

ONSET_S = 150.0


def _flight(tmp_path, fault: dict | None = None):
    d = {"name": "dhc6_full_power_development", "aircraft": "DHC6", "duration_s": 300.0, "seed": 911,
         "description": "development: DHC-6 at 130 KIAS, 3,500 ft, severe turbulence, the lever near full travel",
         "initial": {"h_ft": 3500.0, "vc_kts": 130.0, "psi_deg": 40.0}, "atmosphere": {"turbulence": "severe"}}
    if fault:
        d["faults"] = [fault]
    res = fly(from_dict(d, source="test"), tmp_path, progress=False)
    assert res.status == "completed", res.summary.reason
    return read_log(res.log_path)


def _run(stream: EngineGaugeStream, log) -> tuple[np.ndarray, BlockOutputs]:
    s = log_samples(log, MeasurementSet(output_names=GAUGES), 20.0)
    idx = [s.output_names.index(n) for n in GAUGES]
    y = np.ascontiguousarray((s.dy + s.y0)[:, idx])
    ok = np.ascontiguousarray(s.valid[:, idx])
    out = BlockOutputs.allocate(s.n, 3)
    stream.reset()
    stream.process_block(s.t_s, np.zeros((s.n, 0)), y, ok, ok, out)
    return s.t_s, out


def test_the_limiter_s_latch_is_no_engine_fault(tmp_path) -> None:
    """Fault-free: with the limiter's window the statistic stays under the design's nominal 6; the
    same check without it (no limit, no allowance) goes above 12 on this flight (measured 20.2: the
    flight does reach the latch, or the first half would prove nothing)."""
    log = _flight(tmp_path)
    me = log.topics["/sensors/measurements"]
    near = np.maximum(me["torque_0_ftlb"], me["torque_1_ftlb"]) > 1629.3 - 40.0
    assert near.mean() > 0.3  # measured 0.62
    new = make_engine_gauges(aircraft="DHC6")
    blind = EngineGaugeStream(dataclasses.replace(new.design, torque_limit_ftlb=math.inf))
    _, without = _run(blind, log)
    _, out = _run(new, log)
    assert np.nanmax(without.statistic) > 12.0
    assert np.nanmax(out.statistic) < 6.0


@pytest.mark.parametrize("engine", [0, 1])
def test_a_flameout_near_the_limit_is_caught_and_named(tmp_path, engine: int) -> None:
    """A flameout at 150 s in the same air: above 20 (over 3 x the nominal threshold) from 0.25 s on,
    for the rest of the minute, and that engine named; nothing above 6 before the onset."""
    log = _flight(tmp_path, {"type": "engine-flameout-v1", "target": f"engine_{engine}", "t_start_s": ONSET_S})
    t, out = _run(make_engine_gauges(aircraft="DHC6"), log)
    k = int(np.searchsorted(t, ONSET_S))
    assert np.nanmax(out.statistic[:k]) < 6.0
    after = slice(k + 5, k + 1200)
    assert (out.statistic[after] > 20.0).all()
    assert {HYPOTHESES[h] for h in out.hypothesis[after]} == {f"engine_{engine}"}
