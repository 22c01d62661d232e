"""JSBSim side of the linearizer: central differences about a trim, FGLinearization, doublet runs.

Everything here drives JSBSim; the maths on the resulting matrices (body -> aero transform,
discretization, modes, validation metrics) lives in :mod:`fdi_sim.linear`.

Central differences (JSBSIM_NOTES sec. 4.2, extended)
-----------------------------------------------------
Each evaluation writes a state into JSBSim's initial-condition object (attitude first, then
body velocity, rates and altitude), runs ``run_ic`` with the trim status on (actuators jump to
their commands), brings the engines to a steady state (``get_steady_state``), then takes
``n_settle`` tiny *real* steps of ``dt_eval_s`` (1e-6 s). Real steps rather than ``dt = 0``
runs because at ``dt = 0`` JSBSim's turboprop drops to its trim phase and gives 0 HP
(JSBSIM_NOTES sec. 0); the few steps also converge the terms that lag one model pass
(alpha-dot, the pilot-station accelerations, the F-16 FBW loop on n_z). The derivatives are
read from ``accelerations/*`` and ``velocities/*dot*``; engine-state derivatives are the change
over the last tiny step divided by its length.

The perturbations ("knobs") need not move exactly one state each: every evaluation reads the
state it actually reached, and the Jacobian is the solution of ``dF = M dZ`` over all knobs
(``M = [A B; C D]``, ``dZ`` the reached state/input differences). With diagonal knobs this is
plain central differencing; it also handles the DHC-6 propeller speed, which JSBSim does not
let us write: its knob is the throttle used while the engines settle, after which throttle and
N1 are set back to their trim values.

Engines
-------
* ``"quasi_static"`` (F-16 default): thrust follows the throttle at once. The F100 spools by a
  rate-limited ``Seek`` that crosses a small throttle step within a few steps, so no state is
  needed; a rate limit has no linearization anyway.
* ``"dynamic"`` (DHC-6 default): states ``n1_pct`` (PT6A gas generator, first-order lag of 1 s
  up, 2.4 s down in ``FGTurboProp::Run``; the central difference averages the two slopes) and
  ``prop_rpm`` (propeller on its fine-pitch stop, torque balance). Both engines are moved
  together, so each state is the mean of the two engines. A quasi-static DHC-6 model misses a
  1-2 s thrust lag (measured: thrust reaches 63 % of a throttle step after about 1.5 s).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, Mapping, Sequence

import jsbsim
import numpy as np
from numpy.typing import NDArray

from fdi_sim.aircraft.model import Aircraft
from fdi_sim.aircraft.trim import TrimResult, trim
from fdi_sim.errors import DesignError
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
#: pilot commands (control inputs); the throttle goes to every engine
CONTROL_INPUTS: tuple[str, ...] = ("elevator_cmd_norm", "aileron_cmd_norm", "rudder_cmd_norm", "throttle_cmd_norm")
#: body-axis velocity of the air mass (a gust of +u_gust blows from behind) [ft/s]
GUST_INPUTS: tuple[str, ...] = ("u_gust_body_fps", "v_gust_body_fps", "w_gust_body_fps")
#: optional disturbance columns that exist only when the model has the property
#: (the iced overlay declares ``icing/eta``; JSBSIM_NOTES sec. 5.3)
OPTIONAL_DISTURBANCES: dict[str, tuple[str, float]] = {"icing_eta": ("icing/eta", 0.005)}

_DERIV_PROPS: tuple[str, ...] = (
    "accelerations/udot-ft_sec2", "accelerations/vdot-ft_sec2", "accelerations/wdot-ft_sec2",
    "accelerations/pdot-rad_sec2", "accelerations/qdot-rad_sec2", "accelerations/rdot-rad_sec2",
    "velocities/phidot-rad_sec", "velocities/thetadot-rad_sec", "velocities/psidot-rad_sec",
    "velocities/h-dot-fps",
)
_STATE_PROPS: tuple[str, ...] = (
    "velocities/u-fps", "velocities/v-fps", "velocities/w-fps",
    "velocities/p-rad_sec", "velocities/q-rad_sec", "velocities/r-rad_sec",
    "attitude/phi-rad", "attitude/theta-rad", "attitude/psi-rad", "position/h-sl-ft",
)
_GUST_PROPS: tuple[str, ...] = ("atmosphere/gust-north-fps", "atmosphere/gust-east-fps", "atmosphere/gust-down-fps")
_PSI = BODY_STATES.index("psi_rad")


@dataclass(frozen=True)
class FDSettings:
    """Step sizes and evaluation details of the central differences.

    Attributes
    ----------
    step_vel_fps : float
        Body-velocity and gust step [ft/s].
    step_angle_rad : float
        Attitude step [rad] and body-rate step [rad/s].
    step_h_ft : float
        Altitude step [ft].
    step_cmd_norm : float
        Command step [-].
    step_n1_pct : float
        Gas-generator speed step [%].
    step_rpm_throttle : float
        Throttle offset used while the engines settle, to move the propeller speed [-].
    n_settle : int
        Tiny real steps per evaluation.
    dt_eval_s : float
        Length of each tiny step [s].
    engine : str
        ``"auto"`` (dynamic for propeller aircraft, quasi-static otherwise), ``"dynamic"`` or
        ``"quasi_static"``.
    """

    step_vel_fps: float = 0.1
    step_angle_rad: float = 1e-3
    step_h_ft: float = 1.0
    step_cmd_norm: float = 1e-3
    step_n1_pct: float = 0.1
    step_rpm_throttle: float = 0.005
    n_settle: int = 5
    dt_eval_s: float = 1e-6
    engine: str = "auto"


@dataclass(frozen=True, eq=False)
class BodyJacobians:
    """Continuous-time Jacobians about a trim, in body axes (JSBSim units).

    ``d/dt dx = A dx + B du``, ``dy = C dx + D du``; all signals are deviations from the trim
    values ``x0``, ``u0``, ``y0``.

    Attributes
    ----------
    A, B, C, D : NDArray
        Jacobians, shapes (n, n), (n, m), (p, n), (p, m).
    state_names, input_names, output_names : tuple of str
        Suffixed names (:data:`BODY_STATES` [+ :data:`ENGINE_STATES`], commands then
        disturbances, :data:`SENSOR_OUTPUTS`).
    input_kinds : tuple of str
        ``"control"`` or ``"disturbance"`` per input.
    x0, u0, y0 : NDArray
        Trim values [units of the names].
    xdot0 : NDArray
        State derivatives at the centre evaluation (trim quality) [units/s].
    knob_condition : float
        Condition number of the reached perturbation matrix ``dZ`` (large: a knob did not move
        its state).
    engine : str
        ``"dynamic"`` or ``"quasi_static"``.
    elapsed_s : float
        Wall time of the linearization [s].
    notes : tuple of str
        What was left out and why (e.g. an unavailable disturbance).
    """

    A: NDArray[np.float64]
    B: NDArray[np.float64]
    C: NDArray[np.float64]
    D: NDArray[np.float64]
    state_names: tuple[str, ...]
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    input_kinds: tuple[str, ...]
    x0: NDArray[np.float64]
    u0: NDArray[np.float64]
    y0: NDArray[np.float64]
    xdot0: NDArray[np.float64]
    knob_condition: float
    engine: str
    elapsed_s: float
    notes: tuple[str, ...] = ()


@dataclass(frozen=True)
class _Eval:
    z: NDArray[np.float64]      # reached states and inputs
    f: NDArray[np.float64]      # state derivatives and outputs


def engine_model(ac: Aircraft, settings: FDSettings) -> str:
    """The engine model used for ``ac``: ``"dynamic"`` or ``"quasi_static"``."""
    if settings.engine in ("dynamic", "quasi_static"):
        return settings.engine
    if settings.engine != "auto":
        raise DesignError(f"FDSettings.engine = {settings.engine!r}; use 'auto', 'dynamic' or 'quasi_static'")
    return "dynamic" if ac.fdm.get_property_manager().hasNode("propulsion/engine[0]/propeller-rpm") else "quasi_static"


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
    n1_pct : float
        Mean gas-generator speed of the dynamic engine model at the trim [%] (0 if unused).
    """

    op: OperatingPoint
    x_body: NDArray[np.float64]
    u_cmd: NDArray[np.float64]
    pitch_trim_cmd_norm: float
    n1_pct: float = 0.0


