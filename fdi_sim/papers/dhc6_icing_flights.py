"""Flights and models of the DHC-6 icing study (issue 5, robust-parity bar): the data side.

:func:`linearize_models` gives the linearizer's models of one operating point for every icing
severity eta (icing overlay), reduced by :func:`longitudinal_model` to the longitudinal axis with
the elevator input as the *commanded elevator angle* ``g(elevator_cmd + pitch_trim)`` [rad]
(:func:`elevator_gearing`), and discretized. :func:`fly` flies one seeded JSBSim scenario
(autopilot on, sensor noise on, turbulence, icing from t = 0, optional elevator bias fault) and
:func:`flight_samples` samples its MCAP log at the model's sample time; :func:`windows` stacks
deviation windows ``[Y; U]`` about the clean trim. The designs and statistics are in
:mod:`fdi_sim.papers.dhc6_icing_study`.

Why the known elevator input is an angle and not the raw command: the DHC-6 flight-control
system scales ``c = elevator_cmd + pitch_trim`` by 0.244 rad per unit trailing-edge down but by
0.454 rad per unit trailing-edge up (Conventional Controls.xml, :data:`ELEVATOR_RANGE_RAD`), and in light turbulence ``c`` is below zero in a
third of the steps at 100 KIAS (clean trim c = 0.012). The gearing is known to any
FCS, so the detector applies it; the linearizer's command column is converted with the slope it
differenced (:func:`longitudinal_model`). The pitch-trim setting is read from ``/commands/pilot``
(``pitch_trim_cmd_norm``, set by the trim and held); logs written before it was logged give it
from their first, fault-free step as ``g^-1(elevator_pos) - elevator_cmd``. The iced trim needs more pitch trim (0.057 against 0.012 at
eta 0.1), so a detector that ignored it would see the iced trim as a 0.6 deg elevator fault.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from fdi_sim.aircraft.linearize import FDSettings
from fdi_sim.aircraft.model import Aircraft
from fdi_sim.detectors.pca import series_windows, sliding_windows
from fdi_sim.errors import DesignError
from fdi_sim.flightlog import (
    TOPIC_COMMANDS,
    TOPIC_FAULTS,
    TOPIC_SENSORS,
    TOPIC_SURFACES,
    TOPIC_TRUTH_STATE,
    FlightLog,
    read_log,
)
from fdi_sim.linear.linearize import linearize
from fdi_sim.linear.model import LinearModel
from fdi_sim.linear.transform import discretize
from fdi_sim.operating_point import OperatingPoint

__all__ = [
    "ELEVATOR_RANGE_RAD",
    "FAULT_LABEL",
    "FlightPlan",
    "FlightSamples",
    "LON_INPUTS",
    "LON_OUTPUTS",
    "LON_STATES",
    "ModelSet",
    "StudyConfig",
    "elevator_gearing",
    "elevator_gearing_inverse",
    "flight_samples",
    "fly",
    "fly_all",
    "linearize_models",
    "longitudinal_model",
    "scenario_dict",
    "windows",
]

#: longitudinal states kept from the linearizer's model (lateral ones are dropped, see longitudinal_model)
LON_STATES: tuple[str, ...] = ("vt_fps", "alpha_rad", "q_radps", "theta_rad", "h_ft", "n1_pct", "prop_rpm")
#: longitudinal sensors of the suite (aircraft/DHC6/sensors.toml)
LON_OUTPUTS: tuple[str, ...] = ("q_radps", "nx_g", "nz_g", "theta_rad", "vc_kts", "alpha_rad", "h_ft", "hdot_fps")
#: model inputs after the reduction: known inputs first, then the disturbances
LON_INPUTS: tuple[str, ...] = ("elevator_cmd_rad", "throttle_cmd_norm", "u_gust_body_fps", "w_gust_body_fps",
                               "icing_eta")
LON_KINDS: tuple[str, ...] = ("control", "control", "disturbance", "disturbance", "disturbance")
FAULT_LABEL = "elevator_bias"
#: range of the DHC-6 "Elevator Control" aerosurface_scale (Conventional Controls.xml) [rad]. Not the
#: rounded stops of fdi_sim.aircraft.properties.SURFACES (-26 / +14 deg = -0.4538 / +0.2443 rad): with
#: those, g^-1 of a logged surface is off by 0.14 % and the recovered pitch trim by 1e-4.
ELEVATOR_RANGE_RAD: tuple[float, float] = (-0.454, 0.244)


@dataclass(frozen=True)
class StudyConfig:
    """The experiment: operating point, model set, sampling, flights.

    Attributes
    ----------
    h_ft, vc_kts, flaps_deg : float
        Operating point [ft, kt, deg].
    etas : tuple of float
        Icing severities of the model set [-]; the first is the nominal (clean) model.
    dt_s : float
        Detector sample time [s]; a multiple of the 120 Hz step and of every sensor period used.
    order_s : int
        Parity order s (window of s + 1 samples).
    turbulence : str
        JSBSim turbulence of the flights (none, light, moderate, severe; MIL-F-8785C Dryden).
    duration_s : float
        Length of each flight [s].
    skip_s : float
        Start of every flight not evaluated (autopilot and turbulence start-up) [s].
    fault_bias_deg : float
        Elevator bias of the faulty flights [deg] (``actuator-bias-v1``, trailing edge down).
    fault_start_s : float
        Fault onset [s]; it stays on to the end of the flight.
    sensor_biases : bool
        Draw the suite's constant sensor biases (off by default: a constant sensor bias is a
        sensor fault for any parity relation, which is not what this comparison is about).
    average_s : float
        Moving average of the whitened residual before the chi-square test [s] (:func:`statistics`).
    """

    h_ft: float = 5000.0
    vc_kts: float = 100.0
    flaps_deg: float = 0.0
    etas: tuple[float, ...] = (0.0, 0.05, 0.1)
    dt_s: float = 0.05
    order_s: int = 2
    turbulence: str = "light"
    duration_s: float = 120.0
    skip_s: float = 5.0
    fault_bias_deg: float = 2.0
    fault_start_s: float = 30.0
    sensor_biases: bool = False
    average_s: float = 1.0


# ---------------------------------------------------------------------------- elevator gearing
def elevator_gearing(c_norm: NDArray | float) -> NDArray[np.float64]:
    """DHC-6 elevator angle of a total command ``c = elevator_cmd + pitch_trim`` [rad].

    ``aerosurface_scale`` of Conventional Controls.xml: ``c`` clipped to [-1, 1], then
    ``c * max`` for ``c >= 0`` and ``c * |min|`` below (:data:`ELEVATOR_RANGE_RAD`).
    """
    lo, hi = ELEVATOR_RANGE_RAD
    c = np.clip(np.asarray(c_norm, float), -1.0, 1.0)
    return np.where(c >= 0.0, c * hi, -c * lo)


def elevator_gearing_inverse(delta_rad: NDArray | float) -> NDArray[np.float64]:
    """The total command ``c`` that gives the elevator angle ``delta_rad`` (inverse of :func:`elevator_gearing`)."""
    lo, hi = ELEVATOR_RANGE_RAD
    d = np.asarray(delta_rad, float)
    return np.where(d >= 0.0, d / hi, -d / lo)


# ---------------------------------------------------------------------------- models
@dataclass(frozen=True, eq=False)
class ModelSet:
    """The linear models of the study, continuous and discrete, clean first.

    Attributes
    ----------
    etas : tuple of float
    full : tuple of LinearModel
        The linearizer's continuous models (all states, inputs and sensors).
    lon : tuple of LinearModel
        Discrete longitudinal models (:func:`longitudinal_model`, then ZOH at ``dt_s``).
    pitch_trim_cmd_norm : tuple of float
        Pitch-trim setting of each trim [-].
    """

    etas: tuple[float, ...]
    full: tuple[LinearModel, ...]
    lon: tuple[LinearModel, ...]
    pitch_trim_cmd_norm: tuple[float, ...]


def longitudinal_model(model: LinearModel, pitch_trim_cmd_norm: float, step_cmd_norm: float | None = None) -> LinearModel:
    """Longitudinal part of a linearizer model, elevator input as commanded angle [rad].

    States :data:`LON_STATES`, outputs :data:`LON_OUTPUTS`, inputs :data:`LON_INPUTS`. The lateral
    states are truncated (their coupling into these outputs goes mostly through beta, where the
    DHC-6 tables have a kink at beta = 0: about the trim's -0.3 deg a linear term has the wrong
    sign whenever beta > 0, a third of the time in light turbulence). The elevator column is divided by the slope the linearizer differenced,
    ``(g(c0 + h) - g(c0 - h)) / 2h`` with ``c0`` the trim's pitch trim and ``h`` its command step,
    so it acts per radian of commanded elevator; ``u0`` of it is ``g(c0)``.
    """
    if step_cmd_norm is None:
        step_cmd_norm = FDSettings().step_cmd_norm
    xs = [model.state_names.index(s) for s in LON_STATES]
    ys = [model.output_names.index(o) for o in LON_OUTPUTS]
    src = ("elevator_cmd_norm", "throttle_cmd_norm", "u_gust_body_fps", "w_gust_body_fps", "icing_eta")
    us = [model.input_names.index(i) for i in src]
    c0 = pitch_trim_cmd_norm + model.u0[model.input_names.index("elevator_cmd_norm")]
    slope = float((elevator_gearing(c0 + step_cmd_norm) - elevator_gearing(c0 - step_cmd_norm)) / (2 * step_cmd_norm))
    scale = np.ones(len(us))
    scale[0] = 1.0 / slope  # d/d(delta) = d/dc / (d delta/dc)
    u0 = model.u0[us].copy()
    u0[0] = float(elevator_gearing(c0))
    return LinearModel(
        A=model.A[np.ix_(xs, xs)], B=model.B[np.ix_(xs, us)] * scale, C=model.C[np.ix_(ys, xs)],
        D=model.D[np.ix_(ys, us)] * scale, dt_s=model.dt_s, state_names=LON_STATES, input_names=LON_INPUTS,
        output_names=LON_OUTPUTS, input_kinds=LON_KINDS, x0=model.x0[xs], u0=u0, y0=model.y0[ys], op=model.op,
        meta={**model.meta, "reduced": "longitudinal", "elevator_slope_rad_per_norm": slope,
              "pitch_trim_cmd_norm": pitch_trim_cmd_norm},
    )


def linearize_models(cfg: StudyConfig) -> ModelSet:
    """Trim and linearize the DHC-6 at the study's point for every eta (icing overlay), reduce, discretize.

    Raises
    ------
    DesignError
        A point does not trim.
    """
    ac = Aircraft("DHC6", icing=True)  # eta = 0 flies exactly as the clean model (docs/icing.md)
    full, lon, ptrim = [], [], []
    for eta in cfg.etas:
        op = OperatingPoint("DHC6", cfg.h_ft, vc_kts=cfg.vc_kts, flaps_deg=cfg.flaps_deg, icing_eta=eta)
        lp = linearize(ac, op)
        if lp.model is None:
            raise DesignError(f"{op.label()}: {lp.status} ({lp.reason})")
        pt = float(lp.trim["pitch_trim_cmd_norm"])
        full.append(lp.model)
        ptrim.append(pt)
        lon.append(discretize(longitudinal_model(lp.model, pt), cfg.dt_s, "zoh", lag_outputs=False))
    return ModelSet(etas=tuple(cfg.etas), full=tuple(full), lon=tuple(lon), pitch_trim_cmd_norm=tuple(ptrim))


# ---------------------------------------------------------------------------- flights
@dataclass(frozen=True, eq=False)
class FlightSamples:
    """One flight at the detector's sample time.

    Attributes
    ----------
    t_s : NDArray
        Sample times [s], (N,).
    y : NDArray
        Measurements :data:`LON_OUTPUTS` at ``t_s`` (the sensor suite's output) [signal units], (N, 8).
    u : NDArray
        Known inputs over ``[t_k, t_k + dt)``: commanded elevator angle [rad] and throttle command
        [-], averaged over the simulation steps of the interval (the ZOH model's input), (N, 2).
    fault : NDArray
        True where the elevator fault is active at ``t_s`` (bool), (N,).
    eta : float
        Icing severity flown [-].
    seed : int
    pitch_trim_cmd_norm : float
        Pitch-trim setting recovered from the log [-].
    truth_x : NDArray
        True longitudinal states :data:`LON_STATES` at ``t_s`` where the log has them (vt and alpha
        of the Earth-relative body velocity, q, theta, h; NaN for n1 and rpm), (N, 7), for the
        design's state scaling.
    gust_body_fps : NDArray
        Turbulence velocity along body x and z at ``t_s`` (level flight at heading 0: north, down)
        [ft/s], (N, 2).
    """

    t_s: NDArray[np.float64]
    y: NDArray[np.float64]
    u: NDArray[np.float64]
    fault: NDArray[np.bool_]
    eta: float
    seed: int
    pitch_trim_cmd_norm: float
    truth_x: NDArray[np.float64]
    gust_body_fps: NDArray[np.float64]


def flight_samples(log: FlightLog, dt_s: float, eta: float, seed: int) -> FlightSamples:
    """Sample a flight log (:func:`fdi_sim.flightlog.read_log`) at ``dt_s``.

    Outputs are taken at ``t_k`` (the sensors are sampled at 40, 60 and 120 Hz, and ``dt_s`` is a
    multiple of all their periods, so each is a fresh sample); inputs are the mean command over
    the simulation steps of ``[t_k, t_k + dt)``.

    Raises
    ------
    DesignError
        ``dt_s`` is not a multiple of the simulation step, or (a log without the pitch trim) the
        elevator fault is on at t = 0.
    """
    meas, cmd, surf, truth = (log.topics[t] for t in (TOPIC_SENSORS, TOPIC_COMMANDS, TOPIC_SURFACES, TOPIC_TRUTH_STATE))
    dt_sim_s = float(cmd.t_s[1] - cmd.t_s[0])
    n_sub = int(round(dt_s / dt_sim_s))
    if n_sub < 1 or abs(n_sub * dt_sim_s - dt_s) > 1e-9:
        raise DesignError(f"dt_s = {dt_s} is not a multiple of the simulation step {dt_sim_s}")
    n_steps = len(surf)  # surfaces are logged after each step: one fewer than the commands
    n = n_steps // n_sub
    idx = np.arange(n) * n_sub
    fault = np.zeros(n, bool)
    if TOPIC_FAULTS in log.topics and f"{FAULT_LABEL}_active" in log.topics[TOPIC_FAULTS].fields:
        fault = log.topics[TOPIC_FAULTS][f"{FAULT_LABEL}_active"][idx] > 0.5
    if "pitch_trim_cmd_norm" in cmd.fields:  # logged with the commands: set by the trim, held
        ptrim = float(cmd["pitch_trim_cmd_norm"][0])
    elif fault[0]:
        raise DesignError("the elevator fault is active at t = 0, where the pitch trim is read from this log "
                          "(written without pitch_trim_cmd_norm); start it later (fault_start_s > 0)")
    else:  # an older log: from the first (fault-free) step, elevator_pos = g(cmd + trim)
        ptrim = float(elevator_gearing_inverse(surf["elevator_pos_rad"][0]) - cmd["elevator_cmd_norm"][0])
    delta = elevator_gearing(cmd["elevator_cmd_norm"][:n * n_sub] + ptrim)
    thr = cmd["throttle_cmd_norm"][:n * n_sub]
    u = np.stack([delta.reshape(n, n_sub).mean(1), thr.reshape(n, n_sub).mean(1)], axis=1)
    y = np.stack([meas[o][idx] for o in LON_OUTPUTS], axis=1)
    tx = np.full((n, len(LON_STATES)), np.nan)
    # the model's vt and alpha are those of the Earth-relative body velocity (the log's vt_fps and
    # alpha_rad are air-relative, gusts included): Vt = |(u, v, w)|, alpha = atan2(w, u)
    ub, vb, wb = (truth[f"{c}_body_fps"][idx] for c in "uvw")
    tx[:, 0], tx[:, 1] = np.sqrt(ub**2 + vb**2 + wb**2), np.arctan2(wb, ub)
    for j, s in enumerate(LON_STATES[2:5], start=2):
        tx[:, j] = truth[s][idx]
    gust = np.stack([truth["turb_north_fps"][idx], truth["turb_down_fps"][idx]], axis=1)
    return FlightSamples(t_s=cmd.t_s[idx].copy(), y=y, u=u, fault=fault, eta=eta, seed=seed,
                         pitch_trim_cmd_norm=ptrim, truth_x=tx, gust_body_fps=gust)


def scenario_dict(cfg: StudyConfig, eta: float, seed: int, faulty: bool) -> dict:
    """The scenario of one flight (autopilot holds altitude, airspeed and heading; no maneuvers)."""
    faults = []
    if eta:
        faults.append({"type": "icing-v1", "target": "airframe", "eta_final": eta, "t_start_s": 0.0})
    if faulty:
        faults.append({"type": "actuator-bias-v1", "target": "elevator", "bias_deg": cfg.fault_bias_deg,
                       "t_start_s": cfg.fault_start_s, "label": FAULT_LABEL})
    return {"name": f"dhc6_icing_parity_eta{eta:g}{'_fault' if faulty else ''}", "aircraft": "DHC6",
            "duration_s": cfg.duration_s, "seed": int(seed),
            "initial": {"h_ft": cfg.h_ft, "vc_kts": cfg.vc_kts, "flaps_deg": cfg.flaps_deg},
            "atmosphere": {"turbulence": cfg.turbulence}, "sensors": {"biases": cfg.sensor_biases},
            "faults": faults}


def fly(cfg: StudyConfig, eta: float, seed: int, faulty: bool, out_dir: str | Path) -> FlightSamples:
    """Fly one seeded JSBSim scenario (icing from t = 0 when ``eta > 0``), return its samples.

    The simulation loop is imported here, not at module level: the detectors stage must not
    depend on ``fdi_sim.sim`` (DESIGN: sim and study compose, nothing imports them back); this
    one function is study-level composition.

    Raises
    ------
    DesignError
        The flight did not complete.
    """
    from fdi_sim.scenario import from_dict
    from fdi_sim import training

    sc = from_dict(scenario_dict(cfg, eta, seed, faulty))
    res = training.fly(sc, log_path=Path(out_dir) / f"{sc.name}_seed{seed}.mcap", progress=False)
    if res.status != "completed":
        raise DesignError(f"flight {sc.name} seed {seed} ended {res.status}: {res.summary.reason}")
    return flight_samples(read_log(res.log_path), cfg.dt_s, eta, seed)


# ---------------------------------------------------------------------------- windows
def windows(fs: FlightSamples, ref: LinearModel, order_s: int, skip_s: float = 0.0) -> tuple[NDArray, NDArray, NDArray]:
    """Stacked deviation windows ``X(k) = [Y(k); U(k)]`` about ``ref``'s trim, oldest sample first.

    Returns
    -------
    X : NDArray
        ((N - s), (s+1)(r + m)) windows ending at samples s..N-1 with ``t >= skip_s``.
    fault : NDArray
        True where the fault is active over the whole window.
    t_s : NDArray
        Time of the newest sample of each window [s].
    """
    L = order_s + 1
    cu = list(ref.control_columns())
    X = series_windows(fs.u, fs.y, L, ref.u0[cu], ref.y0)  # row k: the window ending at sample k + s
    f = sliding_windows(fs.fault, L).all(axis=1)
    t_s = fs.t_s[order_s:]
    keep = t_s >= skip_s
    return X[keep], f[keep], t_s[keep]


# ---------------------------------------------------------------------------- flight plan
@dataclass(frozen=True)
class FlightPlan:
    """Seeds of each group of flights (all flights of a group share eta and fault).

    Attributes
    ----------
    train : tuple of int
        Clean fault-free flights: noise levels, state scaling, residual mean and covariance.
    detect : tuple of int
        Faulty flights (clean, and iced at the largest eta) that set the thresholds.
    test : tuple of int
        Fault-free flights at every eta of the model set: the false alarms.
    """

    train: tuple[int, ...] = tuple(range(100, 108))
    detect: tuple[int, ...] = tuple(range(200, 210))
    test: tuple[int, ...] = tuple(range(300, 320))


def fly_all(cfg: StudyConfig, plan: FlightPlan, out_dir: str | Path) -> dict[str, list[FlightSamples]]:
    """Fly every group of the plan: ``train``, ``fault_eta<e>`` (clean and largest eta), ``eta<e>`` (each eta).

    Seeds are offset per group (``seed + 1000 i``) so no two groups share turbulence or noise.
    """
    e_max = max(cfg.etas)
    groups: list[tuple[str, float, bool, tuple[int, ...]]] = [("train", 0.0, False, plan.train),
                                                             ("fault_eta0", 0.0, True, plan.detect),
                                                             (f"fault_eta{e_max:g}", e_max, True, plan.detect)]
    groups += [(f"eta{e:g}", e, False, plan.test) for e in cfg.etas]
    return {name: [fly(cfg, eta, s + 1000 * i, faulty, out_dir) for s in seeds]
            for i, (name, eta, faulty, seeds) in enumerate(groups)}
