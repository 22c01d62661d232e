"""Pilot.step fast path: a list of floats and an array give the same commands, bit for bit.

The simulation loop hands the pilot a list (no numpy per step); the step is written with gains
and states in locals and min/max as conditionals, which must not change a single float.
"""
from __future__ import annotations

import numpy as np

from fdi_sim.aircraft import TRUTH_SIGNALS
from fdi_sim.pilot import maneuvers as m
from fdi_sim.pilot.autopilot import AutopilotGains, AutopilotModes, Pilot, TrimPoint

TRIM = TrimPoint(0.0, 0.0, -0.07, 0.8, 0.05, 0.0, 0.0, 5000.0, 120.0)
DT = 1.0 / 120.0


def _pilot(maneuvers: list) -> Pilot:
    return Pilot(AutopilotGains.for_aircraft("DHC6"), AutopilotModes(), TRIM, maneuvers, TRUTH_SIGNALS, DT)


def test_list_and_array_measurements_give_the_same_commands_through_the_stops() -> None:
    """step() takes the measurement vector as an array or a list of floats (the loop's fast path);
    both give the same floats, also while commands sit at their stops and the protections act."""
    mans = [m.turn(m.TurnParams(type="turn-v1", t_start_s=0.5, phi_deg=30.0, duration_s=1.0)),
            m.altitude(m.AltitudeParams(type="altitude-v1", t_start_s=0.2, h_ft=9000.0, rate_fps=400.0)),
            m.airspeed(m.AirspeedParams(type="airspeed-v1", t_start_s=0.3, vc_kts=60.0, rate_ktps=20.0))]
    pa, pl = _pilot(mans), _pilot(mans)
    rng = np.random.default_rng(4)
    base = np.zeros(len(TRUTH_SIGNALS))
    i = {n: TRUTH_SIGNALS.index(n) for n in ("h_ft", "vc_kts", "nz_g", "alpha_rad", "v_north_fps")}
    base[i["h_ft"]], base[i["vc_kts"]], base[i["nz_g"]], base[i["v_north_fps"]] = 5000.0, 120.0, -1.0, 200.0
    clipped = set()
    for k in range(360):
        y = base + rng.normal(size=len(TRUTH_SIGNALS)) * (0.5 if k % 90 < 45 else 5.0)
        if k >= 180:  # near the stall margin: the nose-up authority fades
            y[i["alpha_rad"]] = 0.3
        ca, cl = pa.step(k * DT, y), pl.step(k * DT, y.tolist())
        assert np.array(ca).tobytes() == np.array(cl).tobytes()
        clipped.update(j for j, v in enumerate(ca[1:5]) if abs(v) == 1.0 or (j == 3 and v == 0.0))
    assert clipped  # the run did reach a command stop
