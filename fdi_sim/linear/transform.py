"""Operations on a :class:`~fdi_sim.linear.model.LinearModel`: discretization, input/output selection, state removal.

Pure maths, no JSBSim: the model schedule discretizes here at every lookup.
"""
from __future__ import annotations

import math
from dataclasses import replace
from typing import Sequence

import numpy as np

from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel
from fdi_sim.linear.step import lag_state_name, step_model

#: default detector rate: the simulation's 120 Hz
DEFAULT_DT_S: float = 1.0 / 120.0
#: discretization methods of :func:`discretize`
DISCRETIZATIONS: tuple[str, ...] = ("zoh", "euler", "step")


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
        ``"zoh"`` (zero-order hold, exact for a held input; the default), ``"euler"``
        (``A_d = I + dt A``, ``B_d = dt B``) or ``"step"``: the discrete model of JSBSim's own
        step (:func:`fdi_sim.linear.step.step_model`: AB3 integration, one-pass delays of the FCS
        and of the aero model, engines inside the pass, accelerometers one step late), at the
        simulation step or a multiple of it (:func:`fdi_sim.linear.step.lift`), only for models
        with step terms; it has more states. fdi-sim runs JSBSim with third-order Adams-Bashforth
        on all four integrators (``Aircraft.__init__``); with it the ZOH model follows the
        simulation at its own step (DHC-6 5000 ft / 120 KCAS doublets without the throttle run:
        ``p_radps`` error 1.6 % with ZOH, 14.7 % with Euler). ``"euler"`` matches JSBSim's
        default rectangular-Euler rate integration, which takes about ``omega^2 dt / 2`` of
        damping out of an oscillatory mode.
    lag_outputs : bool
        Delay the outputs in ``model.meta["lagged_outputs"]`` by one step (see below; the
        ``"step"`` model always does).

    Notes
    -----
    The pilot-station accelerations are computed by JSBSim from the previous step's
    accelerations, so the simulation measures them one step late. They get one state
    ``<name>_lag`` each, ``z_{k+1} = C_i x_k + D_i u_k`` and ``y_i,k = z_k``. Without it a command
    step gives a one-step residual spike (F-16 10 kft / 400 KTAS elevator doublet: ``nz_g``
    error 12 % instead of 2 %; ``test_representative_points_validate``).

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
    if method == "step":
        return step_model(model, dt_s)
    if method == "zoh":
        d = model.discretize(dt_s)
    else:  # x_{k+1} = x_k + dt (A x_k + B u_k)
        d = replace(model, A=np.eye(model.n_states) + dt_s * model.A, B=dt_s * model.B, dt_s=dt_s,
                    meta={**model.meta, "discretized": "euler"}, step=None)
    lag = [model.output_names.index(n) for n in model.meta.get("lagged_outputs", ()) if n in model.output_names]
    if not lag or not lag_outputs:
        return d
    n, q = d.n_states, len(lag)
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
    names = d.state_names + tuple(lag_state_name(d.output_names[i]) for i in lag)
    return replace(d, A=A, B=B, C=C, D=D, state_names=names, x0=np.concatenate([d.x0, d.y0[lag]]),
                   meta={**d.meta, "lag_states": list(names[n:])})


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
    out_names = tuple(model.output_names[i] for i in io)
    step = model.step.select_inputs(ii).select_outputs(out_names) if model.step is not None else None
    return replace(
        model, B=model.B[:, ii], C=model.C[io], D=model.D[np.ix_(io, ii)],
        input_names=tuple(model.input_names[i] for i in ii), output_names=out_names,
        input_kinds=tuple(model.input_kinds[i] for i in ii), u0=model.u0[ii], y0=model.y0[io], meta=dict(model.meta),
        step=step,
    )


