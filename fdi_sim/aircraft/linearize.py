"""JSBSim side of the linearizer: central differences about a trim.

The JSBSim side is four modules: this one (the Jacobians), :mod:`.linearize_state` (signal
sets, writing a state into JSBSim, capturing and restoring a trim), :mod:`.linearize_fglin`
(JSBSim's own FGLinearization, the F-16 cross-check) and :mod:`.linearize_response` (the
nonlinear doublet runs). The maths on the resulting matrices (body -> aero transform,
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

Passes of one simulation step (the step model)
----------------------------------------------
The Jacobians above are *settled*: every evaluation repeats the model until the signals that
JSBSim carries from one pass to the next have caught up with the perturbed state. The simulation
does not wait: in ``FGFDMExec::Run`` the FCS runs before FGAuxiliary, so the F-16 FBW reads rates,
alpha and air data one step late and the pilot-station accelerations two steps late; the aero
model reads alpha-dot and (DHC-6) ``aero/cl-squared`` from the previous pass. :func:`pass_jacobians`
measures how the derivatives build up pass by pass from a settled trim:

* inputs (commands, gusts, disturbances): the input is changed and the model run pass by pass with
  tiny real steps, exactly as the simulation meets a new input;
* air-relative velocity (Vt, alpha, beta): through the gust columns, which move the air-relative
  velocity without a ``run_ic`` (``run_ic`` runs *two* passes, ``FGFDMExec::Initialize`` runs one,
  and refreshes the air data the FCS reads), plus the kinematic terms, which act at once;
* rates, attitude and altitude: ``run_ic`` at the perturbed state; its second pass is the
  simulation's second pass. For the first pass of rates and altitude the FCS outputs are frozen
  at the trim (its inputs are stale there); attitude is read by the FCS from FGPropagate, fresh.

``fdi_sim.linear.step`` turns these into the discrete model of JSBSim's step (third-order
Adams-Bashforth, :class:`~fdi_sim.aircraft.model.Aircraft`).

Engines
-------
* ``"quasi_static"`` (F-16 default): thrust follows the throttle at once. The F100 spools by a
  rate-limited ``Seek`` that crosses a small throttle step within a few steps, so no state is
  needed; a rate limit has no linearization anyway.
* ``"dynamic"`` (DHC-6 default): states ``n1_pct`` (PT6A gas generator, first-order lag of 1 s
  up, 2.4 s down in ``FGTurboProp::Run``; the central difference averages the two slopes) and
  ``prop_rpm`` (propeller on its fine-pitch stop, torque balance). Both engines are moved
  together, so each state is the mean of the two engines. A quasi-static DHC-6 model misses
  this 1-2 s thrust lag (the N1 row against the engine source: ``test_dhc6_engine_rows_follow_the_engine_source``).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Mapping

import jsbsim
import numpy as np
from numpy.typing import NDArray

from fdi_sim.aircraft.linearize_state import (
    BODY_STATES, CONTROL_INPUTS, ENGINE_STATES, GUST_INPUTS, GUST_PROPS, LAGGED_OUTPUTS, OPTIONAL_DISTURBANCES,
    SENSOR_OUTPUTS, TrimState, capture_trim, command_props, engine_reader, has_propeller, restore_trim, set_state,
    wrap_rad,
)
from fdi_sim.aircraft.model import Aircraft
from fdi_sim.aircraft.trim import TrimResult
from fdi_sim.errors import DesignError

_DERIV_PROPS: tuple[str, ...] = (
    "accelerations/udot-ft_sec2", "accelerations/vdot-ft_sec2", "accelerations/wdot-ft_sec2",
    "accelerations/pdot-rad_sec2", "accelerations/qdot-rad_sec2", "accelerations/rdot-rad_sec2",
    "velocities/phidot-rad_sec", "velocities/thetadot-rad_sec", "velocities/psidot-rad_sec",
    "velocities/h-dot-fps",
)
_PSI = BODY_STATES.index("psi_rad")
_PSI_Y = SENSOR_OUTPUTS.index("psi_rad")
_ENGINE_MODELS: tuple[str, ...] = ("auto", "dynamic", "quasi_static")


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
    step_rpm_throttle_norm : float
        Throttle offset used while the engines settle, to move the propeller speed [-].
    n_settle : int
        Tiny real steps per evaluation.
    dt_eval_s : float
        Length of each tiny step [s].
    engine : str
        ``"auto"`` (dynamic for propeller aircraft, quasi-static otherwise), ``"dynamic"`` or
        ``"quasi_static"``.
    step_passes : int
        Passes measured by :func:`pass_jacobians` for the step model (0: none). Five cover the
        F-16 FBW chains to 4e-4 of the largest entry (the pilot-station accelerations reach the
        FCS in the third pass, the PID derivative terms settle in the fourth).
    """

    step_vel_fps: float = 0.1
    step_angle_rad: float = 1e-3
    step_h_ft: float = 1.0
    step_cmd_norm: float = 1e-3
    step_n1_pct: float = 0.1
    step_rpm_throttle_norm: float = 0.005
    n_settle: int = 5
    dt_eval_s: float = 1e-6
    engine: str = "auto"
    step_passes: int = 5


