"""Start a trimmed aircraft in a steady wind without an airspeed jump.

The trims (JSBSim's trimmer for the F-16, the running-engine Newton trim of the DHC-6) fly in
still air: JSBSim's trimmer does not converge with a wind, and with none the ground velocity is
the air velocity. Turning the wind on afterwards moves the air-relative velocity by the wind
vector at once (measured: a 20 kt wind from 45 deg on the DHC-6 at 120 KCAS gave 133.8 KCAS and
5.4 deg of sideslip one step later, then a transient of several knots and degrees), which any
detector watching the air data takes for a fault.

:func:`hold_trim_in_wind` puts the trimmed air-relative state back with the wind on: the ground
velocity becomes the air velocity plus the wind, written through JSBSim's initial conditions
(``ic/u-fps``... body axes) together with the IC wind, and ``run_ic`` starts from there. JSBSim's
``run_ic`` replaces the wind of ``FGWinds`` by the IC wind, and the engines settle
(``get_steady_state``) at the air data of that wind, so the IC wind must be the real one: the
IC's ``ic/vw-mag-fps`` first, then ``ic/vw-dir-deg``, the direction the air moves *to*
(``FGInitialCondition::SetWindDirDegIC`` keeps the magnitude already there: written the other way
round the wind blows toward north; ``ic/vw-north-fps``/``-east-fps`` are read-only). Measured
after the reset (DHC-6 120 KCAS, 20 kt from 45 deg): calibrated airspeed, alpha, beta, propeller
speed and N1 equal to the trim's to the printed digits; with the IC wind left out the propeller
settles 55 rpm slow and the airspeed sags 0.17 kt in 3 s, with magnitude and direction swapped
119 rpm and 0.35 kt (``tests/aircraft/test_wind_start.py``).
"""
from __future__ import annotations

import numpy as np

from fdi_sim.aircraft.linearize_state import capture_trim, set_state
from fdi_sim.aircraft.model import Aircraft, wind_ned_fps
from fdi_sim.aircraft.trim import TrimResult
from fdi_sim.units import FPS_PER_KT


def hold_trim_in_wind(ac: Aircraft, tr: TrimResult, wind_from_deg: float, wind_speed_kts: float) -> None:
    """Re-initialize ``ac`` (just trimmed in still air) with the same air-relative state in a wind.

    Parameters
    ----------
    ac : Aircraft
        Right after :func:`~fdi_sim.aircraft.trim.trim`.
    tr : TrimResult
        That trim.
    wind_from_deg : float
        Direction the wind blows from [deg, true].
    wind_speed_kts : float
        Wind speed [kt]; 0 leaves the aircraft untouched.
    """
    if wind_speed_kts == 0.0:
        return
    ts = capture_trim(ac, tr)
    x = ts.x_body.copy()
    x[:3] += ts.T_b2n.T @ np.array(wind_ned_fps(wind_from_deg, wind_speed_kts))  # ground = air + wind, body axes
    fdm = ac.fdm
    fdm["ic/vw-mag-fps"] = wind_speed_kts * FPS_PER_KT  # magnitude first: the direction needs it
    fdm["ic/vw-dir-deg"] = (wind_from_deg + 180.0) % 360.0  # where the air moves to
    set_state(ac, ts, x, ts.u_cmd, None, ts.n1_pct)
