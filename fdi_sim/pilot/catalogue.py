"""Registered maneuvers (ids used as ``type`` in ``[[maneuvers]]`` of a scenario)."""
from __future__ import annotations

from fdi_sim.pilot import maneuvers as m
from fdi_sim.registry import register

register("maneuver", "doublet-v1", "square doublet (+A for T, -A for T) on one command axis", m.doublet, m.PulseTrainParams)
register("maneuver", "3211-v1", "3-2-1-1 multistep (+A 3T, -A 2T, +A T, -A T) on one command axis", m.three_two_one_one, m.PulseTrainParams)
register("maneuver", "pulse-v1", "single square pulse of height A and width T on one command axis", m.pulse, m.PulseTrainParams)
register("maneuver", "altitude-v1", "ramp the altitude reference to h_ft at rate_fps", m.altitude, m.AltitudeParams)
register("maneuver", "airspeed-v1", "ramp the calibrated-airspeed reference to vc_kts at rate_ktps", m.airspeed, m.AirspeedParams)
register("maneuver", "heading-v1", "new heading reference; the autopilot turns at up to its bank limit", m.heading, m.HeadingParams)
register("maneuver", "turn-v1", "coordinated turn at phi_deg for duration_s, then hold the heading reached", m.turn, m.TurnParams)
