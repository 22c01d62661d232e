"""Pilot: maneuver tables and the reset contract (no JSBSim: the pilot is pure arithmetic on measurements)."""
from __future__ import annotations

import numpy as np
import pytest

from fdi_sim.aircraft import TRUTH_SIGNALS
from fdi_sim.pilot import maneuvers as m
from fdi_sim.pilot.autopilot import AutopilotGains, AutopilotModes, Pilot, TrimPoint
from fdi_sim.units import FPS_PER_KT, G0_FPS2

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


# --- speed estimate and bank command (synthetic, self-consistent measurements) -------------------
G = AutopilotGains.for_aircraft("DHC6")
IX = {name: TRUTH_SIGNALS.index(name) for name in TRUTH_SIGNALS}
VT0_FPS = Pilot(G, AutopilotModes(), TRIM, [], TRUTH_SIGNALS, DT)._fps_per_kcas * TRIM.vc_kts  # TAS at the trim


def _level(vt_fps: float, psi_rad: float, wind_n_fps: float, wind_e_fps: float, phi_rad: float = 0.0,
           ax_fps2: float = 0.0, v_gnd_fps: float | None = None) -> np.ndarray:
    """Level flight (theta = alpha = beta = 0) along psi through a steady wind, coordinated bank phi.

    ``vt_fps`` is the airspeed the air data sees; the ground velocity is that of ``v_gnd_fps``
    (default ``vt_fps``) along psi plus the wind, so a gust is an air-data change alone.
    """
    y = np.zeros(len(TRUTH_SIGNALS))
    v = vt_fps if v_gnd_fps is None else v_gnd_fps
    y[IX["h_ft"]], y[IX["vc_kts"]], y[IX["psi_rad"]], y[IX["phi_rad"]] = TRIM.h_ft, vt_fps / VT0_FPS * TRIM.vc_kts, psi_rad, phi_rad
    y[IX["nx_g"]], y[IX["nz_g"]] = ax_fps2 / G0_FPS2, -1.0 / np.cos(phi_rad)  # specific force, body axes [g]
    y[IX["v_north_fps"]] = v * np.cos(psi_rad) + wind_n_fps
    y[IX["v_east_fps"]] = v * np.sin(psi_rad) + wind_e_fps
    return y


def test_speed_estimate_ignores_a_long_gust_and_follows_a_real_speed_change() -> None:
    """A 60 s, 10 kt headwind gust moves the air data by 10 kt but the estimate only by what leaks
    into the slow wind estimate; an inertial speed change (GNSS and accelerometer agree) is followed."""
    p = Pilot(G, AutopilotModes(), TRIM, [], TRUTH_SIGNALS, DT)
    wind_e = 20.0 * FPS_PER_KT  # a 20 kt westerly
    gust_fps = 10.0 * FPS_PER_KT
    est = []
    for k in range(int(100 / DT)):
        t = k * DT
        gust = gust_fps if 20.0 <= t < 80.0 else 0.0
        p.step(t, _level(VT0_FPS + gust, 0.0, 0.0, wind_e, v_gnd_fps=VT0_FPS))
        est.append(p.airspeed_estimate_kts)
    err = np.abs(np.array(est) - TRIM.vc_kts)
    gust_kcas = gust_fps / VT0_FPS * TRIM.vc_kts
    leak = gust_kcas * (1.0 - np.exp(-60.0 / G.tau_wind_s))  # first-order wind estimate over the gust
    assert 0.5 * leak < err.max() < leak + 0.2
    # a real acceleration: +10 kt over 10 s, inertial and air data together (a fresh pilot)
    p.reset()
    accel = 10.0 * FPS_PER_KT / 10.0
    v = VT0_FPS
    for k in range(int(50 / DT)):
        t = k * DT
        a = accel if 10.0 <= t < 20.0 else 0.0
        p.step(t, _level(v, 0.0, 0.0, wind_e, ax_fps2=a))
        v += a * DT
    assert p.airspeed_estimate_kts == pytest.approx(v / VT0_FPS * TRIM.vc_kts, abs=0.1)


def test_speed_and_wind_estimates_hold_through_a_turn_in_wind() -> None:
    """A full 3 deg/s turn through a 20 kt wind: the ground speed swings by 40 kt, the air data
    and the estimate do not; the wind estimate is the wind."""
    p = Pilot(G, AutopilotModes(), TRIM, [], TRUTH_SIGNALS, DT)
    wn, we = -12.0 * FPS_PER_KT, 16.0 * FPS_PER_KT
    phi = np.arctan(VT0_FPS * np.radians(3.0) / G0_FPS2)  # coordinated bank for 3 deg/s
    gs, est = [], []
    for k in range(int(130 / DT)):
        t = k * DT
        psi = np.radians(3.0) * max(t - 10.0, 0.0)
        y = _level(VT0_FPS, psi, wn, we, phi_rad=phi if t >= 10.0 else 0.0)
        p.step(t, y)
        gs.append(np.hypot(y[IX["v_north_fps"]], y[IX["v_east_fps"]]))
        est.append(p.airspeed_estimate_kts)
    assert np.ptp(gs) > 39.0 * FPS_PER_KT
    assert np.max(np.abs(np.array(est) - TRIM.vc_kts)) < 0.05
    assert p.wind_estimate_fps == pytest.approx((wn, we), abs=0.05)


def test_bank_command_is_smooth_in_heading_mode_and_after_a_turn() -> None:
    """The heading loop's bank command is low-passed (tau_phi): a heading error jump and a turn exit
    move it by at most (step / tau_phi) dt per step, never in one jump."""
    turn = m.turn(m.TurnParams(type="turn-v1", t_start_s=5.0, phi_deg=20.0, duration_s=5.0))
    p = Pilot(G, AutopilotModes(), TRIM, [turn], TRUTH_SIGNALS, DT)
    y = _level(VT0_FPS, 0.0, 0.0, 0.0)
    y[IX["psi_rad"]] = np.radians(-10.0)  # 10 deg left of the held heading from the start
    phi_ref = np.array([p.step(k * DT, y).phi_ref_rad for k in range(int(20 / DT))])
    jumps = np.abs(np.diff(phi_ref))
    in_turn = (np.arange(1, len(phi_ref)) * DT >= 5.0) & (np.arange(1, len(phi_ref)) * DT < 10.0 + DT)
    assert jumps[~in_turn].max() <= np.radians(20.0) * DT / G.tau_phi_s * 1.001
    assert phi_ref[int(5.5 / DT)] == pytest.approx(np.radians(20.0))  # the turn's bank itself is not filtered
    assert phi_ref[int(4.9 / DT)] == pytest.approx(min(G.k_psi * np.radians(10.0), G.phi_max_rad)
                                                   * (1 - np.exp(-4.9 / G.tau_phi_s)), rel=0.01)


def test_autopilot_needs_gnss_velocity() -> None:
    names = tuple(n for n in TRUTH_SIGNALS if n != "v_east_fps")
    with pytest.raises(ValueError, match="v_east_fps"):
        Pilot(G, AutopilotModes(), TRIM, [], names, DT)
