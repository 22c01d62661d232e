"""The discrete model of JSBSim's step (fdi_sim.linear.step) against explicit recursions (no JSBSim).

Each test writes the simulation's step the long way (a Python loop over AB3, the pass delays, the
engine inside the pass and the lagged accelerometers) and checks the realization reproduces it.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.linalg import expm

from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel, StepTerms
from fdi_sim.linear.step import AB3, delay_increments, equivalent_poles, lift, step_model
from fdi_sim.linear.transform import discretize, select
from fdi_sim.linear.validate import simulate_linear

H = 1.0 / 120.0
NR = 10
STATES = ("vt_fps", "alpha_rad", "beta_rad", "p_radps", "q_radps", "r_radps", "phi_rad", "theta_rad", "psi_rad", "h_ft")
LAGGED = ("nx_g", "nz_g")


def _model(rng: np.random.Generator, passes: int, ne: int = 0, m: int = 3) -> LinearModel:
    """A stable random model with ``passes`` pass matrices that build up to A and B, and lagged outputs."""
    n = NR + ne
    A = 0.5 * rng.normal(size=(n, n)) - 4.0 * np.eye(n)
    B = rng.normal(size=(n, m))
    if ne:
        A[NR:, :NR] *= 0.1
    # passes: S_j move from a first-pass value to the settled rows
    Ax = np.array([A[:NR] + (0.6 ** (j + 1) if j < passes - 1 else 0.0) * rng.normal(size=(NR, n)) for j in range(passes)])
    Ax[:, :, NR:] = A[:NR, NR:]  # engine columns act at once
    Bu = np.array([B[:NR] + (0.5 ** (j + 1) if j < passes - 1 else 0.0) * rng.normal(size=(NR, m)) for j in range(passes)])
    outs = ("q_radps", "nx_g", "alpha_rad", "nz_g")
    C = rng.normal(size=(len(outs), n))
    D = rng.normal(size=(len(outs), m))
    Lf = rng.normal(size=(len(LAGGED), NR))
    for r, o in enumerate(LAGGED):  # lagged rows: settled C, D consistent with Lf (Lu = 0)
        i = outs.index(o)
        D[i] = Lf[r] @ B[:NR]
    names = STATES + tuple(f"e{i}_pct" for i in range(ne))
    step = StepTerms(Ax=Ax, Bu=Bu, Lf=Lf, lagged_outputs=LAGGED, dt_s=H, n_rigid=NR)
    return LinearModel(A=A, B=B, C=C, D=D, state_names=names, input_names=tuple(f"u{i}_norm" for i in range(m)),
                       output_names=outs, step=step, meta={"lagged_outputs": list(LAGGED)})


def _recursion(model: LinearModel, U: np.ndarray) -> np.ndarray:
    """The simulation's step written out: f_k = sum_j G_j x_{k-j} + H_j u_{k-j}, AB3, engine in the pass."""
    st = model.step
    n, m = model.n_states, model.n_inputs
    ne = n - NR
    P = st.n_passes
    G = [st.Ax[0]] + [st.Ax[j] - st.Ax[j - 1] for j in range(1, P)]
    Hu = [st.Bu[0]] + [st.Bu[j] - st.Bu[j - 1] for j in range(1, P)]
    M = np.zeros((n + m, n + m))
    M[:ne, :ne], M[:ne, ne:ne + NR], M[:ne, ne + NR:] = model.A[NR:, NR:], model.A[NR:, :NR], model.B[NR:]
    E = expm(M * H)
    Pe, Ex, Eu = E[:ne, :ne], E[:ne, ne:ne + NR], E[:ne, ne + NR:]
    lag = [model.output_names.index(o) for o in st.lagged_outputs]
    Lx = model.C[lag] - st.Lf @ model.A[:NR]
    Lu = model.D[lag] - st.Lf @ model.B[:NR]
    xr, e = np.zeros(NR), np.zeros(ne)
    hist_x, hist_u, hist_f = [], [], [np.zeros(NR), np.zeros(NR)]
    prev = None
    ys = []
    for u in U:
        e = Pe @ e + Ex @ xr + Eu @ u                      # engine inside the pass, with u_k
        x = np.concatenate([xr, e])
        hist_x.insert(0, xr.copy())
        hist_u.insert(0, u)
        f = G[0] @ x + Hu[0] @ u
        for j in range(1, P):
            if j < len(hist_x):
                f += G[j][:, :NR] @ hist_x[j] + Hu[j] @ hist_u[j]
        y = model.C @ x + model.D @ u
        for r, i in enumerate(lag):                         # accelerometers: from the previous step
            y[i] = 0.0 if prev is None else st.Lf[r] @ prev[0] + Lx[r] @ prev[1] + Lu[r] @ prev[2]
        ys.append(y)
        prev = (f, x, u)
        xr = xr + H * (AB3[0] * f + AB3[1] * hist_f[0] + AB3[2] * hist_f[1])
        hist_f = [f, hist_f[0]]
    return np.array(ys)