def capture_trim(ac: Aircraft, tr: TrimResult) -> TrimState:
    """Record the trimmed state of ``ac`` (call right after :func:`~fdi_sim.aircraft.trim.trim`)."""
    fdm = ac.fdm
    n1 = 0.0
    if fdm.get_property_manager().hasNode("propulsion/engine[0]/propeller-rpm"):  # dynamic engine model
        n1 = float(np.mean([fdm[f"propulsion/engine[{i}]/n1"] for i in range(ac.n_engines)]))
    return TrimState(
        op=tr.op, x_body=np.array([fdm[p] for p in _STATE_PROPS]),
        u_cmd=np.array([tr.elevator_cmd_norm, tr.aileron_cmd_norm, tr.rudder_cmd_norm, tr.throttle_cmd_norm]),
        pitch_trim_cmd_norm=float(fdm["fcs/pitch-trim-cmd-norm"]), n1_pct=n1,
    )


def set_state(ac: Aircraft, ts: TrimState, x: NDArray[np.float64], u: NDArray[np.float64],
              gust_body_fps: NDArray[np.float64] | None = None, n1_pct: float | None = None,
              thr_settle: float = 0.0) -> None:
    """Write a body state and commands into JSBSim (IC + ``run_ic``), engines at a steady state.

    Parameters
    ----------
    x, u : NDArray
        :data:`BODY_STATES` and :data:`CONTROL_INPUTS` values.
    gust_body_fps : NDArray, optional
        Air-mass velocity in body axes at the trim attitude [ft/s]; JSBSim gusts persist through
        ``run_ic`` (its IC wind does not).
    n1_pct : float, optional
        Gas-generator speed to set after the engines settled [%].
    thr_settle : float
        Throttle offset used while the engines settle, removed afterwards (moves the propeller
        speed, which JSBSim does not let us write) [-].
    """
    fdm = ac.fdm
    g_ned = body_to_ned(*ts.x_body[6:9]) @ (np.zeros(3) if gust_body_fps is None else gust_body_fps)
    for prop, v in zip(_GUST_PROPS, g_ned):
        fdm[prop] = v
    # attitude first: body velocities written after it are kept (JSBSIM_NOTES 4.2)
    fdm["ic/phi-rad"], fdm["ic/theta-rad"], fdm["ic/psi-true-rad"] = x[6], x[7], x[8]
    fdm["ic/u-fps"], fdm["ic/v-fps"], fdm["ic/w-fps"] = x[0], x[1], x[2]
    fdm["ic/p-rad_sec"], fdm["ic/q-rad_sec"], fdm["ic/r-rad_sec"] = x[3], x[4], x[5]
    fdm["ic/h-sl-ft"] = x[9]
    fdm["fcs/pitch-trim-cmd-norm"] = ts.pitch_trim_cmd_norm
    fdm["fcs/elevator-cmd-norm"], fdm["fcs/aileron-cmd-norm"], fdm["fcs/rudder-cmd-norm"] = u[0], u[1], u[2]
    for i in range(ac.n_engines):
        fdm[f"fcs/throttle-cmd-norm[{i}]"] = u[3] + thr_settle
    fdm.set_trim_status(True)
    fdm.run_ic()  # actuators jump to their commands
    fdm.set_trim_status(False)
    fdm.get_propulsion().get_steady_state()  # engines settle (the turboprop leaves its trim phase)
    if thr_settle:
        for i in range(ac.n_engines):
            fdm[f"fcs/throttle-cmd-norm[{i}]"] = u[3]
    if n1_pct is not None:
        for i in range(ac.n_engines):
            fdm[f"propulsion/engine[{i}]/n1"] = n1_pct


