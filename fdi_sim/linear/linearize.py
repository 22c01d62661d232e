"""Linear models for FDI from the JSBSim Jacobians: body -> aero states, assembly, the grid driver.

The state is ``[vt_fps alpha_rad beta_rad p_radps q_radps r_radps phi_rad theta_rad psi_rad h_ft]``
(plus ``n1_pct prop_rpm`` for the DHC-6 turboprops), the outputs are the sensor suite of
:data:`~fdi_sim.aircraft.linearize_state.SENSOR_OUTPUTS` (so ``C`` and ``D`` hold the accelerometers
and the air data), the inputs are the four pilot commands followed by the disturbance columns
(body-axis gust velocities; ``icing_eta`` when the aircraft flies the icing overlay).

``Vt``, ``alpha`` and ``beta`` of the state are those of the Earth-relative body velocity, which
equals the air-relative one at the (calm) trim. A gust therefore does not move the state directly;
it enters through ``B`` (forces) and through ``D`` into the air-data outputs ``alpha_rad``,
``beta_rad`` and ``vc_kts``, which the sensors measure relative to the air.

Each model also carries its step terms (:class:`~fdi_sim.linear.model.StepTerms`, measured pass by
pass at the trim by :func:`fdi_sim.aircraft.linearize.pass_jacobians`): with them
``discretize(model, method="step")`` is the discrete model of JSBSim's own 120 Hz step
(:mod:`fdi_sim.linear.step`), on which the validation bar is judged. The continuous ``A`` is the
settled linearization (its modes are the aircraft's, compared with FGLinearization's); the step
model adds what the simulation does within a step (AB3, one-pass delays, engines inside the pass).

Operations on the resulting :class:`LinearModel` (discretization, selection) are in
:mod:`fdi_sim.linear.transform`, which needs no JSBSim.
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field, replace
from typing import Any, Callable, Sequence

import numpy as np
from numpy.typing import NDArray

import fdi_sim
from fdi_sim.aircraft.linearize import BodyJacobians, FDSettings, PassJacobians, central_difference
from fdi_sim.aircraft.linearize_response import N1_PROBE, STATE_PROBES, slope_jumps
from fdi_sim.aircraft.fglin_replica import ReplicaLinearization, fglin_replica
from fdi_sim.aircraft.linearize_fglin import JsbsimLinearization, fglinearization
from fdi_sim.aircraft.linearize_state import (
    CONTROL_INPUTS, GUST_INPUTS, LAGGED_OUTPUTS, TrimState, capture_trim, has_propeller,
)
from fdi_sim.aircraft.model import AIRCRAFT, Aircraft
from fdi_sim.aircraft.trim import TrimResult, trim
from fdi_sim.errors import DesignError, TrimError
from fdi_sim.linear.grid import GridSpec
from fdi_sim.linear.model import LinearModel, StepTerms
from fdi_sim.linear.modes import identify_modes
from fdi_sim.linear.schedule import ARRAYS, ModelSchedule, SchedulePoint
from fdi_sim.linear.transform import discretize
from fdi_sim.linear.validate import (
    ENGINE_LAG_KEY, NONSMOOTH_JUMP, DoubletRuns, ValidationResult, ValidationSettings, compare, default_doublets,
    expseek, fly_doublets, lag_row,
)
from fdi_sim.operating_point import OperatingPoint
from fdi_sim.threads import single_blas_thread
from fdi_sim.units import KT_PER_FPS

#: trim-status passes per evaluation that settle the F-16 FBW in FGLinearization's procedure
#: (FGLinearization itself reads after one; tests/linear/test_fglin_roll_root.py)
SETTLED_PASSES: int = 5

#: aero-axis rigid-body state, in order
AERO_STATES: tuple[str, ...] = (
    "vt_fps", "alpha_rad", "beta_rad", "p_radps", "q_radps", "r_radps", "phi_rad", "theta_rad", "psi_rad", "h_ft",
)

#: our aero state name -> FGLinearization's state name (its Lat/Lon/Rpm have no counterpart)
_AERO_TO_FGLIN: dict[str, str] = {
    "vt_fps": "Vt", "alpha_rad": "Alpha", "beta_rad": "Beta", "p_radps": "P", "q_radps": "Q", "r_radps": "R",
    "phi_rad": "Phi", "theta_rad": "Theta", "psi_rad": "Psi", "h_ft": "Alt",
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
    ``D_a = D``. Eigenvalues and input-output behaviour are unchanged. The pass Jacobians (if any)
    are transformed the same way (their rows are the first 10 states, ``T_r = T[:10, :10]``):
    ``Ax_a = T_r Ax T^-1``, ``Bu_a = T_r Bu``, ``Lf_a = Lf T_r^-1``.
    """
    if bj.state_names[:3] != ("u_body_fps", "v_body_fps", "w_body_fps"):
        raise DesignError(f"body_to_aero expects body velocity states first, got {bj.state_names[:3]}")
    n = len(bj.state_names)
    u, v, w = bj.x0[:3]
    T = np.eye(n)
    T[:3, :3] = uvw_to_aero_jacobian(u, v, w)
    Ti = np.linalg.inv(T)
    x0 = bj.x0.copy()
    vt = math.hypot(u, v, w)
    x0[:3] = [vt, math.atan2(w, u), math.asin(v / vt)]
    xdot0 = T @ bj.xdot0
    passes = bj.passes
    if passes is not None:
        nr = passes.Ax.shape[1]
        Tr = T[:nr, :nr]
        passes = replace(passes, Ax=np.einsum("ij,pjk,kl->pil", Tr, passes.Ax, Ti), Bu=np.einsum("ij,pjm->pim", Tr, passes.Bu),
                         Lf=passes.Lf @ np.linalg.inv(Tr))
    return replace(
        bj, A=T @ bj.A @ Ti, B=T @ bj.B, C=bj.C @ Ti, D=bj.D.copy(),
        state_names=AERO_STATES + bj.state_names[len(AERO_STATES):], x0=x0, xdot0=xdot0, passes=passes,
    )