@pytest.mark.parametrize("passes, ne", [(1, 0), (4, 0), (3, 2)])
def test_realization_is_the_simulation_step(passes: int, ne: int) -> None:
    rng = np.random.default_rng(10 + passes + ne)
    model = _model(rng, passes, ne)
    U = np.zeros((400, model.n_inputs))
    U[20:140, 0], U[140:260, 0] = 0.3, -0.3        # a doublet
    U[50:300, 1] = rng.normal(size=250) * 0.1       # a noisy input
    d = step_model(model)
    np.testing.assert_allclose(simulate_linear(d, U), _recursion(model, U), rtol=1e-9, atol=1e-11)
    assert d.dt_s == H and d.meta["discretized"] == "step"
    assert d.state_names[:model.n_states] == model.state_names


def test_without_delays_ab3_settles_half_a_step_ahead_of_zoh() -> None:
    """One pass (no delays): AB3 on f = A x + B u. After an input step the state runs 11/12 dt of the
    derivative jump ahead of ZOH on the first step, then keeps half a step ahead (JSBSim's AB3)."""
    A = -0.5 * np.eye(NR)
    B = np.ones((NR, 1))
    C = np.eye(NR)
    st = StepTerms(Ax=A[None], Bu=B[None], Lf=np.zeros((0, NR)), lagged_outputs=(), dt_s=H)
    m = LinearModel(A=A, B=B, C=C, D=np.zeros((NR, 1)), state_names=STATES, step=st)
    U = np.zeros((40, 1))
    U[10:] = 1.0
    y_ab3 = simulate_linear(step_model(m), U)[:, 0]
    y_zoh = simulate_linear(discretize(m, H), U)[:, 0]
    excess = (y_ab3 - y_zoh) / H  # in units of the derivative jump B = 1
    assert excess[11] == pytest.approx(11 / 12, rel=1e-2)
    assert excess[12] == pytest.approx(6 / 12, rel=2e-2)
    assert excess[20] == pytest.approx(6 / 12, rel=5e-2)


def test_steady_state_is_the_continuous_models() -> None:
    """The delays only move increments in time: the DC gain stays -C A^-1 B + D (lagged outputs included)."""
    model = _model(np.random.default_rng(3), 4, ne=2)
    d = step_model(model)
    dc_step = d.C @ np.linalg.solve(np.eye(d.n_states) - d.A, d.B) + d.D
    dc = -model.C @ np.linalg.solve(model.A, model.B) + model.D
    np.testing.assert_allclose(dc_step, dc, rtol=1e-8, atol=1e-10)


def test_equivalent_poles() -> None:
    """ln(z)/dt of a ZOH model are the continuous eigenvalues; the step model's dominant poles are
    the continuous ones to O(dt^3) (AB3) when there are no delays."""
    rng = np.random.default_rng(4)
    model = _model(rng, 1)
    lam = np.sort_complex(np.linalg.eigvals(model.A))
    np.testing.assert_allclose(np.sort_complex(equivalent_poles(discretize(model, H, lag_outputs=False))), lam,
                               rtol=1e-9)
    eq = np.sort_complex(equivalent_poles(step_model(model), min_abs_z=0.5))
    assert eq.size == lam.size
    np.testing.assert_allclose(eq, lam, rtol=1e-3)


