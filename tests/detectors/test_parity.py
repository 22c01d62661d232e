"""Parity space with known inputs (Lou, Willsky & Verghese 1986, eq. 3-8; Chow et al. 1984, eq. 2.3-2.6)."""
from __future__ import annotations

import control
import numpy as np
import pytest
from scipy.stats import chi2

from fdi_sim.detectors.base import Detector
from fdi_sim.detectors.parity import (
    AdditiveFaults,
    fault_signatures,
    input_toeplitz,
    minimum_order,
    observability_matrix,
    parity_space,
)
from fdi_sim.errors import DesignError, SimulationDiverged
from fdi_sim.linear.model import LinearModel
from fdi_sim.registry import get, ids


def random_model(rng: np.random.Generator, n: int = 4, m: int = 2, r: int = 3, trims: bool = False) -> LinearModel:
    A = rng.standard_normal((n, n))
    A *= 0.9 / max(abs(np.linalg.eigvals(A)))
    kw = {}
    if trims:
        kw = dict(u0=rng.standard_normal(m), y0=rng.standard_normal(r), x0=rng.standard_normal(n))
    return LinearModel(A=A, B=rng.standard_normal((n, m)), C=rng.standard_normal((r, n)),
                       D=rng.standard_normal((r, m)), dt_s=0.1, **kw)


def simulate(model: LinearModel, u: np.ndarray, x0: np.ndarray, fault_b=None, fault_d=None) -> np.ndarray:
    """Plain loop of x+ = A x + B u (+ b), y = C x + D u (+ d); deviations."""
    x, ys = x0.copy(), []
    for uk in u:
        y = model.C @ x + model.D @ uk + (0 if fault_d is None else fault_d)
        ys.append(y)
        x = model.A @ x + model.B @ uk + (0 if fault_b is None else fault_b)
    return np.array(ys)


def test_observability_matrix_matches_python_control():
    rng = np.random.default_rng(1)
    m = random_model(rng, n=4)
    O = observability_matrix(m.A, m.C, order_s=3)  # s = n - 1 -> control.obsv
    np.testing.assert_allclose(O, control.obsv(m.A, m.C), rtol=1e-12, atol=1e-12)


def test_input_toeplitz_columns_are_impulse_responses():
    """Column block j of H (eq. 5) is the response to a unit impulse at step j, from x = 0."""
    rng = np.random.default_rng(2)
    m = random_model(rng)
    s = 3
    H = input_toeplitz(m.A, m.B, m.C, m.D, s)
    for j in range(s + 1):
        for i in range(m.n_inputs):
            u = np.zeros((s + 1, m.n_inputs))
            u[j, i] = 1.0
            Y = simulate(m, u, np.zeros(m.n_states)).ravel()
            np.testing.assert_allclose(H[:, j * m.n_inputs + i], Y, atol=1e-12)


def test_parity_space_is_the_left_null_space_of_O():
    """p orthonormal columns with W'O = 0 and p = (s+1) r - rank O: W spans the whole left null space."""
    rng = np.random.default_rng(3)
    m = random_model(rng, n=4, r=3)
    for s in (1, 2, 3):
        sp = parity_space(m, s)
        O = observability_matrix(m.A, m.C, s)
        assert sp.n_relations == (s + 1) * 3 - np.linalg.matrix_rank(O)
        np.testing.assert_allclose(sp.W.T @ sp.W, np.eye(sp.n_relations), atol=1e-12)
        assert np.abs(sp.W.T @ O).max() < 1e-12 * np.abs(O).max()


def test_residual_vanishes_for_any_state_and_input():
    """Eq. 4-7: r(k) = W'(Y - H U) = W' O x(k-s) = 0 on noise-free data, from any x0, any u."""
    rng = np.random.default_rng(4)
    m = random_model(rng, trims=True)
    s = 2
    u_dev = rng.standard_normal((60, m.n_inputs))
    y_dev = simulate(m, u_dev, 10 * rng.standard_normal(m.n_states))
    det = get("detector", "parity-v1").factory(m, order_s=s, threshold=1.0)
    rs = [det.step(0.1 * k, u_dev[k] + m.u0, y_dev[k] + m.y0) for k in range(60)]
    assert [r.valid for r in rs[:3]] == [False, False, True]
    scale = np.abs(y_dev).max()
    assert max(np.abs(r.r).max() for r in rs[s:]) < 1e-10 * scale
    assert not any(r.alarm for r in rs)


