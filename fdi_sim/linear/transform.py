"""Operations on a :class:`~fdi_sim.linear.model.LinearModel`: discretization, input/output selection, state removal.

Pure maths, no JSBSim: the model schedule discretizes here at every lookup.
"""
from __future__ import annotations

from dataclasses import replace
from typing import Sequence

import numpy as np

from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel

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
        from fdi_sim.linear.step import step_model

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


def lag_state_name(output: str) -> str:
    """``nz_g`` -> ``nz_lag_g``: the state holding an output one step late, unit last (also the step model's)."""
    stem, _, unit = output.rpartition("_")
    return f"{stem}_lag_{unit}" if stem else f"{output}_lag"


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
