"""Real closed-loop flights for the kernel tests: the sensors' and the pilot's inputs, step by step.

The loop of :func:`fdi_sim.sim.run` without the log (truth -> sensors -> faults -> pilot ->
commands -> JSBSim), built with the same ``build_sensors`` / ``build_pilot`` and seed streams,
flown with the suite's and the pilot's list fast paths. Shared by ``tests/pilot`` and
``tests/sensors`` (loaded there by path).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from fdi_sim import registry
from fdi_sim.aircraft import Aircraft, Atmosphere, TrimResult, hold_trim_in_wind, trim
from fdi_sim.aircraft.properties import truth_signals
from fdi_sim.faults.injector import FaultInjector
from fdi_sim.scenario import Scenario, from_dict
from fdi_sim.sim.run import build_pilot, build_sensors

MANEUVERS = [  # every maneuver kind: stick inputs on every axis, both ramps, a heading change, a turn
    {"type": "doublet-v1", "axis": "elevator", "t_start_s": 2.0, "amplitude_norm": 0.08, "pulse_s": 1.0},
    {"type": "3211-v1", "axis": "aileron", "t_start_s": 6.0, "amplitude_norm": 0.1, "pulse_s": 0.5},
    {"type": "pulse-v1", "axis": "rudder", "t_start_s": 10.0, "amplitude_norm": 0.1, "pulse_s": 1.0},
    {"type": "doublet-v1", "axis": "throttle", "t_start_s": 12.0, "amplitude_norm": 0.05, "pulse_s": 1.0},
    {"type": "doublet-v1", "axis": "elevator", "t_start_s": 12.5, "amplitude_norm": 0.03, "pulse_s": 0.5},
    {"type": "altitude-v1", "t_start_s": 14.0, "h_ft": 0.0, "rate_fps": 25.0},  # h_ft set per aircraft
    {"type": "airspeed-v1", "t_start_s": 16.0, "vc_kts": 0.0, "rate_ktps": 2.0},  # vc_kts set per aircraft
    {"type": "heading-v1", "t_start_s": 20.0, "psi_deg": 20.0},
    {"type": "turn-v1", "t_start_s": 28.0, "phi_deg": -25.0, "duration_s": 6.0},
    {"type": "heading-v1", "t_start_s": 30.0, "psi_deg": 90.0},  # during the turn: dropped at its exit
    {"type": "heading-v1", "t_start_s": 40.0, "psi_deg": -10.0},
]
POINTS = {"f16": ({"h_ft": 10000.0, "vt_kts": 400.0}, 10500.0, 420.0),
          "DHC6": ({"h_ft": 5000.0, "vc_kts": 120.0}, 5400.0, 130.0)}


@dataclass(frozen=True)
class Flight:
    """One recorded flight.

    Attributes
    ----------
    sc : Scenario
    tr : TrimResult
    sensor_seed : numpy.random.SeedSequence
        The sensors' stream (``default_rng(sensor_seed)`` replays their noise).
    t_s : ndarray (n,)
    truth : ndarray (n, n_truth)
        The sensors' inputs.
    meas : ndarray (n, n_sensors)
        The sensors' outputs as flown.
    pilot_in : ndarray (n, n_sensors)
        The pilot's inputs (the measurements after the faults).
    pilot_out : ndarray (n, 8)
        The pilot's commands and references as flown (PilotCommand fields 1..8).
    """

    sc: Scenario
    tr: TrimResult
    sensor_seed: np.random.SeedSequence
    t_s: np.ndarray
    truth: np.ndarray
    meas: np.ndarray
    pilot_in: np.ndarray
    pilot_out: np.ndarray


def scenario(aircraft: str, *, duration_s: float = 50.0, autopilot: dict | None = None, faults: list | None = None,
             seed: int = 3) -> Scenario:
    """A scenario with every maneuver kind at ``aircraft``'s test point, moderate turbulence and wind."""
    initial, h_new, vc_new = POINTS[aircraft]
    mans = []
    for m in MANEUVERS:
        if m["t_start_s"] >= duration_s:  # the loader refuses maneuvers after the end
            continue
        m = dict(m)
        if m["type"] == "altitude-v1":
            m["h_ft"] = h_new
        if m["type"] == "airspeed-v1":
            m["vc_kts"] = vc_new
        mans.append(m)
    return from_dict({"name": f"kernel_{aircraft}", "aircraft": aircraft, "duration_s": duration_s, "seed": seed,
                      "initial": initial, "autopilot": autopilot or {}, "maneuvers": mans, "faults": faults or [],
                      "atmosphere": {"turbulence": "moderate", "wind_from_deg": 250.0, "wind_speed_kts": 20.0}})


