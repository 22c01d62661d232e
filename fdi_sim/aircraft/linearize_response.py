"""Nonlinear responses: JSBSim flown from a trim with input deviations added (the validation runs).

Also what a linear model cannot hold, measured from JSBSim at a trim: the asymmetric lag of the
turboprop gas generator (:func:`identify_engine_lag`) and the kinks of JSBSim's tables within a
given excursion of an input or state (:func:`slope_jumps`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.aircraft.linearize import _PSI, FDSettings, _Evaluator, engine_model
from fdi_sim.aircraft.linearize_state import (
    BODY_STATES, CONTROL_INPUTS, GUST_INPUTS, GUST_PROPS, OPTIONAL_DISTURBANCES, SENSOR_OUTPUTS, TrimState,
    command_props, engine_reader, restore_trim,
)
from fdi_sim.aircraft.model import Aircraft
from fdi_sim.errors import DesignError


@dataclass(frozen=True)
class EngineLag:
    """First-order lag of the gas-generator speed with different time constants up and down.

    ``FGTurboProp::Run`` moves N1 toward ``IdleN1 + throttle N1_factor`` by ``ExpSeek``:
    ``N1 <- target + (N1 - target) exp(-dt / tau)`` with ``tau = tau_up_s`` while N1 is below the
    target and ``tau_down_s`` above it. The linear model's ``n1_pct`` row holds the mean of the two
    rates (the central difference averages them); this object holds both, so the validation can fly
    the exact lag in front of the linear model.

    Attributes
    ----------
    tau_up_s : float
        Time constant while N1 rises [s].
    tau_down_s : float
        Time constant while N1 falls [s].
    state_name : str
        The model state it drives.
    input_name : str
        The model input that sets its target.
    """

    tau_up_s: float
    tau_down_s: float
    state_name: str = "n1_pct"
    input_name: str = "throttle_cmd_norm"


def identify_engine_lag(ac: Aircraft, ts: TrimState, step_norm: float = 0.02) -> EngineLag | None:
    """Identify the up and down time constants of N1 from JSBSim at the trim ``ts``.

    From the trim, the throttle is stepped by ``+step_norm`` (then, from the trim again, by
    ``-step_norm``) and held for three steps. With a constant target ``T``, ExpSeek gives
    ``N1_{k+1} - T = r (N1_k - T)``, so ``r = (N1_2 - N1_1) / (N1_1 - N1_0)`` and
    ``tau = -dt / ln r`` without knowing ``T``.

    Parameters
    ----------
    ac : Aircraft
        The aircraft (put back at the trim before each step; fuel frozen).
    ts : TrimState
        The trim.
    step_norm : float
        Throttle step [-].

    Returns
    -------
    EngineLag or None
        None for aircraft without a gas-generator state (no propeller: the F-16's F100 is
        quasi-static in the linear model).

    Raises
    ------
    DesignError
        N1 did not follow the step as a first-order lag (engine not running, or at a limit).
    """
    if ts.n1_pct is None:
        return None
    fdm = ac.fdm
    read_engine = engine_reader(ac)
    throttles = command_props(ac, "throttle_cmd_norm")
    freeze0 = fdm["propulsion/fuel_freeze"]
    fdm["propulsion/fuel_freeze"] = 1
    taus: list[float] = []
    try:
        for sign in (1.0, -1.0):
            restore_trim(ac, ts)
            for p in throttles:
                fdm[p] = ts.u_cmd[CONTROL_INPUTS.index("throttle_cmd_norm")] + sign * step_norm
            n1 = [float(read_engine()[0])]
            for _ in range(3):
                fdm.run()
                n1.append(float(read_engine()[0]))
            d1, d2 = n1[2] - n1[1], n1[3] - n1[2]
            r = d2 / d1 if d1 * sign > 0 else float("nan")
            if not 0.0 < r < 1.0:
                raise DesignError(f"{ac.name} at {ts.op.label()}: N1 did not follow a throttle step of "
                                  f"{sign * step_norm:+g} as a first-order lag (N1 {n1}); is the engine running "
                                  "and below its limits?")
            taus.append(-ac.dt_s / math.log(r))
    finally:
        fdm["propulsion/fuel_freeze"] = freeze0
        restore_trim(ac, ts)
    return EngineLag(tau_up_s=taus[0], tau_down_s=taus[1])


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

    Raises
    ------
    DesignError
        A column count that does not match ``input_names``, an unknown input, or NaN in the run.
    """
    du = np.atleast_2d(np.asarray(du, dtype=float))
    names = tuple(input_names)
    if du.shape[1] != len(names):
        raise DesignError(f"du has {du.shape[1]} columns but {len(names)} input names were given")
    extras = {**OPTIONAL_DISTURBANCES, **dict(extra_disturbances or {})}
    pm = ac.fdm.get_property_manager()
    unknown = [n for n in names if n not in CONTROL_INPUTS + GUST_INPUTS
               and not (n in extras and pm.hasNode(extras[n][0]))]
    if unknown:
        raise DesignError(f"unknown input {unknown[0]!r} for {ac.name}; known: "
                          f"{', '.join(CONTROL_INPUTS + GUST_INPUTS + tuple(extras))}")
    fdm = ac.fdm
    freeze0 = fdm["propulsion/fuel_freeze"]
    fdm["propulsion/fuel_freeze"] = 1  # the mass must not change from run to run (nor within one)
    restore_trim(ac, ts)
    # per column of du: the property setters it drives and the trim value it is added to; gust
    # columns (body axes at the trim attitude) go to JSBSim's NED gust, g_ned = T_b2n g_b
    targets: list[tuple[int, list[Callable[[float], None]], float]] = []
    S_g = np.zeros((len(names), len(GUST_INPUTS)))
    for j, name in enumerate(names):
        if name in GUST_INPUTS:
            S_g[j, GUST_INPUTS.index(name)] = 1.0
        elif name in CONTROL_INPUTS:
            targets.append((j, [ac.node(p).set_double_value for p in command_props(ac, name)], float(ts.u_cmd[CONTROL_INPUTS.index(name)])))
        else:
            node = ac.node(extras[name][0])
            targets.append((j, [node.set_double_value], node.get_double_value()))
    gust_rows = (du @ S_g @ ts.T_b2n.T).tolist() if S_g.any() else []
    gust_set = [ac.node(p).set_double_value for p in GUST_PROPS]
    rows = du.tolist()
    read = ac.reader(output_names)
    out = np.empty((du.shape[0], len(output_names)))
    t = np.empty(du.shape[0])
    try:
        for k, row in enumerate(rows):
            for j, setters, u0 in targets:
                v = u0 + row[j]
                for set_v in setters:
                    set_v(v)
            if gust_rows:
                for set_g, v in zip(gust_set, gust_rows[k]):
                    set_g(v)
            fdm.run()
            out[k] = read()
            t[k] = fdm.get_sim_time()
    finally:
        for set_g in gust_set:
            set_g(0.0)
        fdm["propulsion/fuel_freeze"] = freeze0
    if "psi_rad" in output_names:
        i = list(output_names).index("psi_rad")
        out[:, i] = np.unwrap(np.r_[ts.x_body[_PSI], out[:, i]])[1:]  # continuous about the trim heading
    if not np.all(np.isfinite(out)):
        k = int(np.argmax(~np.all(np.isfinite(out), axis=1)))
        raise DesignError(f"{ac.name} at {ts.op.label()}: the nonlinear run produced NaN at t = {t[k]:.3f} s; "
                          "reduce the doublet amplitude or move the point inside the envelope")
    return NonlinearResponse(t_s=t, y=out, output_names=tuple(output_names))