def drop_states(model: LinearModel, names: Sequence[str], rtol: float = 1e-3) -> LinearModel:
    """Remove states that no other state and no output depends on (e.g. ``psi_rad`` when heading is unused).

    A state ``j`` may be dropped only if column ``j`` of ``A`` (rows of the kept states) and of
    ``C`` is negligible: ``|M[i, j]| <= rtol * max_k |M[i, k]|`` for every such row ``i``. The
    step terms are dropped with it (the step model needs every integrated state).

    Raises
    ------
    DesignError
        A state to drop is not in the model, or feeds another state or an output.
    """
    missing = [s for s in names if s not in model.state_names]
    if missing:
        raise DesignError(f"states {missing} not in the model; states are {', '.join(model.state_names)}")
    keep = [i for i, s in enumerate(model.state_names) if s not in names]
    rows = [(model.A, i, model.state_names[i], "state") for i in keep]
    rows += [(model.C, i, model.output_names[i], "output") for i in range(model.n_outputs)]
    for j in (model.state_names.index(s) for s in names):
        for M, i, who, what in rows:
            if abs(M[i, j]) > rtol * (np.max(np.abs(M[i])) or 1.0):
                raise DesignError(f"cannot drop {model.state_names[j]}: {what} {who} depends on it "
                                  f"({M[i, j]:.3g}); drop the output first or keep the state")
    return replace(
        model, A=model.A[np.ix_(keep, keep)], B=model.B[keep], C=model.C[:, keep],
        state_names=tuple(model.state_names[i] for i in keep), x0=model.x0[keep], meta=dict(model.meta), step=None,
    )


def state_as_input(model: LinearModel, state: str, input_name: str | None = None) -> LinearModel:
    """Make a measured state a known input: drop it, and let its column act as an input column.

    For a continuous model ``dx/dt = A x + B u``, ``y = C x + D u`` with state ``x_i`` measured
    (the DHC-6 engines' N1 gauges): the rest of the states see ``x_i`` through ``A[:, i]`` and
    the outputs through ``C[:, i]``, so with ``x_i`` given these become the new input's columns
    and the dynamics of ``x_i`` itself (the nonlinear, asymmetric N1 lag, linearized at one
    point) leave the model. Inputs that acted only on ``x_i`` keep their (now near-zero) columns.

    Parameters
    ----------
    model : LinearModel
        Continuous.
    state : str
        The state to turn into an input (``"n1_pct"``).
    input_name : str, optional
        The input's name (default the state's); its trim ``u0`` is the state's ``x0``; kind
        ``"control"`` (a known input).

    Raises
    ------
    DesignError
        A discrete model or an unknown state.
    """
    if model.is_discrete:
        raise DesignError("state_as_input works on the continuous model (before discretizing)")
    if state not in model.state_names:
        raise DesignError(f"no state {state!r}; states are {', '.join(model.state_names)}")
    i = model.state_names.index(state)
    keep = [k for k in range(model.n_states) if k != i]
    B = np.hstack([model.B[keep], model.A[keep][:, [i]]])
    D = np.hstack([model.D, model.C[:, [i]]])
    kinds = tuple(model.input_kinds) + ("control",) if model.input_kinds else ()
    return replace(
        model, A=model.A[np.ix_(keep, keep)], B=B, C=model.C[:, keep], D=D,
        state_names=tuple(model.state_names[k] for k in keep), input_names=tuple(model.input_names) + (input_name or state,),
        input_kinds=kinds, x0=model.x0[keep], u0=np.concatenate([model.u0, [model.x0[i]]]),
        meta={**model.meta, "measured_inputs": [*model.meta.get("measured_inputs", []), input_name or state]}, step=None,
    )