def fly(sc: Scenario) -> Flight:
    """Fly ``sc`` as :func:`fdi_sim.sim.run` does (same seeds, same order of calls), recording the inputs."""
    ss_sensors, ss_pilot, ss_jsbsim, ss_faults, _ = np.random.SeedSequence(sc.seed).spawn(5)
    jsbsim_seed = int(ss_jsbsim.generate_state(1)[0] % (2**31 - 1))
    fault_defs = [registry.get("fault", tid).factory(p) for tid, p in sc.faults]
    ac = Aircraft(sc.aircraft, sc.dt_s)
    ac.set_atmosphere(Atmosphere(), jsbsim_seed)
    sensors = build_sensors(sc, sc.dt_s)
    sensors.reset(np.random.default_rng(ss_sensors))
    truth_names = truth_signals(sc.aircraft)
    inj = None
    if fault_defs:
        inj = FaultInjector(fault_defs, ac, sensors.names, [s.rate_hz for s in sensors.specs], truth_names,
                            sc.dt_s, sc.duration_s)
        inj.reset(np.random.default_rng(ss_faults))
    tr = trim(ac, sc.operating_point())
    a = sc.model.atmosphere
    hold_trim_in_wind(ac, tr, a.wind_from_deg, a.wind_speed_kts)
    ac.set_atmosphere(Atmosphere(a.turbulence, a.wind_from_deg, a.wind_speed_kts), jsbsim_seed)
    pilot = build_pilot(sc, tr, sensors.names)
    pilot.reset(np.random.default_rng(ss_pilot))
    read_truth, write_cmd = ac.list_reader(truth_names), ac.command_writer()
    n = int(round(sc.duration_s / sc.dt_s))
    rec: dict[str, list] = {"t": [], "x": [], "y": [], "yp": [], "c": []}
    for k in range(n + 1):
        t_s = k * sc.dt_s
        xl = read_truth()
        y = sensors.step_list(t_s, xl)
        rec["t"].append(t_s)
        rec["x"].append(xl)
        rec["y"].append(list(y))
        if inj is None:
            c = pilot.step(t_s, y)
            write_cmd(*c[1:5])
        else:
            inj.begin_step(t_s)
            y = inj.sensors(t_s, k, y, xl)
            c = pilot.step(t_s, y)
            write_cmd(*inj.commands(t_s, *c[1:5]))
            inj.after_commands()
            inj.plant(t_s, xl)
        rec["yp"].append(list(y))
        rec["c"].append(c[1:])
        if k == n or not ac.step():
            break
    return Flight(sc, tr, ss_sensors, np.array(rec["t"]), np.array(rec["x"]), np.array(rec["y"]),
                  np.array(rec["yp"]), np.array(rec["c"]))


#: the flights of the kernel tests: both aircraft with every maneuver; the DHC-6 with a dropout
#: (its airspeed holds its last value), a stuck vane and a stuck elevator that drives the throttle
#: and pitch to their limits; holds partly off; all holds off
FLIGHTS = {
    "f16_all_maneuvers": lambda: scenario("f16"),
    "dhc6_all_maneuvers": lambda: scenario("DHC6"),
    "dhc6_faults": lambda: scenario("DHC6", seed=8, faults=[
        {"type": "sensor-dropout-v1", "target": "vc_kts", "t_start_s": 5.0, "t_end_s": 9.0},
        {"type": "sensor-stuck-v1", "target": "alpha_rad", "t_start_s": 11.0, "t_end_s": 25.0},
        {"type": "actuator-stuck-v1", "target": "elevator", "t_start_s": 35.0}]),
    "f16_lateral_only": lambda: scenario("f16", duration_s=30.0, autopilot={"altitude": False, "airspeed": False}),
    "dhc6_altitude_only": lambda: scenario("DHC6", duration_s=30.0, autopilot={"lateral": False, "airspeed": False}),
    "dhc6_no_holds": lambda: scenario("DHC6", duration_s=10.0,
                                      autopilot={"altitude": False, "airspeed": False, "lateral": False}),
}


@lru_cache(maxsize=None)
def flight(name: str) -> Flight:
    """The recorded flight ``name`` of :data:`FLIGHTS` (flown once per test session)."""
    return fly(FLIGHTS[name]())