def step_terms(passes: PassJacobians) -> StepTerms:
    """The :class:`~fdi_sim.linear.model.StepTerms` of pass Jacobians (already in the model's states)."""
    return StepTerms(Ax=passes.Ax, Bu=passes.Bu, Lf=passes.Lf, lagged_outputs=passes.lagged_outputs,
                     dt_s=passes.dt_s, n_rigid=passes.Ax.shape[1])


def to_linear_model(bj: BodyJacobians, op: OperatingPoint | None = None, meta: dict[str, Any] | None = None) -> LinearModel:
    """Assemble a continuous-time :class:`LinearModel` in aero states from body Jacobians."""
    aero = body_to_aero(bj) if bj.state_names[0] == "u_body_fps" else bj
    extra = {"step_lf_residual": aero.passes.lf_residual} if aero.passes is not None else {}
    return LinearModel(
        A=aero.A, B=aero.B, C=aero.C, D=aero.D, dt_s=0.0, state_names=aero.state_names,
        input_names=aero.input_names, output_names=aero.output_names, input_kinds=aero.input_kinds,
        x0=aero.x0, u0=aero.u0, y0=aero.y0, op=op,
        meta={"engine": aero.engine, "knob_condition": aero.knob_condition, "notes": list(aero.notes),
              "lagged_outputs": [n for n in LAGGED_OUTPUTS if n in aero.output_names], **extra, **(meta or {})},
        step=step_terms(aero.passes) if aero.passes is not None else None,
    )