def restore_trim(ac: Aircraft, ts: TrimState) -> None:
    """Put ``ac`` back at the trim ``ts`` (same state, commands and engine; gusts zero)."""
    set_state(ac, ts, ts.x_body, ts.u_cmd, None, ts.n1_pct if ts.n1_pct else None)


class _Evaluator:
    """Sets a perturbed state/input in JSBSim and reads derivatives and outputs."""

    def __init__(self, ac: Aircraft, ts: TrimState, engine: str, settings: FDSettings,
                 extra: Mapping[str, tuple[str, float]]) -> None:
        self.ac, self.fdm, self.ts, self.s, self.engine = ac, ac.fdm, ts, settings, engine
        fdm = ac.fdm
        self.n_eng = ac.n_engines
        self.x_trim = ts.x_body.copy()
        self.u_ctrl_trim = ts.u_cmd.copy()
        self.extra = dict(extra)
        self.extra_trim = np.array([fdm[p] for p, _ in self.extra.values()])
        self.read_y = ac.reader(SENSOR_OUTPUTS)
        self.n1_props = [f"propulsion/engine[{i}]/n1" for i in range(self.n_eng)]
        self.rpm_props = [f"propulsion/engine[{i}]/propeller-rpm" for i in range(self.n_eng)]
        self.n1_trim = ts.n1_pct

    def _set(self, x: NDArray[np.float64], u: NDArray[np.float64], gust_b: NDArray[np.float64],
             extra: NDArray[np.float64], n1: float | None, thr_settle: float) -> None:
        for (prop, _), v in zip(self.extra.values(), extra):
            self.fdm[prop] = v
        set_state(self.ac, self.ts, x, u, gust_b, n1, thr_settle)

    def evaluate(self, x: NDArray[np.float64], u: NDArray[np.float64], gust_b: NDArray[np.float64],
                 extra: NDArray[np.float64], n1: float | None = None, thr_settle: float = 0.0) -> _Eval:
        fdm = self.fdm
        dyn = self.engine == "dynamic"
        self._set(x, u, gust_b, extra, n1 if dyn else None, thr_settle)
        fdm.set_dt(self.s.dt_eval_s)
        try:
            eng_before = np.zeros(2)
            for _ in range(self.s.n_settle):
                if dyn:
                    eng_before = self._engine_state()
                fdm.run()
        finally:
            fdm.set_dt(self.ac.dt_s)
        xr = np.array([fdm[p] for p in _STATE_PROPS])
        xr[_PSI] = x[_PSI] + _wrap(xr[_PSI] - x[_PSI])
        xdot = np.array([fdm[p] for p in _DERIV_PROPS])
        y = self.read_y()
        y[SENSOR_OUTPUTS.index("psi_rad")] = x[_PSI] + _wrap(y[SENSOR_OUTPUTS.index("psi_rad")] - x[_PSI])
        parts_z = [xr]
        parts_f = [xdot]
        if dyn:
            eng_after = self._engine_state()
            # the state at the start of the last step and its rate over that step
            parts_z.append(eng_before)
            parts_f.append((eng_after - eng_before) / self.s.dt_eval_s)
        parts_z += [u, gust_b, extra]
        parts_f.append(y)
        return _Eval(z=np.concatenate(parts_z), f=np.concatenate(parts_f))

    def _engine_state(self) -> NDArray[np.float64]:
        fdm = self.fdm
        return np.array([np.mean([fdm[p] for p in self.n1_props]), np.mean([fdm[p] for p in self.rpm_props])])


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def central_difference(ac: Aircraft, tr: TrimResult, settings: FDSettings | None = None,
                       extra_disturbances: Mapping[str, tuple[str, float]] | None = None) -> BodyJacobians:
    """Linearize ``ac`` about the trim ``tr`` by central differences (body axes).

    Parameters
    ----------
    ac : Aircraft
        The aircraft, trimmed at ``tr`` (its current state is the trim).
    tr : TrimResult
        The trim (commands and pitch trim are held at its values).
    settings : FDSettings, optional
        Step sizes and engine model.
    extra_disturbances : mapping, optional
        ``name -> (JSBSim property, step)`` of further disturbance columns (e.g. the drag knob
        ``fcs/speedbrake-pos-norm`` of the DHC-6). :data:`OPTIONAL_DISTURBANCES` are added
        whenever the model has their property.

    Returns
    -------
    BodyJacobians
        A, B, C, D with states :data:`BODY_STATES` (+ :data:`ENGINE_STATES`), inputs
        :data:`CONTROL_INPUTS` + :data:`GUST_INPUTS` + extras, outputs :data:`SENSOR_OUTPUTS`.

    Raises
    ------
    DesignError
        A perturbation did not move its state (singular knob matrix), or an extra disturbance
        property does not exist.

    Notes
    -----
    The aircraft is left at the last evaluation with gusts reset to zero: trim again before
    flying it.
    """
    t_start = time.perf_counter()
    s = settings or FDSettings()
    engine = engine_model(ac, s)
    pm = ac.fdm.get_property_manager()
    extra: dict[str, tuple[str, float]] = {}
    notes: list[str] = []
    for name, (prop, step) in OPTIONAL_DISTURBANCES.items():
        if pm.hasNode(prop):
            extra[name] = (prop, step)
        else:
            notes.append(f"{name}: JSBSim model {ac.name} has no property {prop} (overlay not available)")
    for name, (prop, step) in (extra_disturbances or {}).items():
        if not pm.hasNode(prop):
            raise DesignError(f"extra disturbance {name!r}: {ac.name} has no property {prop!r}; "
                              "pick an existing writable property")
        extra[name] = (prop, float(step))
    ts = capture_trim(ac, tr)
    ev = _Evaluator(ac, ts, engine, s, extra)
    x_t, u_t, g_t, e_t = ev.x_trim, ev.u_ctrl_trim, np.zeros(3), ev.extra_trim
    n1_t = ev.n1_trim if engine == "dynamic" else None
    try:
        center = ev.evaluate(x_t, u_t, g_t, e_t, n1_t)
        h_x = np.array([s.step_vel_fps] * 3 + [s.step_angle_rad] * 6 + [s.step_h_ft])
        dZ, dF = [], []

        def knob(fn: Callable[[float], _Eval]) -> None:
            plus, minus = fn(+1.0), fn(-1.0)
            dZ.append(plus.z - minus.z)
            dF.append(plus.f - minus.f)

        for i in range(len(BODY_STATES)):
            def fx(sg: float, i: int = i) -> _Eval:
                x = x_t.copy()
                x[i] += sg * h_x[i]
                return ev.evaluate(x, u_t, g_t, e_t, n1_t)
            knob(fx)
        if engine == "dynamic":
            knob(lambda sg: ev.evaluate(x_t, u_t, g_t, e_t, n1_t + sg * s.step_n1_pct))
            knob(lambda sg: ev.evaluate(x_t, u_t, g_t, e_t, n1_t, thr_settle=sg * s.step_rpm_throttle))
        for j in range(len(CONTROL_INPUTS)):
            def fu(sg: float, j: int = j) -> _Eval:
                u = u_t.copy()
                u[j] += sg * s.step_cmd_norm
                return ev.evaluate(x_t, u, g_t, e_t, n1_t)
            knob(fu)
        for j in range(3):
            def fg(sg: float, j: int = j) -> _Eval:
                g = np.zeros(3)
                g[j] = sg * s.step_vel_fps
                return ev.evaluate(x_t, u_t, g, e_t, n1_t)
            knob(fg)
        for j, (_, step) in enumerate(extra.values()):
            def fe(sg: float, j: int = j, step: float = step) -> _Eval:
                e = e_t.copy()
                e[j] += sg * step
                return ev.evaluate(x_t, u_t, g_t, e, n1_t)
            knob(fe)
    finally:
        for prop in _GUST_PROPS:
            ac.fdm[prop] = 0.0
        for (prop, _), v in zip(extra.values(), e_t):
            ac.fdm[prop] = v
    Z = np.array(dZ).T  # columns: reached differences of each knob
    F = np.array(dF).T
    cond = float(np.linalg.cond(Z))
    if not np.isfinite(cond) or cond > 1e9:
        raise DesignError(f"central differences of {ac.name} at {tr.op.label()}: the perturbation matrix is "
                          f"singular (condition {cond:.3g}); a knob did not move its state. Check the step sizes "
                          "in FDSettings and that the engines run.")
    M = np.linalg.solve(Z.T, F.T).T  # M dZ = dF
    states = BODY_STATES + (ENGINE_STATES if engine == "dynamic" else ())
    n = len(states)
    inputs = CONTROL_INPUTS + GUST_INPUTS + tuple(extra)
    kinds = ("control",) * len(CONTROL_INPUTS) + ("disturbance",) * (len(GUST_INPUTS) + len(extra))
    zc = center.z
    return BodyJacobians(
        A=M[:n, :n], B=M[:n, n:], C=M[n:, :n], D=M[n:, n:],
        state_names=states, input_names=inputs, output_names=SENSOR_OUTPUTS, input_kinds=kinds,
        x0=zc[:n], u0=np.concatenate([u_t, g_t, e_t]), y0=center.f[n:], xdot0=center.f[:n],
        knob_condition=cond, engine=engine, elapsed_s=time.perf_counter() - t_start, notes=tuple(notes),
    )


