"""Trim both aircraft and hold with fixed controls (issue 2, first bar); bad operating points."""
from __future__ import annotations

import numpy as np
import pytest

from fdi_sim.aircraft import Aircraft, UnknownAircraftError, trim
from fdi_sim.errors import TrimError
from fdi_sim.operating_point import OperatingPoint


@pytest.mark.parametrize("op", [
    OperatingPoint("f16", 10000.0, vt_kts=400.0),
    OperatingPoint("DHC6", 5000.0, vc_kts=120.0),
], ids=lambda op: op.aircraft)
def test_trim_then_120s_fixed_controls_holds(op: OperatingPoint) -> None:
    """Bar: within 30 ft of the initial altitude and 2 ft/s of airspeed over 120 s, no turbulence."""
    ac = Aircraft(op.aircraft)
    tr = trim(ac, op)
    assert tr.residual < 1e-2
    h0, v0 = ac.get("h_ft"), ac.get("vt_fps")
    read = ac.reader(["h_ft", "vt_fps"])
    dev = np.zeros((int(120.0 / ac.dt_s), 2))
    for k in range(dev.shape[0]):
        assert ac.step()
        dev[k] = read() - (h0, v0)
    max_dh, max_dv = np.abs(dev).max(axis=0)
    assert max_dh < 30.0, f"altitude wandered {max_dh:.1f} ft"
    assert max_dv < 2.0, f"airspeed wandered {max_dv:.2f} ft/s"


def test_dhc6_trim_uses_running_engine_torque() -> None:
    """The running trim balances the propeller torque: bank stays small with fixed controls (JSBSIM_NOTES 2.2)."""
    ac = Aircraft("DHC6")
    tr = trim(ac, OperatingPoint("DHC6", 5000.0, vc_kts=120.0))
    assert tr.method == "running"
    assert abs(np.degrees(tr.beta_rad) + 0.3) < 0.05
    for _ in range(int(60 / ac.dt_s)):
        ac.step()
    assert abs(ac.get("phi_rad")) < np.radians(2.0)


def test_f16_turn_trim_holds_turn_rate() -> None:
    """30 deg turn: rate g tan(phi)/V within 2 %; works because the overlay fixes the yaw-PID output bug."""
    ac = Aircraft("f16")
    tr = trim(ac, OperatingPoint("f16", 10000.0, vt_kts=400.0, phi_deg=30.0))
    psi = []
    for _ in range(int(20 / ac.dt_s)):
        ac.step()
        psi.append(ac["attitude/psi-rad"])
    rate = np.mean(np.diff(np.unwrap(psi))) / ac.dt_s
    assert rate == pytest.approx(tr.psidot_radps, rel=0.02)


def test_untrimmable_point_raises_with_reason() -> None:
    """DHC-6 at 150 KIAS / 5000 ft is beyond its thrust (JSBSIM_NOTES 2.1)."""
    ac = Aircraft("DHC6")
    with pytest.raises(TrimError) as ei:
        trim(ac, OperatingPoint("DHC6", 5000.0, vc_kts=150.0))
    assert "DHC6" in str(ei.value) and "150" in str(ei.value)
    # the Newton search stops at its fixed point (throttle clipped at full) and names the cause
    assert "throttle_cmd_norm = 1.000 at its limit" in ei.value.reason


def test_unknown_aircraft() -> None:
    with pytest.raises(UnknownAircraftError, match="known: f16, DHC6"):
        Aircraft("f15")