def fglin_in_aero_order(jl: JsbsimLinearization | ReplicaLinearization, state_names: Sequence[str]
                        ) -> NDArray[np.float64]:
    """FGLinearization's (or its replica's) ``A`` restricted and reordered to our aero states (Lat, Lon, Rpm dropped)."""
    idx = [jl.x_names.index(_AERO_TO_FGLIN[s]) for s in state_names if s in _AERO_TO_FGLIN]
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
    fglin_settled_eigs : NDArray or None
        The same from FGLinearization's procedure with :data:`SETTLED_PASSES` passes per
        evaluation instead of its one (:func:`~fdi_sim.aircraft.fglin_replica.fglin_replica`) [1/s].
    timing_s : dict
        Wall time of ``trim``, ``fd`` and ``fglin`` [s].
    trim_state : TrimState or None
        What :func:`~fdi_sim.aircraft.linearize_state.restore_trim` needs to fly from this trim again.
    """

    op: OperatingPoint
    status: str
    reason: str = ""
    trim: dict[str, float | str] = field(default_factory=dict)
    model: LinearModel | None = None
    fglin_eigs: NDArray[np.complex128] | None = None
    fglin_settled_eigs: NDArray[np.complex128] | None = None
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
    if op.icing_eta and not ac.icing:
        return (f"icing overlay not available: {ac.name} was loaded without it, so eta = {op.icing_eta:g} "
                f"cannot be flown; load Aircraft({ac.name!r}, icing=True) (linearize_grid does for iced grids)")
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

    Raises
    ------
    DesignError
        ``op`` is for another aircraft, or ``check_fglin`` on a propeller aircraft.
    """
    if op.aircraft != ac.name:
        raise DesignError(f"operating point is for {op.aircraft!r} but the aircraft is {ac.name!r}")
    problem = overlay_problem(ac, op)
    if problem:
        return LinearizedPoint(op=op, status="skipped", reason=problem)
    t0 = time.perf_counter()
    try:
        tr = trim(ac, op)
    except TrimError as exc:
        return LinearizedPoint(op=op, status="untrimmable", reason=exc.reason, timing_s={"trim": time.perf_counter() - t0})
    timing = {"trim": time.perf_counter() - t0}
    summary = trim_summary(ac, tr)
    ts = capture_trim(ac, tr)
    fg_eigs = None
    if check_fglin is None:
        check_fglin = not has_propeller(ac)
    settled_eigs = None
    if check_fglin:
        jl = fglinearization(ac)  # right after JSBSim's trim, as it needs; refuses propeller aircraft
        timing["fglin"] = jl.elapsed_s
        fg_eigs = np.linalg.eigvals(fglin_in_aero_order(jl, AERO_STATES))
        # FGLinearization's own procedure with its passes settled, from the same trim again
        # (fdi_sim.aircraft.fglin_replica): it reads after two passes, with the FBW one pass behind
        tr = trim(ac, op)
        rep = fglin_replica(ac, n_runs=SETTLED_PASSES)
        timing["fglin_settled"] = rep.elapsed_s
        settled_eigs = np.linalg.eigvals(fglin_in_aero_order(rep, AERO_STATES))
    bj = central_difference(ac, tr, settings)
    timing["fd"] = bj.elapsed_s
    meta = {"aircraft": ac.name, "method": "central differences about the trim (fdi_sim.aircraft.linearize)",
            "trim_method": tr.method}
    return LinearizedPoint(op=op, status="ok", trim=summary, model=to_linear_model(bj, op=op, meta=meta),
                           fglin_eigs=fg_eigs, fglin_settled_eigs=settled_eigs, timing_s=timing, trim_state=ts)


# ---------------------------------------------------------------------- grids
def _modes_info(model: LinearModel) -> list[dict[str, Any]]:
    return [{"name": m.name, "re": m.eigenvalue.real, "im": m.eigenvalue.imag, "wn_radps": m.wn_radps,
             "zeta": m.zeta, "tau_s": m.tau_s, "period_s": m.period_s, "dominant": list(m.dominant)}
            for m in identify_modes(model.A, model.state_names).modes]


