"""Shared helpers: fly short real JSBSim runs with faults and read the logs back."""
from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from fdi_sim.flightlog import read_log
from fdi_sim.scenario import from_dict
from fdi_sim.sim import run

POINTS = {
    "f16": {"h_ft": 10000.0, "vt_kts": 400.0},
    "DHC6": {"h_ft": 5000.0, "vc_kts": 120.0},
}


def fly(tmp: Path, aircraft: str, *, faults: list[dict] = (), maneuvers: list[dict] = (), duration_s: float = 8.0,
        seed: int = 1, autopilot: bool = False, name: str = "t", sensors: dict | None = None,
        initial: dict | None = None, atmosphere: dict | None = None, may_diverge: bool = False) -> dict[str, Any]:
    """Fly a scenario built from the arguments; return the log's vector topics and the result."""
    data = {
        "name": name, "aircraft": aircraft, "duration_s": duration_s, "seed": seed,
        "initial": initial or POINTS[aircraft],
        "autopilot": {"altitude": autopilot, "airspeed": autopilot, "lateral": autopilot},
        "maneuvers": list(maneuvers), "faults": list(faults),
    }
    if sensors is not None:
        data["sensors"] = sensors
    if atmosphere is not None:
        data["atmosphere"] = atmosphere
    sc = from_dict(data)
    res = run(sc, log_path=tmp / f"{name}_{len(list(tmp.glob('*.mcap')))}.mcap", progress=False)
    assert res.status == "completed" or (may_diverge and res.status == "diverged"), res.summary.reason
    log = read_log(res.log_path)
    return {"log": log, "res": res, **{k: v for k, v in log.topics.items() if hasattr(v, "fields")}}


def doublet(axis: str, t0: float = 3.0, amp: float = 0.1, pulse_s: float = 1.0) -> dict:
    return {"type": "doublet-v1", "axis": axis, "t_start_s": t0, "amplitude_norm": amp, "pulse_s": pulse_s}


@pytest.fixture
def tmp_logs(tmp_path: Path) -> Path:
    return tmp_path


def window(t: np.ndarray, a: float, b: float) -> np.ndarray:
    return (t >= a) & (t < b)
