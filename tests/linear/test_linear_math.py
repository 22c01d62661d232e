"""Pure maths of the linearizer: body -> aero transform, discretization, selection, linear simulation.

Every function is checked against an independent computation (numerical differentiation of the
nonlinear map, scipy's matrix exponential, scipy.signal.dlsim, python-control frequency responses).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import expm
from scipy.signal import dlsim

from fdi_sim.aircraft.linearize import BodyJacobians
from fdi_sim.aircraft.linearize_response import EngineLag
from fdi_sim.errors import DesignError
from fdi_sim.linear.linearize import AERO_STATES, body_to_aero, to_linear_model, uvw_to_aero_jacobian
from fdi_sim.linear.model import LinearModel
from fdi_sim.linear.transform import discretize, drop_states, select
from fdi_sim.linear.validate import DoubletSpec, aggregate, doublet_signal, nrmse, simulate_linear

BODY = ("u_body_fps", "v_body_fps", "w_body_fps", "p_radps", "q_radps", "r_radps", "phi_rad", "theta_rad", "psi_rad", "h_ft")


def _aero(uvw: np.ndarray) -> np.ndarray:
    u, v, w = uvw
    vt = math.sqrt(u * u + v * v + w * w)
    return np.array([vt, math.atan2(w, u), math.asin(v / vt)])


@given(u=st.floats(100, 900), v=st.floats(-40, 40), w=st.floats(-80, 80))
@settings(max_examples=40, deadline=None)
def test_uvw_jacobian_matches_numerical_derivative(u: float, v: float, w: float) -> None:
    J = uvw_to_aero_jacobian(u, v, w)
    x0 = np.array([u, v, w])
    h = 1e-4
    Jn = np.column_stack([(_aero(x0 + h * e) - _aero(x0 - h * e)) / (2 * h) for e in np.eye(3)])
    np.testing.assert_allclose(J, Jn, rtol=1e-6, atol=1e-8)


def _random_body(rng: np.random.Generator, m: int = 3, p: int = 4) -> BodyJacobians:
    n = len(BODY)
    A = rng.normal(size=(n, n)) - 3 * np.eye(n)
    return BodyJacobians(
        A=A, B=rng.normal(size=(n, m)), C=rng.normal(size=(p, n)), D=rng.normal(size=(p, m)), state_names=BODY,
        input_names=tuple(f"u{i}_norm" for i in range(m)), output_names=tuple(f"y{i}_g" for i in range(p)),
        input_kinds=("control",) * m, x0=np.r_[650.0, 3.0, 20.0, np.zeros(6), 1e4], u0=np.zeros(m), y0=np.zeros(p),
        xdot0=np.zeros(n), knob_condition=1.0, engine="quasi_static", elapsed_s=0.0)


def test_body_to_aero_keeps_eigenvalues_and_frequency_response() -> None:
    bj = _random_body(np.random.default_rng(1))
    ab = body_to_aero(bj)
    assert ab.state_names == AERO_STATES
    np.testing.assert_allclose(np.sort_complex(np.linalg.eigvals(ab.A)), np.sort_complex(np.linalg.eigvals(bj.A)),
                               rtol=1e-9)
    for w in (0.1, 1.0, 10.0):  # G(jw) = C (jwI - A)^-1 B + D is coordinate-free
        G = bj.C @ np.linalg.solve(1j * w * np.eye(10) - bj.A, bj.B) + bj.D
        Ga = ab.C @ np.linalg.solve(1j * w * np.eye(10) - ab.A, ab.B) + ab.D
        np.testing.assert_allclose(Ga, G, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(ab.x0[:3], _aero(bj.x0[:3]))


def test_zoh_discretization_against_matrix_exponential() -> None:
    m = to_linear_model(_random_body(np.random.default_rng(2)))
    dt = 1 / 120
    d = discretize(m, dt, lag_outputs=False)
    n = m.n_states
    # [Ad Bd; 0 I] = expm([A B; 0 0] dt)
    M = np.zeros((n + m.n_inputs, n + m.n_inputs))
    M[:n, :n], M[:n, n:] = m.A, m.B
    E = expm(M * dt)
    np.testing.assert_allclose(d.A, E[:n, :n], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(d.B, E[:n, n:], rtol=1e-9, atol=1e-12)
    e = discretize(m, dt, method="euler", lag_outputs=False)
    np.testing.assert_allclose(e.A, np.eye(n) + dt * m.A)
    np.testing.assert_allclose(e.B, dt * m.B)


def test_lagged_outputs_are_the_plain_outputs_one_step_late() -> None:
    m = to_linear_model(_random_body(np.random.default_rng(3)))
    m = LinearModel(A=m.A, B=m.B, C=m.C, D=m.D, state_names=m.state_names, input_names=m.input_names,
                    output_names=m.output_names, meta={"lagged_outputs": ["y1_g", "y3_g"]})
    plain, lagged = discretize(m, 0.01, lag_outputs=False), discretize(m, 0.01)
    assert lagged.n_states == plain.n_states + 2 and lagged.state_names[-2:] == ("y1_lag_g", "y3_lag_g")
    u = np.random.default_rng(4).normal(size=(50, m.n_inputs))
    yp, yl = simulate_linear(plain, u), simulate_linear(lagged, u)
    np.testing.assert_allclose(yl[:, [0, 2]], yp[:, [0, 2]], atol=1e-12)
    np.testing.assert_allclose(yl[1:, [1, 3]], yp[:-1, [1, 3]], atol=1e-12)
    np.testing.assert_allclose(yl[0, [1, 3]], 0.0)


def test_simulate_linear_matches_scipy_dlsim() -> None:
    rng = np.random.default_rng(5)
    A = rng.normal(size=(4, 4)) * 0.2
    m = LinearModel(A=A, B=rng.normal(size=(4, 2)), C=rng.normal(size=(3, 4)), D=rng.normal(size=(3, 2)), dt_s=0.1)
    u = rng.normal(size=(40, 2))
    _, y_ref, _ = dlsim((m.A, m.B, m.C, m.D, m.dt_s), u)
    np.testing.assert_allclose(simulate_linear(m, u), y_ref, rtol=1e-10, atol=1e-12)


def _engine_model(rate: float = 0.7, gain: float = 40.0) -> LinearModel:
    """Discrete (ZOH) model: N1 lag driving a speed state, read by one output."""
    A = np.array([[-rate, 0.0], [0.3, -0.5]])
    B = np.array([[gain * rate, 0.0], [0.0, 1.0]])
    m = LinearModel(A=A, B=B, C=np.array([[0.0, 1.0], [1.0, 0.0]]), D=np.zeros((2, 2)),
                    state_names=("n1_pct", "v_fps"), input_names=("throttle_cmd_norm", "w_gust_body_fps"),
                    output_names=("vc_kts", "n1_pct"))
    return discretize(m, 1 / 120)


def test_engine_lag_with_equal_time_constants_is_the_linear_model() -> None:
    """ExpSeek with tau_up = tau_down = -dt / ln(A_d[n1, n1]) is the model's own N1 row, exactly."""
    d = _engine_model()
    tau = -d.dt_s / math.log(d.A[0, 0])
    u = np.random.default_rng(9).normal(size=(300, 2)) * [0.02, 1.0]
    np.testing.assert_allclose(simulate_linear(d, u, EngineLag(tau, tau)), simulate_linear(d, u),
                               rtol=1e-10, atol=1e-13)


