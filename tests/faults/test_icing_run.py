"""Issue 3 icing bar at the scenario level: ramping eta 0 -> 0.2 on the whole DHC-6 with the
autopilot holding altitude and airspeed shows the power and angle-of-attack rise a pilot would see
(the aircraft-level bars -- trim throttle, doublet response -- are in tests/aircraft/test_icing.py)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from conftest import fly
from fdi_sim.errors import ScenarioError
from fdi_sim.scenario import from_dict


def test_icing_ramp_with_the_autopilot_holding_altitude(tmp_path: Path) -> None:
    faults = [{"type": "icing-v1", "target": "airframe", "region": "all", "eta_final": 0.2,
               "t_start_s": 10.0, "ramp_s": 40.0}]
    run = fly(tmp_path, "DHC6", faults=faults, duration_s=90.0, autopilot=True,
              initial={"h_ft": 5000.0, "vc_kts": 100.0})
    op, x, s = run["/truth/operating_point"], run["/truth/state"], run["/truth/surfaces"]
    t = op["t_s"]
    # eta in the log is the scenario's ramp, step by step
    np.testing.assert_allclose(op["icing_eta"], 0.2 * np.clip((t - 10.0) / 40.0, 0.0, 1.0), atol=1e-12)
    before, after = t < 10.0, t > 70.0
    ts = s["t_s"]
    thr0, thr1 = s["throttle_pos_norm"][ts < 10.0].mean(), s["throttle_pos_norm"][ts > 70.0].mean()
    a0, a1 = np.degrees(x["alpha_rad"][before].mean()), np.degrees(x["alpha_rad"][t > 70.0].mean())
    assert thr1 - thr0 > 0.15, (thr0, thr1)  # drag +130 % on CD0 at eta 0.2: much more power
    assert a1 - a0 > 1.5, (a0, a1)  # lift slope -30 %: a higher angle of attack for the same lift
    assert np.abs(x["h_ft"] - 5000.0).max() < 50.0  # the autopilot holds the altitude
    assert abs(x["vc_kts"][after].mean() - 100.0) < 3.0
    assert np.all(op["icing_eta"][before] == 0.0) and after.any()


def test_iced_from_the_start_trims_with_the_ice(tmp_path: Path) -> None:
    faults = [{"type": "icing-v1", "target": "airframe", "eta_final": 0.1, "t_start_s": 0.0}]
    iced = fly(tmp_path, "DHC6", faults=faults, duration_s=5.0, initial={"h_ft": 5000.0, "vc_kts": 100.0})
    clean = fly(tmp_path, "DHC6", duration_s=5.0, initial={"h_ft": 5000.0, "vc_kts": 100.0})
    assert iced["res"].summary.trim_throttle_norm > clean["res"].summary.trim_throttle_norm + 0.05
    x = iced["/truth/state"]
    assert np.abs(x["h_ft"] - x["h_ft"][0]).max() < 5.0  # trimmed with the ice on: no transient


def test_eta_beyond_the_fitted_range_is_refused() -> None:
    base = {"name": "b", "aircraft": "DHC6", "duration_s": 30.0, "initial": {"h_ft": 5000.0, "vc_kts": 100.0}}
    with pytest.raises(ScenarioError, match=r"faults\[0\]\.eta_final.*fitted.*eta_final <= 0.4"):
        from_dict({**base, "faults": [{"type": "icing-v1", "eta_final": 0.5, "t_start_s": 1.0}]}, "x.toml")
    with pytest.raises(ScenarioError, match=r"faults\[0\]\.target.*airframe"):
        from_dict({**base, "faults": [{"type": "icing-v1", "target": "wing", "eta_final": 0.1, "t_start_s": 1.0}]}, "x.toml")