def test_delay_increments_merge_the_tail_and_keep_the_sum() -> None:
    S = np.zeros((4, 2, 2))
    S[0] = [[1.0, 0.0], [0.0, 1.0]]
    S[1] = [[2.0, 0.0], [0.0, 1.0 + 1e-9]]
    S[2] = [[2.5, 0.0], [0.0, 1.0 + 2e-9]]
    S[3] = [[2.5 + 1e-8, 0.0], [0.0, 1.0 + 2e-9]]
    G, depth = delay_increments(S, tol=1e-6)
    assert depth == [2, 0]
    np.testing.assert_allclose(sum(G), S[-1], rtol=0, atol=1e-15)
    assert np.all(G[3] == 0.0)


def test_select_keeps_the_step_terms_consistent() -> None:
    model = _model(np.random.default_rng(5), 3)
    sub = select(model, outputs=["nz_g", "q_radps"], inputs=["u2_norm", "u0_norm"])
    assert sub.step is not None and sub.step.lagged_outputs == ("nz_g",)
    U = np.random.default_rng(6).normal(size=(200, 2))
    full = np.zeros((200, 3))
    full[:, 2], full[:, 0] = U[:, 0], U[:, 1]
    y_full = simulate_linear(step_model(model), full)
    y_sub = simulate_linear(step_model(sub), U)
    np.testing.assert_allclose(y_sub, y_full[:, [model.output_names.index("nz_g"), model.output_names.index("q_radps")]],
                               rtol=1e-10, atol=1e-12)


def test_step_terms_do_not_survive_a_change_of_a_or_b() -> None:
    """The step terms describe the A and B they were measured with (their last pass is A's, B's rigid
    rows): a model built from it by dataclasses.replace with other matrices has none, so the step model
    of the old matrices cannot be built for the new ones."""
    model = _model(np.random.default_rng(8), 3)
    assert replace(model, meta={}).step is model.step  # nothing changed: the terms stay
    assert replace(model, A=model.A * (1 + 1e-13)).step is model.step  # rounding (the body -> aero transform)
    for changed in (replace(model, A=model.A + 0.1 * np.eye(model.n_states)), replace(model, B=2.0 * model.B)):
        assert changed.step is None
        with pytest.raises(DesignError, match="no step terms"):
            discretize(changed, H, method="step")


def test_bad_input() -> None:
    model = _model(np.random.default_rng(7), 2)
    with pytest.raises(DesignError, match="multiples of the simulation step"):
        discretize(model, 0.02, method="step")  # 2.4 steps
    with pytest.raises(DesignError, match="positive number of steps"):
        lift(step_model(model), 0)
    with pytest.raises(DesignError, match="no step terms"):
        step_model(LinearModel(A=model.A, B=model.B, C=model.C, D=model.D))
    with pytest.raises(DesignError, match="continuous model"):
        step_model(discretize(model, H))
    with pytest.raises(ValueError, match="do not fit"):
        LinearModel(A=np.eye(12), B=np.ones((12, 3)), C=np.ones((4, 12)), D=model.D, output_names=model.output_names,
                    step=model.step)
    with pytest.raises(ValueError, match="not model outputs"):
        LinearModel(A=model.A, B=model.B, C=model.C, D=model.D, step=model.step)


@pytest.mark.parametrize("n", [1, 2, 6])
def test_lifted_step_model_is_the_step_model_read_every_n_steps(n: int) -> None:
    """A detector at n simulation steps holds its input over a block and reads the outputs after
    the block's last step: the lifted model gives exactly the fine model's outputs there."""
    rng = np.random.default_rng(3 + n)
    model = _model(rng, 3, 2)
    fine = step_model(model)
    blocks = 60
    Ub = rng.normal(size=(blocks, model.n_inputs)) * 0.2
    y_fine = simulate_linear(fine, np.repeat(Ub, n, axis=0))
    lifted = discretize(model, n * H, method="step")
    assert lifted.dt_s == pytest.approx(n * H) and lifted.n_states == fine.n_states
    np.testing.assert_allclose(simulate_linear(lifted, Ub), y_fine[n - 1::n], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(np.sort(np.abs(np.linalg.eigvals(lifted.A))),
                               np.sort(np.abs(np.linalg.eigvals(fine.A)) ** n), atol=1e-9)
