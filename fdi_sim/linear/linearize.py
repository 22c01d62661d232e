"""Linear models for FDI from the JSBSim Jacobians: body -> aero states, selection, assembly.

The state is ``[vt_fps alpha_rad beta_rad p_radps q_radps r_radps phi_rad theta_rad psi_rad h_ft]``
(plus ``n1_pct prop_rpm`` for the DHC-6 turboprops), the outputs are the sensor suite of
:data:`~fdi_sim.aircraft.linearize.SENSOR_OUTPUTS` (so ``C`` and ``D`` hold the accelerometers
and the air data), the inputs are the four pilot commands followed by the disturbance columns
(body-axis gust velocities; ``icing_eta`` when the iced overlay exists).

``Vt``, ``alpha`` and ``beta`` of the state are those of the Earth-relative body velocity, which
equals the air-relative one at the (calm) trim. A gust therefore does not move the state directly;
it enters through ``B`` (forces) and through ``D`` into the air-data outputs ``alpha_rad``,
``beta_rad`` and ``vc_kts``, which the sensors measure relative to the air.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.aircraft.linearize import (
    LAGGED_OUTPUTS, BodyJacobians, FDSettings, JsbsimLinearization, TrimState, capture_trim, central_difference,
    fglinearization,
)
from fdi_sim.aircraft.model import Aircraft
from fdi_sim.aircraft.trim import TrimResult, trim
from fdi_sim.errors import DesignError, TrimError
from fdi_sim.linear.model import LinearModel
from fdi_sim.operating_point import OperatingPoint
from fdi_sim.units import KT_PER_FPS

#: aero-axis rigid-body state, in order
AERO_STATES: tuple[str, ...] = (
    "vt_fps", "alpha_rad", "beta_rad", "p_radps", "q_radps", "r_radps", "phi_rad", "theta_rad", "psi_rad", "h_ft",
)
#: default detector rate: the simulation's 120 Hz
DEFAULT_DT_S: float = 1.0 / 120.0

#: FGLinearization state name -> our aero state name (Lat/Lon/Rpm have no counterpart)
_FGLIN_TO_AERO: dict[str, str] = {
    "Vt": "vt_fps", "Alpha": "alpha_rad", "Beta": "beta_rad", "P": "p_radps", "Q": "q_radps", "R": "r_radps",
    "Phi": "phi_rad", "Theta": "theta_rad", "Psi": "psi_rad", "Alt": "h_ft",
}


def uvw_to_aero_jacobian(u_fps: float, v_fps: float, w_fps: float) -> NDArray[np.float64]:
    """Jacobian of (Vt, alpha, beta) with respect to body velocity (u, v, w).

    ``Vt = |(u, v, w)|``, ``alpha = atan2(w, u)``, ``beta = asin(v / Vt)`` (JSBSim's definitions).

    Returns
    -------
    NDArray
        3x3 matrix, rows (Vt [ft/s], alpha [rad], beta [rad]), columns (u, v, w) [ft/s].
    """
    vt = math.sqrt(u_fps**2 + v_fps**2 + w_fps**2)
    uw2 = u_fps**2 + w_fps**2
    if vt < 1.0 or uw2 <= 0.0:
        raise DesignError(f"airspeed {vt:.3g} ft/s is too low to define alpha and beta; trim at flying speed")
    uw = math.sqrt(uw2)
    return np.array([
        [u_fps / vt, v_fps / vt, w_fps / vt],           # dVt = (u du + v dv + w dw) / Vt
        [-w_fps / uw2, 0.0, u_fps / uw2],               # dalpha = (u dw - w du) / (u^2 + w^2)
        # dbeta = (Vt dv - v dVt) / (Vt^2 cos beta),  cos beta = sqrt(u^2 + w^2) / Vt
        [-u_fps * v_fps / (vt**2 * uw), uw / vt**2, -v_fps * w_fps / (vt**2 * uw)],
    ])


def body_to_aero(bj: BodyJacobians) -> BodyJacobians:
    """Change the velocity states from body (u, v, w) to aero (Vt, alpha, beta).

    A similarity transform ``x_a = T x_b`` with ``T = diag(J, I)`` and ``J`` from
    :func:`uvw_to_aero_jacobian` at the trim: ``A_a = T A T^-1``, ``B_a = T B``, ``C_a = C T^-1``,
    ``D_a = D``. Eigenvalues and input-output behaviour are unchanged.
    """
    if bj.state_names[:3] != ("u_body_fps", "v_body_fps", "w_body_fps"):
        raise DesignError(f"body_to_aero expects body velocity states first, got {bj.state_names[:3]}")
    n = len(bj.state_names)
    u, v, w = bj.x0[:3]
    T = np.eye(n)
    T[:3, :3] = uvw_to_aero_jacobian(u, v, w)
    Ti = np.linalg.inv(T)
    x0 = bj.x0.copy()
    x0[:3] = [math.sqrt(u * u + v * v + w * w), math.atan2(w, u), math.asin(v / math.sqrt(u * u + v * v + w * w))]
    xdot0 = T @ bj.xdot0
    return replace(
        bj, A=T @ bj.A @ Ti, B=T @ bj.B, C=bj.C @ Ti, D=bj.D.copy(),
        state_names=AERO_STATES + bj.state_names[len(AERO_STATES):], x0=x0, xdot0=xdot0,
    )


def to_linear_model(bj: BodyJacobians, op: OperatingPoint | None = None, meta: dict[str, Any] | None = None) -> LinearModel:
    """Assemble a continuous-time :class:`LinearModel` in aero states from body Jacobians."""
    aero = body_to_aero(bj) if bj.state_names[0] == "u_body_fps" else bj
    return LinearModel(
        A=aero.A, B=aero.B, C=aero.C, D=aero.D, dt_s=0.0, state_names=aero.state_names,
        input_names=aero.input_names, output_names=aero.output_names, input_kinds=aero.input_kinds,
        x0=aero.x0, u0=aero.u0, y0=aero.y0, op=op,
        meta={"engine": aero.engine, "knob_condition": aero.knob_condition, "notes": list(aero.notes),
              "lagged_outputs": [n for n in LAGGED_OUTPUTS if n in aero.output_names], **(meta or {})},
    )


def select(model: LinearModel, outputs: Sequence[str] | None = None, inputs: Sequence[str] | None = None) -> LinearModel:
    """Keep only some outputs and inputs (in the order given); the state is unchanged.

    Raises
    ------
    DesignError
        A name is not in the model (the message lists the available ones).
    """
    def idx(names: Sequence[str] | None, have: tuple[str, ...], what: str) -> list[int]:
        if names is None:
            return list(range(len(have)))
        missing = [n for n in names if n not in have]
        if missing:
            raise DesignError(f"{what} {missing} not in the model; available: {', '.join(have)}")
        return [have.index(n) for n in names]

    io, ii = idx(outputs, model.output_names, "outputs"), idx(inputs, model.input_names, "inputs")
    return LinearModel(
        A=model.A, B=model.B[:, ii], C=model.C[io], D=model.D[np.ix_(io, ii)], dt_s=model.dt_s,
        state_names=model.state_names, input_names=tuple(model.input_names[i] for i in ii),
        output_names=tuple(model.output_names[i] for i in io),
        input_kinds=tuple(model.input_kinds[i] for i in ii), x0=model.x0, u0=model.u0[ii], y0=model.y0[io],
        op=model.op, meta=dict(model.meta),
    )


def drop_states(model: LinearModel, names: Sequence[str], rtol: float = 1e-3) -> LinearModel:
    """Remove states that no other state and no output depends on (e.g. ``psi_rad`` when heading is unused).

    A state ``j`` may be dropped only if column ``j`` of ``A`` (rows of the kept states) and of
    ``C`` is negligible: ``|M[i, j]| <= rtol * max_k |M[i, k]|`` for every such row ``i``.

    Raises
    ------
    DesignError
        A state to drop feeds another state or an output.
    """
    keep = [i for i, s in enumerate(model.state_names) if s not in names]
    drop = [model.state_names.index(s) for s in names if s in model.state_names]
    missing = [s for s in names if s not in model.state_names]
    if missing:
        raise DesignError(f"states {missing} not in the model; states are {', '.join(model.state_names)}")
    for j in drop:
        for M, rows, what in ((model.A, keep, "state"), (model.C, range(model.n_outputs), "output")):
            for i in rows:
                row_scale = np.max(np.abs(M[i])) or 1.0
                if abs(M[i, j]) > rtol * row_scale:
                    who = model.state_names[i] if what == "state" else model.output_names[i]
                    raise DesignError(f"cannot drop {model.state_names[j]}: {what} {who} depends on it "
                                      f"({M[i, j]:.3g}); drop the output first or keep the state")
    return LinearModel(
        A=model.A[np.ix_(keep, keep)], B=model.B[keep], C=model.C[:, keep], D=model.D, dt_s=model.dt_s,
        state_names=tuple(model.state_names[i] for i in keep), input_names=model.input_names,
        output_names=model.output_names, input_kinds=model.input_kinds, x0=model.x0[keep], u0=model.u0,
        y0=model.y0, op=model.op, meta=dict(model.meta),
    )


def fglin_in_aero_order(jl: JsbsimLinearization, state_names: Sequence[str]) -> NDArray[np.float64]:
    """FGLinearization's ``A`` restricted and reordered to our aero states (Lat, Lon, Rpm dropped)."""
    ours = {v: k for k, v in _FGLIN_TO_AERO.items()}
    idx = [jl.x_names.index(ours[s]) for s in state_names if s in ours]
    return jl.A[np.ix_(idx, idx)]


@dataclass(frozen=True, eq=False)
class LinearizedPoint:
    """One grid point after trim and linearization.

    Attributes
    ----------
    op : OperatingPoint
        The requested point.
    status : str
        ``"ok"``, ``"untrimmable"`` or ``"skipped"``.
    reason : str
        Why a point is not ``"ok"`` (the trim's own message, or the missing overlay).
    trim : dict
        Trimmed values (``alpha_rad``, ``theta_rad``, ``vt_fps``, ``vc_kts``, ``mach``, commands,
        ``residual``, ``method``) or empty.
    model : LinearModel or None
        Continuous-time model in aero states (``dt_s = 0``).
    fglin_eigs : NDArray or None
        Eigenvalues of FGLinearization's ``A`` on the same states (F-16 cross-check) [1/s].
    timing_s : dict
        Wall time of ``trim``, ``fd`` and ``fglin`` [s].
    trim_state : TrimState or None
        What :func:`~fdi_sim.aircraft.linearize.restore_trim` needs to fly from this trim again.
    """

    op: OperatingPoint
    status: str
    reason: str = ""
    trim: dict[str, float | str] = field(default_factory=dict)
    model: LinearModel | None = None
    fglin_eigs: NDArray[np.complex128] | None = None
    timing_s: dict[str, float] = field(default_factory=dict)
    trim_state: TrimState | None = None


def trim_summary(ac: Aircraft, tr: TrimResult) -> dict[str, float | str]:
    """The trimmed values stored with each schedule point."""
    return {
        "alpha_rad": tr.alpha_rad, "beta_rad": tr.beta_rad, "phi_rad": tr.phi_rad, "theta_rad": tr.theta_rad,
        "vt_fps": tr.vt_fps, "vt_kts": tr.vt_fps * KT_PER_FPS, "vc_kts": tr.vc_kts, "mach": ac["velocities/mach"],
        "elevator_cmd_norm": tr.elevator_cmd_norm, "aileron_cmd_norm": tr.aileron_cmd_norm,
        "rudder_cmd_norm": tr.rudder_cmd_norm, "throttle_cmd_norm": tr.throttle_cmd_norm,
        "pitch_trim_cmd_norm": tr.pitch_trim_cmd_norm, "residual": tr.residual, "method": tr.method,
    }


def overlay_problem(ac: Aircraft, op: OperatingPoint) -> str:
    """Why ``op`` cannot be flown on ``ac`` for lack of a model overlay, or ``""``."""
    if op.icing_eta and not ac.fdm.get_property_manager().hasNode("icing/eta"):
        return (f"icing overlay not available: JSBSim model {ac.name} has no icing/eta property, so "
                f"eta = {op.icing_eta:g} cannot be flown (the iced DHC-6 overlay comes with the icing issue)")
    return ""


def linearize(ac: Aircraft, op: OperatingPoint, settings: FDSettings | None = None,
              check_fglin: bool | None = None) -> LinearizedPoint:
    """Trim ``ac`` at ``op`` and linearize it (continuous time, aero states).

    Parameters
    ----------
    ac : Aircraft
        A loaded aircraft whose name matches ``op.aircraft``.
    op : OperatingPoint
        Where to linearize.
    settings : FDSettings, optional
        Central-difference settings.
    check_fglin : bool, optional
        Also run JSBSim's FGLinearization and keep its eigenvalues (default: for aircraft without
        propellers, where it is reliable; 0.1-0.4 s per point).

    Returns
    -------
    LinearizedPoint
        ``status = "untrimmable"`` with the reason instead of raising when the trim fails.
    """
    if op.aircraft != ac.name:
        raise DesignError(f"operating point is for {op.aircraft!r} but the aircraft is {ac.name!r}")
    problem = overlay_problem(ac, op)
    if problem:
        return LinearizedPoint(op=op, status="skipped", reason=problem)
    timing: dict[str, float] = {}
    t0 = time.perf_counter()
    try:
        tr = trim(ac, op)
    except TrimError as exc:
        return LinearizedPoint(op=op, status="untrimmable", reason=exc.reason, timing_s={"trim": time.perf_counter() - t0})
    timing["trim"] = time.perf_counter() - t0
    summary = trim_summary(ac, tr)
    ts = capture_trim(ac, tr)
    s = settings or FDSettings()
    propeller = ac.fdm.get_property_manager().hasNode("propulsion/engine[0]/propeller-rpm")
    fg_eigs = None
    if check_fglin if check_fglin is not None else not propeller:
        if propeller:
            raise DesignError("FGLinearization cross-check is not available for propeller aircraft (JSBSIM_NOTES 4.1)")
        jl = fglinearization(ac)  # right after JSBSim's trim, as it needs
        timing["fglin"] = jl.elapsed_s
        fg_eigs = np.linalg.eigvals(fglin_in_aero_order(jl, AERO_STATES))
    bj = central_difference(ac, tr, s)
    timing["fd"] = bj.elapsed_s
    meta = {"aircraft": ac.name, "method": "central differences about the trim (fdi_sim.aircraft.linearize)",
            "trim_method": tr.method}
    model = to_linear_model(bj, op=op, meta=meta)
    return LinearizedPoint(op=op, status="ok", trim=summary, model=model, fglin_eigs=fg_eigs, timing_s=timing,
                           trim_state=ts)


#: discretization methods of :func:`discretize`
DISCRETIZATIONS: tuple[str, ...] = ("zoh", "euler")


def discretize(model: LinearModel, dt_s: float = DEFAULT_DT_S, method: str = "zoh",
               lag_outputs: bool = True) -> LinearModel:
    """Discretize at the detector rate ``dt_s`` [s] (default 1/120 s).

    Parameters
    ----------
    model : LinearModel
        Continuous-time model.
    dt_s : float
        Sample time [s].
    method : str
        ``"zoh"`` (zero-order hold, exact for a held input; the default) or ``"euler"``
        (``A_d = I + dt A``, ``B_d = dt B``). JSBSim integrates the body rates and the attitude
        with rectangular Euler by default (``simulation/integrator/rate/rotational = 1``), which
        takes damping out of oscillatory modes: on the DHC-6 Dutch roll (4.4 rad/s) about
        ``omega^2 dt / 2 = 0.08 1/s``. At the simulation step, ``"euler"`` follows JSBSim more
        closely (DHC-6 doublets: ``p_radps`` error 13 % with ZOH, 4 % with Euler); at any other
        rate use ZOH.
    lag_outputs : bool
        Delay the outputs in ``model.meta["lagged_outputs"]`` by one step (see below).

    Notes
    -----
    The pilot-station accelerations are computed by JSBSim from the previous step's
    accelerations, so the simulation measures them one step late. They get one state
    ``<name>_lag`` each, ``z_{k+1} = C_i x_k + D_i u_k`` and ``y_i,k = z_k``. Without it a command
    step gives a one-step residual spike (measured at the F-16 point: 12 % normalized error on
    ``nz_g`` for an elevator doublet).

    Raises
    ------
    DesignError
        ``dt_s`` not positive, an unknown method, or the model already discrete at another rate.
    """
    if not dt_s > 0:
        raise DesignError(f"dt_s = {dt_s!r}: the detector sample time must be positive (default 1/120 s)")
    if method not in DISCRETIZATIONS:
        raise DesignError(f"unknown discretization {method!r}; use one of {', '.join(DISCRETIZATIONS)}")
    if model.is_discrete:
        if abs(model.dt_s - dt_s) > 1e-12:
            raise DesignError(f"model is already discrete at {model.dt_s} s; discretize the continuous model at {dt_s} s")
        return model
    if method == "zoh":
        d = model.discretize(dt_s)
    else:  # x_{k+1} = x_k + dt (A x_k + B u_k)
        d = LinearModel(
            A=np.eye(model.n_states) + dt_s * model.A, B=dt_s * model.B, C=model.C, D=model.D, dt_s=dt_s,
            state_names=model.state_names, input_names=model.input_names, output_names=model.output_names,
            input_kinds=model.input_kinds, x0=model.x0, u0=model.u0, y0=model.y0, op=model.op,
            meta={**model.meta, "discretized": "euler"},
        )
    lag = [model.output_names.index(n) for n in model.meta.get("lagged_outputs", ()) if n in model.output_names]
    if not lag or not lag_outputs:
        return d
    n, m, q = d.n_states, d.n_inputs, len(lag)
    A = np.zeros((n + q, n + q))
    A[:n, :n] = d.A
    A[n:, :n] = d.C[lag]            # z_{k+1} = C_i x_k + D_i u_k
    B = np.vstack([d.B, d.D[lag]])
    C = np.hstack([d.C, np.zeros((d.n_outputs, q))])
    D = d.D.copy()
    for j, i in enumerate(lag):     # y_i,k = z_k
        C[i] = 0.0
        C[i, n + j] = 1.0
        D[i] = 0.0
    names = d.state_names + tuple(_lag_name(d.output_names[i]) for i in lag)
    return LinearModel(
        A=A, B=B, C=C, D=D, dt_s=dt_s, state_names=names, input_names=d.input_names, output_names=d.output_names,
        input_kinds=d.input_kinds, x0=np.concatenate([d.x0, d.y0[lag]]), u0=d.u0, y0=d.y0, op=d.op,
        meta={**d.meta, "lag_states": [names[n + j] for j in range(q)]},
    )


def _lag_name(output: str) -> str:
    """``nz_g`` -> ``nz_lag_g``: the unit stays last."""
    stem, _, unit = output.rpartition("_")
    return f"{stem}_lag_{unit}"


# ---------------------------------------------------------------------- grids
def _modes_info(model: LinearModel) -> list[dict[str, Any]]:
    from fdi_sim.linear.modes import identify_modes

    return [{"name": m.name, "re": m.eigenvalue.real, "im": m.eigenvalue.imag, "wn_radps": m.wn_radps,
             "zeta": m.zeta, "tau_s": m.tau_s, "period_s": m.period_s, "dominant": list(m.dominant)}
            for m in identify_modes(model.A, model.state_names).modes]


def _fglin_info(model: LinearModel, fg_eigs: NDArray[np.complex128]) -> dict[str, Any]:
    """Match our eigenvalues (same 10 aero states) with FGLinearization's."""
    from fdi_sim.linear.modes import identify_modes, match_eigenvalues

    idx = [model.state_names.index(s) for s in AERO_STATES]
    mt = identify_modes(model.A[np.ix_(idx, idx)], AERO_STATES)
    ours = mt.eigenvalues()
    j, rel = match_eigenvalues(ours, fg_eigs)
    per_mode: dict[str, float] = {}
    k = 0
    for m in mt.modes:
        span = 2 if m.is_pair else 1
        per_mode[f"{m.name} {m.eigenvalue.real:.4g}"] = float(np.max(rel[k:k + span]))
        k += span
    big = [i for i in range(len(ours)) if abs(fg_eigs[j[i]]) > 1e-3]  # zero roots have no relative error
    return {"max_rel": float(np.max(rel[big])) if big else 0.0, "per_mode": per_mode,
            "fglin_re": [float(z.real) for z in fg_eigs[j]], "fglin_im": [float(z.imag) for z in fg_eigs[j]]}


def _validation_info(results: Mapping[str, Any]) -> dict[str, Any]:
    out = {}
    for method, vr in results.items():
        w_out, w_val = vr.worst
        wo = vr.nrmse_without(("throttle_cmd_norm",))
        k = int(np.argmax(wo))
        out[method] = {"nrmse": [float(x) for x in vr.nrmse], "worst_output": w_out, "worst": w_val,
                       "worst_without_throttle": float(wo[k]), "worst_output_without_throttle": vr.output_names[k],
                       "input_names": list(vr.input_names), "nrmse_pair": vr.nrmse_pair.tolist(),
                       "rms_nl": vr.rms_nl.tolist(), "passed": vr.passed(), "duration_s": vr.duration_s}
    return out


def linearize_grid(grid: Any, settings: FDSettings | None = None, validate: bool = True,
                   methods: Sequence[str] = DISCRETIZATIONS, check_fglin: bool | None = None,
                   progress: Any = None) -> Any:
    """Trim, linearize and (optionally) validate every point of a grid; returns a ``ModelSchedule``.

    Parameters
    ----------
    grid : fdi_sim.linear.grid.GridSpec
        The points, with the validation settings (``[validation]`` table).
    settings : FDSettings, optional
        Central-difference settings.
    validate : bool
        Fly the doublets at every trimmed point (about 0.3 s per point).
    methods : sequence of str
        Discretizations to validate (the nonlinear runs are shared).
    check_fglin : bool, optional
        FGLinearization cross-check (default: aircraft without propellers).
    progress : callable, optional
        Called as ``progress(i, n, point)`` after each point.

    Every point ends up ``ok``, ``untrimmable`` (with the trim's reason) or ``skipped`` (with the
    reason, e.g. no icing overlay): no silent skips.
    """
    from fdi_sim.aircraft.model import AIRCRAFT
    from fdi_sim.linear.schedule import ModelSchedule, SchedulePoint
    from fdi_sim.linear.validate import default_doublets, fly_doublets, compare

    import fdi_sim

    t_start = time.perf_counter()
    s = settings or FDSettings()
    val = dict(grid.validation)
    amps = dict(val.get("amplitudes", {}))
    duration_s = float(val.get("duration_s", 10.0))
    points: list[Any] = []
    arrays: dict[str, list[NDArray[np.float64]]] = {k: [] for k in ("A", "B", "C", "D", "x0", "u0", "y0")}
    names: dict[str, Any] = {}
    ac = None
    if grid.aircraft in AIRCRAFT:
        ac = Aircraft(grid.aircraft)
    n = len(grid.points)
    for i, op in enumerate(grid.points):
        if ac is None:
            points.append(SchedulePoint(op=op, status="skipped", reason=(
                f"overlay not available: JSBSim model {grid.aircraft!r} is not one of {', '.join(AIRCRAFT)} "
                "(the iced DHC-6 overlay comes with the icing issue)")))
            continue
        lp = linearize(ac, op, s, check_fglin=check_fglin)
        if lp.status != "ok" or lp.model is None:
            points.append(SchedulePoint(op=op, status=lp.status, reason=lp.reason, info={"timing_s": lp.timing_s}))
        else:
            m = lp.model
            if not names:
                names = {"state_names": m.state_names, "input_names": m.input_names, "input_kinds": m.input_kinds,
                         "output_names": m.output_names, "lagged_outputs": tuple(m.meta.get("lagged_outputs", ()))}
            elif names["state_names"] != m.state_names or names["input_names"] != m.input_names:
                raise DesignError(f"{op.label()}: states/inputs {m.state_names}/{m.input_names} differ from the "
                                  "grid's first point; one schedule needs one signal set")
            info: dict[str, Any] = {"modes": _modes_info(m), "timing_s": dict(lp.timing_s),
                                    "engine": m.meta.get("engine"), "knob_condition": m.meta.get("knob_condition")}
            if lp.fglin_eigs is not None:
                info["fglin"] = _fglin_info(m, lp.fglin_eigs)
            if validate:
                t0 = time.perf_counter()
                doublets = default_doublets(m, amps, float(val.get("width_s", 1.0)), float(val.get("start_s", 0.5)))
                runs = fly_doublets(ac, lp.trim_state, doublets, m.output_names, duration_s)
                info["validation"] = _validation_info(
                    {meth: compare(discretize(m, ac.dt_s, method=meth), runs) for meth in methods})
                info["timing_s"]["validate"] = time.perf_counter() - t0
            trim_vals = dict(lp.trim)
            sched = {"h_ft": op.h_ft, "vc_kts": float(trim_vals["vc_kts"]), "flaps_deg": op.flaps_deg,
                     "icing_eta": op.icing_eta}
            for k in arrays:
                arrays[k].append(np.asarray(getattr(m, k), dtype=float))
            points.append(SchedulePoint(op=op, status="ok", index=len(arrays["A"]) - 1, sched=sched,
                                        trim=trim_vals, info=info))
        if progress is not None:
            progress(i + 1, n, points[-1])
    stacked = {k: (np.array(v) if v else np.zeros((0, 0))) for k, v in arrays.items()}
    meta = {
        "created_by": f"fdi-sim {fdi_sim.__version__}", "grid_source": grid.source,
        "jsbsim_version": ac.fdm.get_version() if ac is not None else "", "fd_settings": s.__dict__,
        "validation": {"amplitudes": amps, "duration_s": duration_s, "width_s": float(val.get("width_s", 1.0)),
                       "start_s": float(val.get("start_s", 0.5)), "methods": list(methods) if validate else []},
        "envelope": {k: list(v) for k, v in grid.envelope.limits.items()}, "envelope_why": grid.envelope.why,
        "elapsed_s": time.perf_counter() - t_start,
    }
    return ModelSchedule(grid.aircraft, points, stacked, names, meta)