def test_step_equals_the_stacked_window_formula_at_every_buffer_position():
    """Eq. 4 on windows [y(k-s); ...; y(k)] for every k (the ring buffer wraps every s + 1 steps);
    the relations form [W; -H'W] gives the same checks on [Y; U]."""
    rng = np.random.default_rng(11)
    m = random_model(rng, trims=True)
    s = 3
    sp = parity_space(m, s)
    u, y = rng.standard_normal((20, m.n_inputs)), rng.standard_normal((20, m.n_outputs))
    det = get("detector", "parity-v1").factory(m, order_s=s, threshold=1.0)
    rs = [det.step(0.1 * k, u[k] + m.u0, y[k] + m.y0) for k in range(20)]
    Y = np.array([y[k - s:k + 1].ravel() for k in range(s, 20)])
    U = np.array([u[k - s:k + 1].ravel() for k in range(s, 20)])
    np.testing.assert_allclose(np.array([r.r for r in rs[s:]]), sp.residual(Y, U), atol=1e-12)
    np.testing.assert_allclose(np.hstack([Y, U]) @ sp.relations(), sp.residual(Y, U), atol=1e-12)



def test_input_vector_of_the_model_width_or_of_the_known_inputs():
    """With a disturbance column, u may be the full input vector or only the known (control) inputs."""
    rng = np.random.default_rng(13)
    m0 = random_model(rng, trims=True)
    m = LinearModel(A=m0.A, B=m0.B, C=m0.C, D=m0.D, dt_s=0.1, input_kinds=("control", "disturbance"),
                    u0=m0.u0, y0=m0.y0)
    u, y = rng.standard_normal((6, 2)) + m.u0, rng.standard_normal((6, 3)) + m.y0
    full = get("detector", "parity-v1").factory(m, order_s=2, threshold=1.0)
    known = get("detector", "parity-v1").factory(m, order_s=2, threshold=1.0)
    for k in range(6):
        np.testing.assert_array_equal(full.step(0.1 * k, u[k], y[k]).r, known.step(0.1 * k, u[k, :1], y[k]).r)


def test_chow_willsky_double_sum_form():
    """Chow et al. eq. 2.5: r = sum_i w_i'[y(k-p+i) - sum_{j<i} C A^(i-j-1) B u(k-p+j)] (D = 0)."""
    rng = np.random.default_rng(5)
    m0 = random_model(rng)
    m = LinearModel(A=m0.A, B=m0.B, C=m0.C, D=np.zeros_like(m0.D), dt_s=0.1)
    p = 2
    sp = parity_space(m, p)
    y = rng.standard_normal((p + 1, 3))
    u = rng.standard_normal((p + 1, 2))
    for w in sp.W.T:
        wi = w.reshape(p + 1, 3)
        r = sum(wi[i] @ (y[i] - sum(m.C @ np.linalg.matrix_power(m.A, i - j - 1) @ m.B @ u[j] for j in range(i)))
                for i in range(p + 1))
        assert r == pytest.approx(float(w @ (y.ravel() - sp.H @ u.ravel())), abs=1e-12)


def test_two_sensors_of_one_variable_lou_eq_9_10():
    """y2 = a y1 (Lou et al. eq. 9) has the order-0 relation r = y2 - a y1 (eq. 10), up to scale."""
    a = 2.5
    m = LinearModel(A=[[0.9]], B=[[1.0]], C=[[1.0], [a]], D=[[0.0], [0.0]], dt_s=0.1)
    assert minimum_order(m.A, m.C) == 0
    sp = parity_space(m, 0)
    w = sp.W[:, 0] / sp.W[1, 0]
    np.testing.assert_allclose(w, [-a, 1.0], atol=1e-12)