@dataclass(frozen=True, eq=False)
class PassJacobians:
    """Derivatives of the rigid-body states pass by pass from a settled trim (body axes).

    ``Ax[k]`` and ``Bu[k]`` are the Jacobians of the 10 :data:`BODY_STATES` derivatives after
    pass ``k + 1`` of the model with the state or input changed before pass 1; the last pass is
    taken as settled (``fdi_sim.linear.step`` makes the last entry equal to the settled ``A``, ``B``).

    Attributes
    ----------
    Ax : NDArray
        Shape (P, 10, n): columns are all states of the model (engine columns act at once).
    Bu : NDArray
        Shape (P, 10, m), columns the model inputs.
    Lf : NDArray
        Shape (q, 10): the lagged outputs (:data:`LAGGED_OUTPUTS`) as JSBSim computes them in the
        next pass, from the state derivatives of this one (the rest, ``C x + D u - Lf (A x + B u)``,
        follows from the settled model).
    lagged_outputs : tuple of str
        The outputs of ``Lf``.
    dt_s : float
        The simulation step the passes belong to [s].
    lf_residual : float
        Relative residual of the least-squares fit of ``Lf`` [-].
    """

    Ax: NDArray[np.float64]
    Bu: NDArray[np.float64]
    Lf: NDArray[np.float64]
    lagged_outputs: tuple[str, ...]
    dt_s: float
    lf_residual: float


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
    passes : PassJacobians or None
        The pass-by-pass Jacobians of the step model (:func:`pass_jacobians`), if measured.
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
    passes: PassJacobians | None = None


@dataclass(frozen=True)
class _Eval:
    z: NDArray[np.float64]      # reached states and inputs
    f: NDArray[np.float64]      # state derivatives and outputs


def engine_model(ac: Aircraft, settings: FDSettings) -> str:
    """The engine model used for ``ac``: ``"dynamic"`` or ``"quasi_static"``.

    Raises
    ------
    DesignError
        An unknown ``settings.engine``, or ``"dynamic"`` for an aircraft without propellers
        (its engine states are the propeller's).
    """
    if settings.engine not in _ENGINE_MODELS:
        raise DesignError(f"FDSettings.engine = {settings.engine!r}; use 'auto', 'dynamic' or 'quasi_static'")
    propeller = has_propeller(ac)
    if settings.engine == "auto":
        return "dynamic" if propeller else "quasi_static"
    if settings.engine == "dynamic" and not propeller:
        raise DesignError(f"FDSettings.engine = 'dynamic' needs propeller engines (states {ENGINE_STATES}); "
                          f"{ac.name} has none: use 'auto' or 'quasi_static'")
    return settings.engine