# ---------------------------------------------------------------------- JSBSim's FGLinearization
@dataclass(frozen=True, eq=False)
class JsbsimLinearization:
    """The result of JSBSim's own ``FGLinearization`` (JSBSIM_NOTES sec. 4.1).

    Attributes
    ----------
    A, B : NDArray
        State and input matrices in JSBSim's state order and units.
    x_names, x_units, u_names : tuple of str
        JSBSim's names (``Vt``, ``Alpha``, ... ``Alt``; ``ThtlCmd``, ``DaCmd``, ``DeCmd``, ``DrCmd``).
    x0, u0 : NDArray
        Trim values.
    elapsed_s : float
        Wall time [s].
    """

    A: NDArray[np.float64]
    B: NDArray[np.float64]
    x_names: tuple[str, ...]
    x_units: tuple[str, ...]
    u_names: tuple[str, ...]
    x0: NDArray[np.float64]
    u0: NDArray[np.float64]
    elapsed_s: float


def fglinearization(ac: Aircraft, allow_propeller: bool = False) -> JsbsimLinearization:
    """Run JSBSim's ``FGLinearization`` about the current (just trimmed) state.

    Call it right after JSBSim's own trim. For propeller aircraft its ``Rpm`` rows and throttle
    column are wrong (the real step inside hits the turboprop N1 reset), and after the
    running-engine trim of the DHC-6 it does not converge (more than 15 min, JSBSIM_NOTES
    4.1), so it is refused unless ``allow_propeller`` (and then only right after JSBSim's trim).

    Raises
    ------
    DesignError
        Propeller aircraft without ``allow_propeller``.
    """
    if engine_model(ac, FDSettings()) == "dynamic" and not allow_propeller:
        raise DesignError(f"FGLinearization is not reliable for the propeller aircraft {ac.name} (Rpm rows and "
                          "throttle column wrong, no convergence after the running trim); use central_difference, "
                          "or pass allow_propeller=True right after a plain JSBSim trim")
    t0 = time.perf_counter()
    try:
        lin = jsbsim.FGLinearization(ac.fdm)
        A, B, _, _ = lin.state_space
    finally:
        # FGLinearization leaves the integration suspended (dt = 0): give the aircraft its step back
        if ac.fdm.integration_suspended():
            ac.fdm.resume_integration()
        ac.fdm.set_dt(ac.dt_s)
    return JsbsimLinearization(
        A=np.array(A, dtype=float), B=np.array(B, dtype=float), x_names=tuple(lin.x_names),
        x_units=tuple(lin.x_units), u_names=tuple(lin.u_names), x0=np.array(lin.x0, dtype=float),
        u0=np.array(lin.u0, dtype=float), elapsed_s=time.perf_counter() - t0,
    )


