"""Nonlinear responses: JSBSim flown from a trim with input deviations added (the validation runs)."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.aircraft.linearize_state import (
    BODY_STATES, CONTROL_INPUTS, GUST_INPUTS, GUST_PROPS, OPTIONAL_DISTURBANCES, SENSOR_OUTPUTS, TrimState,
    restore_trim,
)
from fdi_sim.aircraft.model import Aircraft
from fdi_sim.aircraft.properties import property_map
from fdi_sim.errors import DesignError

_PSI = BODY_STATES.index("psi_rad")


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
            props = ([f"fcs/throttle-cmd-norm[{i}]" for i in range(ac.n_engines)] if name == "throttle_cmd_norm"
                     else [property_map(ac.name)[name]])  # the throttle goes to every engine
            targets.append((j, [ac.node(p).set_double_value for p in props], float(ts.u_cmd[CONTROL_INPUTS.index(name)])))
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