def _fglin_info(model: LinearModel, fg_eigs: NDArray[np.complex128], dt_s: float | None = None) -> dict[str, Any]:
    """Our modes (same 10 aero states) against FGLinearization's eigenvalues, and both against the simulation.

    Returns
    -------
    dict
        ``per_mode``: ``"<name> <real part>" -> relative difference`` [-]; ``max_rel``: the
        largest over the non-zero roots (a zero root has no relative error) [-]; ``fglin_eigs``:
        FGLinearization's eigenvalues as ``[re, im]`` [1/s]. With step terms and ``dt_s`` also
        ``sim``: the poles of the discrete model of the simulation step mapped back by
        ``ln(z) / dt`` (:func:`fdi_sim.linear.step.equivalent_poles`, the referee: what the 120 Hz
        simulation does) and, per mode, the relative difference of ours (``ours_vs_sim``) and of
        FGLinearization's (``fglin_vs_sim``) to them.
    """
    idx = [model.state_names.index(s) for s in AERO_STATES]
    mt = identify_modes(model.A[np.ix_(idx, idx)], AERO_STATES)
    rel = mt.relative_errors(fg_eigs)
    big = np.array([abs(m.eigenvalue) > 1e-3 for m in mt.modes])
    labels = [f"{m.name} {m.eigenvalue.real:.4g}" for m in mt.modes]
    out: dict[str, Any] = {
        "max_rel": float(np.max(rel[big])) if big.any() else 0.0,
        "per_mode": dict(zip(labels, rel.tolist())),
        "fglin_eigs": [[float(z.real), float(z.imag)] for z in fg_eigs]}
    if model.step is not None and dt_s is not None and len(idx) == model.n_states:
        from scipy.optimize import linear_sum_assignment

        from fdi_sim.linear.modes import match_eigenvalues
        from fdi_sim.linear.step import equivalent_poles

        sim = equivalent_poles(discretize(model, dt_s, method="step"))
        ours = mt.eigenvalues()
        if sim.size >= ours.size:
            ri, ci = linear_sum_assignment(np.abs(ours[:, None] - sim[None, :]))
            sim_m = sim[ci[np.argsort(ri)]]  # the simulation's pole next to each of ours, in mode order
            k, _ = match_eigenvalues(sim_m, fg_eigs)
            fg_m = fg_eigs[k]

            def per_mode(a: NDArray[np.complex128]) -> dict[str, float]:
                return dict(zip(labels, mt.per_mode(np.abs(a - sim_m) / np.maximum(np.abs(sim_m), 1e-3)).tolist()))

            out["sim"] = {"poles": [[float(z.real), float(z.imag)] for z in sim_m],
                          "ours_vs_sim": per_mode(ours), "fglin_vs_sim": per_mode(fg_m)}
    return out


def _validation_info(vr: ValidationResult) -> dict[str, Any]:
    w_out, w_val = vr.worst
    wo = vr.nrmse_without(("throttle_cmd_norm",))
    k = int(np.argmax(wo))
    return {"nrmse": vr.nrmse.tolist(), "worst_output": w_out, "worst": w_val,
            "worst_without_throttle": float(wo[k]), "worst_output_without_throttle": vr.runs.output_names[k],
            "input_names": list(vr.runs.input_names), "nrmse_pair": vr.nrmse_pair.tolist(),
            "rms_nl": vr.rms_nl.tolist(), "passed": vr.passed(), "duration_s": vr.runs.duration_s}


