"""Pilot: maneuver tables and the reset contract (no JSBSim: the pilot is pure arithmetic on measurements)."""
from __future__ import annotations

import numpy as np
import pytest

from fdi_sim.aircraft import TRUTH_SIGNALS
from fdi_sim.pilot import maneuvers as m
from fdi_sim.pilot.autopilot import AutopilotGains, AutopilotModes, Pilot, TrimPoint

TRIM = TrimPoint(0.0, 0.0, -0.07, 0.8, 0.05, 0.0, 0.0, 5000.0, 120.0)
DT = 1.0 / 120.0


def _pilot(maneuvers: list) -> Pilot:
    return Pilot(AutopilotGains.for_aircraft("DHC6"), AutopilotModes(), TRIM, maneuvers, TRUTH_SIGNALS, DT)


def _fly(p: Pilot, n: int) -> np.ndarray:
    """Feed a slowly turning, trimmed measurement vector; return the commands."""
    y = np.zeros(len(TRUTH_SIGNALS))
    i = {name: TRUTH_SIGNALS.index(name) for name in ("h_ft", "vc_kts", "theta_rad", "nz_g", "psi_rad", "phi_rad")}
    y[i["h_ft"]], y[i["vc_kts"]], y[i["theta_rad"]], y[i["nz_g"]] = 5000.0, 120.0, 0.05, -1.0
    out = []
    for k in range(n):
        y[i["psi_rad"]] = 0.002 * k  # heading creeps, so leaving the turn captures a new heading
        y[i["phi_rad"]] = 0.3 if 120 <= k < 240 else 0.0
        c = p.step(k * DT, y)
        out.append((c.elevator_cmd_norm, c.aileron_cmd_norm, c.rudder_cmd_norm, c.throttle_cmd_norm, c.psi_ref_rad))
    return np.array(out)


def test_reset_replays_identically_after_a_turn_and_heading_change() -> None:
    mans = [m.turn(m.TurnParams(type="turn-v1", t_start_s=1.0, phi_deg=20.0, duration_s=1.0)),
            m.heading(m.HeadingParams(type="heading-v1", t_start_s=0.25, psi_deg=30.0)),
            m.doublet(m.PulseTrainParams(type="doublet-v1", axis="elevator", t_start_s=0.5, amplitude_norm=0.1, pulse_s=0.5))]
    p = _pilot(mans)
    first = _fly(p, 480)
    p.reset()
    second = _fly(p, 480)
    np.testing.assert_array_equal(first, second)
    assert first[60, 4] == pytest.approx(np.radians(30.0))  # the heading change before the turn
    assert first[-1, 4] == pytest.approx(0.002 * 240)  # after the turn: the heading reached at its end


def test_doublet_and_3211_shapes() -> None:
    t = np.arange(0.0, 10.0, DT)
    d = m.doublet(m.PulseTrainParams(type="doublet-v1", axis="rudder", t_start_s=1.0, amplitude_norm=0.2, pulse_s=1.0)).stick(t)
    assert d[(t >= 1.0) & (t < 2.0)].min() == 0.2 and d[(t >= 2.0) & (t < 3.0)].max() == -0.2
    assert not d[(t < 1.0) | (t >= 3.0)].any()
    s = m.three_two_one_one(m.PulseTrainParams(type="3211-v1", axis="rudder", t_start_s=0.0, amplitude_norm=0.5, pulse_s=0.5)).stick(t)
    # 3-2-1-1: +1 for 1.5 s, -1 for 1.0 s, +1 for 0.5 s, -1 for 0.5 s
    assert np.sum(s > 0) * DT == pytest.approx(2.0, abs=DT) and np.sum(s < 0) * DT == pytest.approx(1.5, abs=DT)


def test_consecutive_ramps_chain() -> None:
    """A second altitude ramp starts where the first one had got to when it begins."""
    mans = [m.altitude(m.AltitudeParams(type="altitude-v1", t_start_s=0.0, h_ft=6000.0, rate_fps=10.0)),
            m.altitude(m.AltitudeParams(type="altitude-v1", t_start_s=20.0, h_ft=5000.0, rate_fps=10.0))]
    p = _pilot(mans)
    assert p._ramp_start == [5000.0, 5200.0]