# ---------------------------------------------------------------------- nonlinear responses
@dataclass(frozen=True, eq=False)
class NonlinearResponse:
    """Outputs of a JSBSim run from a trim with input deviations applied.

    Attributes
    ----------
    t_s : NDArray
        Time after each step [s], shape (N,).
    y : NDArray
        Absolute outputs after each step, shape (N, p), ``psi_rad`` unwrapped.
    output_names : tuple of str
        Output order.
    """

    t_s: NDArray[np.float64]
    y: NDArray[np.float64]
    output_names: tuple[str, ...]


def simulate_inputs(ac: Aircraft, ts: TrimState, input_names: Sequence[str], du: NDArray[np.float64],
                    output_names: Sequence[str] = SENSOR_OUTPUTS,
                    extra_disturbances: Mapping[str, tuple[str, float]] | None = None) -> NonlinearResponse:
    """Fly ``len(du)`` steps from the trim ``ts`` with input deviations ``du`` added to it.

    Parameters
    ----------
    ac : Aircraft
        The aircraft; put back at ``ts`` first (:func:`restore_trim`), so every run starts
        from the same state.
    ts : TrimState
        The trim (from :func:`capture_trim`).
    input_names : sequence of str
        Names of the columns of ``du``: :data:`CONTROL_INPUTS`, :data:`GUST_INPUTS` (body axes at
        the trim attitude, applied as JSBSim gusts) or extra disturbances.
    du : NDArray
        Input deviations, shape (N, m); row k is applied before step k [units of the names].
    output_names : sequence of str
        Signals to record after each step.
    extra_disturbances : mapping, optional
        ``name -> (property, step)`` for extra disturbance columns.

    Returns
    -------
    NonlinearResponse
    """
    du = np.atleast_2d(np.asarray(du, dtype=float))
    names = tuple(input_names)
    if du.shape[1] != len(names):
        raise DesignError(f"du has {du.shape[1]} columns but {len(names)} input names were given")
    extras = {**OPTIONAL_DISTURBANCES, **dict(extra_disturbances or {})}
    fdm = ac.fdm
    freeze0 = fdm["propulsion/fuel_freeze"]
    fdm["propulsion/fuel_freeze"] = 1  # the mass must not change from run to run (nor within one)
    restore_trim(ac, ts)
    u0 = dict(zip(CONTROL_INPUTS, ts.u_cmd))
    writers: list[Callable[[float], None]] = []
    gust_cols: list[int] = []
    for j, name in enumerate(names):
        if name in ("elevator_cmd_norm", "aileron_cmd_norm", "rudder_cmd_norm"):
            node = ac.node(f"fcs/{name.replace('_cmd_norm', '')}-cmd-norm")
            writers.append(lambda v, node=node, base=u0[name]: node.set_double_value(base + v))
        elif name == "throttle_cmd_norm":
            nodes = [ac.node(f"fcs/throttle-cmd-norm[{i}]") for i in range(ac.n_engines)]

            def wthr(v: float, nodes: list = nodes, base: float = u0[name]) -> None:
                for n in nodes:
                    n.set_double_value(base + v)
            writers.append(wthr)
        elif name in GUST_INPUTS:
            gust_cols.append(j)
            writers.append(lambda v: None)
        elif name in extras and fdm.get_property_manager().hasNode(extras[name][0]):
            node = ac.node(extras[name][0])
            writers.append(lambda v, node=node, base=node.get_double_value(): node.set_double_value(base + v))
        else:
            raise DesignError(f"unknown input {name!r} for {ac.name}; known: "
                              f"{', '.join(CONTROL_INPUTS + GUST_INPUTS + tuple(extras))}")
    T_b2n = body_to_ned(*ts.x_body[6:9])
    gust_nodes = [ac.node(p) for p in _GUST_PROPS]
    gidx = [GUST_INPUTS.index(names[j]) for j in gust_cols]
    read = ac.reader(output_names)
    out = np.empty((du.shape[0], len(output_names)))
    t = np.empty(du.shape[0])
    g_b = np.zeros(3)
    try:
        for k in range(du.shape[0]):
            row = du[k]
            for j, w in enumerate(writers):
                w(row[j])
            if gust_cols:
                g_b[:] = 0.0
                for j, gi in zip(gust_cols, gidx):
                    g_b[gi] = row[j]
                for node, v in zip(gust_nodes, T_b2n @ g_b):
                    node.set_double_value(v)
            fdm.run()
            out[k] = read()
            t[k] = fdm.get_sim_time()
    finally:
        for node in gust_nodes:
            node.set_double_value(0.0)
        fdm["propulsion/fuel_freeze"] = freeze0
    if "psi_rad" in output_names:
        i = list(output_names).index("psi_rad")
        out[:, i] = ts.x_body[_PSI] + np.unwrap(np.r_[0.0, [_wrap(v - ts.x_body[_PSI]) for v in out[:, i]]])[1:]
    if not np.all(np.isfinite(out)):
        k = int(np.argmax(~np.all(np.isfinite(out), axis=1)))
        raise DesignError(f"{ac.name} at {ts.op.label()}: the nonlinear run produced NaN at t = {t[k]:.3f} s; "
                          "reduce the doublet amplitude or move the point inside the envelope")
    return NonlinearResponse(t_s=t, y=out, output_names=tuple(output_names))