class _Evaluator:
    """Sets a perturbed state/input in JSBSim and reads derivatives and outputs.

    The perturbed vector ``v`` is :data:`BODY_STATES`, :data:`CONTROL_INPUTS`,
    :data:`GUST_INPUTS` and the extra disturbances, in that order.
    """

    def __init__(self, ac: Aircraft, ts: TrimState, dynamic: bool, settings: FDSettings,
                 extra_props: list[str]) -> None:
        self.ac, self.ts, self.dynamic, self.s, self.extra_props = ac, ts, dynamic, settings, extra_props
        nx, nu, ng = len(BODY_STATES), len(CONTROL_INPUTS), len(GUST_INPUTS)
        self.splits = (nx, nx + nu, nx + nu + ng)
        self.read_x = ac.reader(BODY_STATES)
        self.read_y = ac.reader(SENSOR_OUTPUTS)
        self._engine_state = engine_reader(ac) if dynamic else None

    def evaluate(self, v: NDArray[np.float64], dn1_pct: float = 0.0, thr_settle_norm: float = 0.0) -> _Eval:
        """Derivatives and outputs at ``v``; the dynamic engine's N1 offset by ``dn1_pct`` [%]."""
        fdm = self.ac.fdm
        x, u, gust_b, extra = np.split(v, self.splits)
        for prop, val in zip(self.extra_props, extra):
            fdm[prop] = val
        n1 = self.ts.n1_pct + dn1_pct if self.dynamic and self.ts.n1_pct is not None else None
        set_state(self.ac, self.ts, x, u, gust_b, n1, thr_settle_norm)
        fdm.set_dt(self.s.dt_eval_s)
        try:
            eng_before = np.zeros(2)
            for _ in range(self.s.n_settle):
                if self.dynamic:
                    eng_before = self._engine_state()
                fdm.run()
        finally:
            fdm.set_dt(self.ac.dt_s)
        xr = self.read_x()
        xr[_PSI] = x[_PSI] + wrap_rad(xr[_PSI] - x[_PSI])
        xdot = np.array([fdm[p] for p in _DERIV_PROPS])
        y = self.read_y()
        y[_PSI_Y] = x[_PSI] + wrap_rad(y[_PSI_Y] - x[_PSI])
        if not self.dynamic:
            return _Eval(z=np.concatenate([xr, u, gust_b, extra]), f=np.concatenate([xdot, y]))
        # engine: the state at the start of the last tiny step and its rate over that step
        eng_rate = (self._engine_state() - eng_before) / self.s.dt_eval_s
        return _Eval(z=np.concatenate([xr, eng_before, u, gust_b, extra]), f=np.concatenate([xdot, eng_rate, y]))


def _disturbance_columns(ac: Aircraft, extra_disturbances: Mapping[str, tuple[str, float]] | None
                         ) -> tuple[dict[str, tuple[str, float]], list[str]]:
    """The extra disturbance columns ``name -> (property, step)`` and notes on the optional ones left out."""
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
    return extra, notes


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
    extra, notes = _disturbance_columns(ac, extra_disturbances)
    ts = capture_trim(ac, tr)
    extra_props = [prop for prop, _ in extra.values()]
    extra_trim = np.array([ac[p] for p in extra_props])
    ev = _Evaluator(ac, ts, engine == "dynamic", s, extra_props)
    # the knob vector (states, commands, gusts, extras) at the trim and the step of each knob
    v0 = np.concatenate([ts.x_body, ts.u_cmd, np.zeros(len(GUST_INPUTS)), extra_trim])
    h = np.concatenate([[s.step_vel_fps] * 3 + [s.step_angle_rad] * 6 + [s.step_h_ft],
                        [s.step_cmd_norm] * len(CONTROL_INPUTS), [s.step_vel_fps] * len(GUST_INPUTS),
                        [step for _, step in extra.values()]])
    dZ, dF = [], []

    def knob(plus: _Eval, minus: _Eval) -> None:
        dZ.append(plus.z - minus.z)
        dF.append(plus.f - minus.f)

    def axis_knob(i: int) -> None:
        e = np.zeros(v0.size)
        e[i] = h[i]
        knob(ev.evaluate(v0 + e), ev.evaluate(v0 - e))

    nx = len(BODY_STATES)
    try:
        center = ev.evaluate(v0)
        for i in range(nx):
            axis_knob(i)
        if engine == "dynamic":  # N1 directly; the propeller speed through the settling throttle
            knob(ev.evaluate(v0, dn1_pct=s.step_n1_pct), ev.evaluate(v0, dn1_pct=-s.step_n1_pct))
            knob(ev.evaluate(v0, thr_settle_norm=s.step_rpm_throttle_norm),
                 ev.evaluate(v0, thr_settle_norm=-s.step_rpm_throttle_norm))
        for i in range(nx, v0.size):
            axis_knob(i)
    finally:
        for prop in GUST_PROPS:
            ac.fdm[prop] = 0.0
        for prop, val in zip(extra_props, extra_trim):
            ac.fdm[prop] = val
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
    kinds = ("control",) * len(CONTROL_INPUTS) + ("disturbance",) * (len(GUST_INPUTS) + len(extra))
    inputs = CONTROL_INPUTS + GUST_INPUTS + tuple(extra)
    passes = None
    if s.step_passes > 0:
        passes = pass_jacobians(ac, ts, M[:n, :n], M[:n, n:], M[n:, :n], inputs, extra, s)
    return BodyJacobians(
        A=M[:n, :n], B=M[:n, n:], C=M[n:, :n], D=M[n:, n:],
        state_names=states, input_names=inputs, output_names=SENSOR_OUTPUTS,
        input_kinds=kinds, x0=center.z[:n], u0=v0[nx:], y0=center.f[n:], xdot0=center.f[:n],
        knob_condition=cond, engine=engine, elapsed_s=time.perf_counter() - t_start, notes=tuple(notes),
        passes=passes,
    )