def test_engine_lag_follows_expseek_on_a_doublet() -> None:
    """Up at 1 s, down at 2.4 s (FGTurboProp): N1 rises fast, falls slowly, so it stays above the trim
    after a zero-mean doublet, which no linear model does."""
    d = _engine_model()
    u = np.zeros((600, 2))
    u[:, 0] = doublet_signal(600, d.dt_s, DoubletSpec("throttle_cmd_norm", 0.02))
    y = simulate_linear(d, u, EngineLag(1.0, 2.4))[:, 1]
    # hand-rolled ExpSeek toward 40 u, state before the step -> output
    n1, ref = 0.0, []
    for uk in u[:, 0]:
        ref.append(n1)
        target = 40.0 * uk
        n1 = target + (n1 - target) * math.exp(-d.dt_s / (1.0 if n1 < target else 2.4))
    np.testing.assert_allclose(y, ref, rtol=1e-9, atol=1e-12)
    assert np.min(y) > -1e-12 and y[-1] > 0.01  # never below the trim; the linear model swings both ways
    assert np.min(simulate_linear(d, u)[:, 1]) < -0.1


def test_engine_lag_needs_a_first_order_row() -> None:
    d = _engine_model()
    coupled = LinearModel(A=d.A.T, B=d.B, C=d.C, D=d.D, dt_s=d.dt_s, state_names=d.state_names,
                          input_names=d.input_names, output_names=d.output_names)
    with pytest.raises(DesignError, match="depends on other states"):
        simulate_linear(coupled, np.zeros((3, 2)), EngineLag(1.0, 2.4))
    with pytest.raises(DesignError, match="no such state"):
        simulate_linear(d, np.zeros((3, 2)), EngineLag(1.0, 2.4, state_name="n2_pct"))


