"""The discrete model of JSBSim's own step: what the simulation does between two samples.

A continuous model discretized by zero-order hold is exact for ``dx/dt = A x + B u`` with a held
input. The simulation is not that system at the level of one step (measured in
``tests/linear/test_linearize_jsbsim.py``):

1. **Integration.** ``FGPropagate`` integrates with third-order Adams-Bashforth (``Aircraft``
   sets all four integrators): ``x_{k+1} = x_k + dt (23 f_k - 16 f_{k-1} + 5 f_{k-2}) / 12``. On a
   smooth trajectory that is ZOH to O(dt^4); at an input step it overshoots by ``11/12 dt`` of the
   derivative jump, then settles half a step ahead.
2. **One-pass delays.** Models read values computed later in the previous pass: the F-16 FBW
   (FCS before FGAuxiliary) reads rates, alpha and air data one step late and the pilot-station
   accelerations two steps late; alpha-dot and the DHC-6 induced drag (``aero/cl-squared``) come
   from the previous pass. With the derivative after pass ``j + 1`` written ``S_j`` (the step
   terms ``Ax``, ``Bu`` of :class:`~fdi_sim.linear.model.StepTerms`) the derivative at step ``k``
   is ``f_k = sum_j (G_j x_{k-j} + H_j u_{k-j})`` with ``G_0 = S_0`` and
   ``G_j = S_j - S_{j-1}``: what a pass adds arrives one step later in the simulation.
3. **Engines inside the pass.** ``FGPropulsion`` runs after the FCS with the new throttle, so
   the engine state used in step ``k`` already holds ``u_k``: ``e_k = P e_{k-1} + G x_k + G_u u_k``
   (ZOH of the engine rows over one step).
4. **Accelerometers one step late.** The pilot-station accelerations read after step ``k`` are
   computed from the derivatives of step ``k - 1``: ``y_k = z_k``,
   ``z_{k+1} = Lf f_k + Lx x_k + Lu u_k`` with ``Lx = C - Lf A``, ``Lu = D - Lf B``.

:func:`step_model` realizes exactly this as a :class:`~fdi_sim.linear.model.LinearModel` at the
simulation step. Its state: the model states, shift registers of the delayed states and inputs
(only the columns and depths that carry a delay), the two previous derivatives (AB3), and one
state per lagged output. For the F-16 the realization has about 60-80 states, for the DHC-6
about 40-50; its dominant poles mapped back by ``ln(z) / dt`` (:func:`equivalent_poles`) are the
modes the 120 Hz simulation actually has.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import expm

from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel, StepTerms

#: third-order Adams-Bashforth weights of f_k, f_{k-1}, f_{k-2}
AB3: tuple[float, float, float] = (23.0 / 12.0, -16.0 / 12.0, 5.0 / 12.0)
#: a delayed increment smaller than this fraction of its column's largest entry is merged into the
#: previous delay (the sum, hence the steady state, is kept exactly)
DELAY_TOL: float = 1e-4
#: unit of the derivative of a state, by the unit suffix of the state
_RATE_UNIT: dict[str, str] = {"fps": "fps2", "rad": "radps", "radps": "radps2", "ft": "fps", "pct": "pctps",
                              "rpm": "rpmps", "norm": "normps", "g": "gps"}


def lag_state_name(output: str) -> str:
    """``nz_g`` -> ``nz_lag_g``: the state holding an output one step late, unit last (step model and ``discretize``)."""
    stem, _, unit = output.rpartition("_")
    return f"{stem}_lag_{unit}" if stem else f"{output}_lag"


def _split(name: str) -> tuple[str, str]:
    stem, _, unit = name.rpartition("_")
    return (stem, unit) if stem else (name, "")


def _lagged(name: str, j: int) -> str:
    """``alpha_rad`` -> ``alpha_lag1_rad``: the value ``j`` steps ago, unit last."""
    stem, unit = _split(name)
    return f"{stem}_lag{j}_{unit}"


def _rate_lagged(name: str, j: int) -> str:
    """``vt_fps`` -> ``vtdot_lag1_fps2``: the derivative ``j`` steps ago."""
    stem, unit = _split(name)
    return f"{stem}dot_lag{j}_{_RATE_UNIT.get(unit, unit + 'ps')}"


def delay_increments(S: NDArray[np.float64], tol: float = DELAY_TOL) -> tuple[list[NDArray[np.float64]], list[int]]:
    """``G_j = S_j - S_{j-1}`` (``G_0 = S_0``) and, per column, the last delay that matters.

    Increments after a column's last significant delay (``|G_j[:, c]| <= tol max_j |G_j[:, c]|``)
    are added to that delay, so ``sum_j G_j`` stays the settled matrix exactly.

    Parameters
    ----------
    S : NDArray
        Shape (P, r, c): the derivative rows after each pass.

    Returns
    -------
    G : list of NDArray
        ``G_0 .. G_{P-1}``, each (r, c).
    depth : list of int
        Per column, the largest ``j`` with a non-zero ``G_j`` (0: no delay).
    """
    G = [S[0].copy()] + [S[j] - S[j - 1] for j in range(1, S.shape[0])]
    depth = []
    for c in range(S.shape[2]):
        scale = max(float(np.max(np.abs(Gj[:, c]))) for Gj in G) or 1.0
        last = max([j for j in range(len(G)) if np.max(np.abs(G[j][:, c])) > tol * scale] or [0])
        for j in range(last + 1, len(G)):  # merge the negligible tail into the last delay
            G[last][:, c] += G[j][:, c]
            G[j][:, c] = 0.0
        depth.append(last)
    return G, depth


def engine_in_pass(model: LinearModel, dt_s: float) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """``e_k = P e_{k-1} + Gx x_k + Gu u_k``: ZOH of the engine rows over one step (states after ``n_rigid``).

    Returns
    -------
    P, Gx, Gu : NDArray
        Shapes (ne, ne), (ne, n_rigid), (ne, m).
    """
    assert model.step is not None
    nr, n, m = model.step.n_rigid, model.n_states, model.n_inputs
    ne = n - nr
    if ne == 0:
        return np.zeros((0, 0)), np.zeros((0, nr)), np.zeros((0, m))
    M = np.zeros((n + m, n + m))  # [e; x; u] with x and u held over the step
    M[:ne, :ne] = model.A[nr:, nr:]
    M[:ne, ne:ne + nr] = model.A[nr:, :nr]
    M[:ne, ne + nr:] = model.B[nr:]
    E = expm(M * dt_s)
    return E[:ne, :ne], E[:ne, ne:ne + nr], E[:ne, ne + nr:]


def step_model(model: LinearModel, dt_s: float | None = None, tol: float = DELAY_TOL) -> LinearModel:
    """The discrete model of JSBSim's simulation step (see the module notes).

    Parameters
    ----------
    model : LinearModel
        Continuous model with step terms (``model.step``), from the linearizer.
    dt_s : float, optional
        ``model.step.dt_s`` (the step the terms were measured at; the default) or a multiple of it,
        which gives the step model sampled every so many steps with the input held (:func:`lift`) [s].
    tol : float
        Delayed increments below this fraction of their column are merged (see
        :func:`delay_increments`).

    Returns
    -------
    LinearModel
        Discrete at the simulation step; outputs and inputs as ``model``; states: the model's
        states, then ``<state>_lag<j>_<unit>`` and ``<input>_lag<j>_<unit>`` (values ``j`` steps
        ago), ``<state>dot_lag<j>_<unit>`` (derivatives of the last two steps), and
        ``<output>_lag_<unit>`` per lagged output. ``meta["discretized"] = "step"``.

    Raises
    ------
    DesignError
        A model without step terms, a discrete model, or another step.
    """
    st = model.step
    if model.is_discrete:
        raise DesignError("step_model needs the continuous model with its step terms, not a discrete one")
    if st is None:
        raise DesignError("this model has no step terms: linearize it with FDSettings(step_passes > 0) "
                          "(fdi_sim.linear.linearize.linearize does by default); a model whose A or B was "
                          "changed afterwards has none (LinearModel.step)")
    h = st.dt_s if dt_s is None else float(dt_s)
    n_lift = round(h / st.dt_s)
    if n_lift < 1 or abs(h - n_lift * st.dt_s) > 1e-9 * h:
        raise DesignError(f"the step model exists at multiples of the simulation step {st.dt_s:g} s (asked {h:g} s); "
                          "use a multiple, or method='zoh' at other rates")
    if n_lift > 1:  # the model of the simulation step, sampled every n_lift steps (input held)
        return lift(step_model(model, st.dt_s, tol), n_lift)
    nr, n, m = st.n_rigid, model.n_states, model.n_inputs
    ne = n - nr
    lag = [model.output_names.index(o) for o in st.lagged_outputs]
    Gx, dx = delay_increments(st.Ax, tol)     # G_j on the states (rigid rows, all columns)
    Hu, du = delay_increments(st.Bu, tol)     # H_j on the inputs
    dx = [0 if c >= nr else d for c, d in enumerate(dx)]  # engine columns act at once (in the pass)
    Pe, Ex, Eu = engine_in_pass(model, h)
    # ---- state layout
    names: list[str] = list(model.state_names)
    x0: list[float] = list(model.x0)

    def registers(signals: tuple[str, ...], depth: list[int], trim: NDArray[np.float64]) -> dict[tuple[int, int], int]:
        """Append a shift register of ``depth[c]`` past values per signal ``c``; ``(c, j) -> state index``."""
        mem = {}
        for c, d in enumerate(depth):
            for j in range(1, d + 1):
                mem[(c, j)] = len(names)
                names.append(_lagged(signals[c], j))
                x0.append(float(trim[c]))
        return mem

    mem_x = registers(model.state_names, dx, model.x0)
    mem_u = registers(model.input_names, du, model.u0)
    i_f1 = len(names)
    names += [_rate_lagged(model.state_names[c], 1) for c in range(nr)]
    names += [_rate_lagged(model.state_names[c], 2) for c in range(nr)]
    x0 += [0.0] * (2 * nr)
    i_z = len(names)
    names += [lag_state_name(model.output_names[i]) for i in lag]
    x0 += [float(model.y0[i]) for i in lag]
    N = len(names)
    # ---- the engine of this pass: e_k = Pe e_{k-1} + Ex x_k + Eu u_k, as rows over [s; u]
    Es, Eu_ = np.zeros((ne, N)), Eu.copy()
    Es[:, nr:n], Es[:, :nr] = Pe, Ex
    # ---- the derivative of this step: f_k = Fs s + Fu u
    Fs, Fu = np.zeros((nr, N)), Hu[0].copy()
    Fs[:, :nr] = Gx[0][:, :nr]
    if ne:
        Fs += Gx[0][:, nr:] @ Es
        Fu += Gx[0][:, nr:] @ Eu_
    for (c, j), k in mem_x.items():
        Fs[:, k] += Gx[j][:, c]
    for (c, j), k in mem_u.items():
        Fs[:, k] += Hu[j][:, c]
    # ---- next state
    Ad, Bd = np.zeros((N, N)), np.zeros((N, m))
    Ad[:nr] = h * AB3[0] * Fs
    Bd[:nr] = h * AB3[0] * Fu
    Ad[:nr, :nr] += np.eye(nr)
    Ad[:nr, i_f1:i_f1 + nr] += h * AB3[1] * np.eye(nr)
    Ad[:nr, i_f1 + nr:i_f1 + 2 * nr] += h * AB3[2] * np.eye(nr)
    Ad[nr:n], Bd[nr:n] = Es, Eu_                       # the engine state carries e_k to the next step
    for mem, first in ((mem_x, Ad), (mem_u, Bd)):      # shift registers: x_{k-j+1} -> x_{k-j}, u likewise
        for (c, j), k in mem.items():
            if j == 1:
                first[k, c] = 1.0
            else:
                Ad[k, mem[(c, j - 1)]] = 1.0
    Ad[i_f1:i_f1 + nr], Bd[i_f1:i_f1 + nr] = Fs, Fu     # f_{k-1} <- f_k
    Ad[i_f1 + nr:i_f1 + 2 * nr, i_f1:i_f1 + nr] = np.eye(nr)
    # state at this pass [x_k; e_k] as rows over [s; u]
    Xs, Xu = np.zeros((n, N)), np.zeros((n, m))
    Xs[:nr, :nr] = np.eye(nr)
    if ne:
        Xs[nr:], Xu[nr:] = Es, Eu_
    # lagged outputs: z_{k+1} = Lf f_k + Lx [x_k; e_k] + Lu u_k
    Lf = st.Lf
    Lx = model.C[lag] - Lf @ model.A[:nr]
    Lu = model.D[lag] - Lf @ model.B[:nr]
    Ad[i_z:] = Lf @ Fs + Lx @ Xs
    Bd[i_z:] = Lf @ Fu + Lx @ Xu + Lu
    # ---- outputs: y_k = C [x_k; e_k] + D u_k, lagged ones y_k = z_k
    Cd = model.C @ Xs
    Dd = model.C @ Xu + model.D
    for r, i in enumerate(lag):
        Cd[i], Dd[i] = 0.0, 0.0
        Cd[i, i_z + r] = 1.0
    depth = {"states": {model.state_names[c]: dx[c] for c in range(nr) if dx[c]},
             "inputs": {model.input_names[c]: du[c] for c in range(m) if du[c]}}
    return LinearModel(
        A=Ad, B=Bd, C=Cd, D=Dd, dt_s=h, state_names=tuple(names), input_names=model.input_names,
        output_names=model.output_names, input_kinds=model.input_kinds, x0=np.array(x0), u0=model.u0,
        y0=model.y0, op=model.op,
        meta={**model.meta, "discretized": "step", "step_delays": depth, "step_passes": st.n_passes,
              "lag_states": names[i_z:]},
    )


def lift(model_d: LinearModel, n: int) -> LinearModel:
    """The discrete model ``model_d`` sampled every ``n`` steps with the input held over each block.

    With the timing convention of :mod:`fdi_sim.linear.validate` (``u_k`` set before step ``k``,
    ``y_k = C x_k + D u_k`` read after it, ``x_{k+1} = A x_k + B u_k``), a detector that sets
    ``u_j`` at the start of block ``j`` (simulation step ``jn``) and reads the outputs after the
    block's last step (``jn + n - 1``) sees, with ``xi_j = x_{jn}`` and ``S_m = sum_{i<m} A^i``::

        xi_{j+1} = A^n xi_j + S_n B u_j,    y_j = C A^(n-1) xi_j + (C S_(n-1) B + D) u_j

    This is exact for the step model at any multiple of the simulation step, where a continuous
    model discretized by ZOH carries the continuous model's error at every rate.

    Raises
    ------
    DesignError
        A continuous model or ``n < 1``.
    """
    if not model_d.is_discrete:
        raise DesignError("lift needs a discrete model")
    if n < 1:
        raise DesignError(f"lift: n = {n} must be a positive number of steps")
    if n == 1:
        return model_d
    A, B = model_d.A, model_d.B
    An1 = np.eye(A.shape[0])
    Sn1 = np.zeros_like(A)
    for _ in range(n - 1):  # after the loop An1 = A^(n-1), Sn1 = S_(n-1)
        Sn1 = Sn1 + An1
        An1 = A @ An1
    return replace(model_d, A=A @ An1, B=(Sn1 + An1) @ B, C=model_d.C @ An1, D=model_d.C @ Sn1 @ B + model_d.D,
                   dt_s=n * model_d.dt_s, meta={**model_d.meta, "lifted_steps": n})


def equivalent_poles(model_d: LinearModel, min_abs_z: float = 0.3) -> NDArray[np.complex128]:
    """Continuous-time equivalents ``ln(z) / dt`` of the poles of a discrete model [1/s].

    Poles with ``|z| < min_abs_z`` (the deadbeat shift registers and the parasitic AB3 roots,
    faster than ``ln(0.3) / dt`` = -144 1/s at 120 Hz) are left out. The result is what the
    sampled system does, to compare with the eigenvalues of continuous linearizations.
    """
    if not model_d.is_discrete:
        raise DesignError("equivalent_poles needs a discrete model")
    z = np.linalg.eigvals(model_d.A).astype(complex)
    z = z[np.abs(z) >= min_abs_z]
    return np.log(z) / model_d.dt_s


__all__ = ["AB3", "DELAY_TOL", "StepTerms", "delay_increments", "engine_in_pass", "equivalent_poles", "lift",
           "step_model"]