def reduce(model: LinearModel, order: int | None = None, *, rel_tol: float = 1e-5,
           input_scale: Sequence[float] | None = None, output_scale: Sequence[float] | None = None,
           keep_slower_than_s: float = 100.0) -> LinearModel:
    """Balanced truncation of ``model`` (SLICOT ``AB09MD`` through slycot), continuous or discrete.

    The step model of the F-16 has 71-84 states, most of them shift registers and AB3 history of
    which only a few combinations reach the outputs; balanced truncation keeps the states with
    the largest Hankel singular values (measured: 84 -> 22 states at 5000 ft / 420 KTAS with the
    same doublet-validation error, 1.6 %; ``tests/linear/test_reduce.py``).

    Modes slower than ``keep_slower_than_s`` (``|z| >= exp(-dt / T)`` discrete, ``Re s >= -1 / T``
    continuous: the heading and altitude integrators, a slow spiral, unstable modes) are kept as
    they are; the rest is balanced and truncated. Without that split, near-integrators give Hankel
    singular values so large that a relative tolerance keeps too few of the others (measured on
    the DHC-6 step model: 20 states needed a tolerance of 3e-8). ``D`` is unchanged.

    Parameters
    ----------
    model : LinearModel
        The model (any states; discrete models are reduced in discrete time).
    order : int, optional
        States to keep in total (the unstable part included). Default: every state whose Hankel
        singular value is at least ``rel_tol`` times the largest.
    rel_tol : float
        Relative Hankel singular value kept when ``order`` is not given [-].
    input_scale, output_scale : sequence of float, optional
        Typical size of each input and output [their units]. Balanced truncation weighs signals by
        their units; with mixed units (ft, rad, g) give the sizes that matter (e.g. the doublet
        amplitudes and the response RMS, or the sensor noise). Default 1 for all.
    keep_slower_than_s : float
        Time constant above which a mode is kept as it is, not balanced [s].

    Returns
    -------
    LinearModel
        States ``bal<i>`` (the kept slow modes in real Schur form, then balanced coordinates; no
        physical meaning), no step terms; ``meta["reduced"]`` holds the original order, the kept
        order, the number of slow modes kept and the Hankel singular values of the scaled fast
        part (``meta["lag_states"]`` is dropped: those states are gone).

    Raises
    ------
    DesignError
        A bad order or scale, or SLICOT failing (the message says why).
    """
    from slycot import ab09md
    from slycot.exceptions import SlycotError

    n, m, p = model.n_states, model.n_inputs, model.n_outputs
    su = np.ones(m) if input_scale is None else np.asarray(input_scale, dtype=float)
    sy = np.ones(p) if output_scale is None else np.asarray(output_scale, dtype=float)
    if su.shape != (m,) or sy.shape != (p,) or np.any(su <= 0) or np.any(sy <= 0):
        raise DesignError(f"input_scale needs {m} and output_scale {p} positive sizes")
    if order is not None and not 0 < order <= n:
        raise DesignError(f"order {order} must be between 1 and the model's {n} states")
    dico = "D" if model.is_discrete else "C"
    if not keep_slower_than_s > 0:
        raise DesignError(f"keep_slower_than_s = {keep_slower_than_s} must be positive")
    alpha = math.exp(-model.dt_s / keep_slower_than_s) if model.is_discrete else -1.0 / keep_slower_than_s
    # balance the scaled system B diag(su), diag(1/sy) C: units no longer decide what is kept
    Bs, Cs = model.B * su, model.C / sy[:, None]

    def truncate(nr: int | None) -> tuple:
        # fixed order nr (the unstable part included), or None: a minimal realization (SLICOT's
        # default tolerance); returns (nr, Ar, Br, Cr, ns, hsv)
        try:
            return ab09md(dico, "B", "N", n, m, p, model.A.copy(), Bs.copy(), Cs.copy(), alpha=alpha, nr=nr, tol=0.0)
        except SlycotError as exc:
            raise DesignError(f"balanced truncation failed: {exc}") from None

    nr, Ar, Br, Cr, ns, hsv = truncate(order)
    n_unstable = n - ns
    if order is None:  # keep the Hankel singular values above rel_tol of the largest
        keep = int(np.sum(hsv[:ns] >= rel_tol * hsv[0])) if ns else 0
        nr, Ar, Br, Cr, _, _ = truncate(keep + n_unstable)
    Ar, Br, Cr = Ar[:nr, :nr], Br[:nr] / su, Cr[:, :nr] * sy[:, None]
    return LinearModel(
        A=Ar, B=Br, C=Cr, D=model.D.copy(), dt_s=model.dt_s, state_names=tuple(f"bal{i}" for i in range(nr)),
        input_names=model.input_names, output_names=model.output_names, input_kinds=model.input_kinds,
        u0=model.u0, y0=model.y0, op=model.op,
        meta={**{k: v for k, v in model.meta.items() if k != "lag_states"},
              "reduced": {"from_states": n, "states": int(nr), "unstable_kept": int(n_unstable),
                          "hankel_sv": [float(h) for h in hsv[:ns]]}},
    )