def _point_info(ac: Aircraft, lp: LinearizedPoint, validation: ValidationSettings | None,
                methods: Sequence[str]) -> dict[str, Any]:
    """What the schedule records of one linearized point: modes, FGLinearization check, validation.

    ``validation[method]`` per discretization (``"step"`` only for models with step terms);
    ``validation_engine_lag`` (turboprops): the step model (ZOH without step terms) flown with the
    identified N1 lag in place of its N1 row, its ``method`` says which.
    """
    m = lp.model
    assert m is not None and lp.trim_state is not None
    info: dict[str, Any] = {"modes": _modes_info(m), "timing_s": dict(lp.timing_s),
                            "engine": m.meta.get("engine"), "knob_condition": m.meta.get("knob_condition")}
    if lp.fglin_eigs is not None:
        info["fglin"] = _fglin_info(m, lp.fglin_eigs, ac.dt_s)
        if lp.fglin_settled_eigs is not None:
            settled = _fglin_info(m, lp.fglin_settled_eigs)
            info["fglin"]["settled"] = {"max_rel": settled["max_rel"], "per_mode": settled["per_mode"]}
    if validation is not None:
        t0 = time.perf_counter()
        runs = fly_doublets(ac, lp.trim_state, default_doublets(m, validation), m.output_names, validation.duration_s)
        usable = [meth for meth in methods if meth != "step" or m.step is not None]
        models = {meth: discretize(m, ac.dt_s, method=meth) for meth in usable}
        info.update(_validations(ac, m, models, runs))
        if "step" in models:
            info["step_states"] = models["step"].n_states
        if runs.engine_lag is not None:
            info["engine_lag"] = {"tau_up_s": runs.engine_lag.tau_up_s, "tau_down_s": runs.engine_lag.tau_down_s}
        info["nonsmooth"] = nonsmooth(ac, lp.trim_state, runs, m)
        info["linear_range"] = _linear_range_info(ac, lp, runs, info, models)
        info["timing_s"]["validate"] = time.perf_counter() - t0
    return info


def _validations(ac: Aircraft, model: LinearModel, models: dict[str, LinearModel], runs: DoubletRuns
                 ) -> dict[str, Any]:
    """``validation`` (per discretization in ``models``) and, for turboprops, :data:`ENGINE_LAG_KEY`:
    the step model (ZOH without step terms) with its N1 row replaced by the identified lag."""
    out: dict[str, Any] = {"validation": {meth: _validation_info(compare(md, runs)) for meth, md in models.items()}}
    if runs.engine_lag is not None:
        meth = "step" if model.step is not None else "zoh"
        md = models.get(meth) or discretize(model, ac.dt_s, method=meth)
        out[ENGINE_LAG_KEY] = {**_validation_info(compare(md, runs, engine_lag=True)), "method": meth}
    return out


def _linear_range_info(ac: Aircraft, lp: LinearizedPoint, runs: DoubletRuns, info: dict[str, Any],
                       models: dict[str, LinearModel]) -> dict[str, Any]:
    """The validation again with each doublet inside the smooth range of JSBSim's tables.

    ``info["linear_range"]``: ``doublets`` (input -> amplitude flown), ``reduced`` (input ->
    ``{"factor", "by", "radius", "jump"}`` for every doublet made smaller), ``no_smooth_range``
    (probes with a kink at the trim itself), ``nonsmooth`` of the runs flown, and ``validation``
    / ``validation_engine_lag`` as in the point's info. Where no doublet is reduced the entries
    are those of the configured amplitudes.
    """
    assert lp.trim_state is not None and lp.model is not None
    lr = linear_range_runs(ac, lp.trim_state, runs, info["nonsmooth"], lp.model)
    out: dict[str, Any] = {"doublets": {d.input_name: d.amplitude for d in lr.runs.doublets},
                           "reduced": lr.reduced, "no_smooth_range": lr.no_smooth_range}
    if not lr.reduced:
        out.update(nonsmooth=info["nonsmooth"], validation=info["validation"])
        if ENGINE_LAG_KEY in info:
            out[ENGINE_LAG_KEY] = info[ENGINE_LAG_KEY]
        return out
    out["nonsmooth"] = nonsmooth(ac, lp.trim_state, lr.runs, lp.model)
    out.update(_validations(ac, lp.model, models, lr.runs))
    return out


@dataclass(frozen=True, eq=False)
class LinearRangeRuns:
    """Doublet runs kept inside the smooth range of JSBSim's model (:func:`linear_range_runs`).

    Attributes
    ----------
    runs : DoubletRuns
        All runs: those of the configured amplitudes, with the reduced ones flown again.
    reduced : dict
        Input -> ``{"factor": f, "amplitude": a, "by": probe, "radius": r, "jump": j}``: the
        doublet was flown at ``f`` times its amplitude because ``probe`` (an input or a state) has
        a slope jump ``j`` within the configured excursion and none above the bar within ``r``.
    no_smooth_range : dict
        Probe -> jump for kinks still found after halving the excursion ``max_halvings`` times
        (a kink at the trim itself): the doublets that cross it are left as configured.
    """

    runs: DoubletRuns
    reduced: dict[str, dict[str, Any]]
    no_smooth_range: dict[str, float]


