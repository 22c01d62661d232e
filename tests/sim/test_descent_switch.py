"""A DHC-6 descent through two schedule switches of the gust filter, with the default bank
designed at the grid nodes as a study designs it (slow).

fdi-bench-v1 found 441 false alarms in 10.25 h of DHC-6 descents (43 per h, in all 62 descent
flights): the node at 4,000 ft was trimmed at a heading JSBSim reads as 6.2832 rad, the nodes above
at 0.0, and the bumpless transfer carried that 2 pi into the heading state, so the statistic stood
at thousands of times its threshold from the switch on. This development flight (not a benchmark
case: its own seed, heading and airspeed) reproduced it before the fix: 7 false alarms from the
switch at 288.25 s on, the first at 398 x the threshold."""
from __future__ import annotations

import pytest

from fdi_sim.flightlog import read_log
from fdi_sim.scenario.loader import from_dict
from fdi_sim.training import fly

DESCENT = {
    "name": "dhc6_descent_development", "aircraft": "DHC6", "duration_s": 600.0, "seed": 3,
    "description": "development: DHC-6 descending 7000 -> 4000 ft at 8 ft/s, 120 KIAS, moderate turbulence",
    "initial": {"h_ft": 7000.0, "vc_kts": 120.0, "psi_deg": 90.0},
    "atmosphere": {"turbulence": "moderate"},
    "fdi": {"bank": "default", "design": {"point": "grid", "turbulence": "moderate", "wind_speed_kts": 0.0,
                                          "noise_scale": 1.0}},
    "maneuvers": [{"type": "altitude-v1", "t_start_s": 15.0, "h_ft": 4000.0, "rate_fps": 8.0}],
}


@pytest.mark.slow
def test_a_descent_through_the_schedule_switches_raises_no_alarm(tmp_path):
    res = fly(from_dict(DESCENT, source="test"), tmp_path, progress=False)
    assert res.status == "completed", res.summary.reason
    st = read_log(res.log_path).topics["/fdi/kalman-gust-v1/statistic"]
    switches = int((st["point"][1:] != st["point"][:-1]).sum())
    assert switches >= 2, switches  # 8000 -> 6000 -> 4000 ft
    assert not res.summary.fdi_false_alarms, res.summary.format()