def test_fault_signature_is_the_residual_of_a_constant_fault():
    """mu_i = W' H_f (1 ⊗ e_i): the residual of noise-free data with a constant unit fault."""
    rng = np.random.default_rng(6)
    m = random_model(rng)
    faults = AdditiveFaults.from_model(m, actuators=["u1"], sensors=["y0", "y2"])
    assert faults.names == ("u1_actuator", "y0_sensor", "y2_sensor")
    s = 2
    sp = parity_space(m, s)
    mu = fault_signatures(m, faults, s, sp.W)
    u = rng.standard_normal((20, 2))
    for i in range(3):
        y = simulate(m, u, rng.standard_normal(4), faults.Bf[:, i], faults.Df[:, i])
        r = sp.residual(y[-3:].ravel(), u[-3:].ravel())
        np.testing.assert_allclose(r, mu[i], atol=1e-10)


def test_minimum_order_and_too_short_window():
    rng = np.random.default_rng(7)
    m = random_model(rng, n=5, r=2)  # generic: rank O_s = min((s+1) r, n) -> s_min = 2
    assert minimum_order(m.A, m.C) == 2
    with pytest.raises(DesignError, match=r"order_s >= 2"):
        parity_space(m, 1)
    with pytest.raises(DesignError, match="non-negative integer"):
        parity_space(m, -1)
    cont = LinearModel(A=np.eye(2), B=np.ones((2, 1)), C=np.eye(2), D=np.zeros((2, 1)))
    with pytest.raises(DesignError, match="discrete"):
        parity_space(cont, 1)


def test_unknown_signal_names_say_what_exists():
    m = random_model(np.random.default_rng(8))
    with pytest.raises(DesignError, match="Did you mean 'y1'"):
        AdditiveFaults.from_model(m, sensors=["y_1"])
    with pytest.raises(DesignError, match="at least one"):
        AdditiveFaults.from_model(m)


def test_noise_normalized_parity_detector_and_isolation():
    """With R given, the statistic is r'(W'SW)^-1 r (chi-square); a large sensor bias isolates."""
    rng = np.random.default_rng(9)
    m = random_model(rng)
    R = np.diag([1e-4, 2e-4, 1e-4])
    det = get("detector", "parity-v1").factory(m, order_s=2, R=R, sensors=["y0", "y1", "y2"])
    assert isinstance(det, Detector) and det.dof == det.proj_y.shape[0]
    u = rng.standard_normal((400, 2))
    y = simulate(m, u, np.zeros(4), fault_d=np.array([0.0, 0.5, 0.0]))
    y += rng.standard_normal(y.shape) @ np.sqrt(R)
    out = [det.step(0.1 * k, u[k], y[k]) for k in range(400)]
    assert np.mean([o.isolation == "y1_sensor" for o in out[2:]]) > 0.99
    det.reset(np.random.default_rng(0))
    assert det.step(0.0, u[0], y[0]).valid is False


def test_registry_lists_the_parity_family():
    for id_ in ("parity-v1", "parity-robust-v1", "parity-stochastic-v1", "pca-v1"):
        assert id_ in ids("detector")


def test_non_finite_signals_raise_with_time_and_signal():
    m = random_model(np.random.default_rng(10))
    det = get("detector", "parity-v1").factory(m, order_s=2, threshold=1.0)
    det.step(0.0, np.zeros(2), np.zeros(3))
    with pytest.raises(SimulationDiverged, match=r"0\.100 s: detector parity-v1 received non-finite y\[1\]"):
        det.step(0.1, np.zeros(2), np.array([0.0, np.nan, 0.0]))
    with pytest.raises(DesignError, match="expected the model's 2 inputs"):
        det.step(0.2, np.zeros(5), np.zeros(3))


def test_default_threshold_is_the_shared_chi2_quantile_and_checks_its_probability():
    m = random_model(np.random.default_rng(12))
    R = np.diag([1e-4, 2e-4, 1e-4])
    det = get("detector", "parity-v1").factory(m, order_s=2, R=R, p_false_alarm=0.01)
    assert det.threshold == pytest.approx(chi2.ppf(0.99, det.dof))
    with pytest.raises(DesignError, match=r"\(0, 1\)"):
        get("detector", "parity-v1").factory(m, order_s=2, R=R, p_false_alarm=1.5)