def _run_excursions(runs: DoubletRuns, model: LinearModel | None = None) -> list[dict[str, float]]:
    """Per run, how far it moves each probe: its own input (the amplitude), the states and N1 [units of the probe]."""
    out = []
    n1 = n1_excursions(runs, model)
    for r, d in enumerate(runs.doublets):
        exc = {d.input_name: abs(d.amplitude)} if d.input_name in CONTROL_INPUTS + GUST_INPUTS else {}
        for name in STATE_PROBES:
            if name in runs.output_names:
                exc[name] = float(np.max(np.abs(runs.dy[r, :, runs.output_names.index(name)])))
        if n1[r] > 0:
            exc[N1_PROBE] = float(n1[r])
        out.append(exc)
    return out


def linear_range_runs(ac: Aircraft, ts: TrimState, runs: DoubletRuns, jumps: dict[str, dict[str, float]],
                      model: LinearModel | None = None, jump_bar: float = NONSMOOTH_JUMP,
                      max_halvings: int = 6) -> LinearRangeRuns:
    """Fly again, smaller, every doublet that carries JSBSim across a kink of its tables.

    A linear model is the tangent of a smooth function; across a table breakpoint or a kink (the
    DHC-6 left aileron's unequal travel at zero deflection, a breakpoint of its lift table) the
    tangent changes, so a doublet that crosses one tests the model outside the range where any
    linear model can hold. For every probe (input or state, :func:`nonsmooth`) whose slope jump
    over the configured excursion ``a`` is at least ``jump_bar``, the smooth radius is the first
    of ``a/2, a/4, ...`` (at most ``max_halvings``) with the jump below the bar (probed alone, so
    judged on every row it drives substantially: at least the rows of the joint probe of
    :func:`nonsmooth`, which can only make the radius smaller); each run whose
    excursion of that probe exceeds the radius is flown again with its amplitude scaled by
    ``radius / excursion`` (the responses are linear in the amplitude to first order).

    Parameters
    ----------
    ac : Aircraft
        At the trim ``ts``.
    ts : TrimState
        The trim.
    runs : DoubletRuns
        The runs at the configured amplitudes.
    jumps : dict
        :func:`nonsmooth` of ``runs`` (``probe -> {"excursion", "jump"}``).
    model : LinearModel, optional
        The continuous model (turboprops: the N1 excursion of the throttle run comes from its
        static gain and the identified lag, :func:`n1_excursions`).
    jump_bar : float
        Slope jump that counts as a kink [-].
    max_halvings : int
        Halvings of the excursion tried per probe.
    """
    flagged = {k: d for k, d in jumps.items() if d["jump"] >= jump_bar and d["excursion"] > 0}
    radius: dict[str, float] = {}
    no_range: dict[str, float] = {}
    for probe, d in flagged.items():
        a = float(d["excursion"])
        j = float(d["jump"])
        for _ in range(max_halvings):
            a /= 2.0
            j = slope_jumps(ac, ts, {probe: a}).get(probe, 0.0)
            if j < jump_bar:
                radius[probe] = a
                break
        else:
            no_range[probe] = j
    exc = _run_excursions(runs, model)
    reduced: dict[str, dict[str, Any]] = {}
    specs = []
    for r, d in enumerate(runs.doublets):
        f, by = 1.0, ""
        for probe, rad in radius.items():
            e = exc[r].get(probe, 0.0)
            if e > rad and rad / e < f:
                f, by = rad / e, probe
        if f < 1.0:
            reduced[d.input_name] = {"factor": f, "amplitude": d.amplitude * f, "by": by, "radius": radius[by],
                                     "jump": float(flagged[by]["jump"])}
            specs.append((r, replace(d, amplitude=d.amplitude * f)))
    if not specs:
        return LinearRangeRuns(runs=runs, reduced={}, no_smooth_range=no_range)
    again = fly_doublets(ac, ts, [s for _, s in specs], runs.output_names, runs.duration_s)
    du, dy, doublets = runs.du.copy(), runs.dy.copy(), list(runs.doublets)
    for k, (r, spec) in enumerate(specs):
        du[r], dy[r], doublets[r] = again.du[k], again.dy[k], spec
    return LinearRangeRuns(runs=replace(runs, du=du, dy=dy, doublets=tuple(doublets)), reduced=reduced,
                           no_smooth_range=no_range)