#: probes of :func:`slope_jumps` that are states, not inputs
STATE_PROBES: tuple[str, ...] = ("alpha_rad", "beta_rad", "p_radps", "q_radps", "r_radps")

#: the gas-generator probe of :func:`slope_jumps` (turboprops: power and propeller torque as N1 moves)
N1_PROBE: str = "n1_pct"


def slope_jumps(ac: Aircraft, ts: TrimState, probes: Mapping[str, float],
                settings: FDSettings | None = None) -> dict[str, float]:
    """How far JSBSim's model is from smooth within a given excursion of each input or state.

    For every probe the settled derivatives (as in :func:`central_difference`) are evaluated at
    the trim and at ``+a`` and ``-a``; the one-sided slopes ``s+ = (f(+a) - f(0)) / a`` and
    ``s- = (f(0) - f(-a)) / a`` agree to O(a) for a smooth model and differ by the jump of the
    slope where a table breakpoint or a kink lies within ``+-a``. The result is, over the
    acceleration rows the probe drives substantially (``|s| a`` at least 20 % of the largest
    change any probe makes in that row), the largest ``|s+ - s-| / |(s+ + s-) / 2|``.

    Parameters
    ----------
    ac : Aircraft
        At the trim ``ts`` (put back there afterwards).
    ts : TrimState
        The trim.
    probes : mapping
        Input name (:data:`CONTROL_INPUTS`, :data:`GUST_INPUTS`) or state name
        (:data:`STATE_PROBES`, and :data:`N1_PROBE` on turboprops) -> excursion ``a`` [units of
        the name]; non-positive ones are skipped. The N1 probe moves the gas generator with the
        rest held and is judged on the accelerations and the propeller's speed rate (where the
        engine's power reaches the airframe); N1's own rate is left out, its asymmetric lag being
        :func:`identify_engine_lag`'s.
    settings : FDSettings, optional
        Evaluation settings (``n_settle``, ``dt_eval_s``, ``engine``).

    Returns
    -------
    dict
        Probe name -> relative slope jump [-].

    Raises
    ------
    DesignError
        An unknown probe name.
    """
    s = settings or FDSettings()
    ev = _Evaluator(ac, ts, engine_model(ac, s) == "dynamic", s, [])
    v0 = np.concatenate([ts.x_body, ts.u_cmd, np.zeros(len(GUST_INPUTS))])
    u, v, w = ts.x_body[:3]
    dirs: dict[str, NDArray[np.float64]] = {}
    n1_a = 0.0
    for name, a in probes.items():
        if not a > 0:
            continue
        e = np.zeros(v0.size)
        if name == N1_PROBE:
            if not ev.dynamic or ts.n1_pct is None:
                raise DesignError(f"slope_jumps: probe {N1_PROBE!r} needs a turboprop with its dynamic engine model")
            n1_a = float(a)
            continue
        if name in CONTROL_INPUTS:
            e[len(BODY_STATES) + CONTROL_INPUTS.index(name)] = 1.0
        elif name in GUST_INPUTS:
            e[len(BODY_STATES) + len(CONTROL_INPUTS) + GUST_INPUTS.index(name)] = 1.0
        elif name == "alpha_rad":
            e[2] = (u * u + w * w) / u  # d alpha = (u dw - w du) / (u^2 + w^2) with du = 0
        elif name == "beta_rad":
            e[1] = math.sqrt(u * u + v * v + w * w)  # d beta = dv / Vt at small beta
        elif name in STATE_PROBES:
            e[BODY_STATES.index(name)] = 1.0
        else:
            raise DesignError(f"slope_jumps: unknown probe {name!r}; use a control, a gust or one of {STATE_PROBES}")
        dirs[name] = e * a
    # u, v, w, p, q, r derivatives; with the dynamic engine also the propeller speed rate (the
    # row after N1's own rate), used for the N1 probe only
    rows = list(range(6)) + ([len(BODY_STATES) + 1] if ev.dynamic else [])
    weights = np.array([1.0, 1.0, 1.0, 100.0, 100.0, 100.0] + ([1.0] if ev.dynamic else []))
    try:
        f0 = ev.evaluate(v0).f[rows]
        ends = {n: (ev.evaluate(v0 + d).f[rows], ev.evaluate(v0 - d).f[rows]) for n, d in dirs.items()}
        if n1_a > 0:
            ends[N1_PROBE] = (ev.evaluate(v0, dn1_pct=n1_a).f[rows], ev.evaluate(v0, dn1_pct=-n1_a).f[rows])
    finally:
        for prop in GUST_PROPS:
            ac.fdm[prop] = 0.0
        restore_trim(ac, ts)
    if not ends:
        return {}
    change = np.array([np.abs(fp - fm) / 2 for fp, fm in ends.values()])  # |s| a per probe and row
    if ev.dynamic:  # the propeller row belongs to the N1 probe alone
        change[[n != N1_PROBE for n in ends], -1] = 0.0
    # rows that matter for a probe: 20 % of what any probe does there, and 10 % of the probe's own
    # largest effect with the rows weighted as in the trim (ft/s^2; rad/s^2 x 100; rpm/s)
    weighted = change * weights
    big = (change >= 0.2 * np.max(change, axis=0)) & (weighted >= 0.1 * np.max(weighted, axis=1, keepdims=True))
    big &= change > 0
    out = {}
    for k, (name, (fp, fm)) in enumerate(ends.items()):
        a = float(probes[name])
        sp, sm = (fp - f0) / a, (f0 - fm) / a
        mean = np.abs(sp + sm) / 2
        r = np.abs(sp - sm)[big[k]] / np.maximum(mean[big[k]], 1e-300)
        out[name] = float(np.max(r)) if r.size else 0.0
    return out