def test_doublet_signal_and_error_metrics() -> None:
    u = doublet_signal(1200, 1 / 120, DoubletSpec("elevator_cmd_norm", 0.01, start_s=0.5, width_s=1.0))
    assert u[59] == 0 and u[60] == 0.01 and u[179] == 0.01 and u[180] == -0.01 and u[299] == -0.01 and u[300] == 0
    assert abs(u.sum()) < 1e-12
    y = np.sin(np.linspace(0, 6, 100))
    assert nrmse(y, y) == 0.0
    np.testing.assert_allclose(nrmse(1.1 * y, y), 0.1)
    # aggregate over runs equals the direct computation on the stacked signals
    rng = np.random.default_rng(6)
    yn, yl = rng.normal(size=(3, 200, 2)), rng.normal(size=(3, 200, 2))
    pair, rms = nrmse(yl, yn, axis=1), np.sqrt(np.mean(yn**2, axis=1))
    np.testing.assert_allclose(aggregate(pair, rms), nrmse(yl, yn, axis=(0, 1)), rtol=1e-12)


def test_select_and_drop_states() -> None:
    m = to_linear_model(_random_body(np.random.default_rng(7)))
    s = select(m, outputs=["y2_g", "y0_g"], inputs=["u1_norm"])
    np.testing.assert_allclose(s.C, m.C[[2, 0]])
    np.testing.assert_allclose(s.D, m.D[np.ix_([2, 0], [1])])
    with pytest.raises(DesignError, match="not in the model"):
        select(m, outputs=["nz_g"])
    with pytest.raises(DesignError, match="depends on it"):
        drop_states(m, ["psi_rad"])  # random A: everything couples
    A = np.diag([-1.0, -2.0, 0.0])
    A[0, 1] = 1.0
    m3 = LinearModel(A=A, B=np.ones((3, 1)), C=np.array([[1.0, 0, 0]]), D=np.zeros((1, 1)),
                     state_names=("a_rad", "b_rad", "psi_rad"))
    d = drop_states(m3, ["psi_rad"])
    assert d.state_names == ("a_rad", "b_rad") and d.A.shape == (2, 2)


def test_bad_discretization_input() -> None:
    m = to_linear_model(_random_body(np.random.default_rng(8)))
    with pytest.raises(DesignError, match="positive"):
        discretize(m, 0.0)
    with pytest.raises(DesignError, match="unknown discretization"):
        discretize(m, 0.01, method="tustin")
    with pytest.raises(DesignError, match="already discrete"):
        discretize(discretize(m, 0.01), 0.02)


def test_state_as_input_reproduces_the_model_when_fed_the_state() -> None:
    """DHC-6 N1 as a measured input: fed the original model's own N1 trajectory, the reduced model
    gives the same outputs (exact up to the discretization of the input), and the throttle then
    acts only through N1's former row."""
    from fdi_sim.linear.grid import parse_grid_spec
    from fdi_sim.linear.linearize import linearize_grid
    from fdi_sim.linear.transform import state_as_input
    from fdi_sim.operating_point import OperatingPoint

    sched = linearize_grid(parse_grid_spec("h_ft=5000;vc_kts=120", "DHC6"), validate=False)
    cont = sched.continuous_at(OperatingPoint("DHC6", 5000.0, vc_kts=120.0))
    red = state_as_input(cont, "n1_pct")
    assert "n1_pct" not in red.state_names and red.input_names[-1] == "n1_pct"
    assert red.u0[-1] == pytest.approx(cont.x0[cont.state_names.index("n1_pct")])
    dt = 1.0 / 1000.0
    full, part = cont.discretize(dt), red.discretize(dt)
    i = cont.state_names.index("n1_pct")
    t = np.arange(4000) * dt
    u = np.zeros((len(t), cont.n_inputs))
    u[:, cont.input_names.index("throttle_cmd_norm")] = 0.05 * (t > 0.2)
    x = np.zeros(cont.n_states)
    xr = np.zeros(red.n_states)
    err = 0.0
    for k in range(len(t)):
        y = full.C @ x + full.D @ u[k]
        ur = np.concatenate([u[k], [x[i]]])
        yr = part.C @ xr + part.D @ ur
        err = max(err, float(np.max(np.abs(y - yr) / (np.abs(y).max() + 1e-9))))
        x = full.A @ x + full.B @ u[k]
        xr = part.A @ xr + part.B @ ur
    assert err < 0.02, err  # first-order hold error of the state fed as a held input at 1 kHz