def n1_excursions(runs: DoubletRuns, model: LinearModel | None) -> NDArray[np.float64]:
    """Largest gas-generator excursion of each run [%], from the identified lag (zeros without one).

    N1 follows ``K u`` (``K`` the model's static gain of its N1 row, :func:`lag_row`) by
    FGTurboProp's ExpSeek with the lag of ``runs.engine_lag`` (:func:`~fdi_sim.linear.validate.expseek`,
    as the validation flies it); only the throttle run moves it.
    """
    out = np.zeros(len(runs.doublets))
    lag = runs.engine_lag
    if lag is None or model is None or lag.state_name not in model.state_names:
        return out
    _, _, K = lag_row(model, lag)
    for r, d in enumerate(runs.doublets):
        if d.input_name == lag.input_name:
            out[r] = float(np.max(np.abs(expseek(K * runs.du[r], runs.dt_s, lag))))
    return out


def nonsmooth(ac: Aircraft, ts: TrimState, runs: DoubletRuns, model: LinearModel | None = None
              ) -> dict[str, dict[str, float]]:
    """Slope jumps of JSBSim's model within the excursions of the doublet runs.

    Probes: every doublet input except the throttle (it moves the gas generator, probed as N1)
    and the extra disturbances, with the doublet amplitude; the states alpha, beta, p, q, r with
    their largest excursion over all runs; and, for turboprops (``model`` given, an engine lag
    identified), N1 with the throttle run's excursion (:func:`n1_excursions`).

    Returns
    -------
    dict
        ``probe -> {"excursion": a, "jump": relative slope jump}`` [units of the probe, -].
    """
    exc = _run_excursions(runs, model)
    names = dict.fromkeys(n for e in exc for n in e if n != "throttle_cmd_norm")  # the throttle's probe is N1
    probes = {n: max(e.get(n, 0.0) for e in exc) for n in names}
    jumps = slope_jumps(ac, ts, probes)
    return {k: {"excursion": float(probes[k]), "jump": v} for k, v in jumps.items()}


#: discretizations validated by :func:`linearize_grid` by default: the detectors' ZOH model and the
#: model of the simulation step (``"euler"`` on request)
VALIDATED: tuple[str, ...] = ("zoh", "step")