#: state columns whose first pass is measured with the FCS outputs frozen at the trim: the FCS
#: reads rates and air data (FGAuxiliary, after the FCS in FGFDMExec::Run) one step late, but the
#: attitude (FGPropagate, first in the step) fresh
_FROZEN_FIRST_PASS: tuple[str, ...] = ("p_radps", "q_radps", "r_radps", "h_ft")
_N_RIGID = len(BODY_STATES)


def _fcs_output_nodes(ac: Aircraft) -> list[object]:
    """Every writable ``fcs/`` node except the pilot's commands (the FCS outputs to freeze)."""
    pm = ac.fdm.get_property_manager()
    names = [c.split(" ")[0] for c in ac.fdm.get_property_catalog() if c.startswith("fcs/") and "(RW)" in c]
    return [pm.get_node(n, False) for n in names if "-cmd-norm" not in n]


def pass_jacobians(ac: Aircraft, ts: TrimState, A: NDArray[np.float64], B: NDArray[np.float64],
                   C: NDArray[np.float64], input_names: tuple[str, ...],
                   extra: Mapping[str, tuple[str, float]], settings: FDSettings) -> PassJacobians:
    """Derivatives pass by pass after a state or input change from a settled trim (see the module notes).

    Parameters
    ----------
    ac : Aircraft
        The aircraft at the trim ``ts``; left there afterwards.
    ts : TrimState
        The trim.
    A, B, C : NDArray
        The settled body Jacobians of :func:`central_difference` (the last pass is scaled onto them).
    input_names : tuple of str
        The model inputs (:data:`CONTROL_INPUTS`, :data:`GUST_INPUTS`, then the keys of ``extra``).
    extra : mapping
        ``name -> (property, step)`` of the extra disturbance columns.
    settings : FDSettings
        ``step_passes`` passes of ``dt_eval_s``; the step sizes of the central differences.

    Returns
    -------
    PassJacobians

    Notes
    -----
    The throttle columns are the settled ones at every pass: the throttle acts through the engine
    (its states, or its quasi-static thrust), which a 1e-6 s pass does not move.
    """
    fdm = ac.fdm
    P, nr, n = settings.step_passes, _N_RIGID, A.shape[0]
    dyn = ts.n1_pct is not None and n > nr
    read_lag = ac.reader(LAGGED_OUTPUTS)
    engine = engine_reader(ac) if dyn else None

    restore_trim(ac, ts)  # central_difference leaves the aircraft at its last evaluation
    e_trim = engine() if engine is not None else np.zeros(0)

    def derivs() -> NDArray[np.float64]:
        f = np.array([fdm[p] for p in _DERIV_PROPS])
        if engine is not None:  # an engine that moved off its trim (steady state of a perturbed point) acts through A
            f -= A[:nr, nr:] @ (engine() - e_trim)
        return f

    def settle() -> None:
        restore_trim(ac, ts)
        for _ in range(settings.n_settle):
            fdm.run()

    def setter(name: str) -> tuple[list[str], float]:
        if name in CONTROL_INPUTS:
            return command_props(ac, name), float(ts.u_cmd[CONTROL_INPUTS.index(name)])
        prop = extra[name][0]
        return [prop], float(fdm[prop])

    steps = {**{nm: settings.step_cmd_norm for nm in CONTROL_INPUTS}, **{nm: settings.step_vel_fps for nm in GUST_INPUTS},
             **{nm: st for nm, (_, st) in extra.items()}}
    Fu = np.zeros((P, nr, len(input_names)))
    Yu = np.zeros((P, len(LAGGED_OUTPUTS), len(input_names)))
    cols = range(3, nr)  # rates, attitude, altitude: the states after the body velocity
    Rx = np.zeros((P, nr, len(cols)))
    nodes = _fcs_output_nodes(ac)
    fdm.set_dt(settings.dt_eval_s)
    try:
        for j, name in enumerate(input_names):
            h = steps[name]
            for sign in (1.0, -1.0):
                settle()
                props, base = setter(name) if name not in GUST_INPUTS else ([], 0.0)
                for prop in props:
                    fdm[prop] = base + sign * h
                if name in GUST_INPUTS:  # body-axis gust at the trim attitude -> JSBSim's NED gust
                    g_ned = ts.T_b2n @ (sign * h * np.eye(3)[GUST_INPUTS.index(name)])
                    for prop, v in zip(GUST_PROPS, g_ned):
                        fdm[prop] = v
                for k in range(P):
                    fdm.run()
                    Fu[k, :, j] += sign * derivs() / (2 * h)
                    Yu[k, :, j] += sign * read_lag() / (2 * h)
                for prop in props:
                    fdm[prop] = base
                for prop in GUST_PROPS:
                    fdm[prop] = 0.0
        for c, i in enumerate(cols):
            frozen = BODY_STATES[i] in _FROZEN_FIRST_PASS
            h = settings.step_h_ft if BODY_STATES[i] == "h_ft" else settings.step_angle_rad
            for sign in (1.0, -1.0):
                x = ts.x_body.copy()
                x[i] += sign * h
                seq = []
                if frozen:  # first pass: the FCS outputs stay at the trim (their inputs are stale)
                    settle()
                    for node in nodes:
                        node.set_attribute(jsbsim.Attribute.WRITE, False)
                    try:
                        set_state(ac, ts, x, ts.u_cmd, None, ts.n1_pct)
                    finally:
                        for node in nodes:
                            node.set_attribute(jsbsim.Attribute.WRITE, True)
                    seq.append(derivs())
                settle()
                set_state(ac, ts, x, ts.u_cmd, None, ts.n1_pct)  # run_ic: the simulation's second pass
                seq.append(derivs())
                while len(seq) < P:
                    fdm.run()
                    seq.append(derivs())
                if not frozen:  # attitude: the FCS reads it fresh, so pass 1 equals pass 2
                    seq = [seq[0]] + seq[:P - 1]
                Rx[:, :, c] += sign * np.array(seq) / (2 * h)
    finally:
        fdm.set_dt(ac.dt_s)
        for prop in GUST_PROPS:
            fdm[prop] = 0.0
        restore_trim(ac, ts)
    # the last pass is taken as settled: shift every sequence onto the settled Jacobians
    ig = [input_names.index(g) for g in GUST_INPUTS]
    Fv = -Fu[:, :, ig]  # d f / d(air-relative body velocity) = -d f / d(gust), pass by pass
    Ax = np.repeat(A[None, :nr, :], P, axis=0)
    Ax[:, :, :3] -= Fv[-1][None] - Fv
    Ax[:, :, 3:nr] -= Rx[-1][None] - Rx
    Bu = B[None, :nr, :] - (Fu[-1][None] - Fu)
    if "throttle_cmd_norm" in input_names:
        Bu[:, :, input_names.index("throttle_cmd_norm")] = B[:nr, input_names.index("throttle_cmd_norm")]
    # lagged outputs of pass k + 1 are computed from the derivatives of pass k: Y_{k+1} = Lf F_k
    X = Fu[:-1].transpose(1, 0, 2).reshape(nr, -1)
    Y = Yu[1:].transpose(1, 0, 2).reshape(len(LAGGED_OUTPUTS), -1)
    Lf = np.linalg.lstsq(X.T, Y.T, rcond=None)[0].T
    res = float(np.max(np.abs(Lf @ X - Y)) / max(np.max(np.abs(Y)), 1e-300))
    return PassJacobians(Ax=Ax, Bu=Bu, Lf=Lf, lagged_outputs=LAGGED_OUTPUTS, dt_s=float(ac.dt_s), lf_residual=res)


