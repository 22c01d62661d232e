"""Signal sets of the linearizer and how a state is written into JSBSim and back to a trim.

A state is written through JSBSim's initial-condition object: attitude first (body velocities
written after it are kept, JSBSIM_NOTES sec. 4.2), then body velocity, rates and altitude; then
``run_ic`` with the trim status on (actuators jump to their commands) and the engines brought to
a steady state. :func:`capture_trim` records what :func:`restore_trim` needs to put the aircraft
back exactly at a trim.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from numpy.typing import NDArray

from fdi_sim.aircraft.model import Aircraft
from fdi_sim.aircraft.properties import COMMAND_SIGNALS, property_map
from fdi_sim.aircraft.trim import TrimResult
from fdi_sim.operating_point import OperatingPoint

#: body-axis state of the central differences, in order
BODY_STATES: tuple[str, ...] = (
    "u_body_fps", "v_body_fps", "w_body_fps", "p_radps", "q_radps", "r_radps",
    "phi_rad", "theta_rad", "psi_rad", "h_ft",
)
#: engine states added by the dynamic engine model (mean of all engines)
ENGINE_STATES: tuple[str, ...] = ("n1_pct", "prop_rpm")
#: the sensor suite of the foundation issue, in order
SENSOR_OUTPUTS: tuple[str, ...] = (
    "p_radps", "q_radps", "r_radps", "nx_g", "ny_g", "nz_g", "phi_rad", "theta_rad", "psi_rad",
    "vc_kts", "alpha_rad", "beta_rad", "h_ft", "hdot_fps",
)
#: outputs JSBSim computes in FGAuxiliary from the accelerations of the *previous* step
#: (FGAuxiliary runs before FGAccelerations in FGFDMExec::Run): measured one step late
LAGGED_OUTPUTS: tuple[str, ...] = ("nx_g", "ny_g", "nz_g")
#: pilot commands (control inputs), the simulation's command signals; the throttle goes to every engine
CONTROL_INPUTS: tuple[str, ...] = COMMAND_SIGNALS
#: body-axis velocity of the air mass (a gust of +u_gust blows from behind) [ft/s]
GUST_INPUTS: tuple[str, ...] = ("u_gust_body_fps", "v_gust_body_fps", "w_gust_body_fps")
#: optional disturbance columns that exist only when the model has the property
#: (the iced overlay declares ``icing/eta``; JSBSIM_NOTES sec. 5.3)
OPTIONAL_DISTURBANCES: dict[str, tuple[str, float]] = {"icing_eta": ("icing/eta", 0.005)}

#: JSBSim's gust velocity in local NED axes (it persists through ``run_ic``; the IC wind does not)
GUST_PROPS: tuple[str, ...] = ("atmosphere/gust-north-fps", "atmosphere/gust-east-fps", "atmosphere/gust-down-fps")
_PROPELLER_RPM = "propulsion/engine[0]/propeller-rpm"
#: positions of the Euler angles in :data:`BODY_STATES`
_ATTITUDE = slice(BODY_STATES.index("phi_rad"), BODY_STATES.index("psi_rad") + 1)


def has_propeller(ac: Aircraft) -> bool:
    """True for propeller aircraft (the DHC-6), whose engines get the dynamic model."""
    return bool(ac.fdm.get_property_manager().hasNode(_PROPELLER_RPM))


def command_props(ac: Aircraft, name: str) -> list[str]:
    """The JSBSim properties the pilot command ``name`` (:data:`CONTROL_INPUTS`) drives; the throttle goes to every engine."""
    if name == "throttle_cmd_norm":
        return [f"fcs/throttle-cmd-norm[{i}]" for i in range(ac.n_engines)]
    return [str(property_map(ac.name)[name])]


def engine_reader(ac: Aircraft) -> Callable[[], NDArray[np.float64]]:
    """A closure reading :data:`ENGINE_STATES`, each the mean over the engines [%, rpm] (propeller aircraft)."""
    n1 = [ac.node(f"propulsion/engine[{i}]/n1").get_double_value for i in range(ac.n_engines)]
    rpm = [ac.node(f"propulsion/engine[{i}]/propeller-rpm").get_double_value for i in range(ac.n_engines)]

    def read() -> NDArray[np.float64]:
        return np.array([np.mean([g() for g in n1]), np.mean([g() for g in rpm])])

    return read


def wrap_rad(a_rad: float) -> float:
    """Angle wrapped into [-pi, pi) [rad]."""
    return (a_rad + math.pi) % (2 * math.pi) - math.pi


def body_to_ned(phi_rad: float, theta_rad: float, psi_rad: float) -> NDArray[np.float64]:
    """Rotation matrix from body to local NED axes (3-2-1 Euler angles) [-]."""
    cf, sf = math.cos(phi_rad), math.sin(phi_rad)
    ct, st = math.cos(theta_rad), math.sin(theta_rad)
    cp, sp = math.cos(psi_rad), math.sin(psi_rad)
    # T_b2n = R_z(psi) R_y(theta) R_x(phi)
    return np.array([
        [ct * cp, sf * st * cp - cf * sp, cf * st * cp + sf * sp],
        [ct * sp, sf * st * sp + cf * cp, cf * st * sp - sf * cp],
        [-st, sf * ct, cf * ct],
    ])


@dataclass(frozen=True, eq=False)
class TrimState:
    """Everything needed to put the aircraft back exactly at a trim (see :func:`restore_trim`).

    Attributes
    ----------
    op : OperatingPoint
        The trimmed operating point.
    x_body : NDArray
        :data:`BODY_STATES` at the trim [ft/s, rad/s, rad, ft].
    u_cmd : NDArray
        :data:`CONTROL_INPUTS` at the trim [-].
    pitch_trim_cmd_norm : float
        Pitch-trim command held [-].
    n1_pct : float or None
        Mean gas-generator speed at the trim [%]; None for aircraft without propellers.
    """

    op: OperatingPoint
    x_body: NDArray[np.float64]
    u_cmd: NDArray[np.float64]
    pitch_trim_cmd_norm: float
    n1_pct: float | None = None

    @property
    def T_b2n(self) -> NDArray[np.float64]:
        """Rotation from body to NED axes at the trim attitude (:func:`body_to_ned`) [-]."""
        return body_to_ned(*self.x_body[_ATTITUDE])


def capture_trim(ac: Aircraft, tr: TrimResult) -> TrimState:
    """Record the trimmed state of ``ac`` (call right after :func:`~fdi_sim.aircraft.trim.trim`)."""
    n1 = float(engine_reader(ac)()[0]) if has_propeller(ac) else None
    return TrimState(
        op=tr.op, x_body=ac.read(BODY_STATES),
        u_cmd=np.array([tr.elevator_cmd_norm, tr.aileron_cmd_norm, tr.rudder_cmd_norm, tr.throttle_cmd_norm]),
        pitch_trim_cmd_norm=ac["fcs/pitch-trim-cmd-norm"], n1_pct=n1,
    )


def set_state(ac: Aircraft, ts: TrimState, x: NDArray[np.float64], u: NDArray[np.float64],
              gust_body_fps: NDArray[np.float64] | None = None, n1_pct: float | None = None,
              thr_settle_norm: float = 0.0) -> None:
    """Write a body state and commands into JSBSim (IC + ``run_ic``), engines at a steady state.

    Parameters
    ----------
    ac : Aircraft
        The aircraft.
    ts : TrimState
        The trim (its attitude rotates the gust, its pitch trim is held).
    x, u : NDArray
        :data:`BODY_STATES` and :data:`CONTROL_INPUTS` values.
    gust_body_fps : NDArray, optional
        Air-mass velocity in body axes at the trim attitude [ft/s]; JSBSim gusts persist through
        ``run_ic`` (its IC wind does not).
    n1_pct : float, optional
        Gas-generator speed to set after the engines settled [%].
    thr_settle_norm : float
        Throttle offset used while the engines settle, removed afterwards (moves the propeller
        speed, which JSBSim does not let us write) [-].
    """
    fdm = ac.fdm
    g_ned = ts.T_b2n @ gust_body_fps if gust_body_fps is not None else np.zeros(3)
    for prop, v in zip(GUST_PROPS, g_ned):
        fdm[prop] = v
    # attitude first: body velocities written after it are kept (JSBSIM_NOTES 4.2)
    fdm["ic/phi-rad"], fdm["ic/theta-rad"], fdm["ic/psi-true-rad"] = x[6], x[7], x[8]
    fdm["ic/u-fps"], fdm["ic/v-fps"], fdm["ic/w-fps"] = x[0], x[1], x[2]
    fdm["ic/p-rad_sec"], fdm["ic/q-rad_sec"], fdm["ic/r-rad_sec"] = x[3], x[4], x[5]
    fdm["ic/h-sl-ft"] = x[9]
    fdm["fcs/pitch-trim-cmd-norm"] = ts.pitch_trim_cmd_norm
    write = ac.command_writer()
    write(u[0], u[1], u[2], u[3] + thr_settle_norm)
    fdm.set_trim_status(True)
    fdm.run_ic()  # actuators jump to their commands
    fdm.set_trim_status(False)
    fdm.get_propulsion().get_steady_state()  # engines settle (the turboprop leaves its trim phase)
    if thr_settle_norm:
        write(u[0], u[1], u[2], u[3])
    if n1_pct is not None:
        for i in range(ac.n_engines):
            fdm[f"propulsion/engine[{i}]/n1"] = n1_pct


def restore_trim(ac: Aircraft, ts: TrimState) -> None:
    """Put ``ac`` back at the trim ``ts`` (same state, commands and engine; gusts zero)."""
    set_state(ac, ts, ts.x_body, ts.u_cmd, None, ts.n1_pct)