@single_blas_thread
def linearize_grid(grid: GridSpec, settings: FDSettings | None = None, validate: bool = True,
                   methods: Sequence[str] = VALIDATED, check_fglin: bool | None = None,
                   progress: Callable[[int, int, SchedulePoint], None] | None = None) -> ModelSchedule:
    """Trim, linearize and (optionally) validate every point of a grid.

    Parameters
    ----------
    grid : GridSpec
        The points, with the validation settings (``[validation]`` table).
    settings : FDSettings, optional
        Central-difference settings.
    validate : bool
        Fly the doublets at every trimmed point (about 0.3 s per point).
    methods : sequence of str
        Discretizations to validate (the nonlinear runs are shared); ``"step"`` is validated
        where the model has step terms (``FDSettings.step_passes > 0``, the default).
    check_fglin : bool, optional
        FGLinearization cross-check (default: aircraft without propellers).
    progress : callable, optional
        Called as ``progress(i, n, point)`` after each point.

    Returns
    -------
    ModelSchedule
        Every point ends up ``ok``, ``untrimmable`` (with the trim's reason) or ``skipped`` (with
        the reason, e.g. an unknown aircraft): no silent skips. A grid with any ``icing_eta > 0``
        is flown on the icing overlay (``Aircraft(name, icing=True)``, the trim sets eta per
        point), and its models carry the ``icing_eta`` disturbance column.

    Raises
    ------
    DesignError
        Two trimmed points with different states or inputs (one schedule needs one signal set).
    """
    t_start = time.perf_counter()
    s = settings or FDSettings()
    # a grid with iced points flies every point on the icing overlay (eta = 0 flies exactly as the
    # clean model), so all points share one signal set: the icing_eta disturbance column
    iced = any(op.icing_eta for op in grid.points)
    ac = Aircraft(grid.aircraft, icing=iced) if grid.aircraft in AIRCRAFT else None
    no_model = (f"overlay not available: JSBSim model {grid.aircraft!r} is not one of {', '.join(AIRCRAFT)} "
                "(icing is the icing_eta axis of a grid of one of these)")
    points: list[SchedulePoint] = []
    models: list[LinearModel] = []
    for i, op in enumerate(grid.points):
        lp = linearize(ac, op, s, check_fglin) if ac is not None else LinearizedPoint(op, "skipped", no_model)
        if lp.model is None:
            points.append(SchedulePoint(op=op, status=lp.status, reason=lp.reason, info={"timing_s": lp.timing_s}))
        else:
            assert ac is not None
            m = lp.model
            if models and (m.state_names, m.input_names) != (models[0].state_names, models[0].input_names):
                raise DesignError(f"{op.label()}: states/inputs {m.state_names}/{m.input_names} differ from the "
                                  "grid's first point; one schedule needs one signal set")
            info = _point_info(ac, lp, grid.validation if validate else None, methods)
            sched = {"h_ft": op.h_ft, "vc_kts": float(lp.trim["vc_kts"]), "flaps_deg": op.flaps_deg,
                     "icing_eta": op.icing_eta}
            points.append(SchedulePoint(op=op, status="ok", index=len(models), sched=sched, trim=dict(lp.trim),
                                        info=info))
            models.append(m)
        if progress is not None:
            progress(i + 1, len(grid.points), points[-1])
    names: dict[str, Any] = {}
    arrays = {k: np.zeros((0, 0)) for k in ARRAYS}
    step_meta: dict[str, Any] = {}
    if models:
        m0 = models[0]
        names = {"state_names": m0.state_names, "input_names": m0.input_names, "input_kinds": m0.input_kinds,
                 "output_names": m0.output_names, "lagged_outputs": tuple(m0.meta.get("lagged_outputs", ()))}
        arrays = {k: np.array([getattr(m, k) for m in models]) for k in ARRAYS}
        steps = [m.step for m in models]
        if all(st is not None for st in steps) and len({(st.Ax.shape, st.lagged_outputs) for st in steps}) == 1:
            arrays.update(step_Ax=np.array([st.Ax for st in steps]), step_Bu=np.array([st.Bu for st in steps]),
                          step_Lf=np.array([st.Lf for st in steps]))
            step_meta = {"step": {"dt_s": steps[0].dt_s, "n_rigid": steps[0].n_rigid,
                                  "lagged_outputs": list(steps[0].lagged_outputs)}}
    meta = {
        "created_by": f"fdi-sim {fdi_sim.__version__}", "grid_source": grid.source,
        "jsbsim_version": ac.fdm.get_version() if ac is not None else "", "fd_settings": asdict(s),
        "validation": {**asdict(grid.validation), "methods": list(methods) if validate else []},
        "envelope": {k: list(v) for k, v in grid.envelope.limits.items()}, "envelope_why": grid.envelope.why,
        "elapsed_s": time.perf_counter() - t_start, **step_meta,
    }
    return ModelSchedule(grid.aircraft, points, arrays, names, meta)
