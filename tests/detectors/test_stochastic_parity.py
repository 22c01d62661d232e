"""Stochastic parity space (Hagenblad, Gustafsson & Klein, eq. 1-14, Algorithms 1-2)."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.special import erfc
from scipy.stats import binom, chi2

from fdi_sim.decision.chi2 import chi2_threshold
from fdi_sim.detectors.parity import AdditiveFaults, ParitySpace, observability_matrix
from fdi_sim.detectors.stochastic_parity import (
    StochasticParity,
    incorrect_diagnosis_matrix,
    isolate_by_angle,
    isolation_rates,
    make_stochastic_parity_detector,
    noise_window_covariance,
    stochastic_parity,
    threshold_by_simulation,
)
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel


def model_with_disturbance(rng: np.random.Generator) -> LinearModel:
    n = 4
    A = rng.standard_normal((n, n))
    A *= 0.9 / max(abs(np.linalg.eigvals(A)))
    B = rng.standard_normal((n, 3))
    return LinearModel(A=A, B=B, C=rng.standard_normal((3, n)), D=np.zeros((3, 3)), dt_s=0.1,
                       input_kinds=("control", "control", "disturbance"))


def simulate_windows(model, s, R, Qv, n_win, rng, fault_b=None, fault_d=None):
    """Independent windows (x at window start random), control u random, disturbance v ~ N(0, Qv)."""
    L = s + 1
    x = 3 * rng.standard_normal((n_win, model.n_states))
    Rs, Qs = np.linalg.cholesky(R), np.sqrt(Qv)
    Ys, Us = [], []
    for _ in range(L):
        u = rng.standard_normal((n_win, 2))
        v = Qs * rng.standard_normal((n_win, 1))
        y = x @ model.C.T + u @ model.D[:, :2].T + rng.standard_normal((n_win, 3)) @ Rs.T
        if fault_d is not None:
            y += fault_d
        Ys.append(y)
        Us.append(u)
        x = x @ model.A.T + u @ model.B[:, :2].T + v @ model.B[:, 2:].T + (0 if fault_b is None else fault_b)
    return np.stack(Ys, 1).reshape(n_win, -1), np.stack(Us, 1).reshape(n_win, -1)


def test_window_noise_covariance_against_markov_sum():
    """S = H_v (I ⊗ Q) H_v' + I ⊗ R (eq. 9); block (i, j) = sum_k C A^(i-k-1) Bv Q Bv' A'^(j-k-1) C' + d_ij R."""
    rng = np.random.default_rng(10)
    m = model_with_disturbance(rng)
    R, Q, s = np.diag([0.1, 0.2, 0.3]), np.array([[0.7]]), 3
    S = noise_window_covariance(m, s, R, Q=Q)
    Bv, C, A = m.B[:, 2:], m.C, m.A
    for i in range(s + 1):
        for j in range(s + 1):
            blk = R.copy() if i == j else np.zeros((3, 3))
            for k in range(min(i, j)):
                blk = blk + C @ np.linalg.matrix_power(A, i - k - 1) @ Bv @ Q @ Bv.T @ np.linalg.matrix_power(A, j - k - 1).T @ C.T
            np.testing.assert_allclose(S[3 * i:3 * i + 3, 3 * j:3 * j + 3], blk, atol=1e-12)


def test_normalized_residual_is_white_and_chi_square():
    """Eq. 10-13: W_bar'SW_bar = I, W_bar'O = 0, and r_bar'r_bar ~ chi2(n_r) on simulated data."""
    rng = np.random.default_rng(11)
    m = model_with_disturbance(rng)
    R, Qv, s = np.diag([0.01, 0.02, 0.01]), 0.5, 2
    faults = AdditiveFaults.from_model(m, actuators=["u0"], sensors=["y1"])
    d = stochastic_parity(m, s, faults, R, Q=np.array([[Qv]]))
    assert d.n_residuals == 3 * 3 - 4  # eq. 7
    np.testing.assert_allclose(d.W_bar.T @ d.S @ d.W_bar, np.eye(d.n_residuals), atol=1e-10)
    assert np.abs(d.W_bar.T @ observability_matrix(m.A, m.C, s)).max() < 1e-9
    Y, U = simulate_windows(m, s, R, Qv, 20000, rng)
    rb = d.residual(Y, U)
    np.testing.assert_allclose(np.cov(rb.T), np.eye(d.n_residuals), atol=0.05)  # se ~ 0.01
    h = chi2_threshold(d.n_residuals, 0.05)
    k = int(np.sum(np.einsum("ij,ij->i", rb, rb) > h))
    lo, hi = binom.ppf([0.0005, 0.9995], 20000, 0.05)  # 99.9 % binomial band
    assert lo <= k <= hi


def test_fault_vector_is_the_mean_shift_of_a_constant_fault():
    """mu_bar_i = W_bar' H_f F^i (eq. 11): noise-free simulation with a unit fault gives exactly it."""
    rng = np.random.default_rng(12)
    m = model_with_disturbance(rng)
    faults = AdditiveFaults.from_model(m, actuators=["u1"], sensors=["y0"])
    d = stochastic_parity(m, 2, faults, np.eye(3) * 1e-2)
    tiny = np.eye(3) * 1e-30
    for i in range(2):
        Y, U = simulate_windows(m, 2, tiny, 0.0, 5, rng, faults.Bf[:, i], faults.Df[:, i])
        np.testing.assert_allclose(d.residual(Y, U), np.tile(d.mu_bar[i], (5, 1)), atol=1e-8)


def test_algorithm2_paper_erfc_and_two_fault_monte_carlo():
    """Eq. 14 with the paper's erfc(x) = 2 int_x^inf N(0,1) pdf = erfc_std(x / sqrt 2); for two equal-norm
    faults it is the exact probability that angle isolation picks the wrong one."""
    th = 0.5
    mu = np.array([[2.0, 0.0], [2 * np.cos(th), 2 * np.sin(th)]])
    space = ParitySpace(order_s=0, W=np.eye(2), O=np.zeros((2, 1)), H=np.zeros((2, 0)), known_inputs=())
    d = StochasticParity(space=space, S=np.eye(2), W_bar=np.eye(2), mu_bar=mu, fault_names=("a", "b"),
                         detectable=np.array([True, True]))
    P = incorrect_diagnosis_matrix(d, 1.5).P
    # distance of m mu_j to the bisector through the origin is m |mu| sin(th/2); 1/2 erfc_paper(x) of eq. 14
    x = 1.5 * 2 * np.sin(th / 2)
    assert P[1, 0] == pytest.approx(0.5 * erfc(x / np.sqrt(2)), rel=1e-12)
    assert P[0, 1] == pytest.approx(P[1, 0]) and P[0, 0] == pytest.approx(1 - P[1, 0])
    rng = np.random.default_rng(13)
    r = 1.5 * mu[0] + rng.standard_normal((40000, 2))
    rates = isolation_rates(r, mu, np.array([True, True]), threshold=-1.0)
    n = 40000
    assert abs(rates[1] - P[1, 0]) < 4 * np.sqrt(P[1, 0] * (1 - P[1, 0]) / n)


def test_isolation_reject_option_and_undetectable():
    mu = np.array([[1.0, 0.0], [0.0, 1.0], [0.0, 0.0]])
    det = np.array([True, True, False])
    iso = isolate_by_angle(np.array([1.0, 0.1]), mu, det)
    assert iso.index == 0 and np.isnan(iso.angles_rad[2])
    assert isolate_by_angle(np.array([1.0, 1.0]), mu, det, reject_angle_rad=0.5).index is None  # 45 deg > 0.5 rad
    assert isolate_by_angle(np.array([1.0, 1.0]), mu, det, reject_angle_rad=0.8).index in (0, 1)
    zero = isolate_by_angle(np.zeros(2), mu, det)  # a zero residual has no direction
    assert zero.index is None and np.all(np.isnan(zero.angles_rad))
    assert isolate_by_angle(np.array([1.0, 0.1]), mu, [False, False, False]).index is None
    rates = isolation_rates(np.array([[3.0, 3.1], [0.1, 0.0]]), mu, det, threshold=1.0, reject_angle_rad=0.5)
    np.testing.assert_allclose(rates, [0, 0, 0, 0.5])  # one alarm, rejected; one below threshold


def test_threshold_by_simulation_covers_the_true_quantile():
    rng = np.random.default_rng(14)
    hits = 0
    for _ in range(40):
        est = threshold_by_simulation(rng.chisquare(4, 4000), 0.05)
        hits += est.h_low <= chi2.ppf(0.95, 4) <= est.h_high
    assert hits >= 33  # 95 % intervals: P(hits < 34 of 40) ~ 0.02; observed band is honest
    with pytest.raises(DesignError, match="too few"):
        threshold_by_simulation(np.ones(50), 0.05)


def test_detector_runs_algorithm1_on_a_log():
    rng = np.random.default_rng(15)
    m = model_with_disturbance(rng)
    R = np.diag([0.01, 0.02, 0.01])
    faults = AdditiveFaults.from_model(m, sensors=["y0", "y1", "y2"])
    d = stochastic_parity(m, 2, faults, R, Q=np.array([[0.2]]))
    det = make_stochastic_parity_detector(m, d, p_false_alarm=0.01)
    x = np.zeros(4)
    hits = []
    for k in range(300):
        u = rng.standard_normal(3)
        u[2] = np.sqrt(0.2) * u[2]  # the disturbance column is not measured
        y = m.C @ x + rng.standard_normal(3) @ np.sqrt(R) + (np.array([0, 0, 2.0]) if k >= 100 else 0)
        res = det.step(0.1 * k, u[:2], y)
        hits.append(res.isolation)
        x = m.A @ x + m.B @ u
    assert np.mean([h is not None for h in hits[2:100]]) < 0.05
    assert np.mean([h == "y2_sensor" for h in hits[102:]]) > 0.95
    assert res.dof == 5 and res.threshold == pytest.approx(chi2.ppf(0.99, 5))  # n_r = 3*3 - 4


def test_bad_noise_models_are_refused():
    rng = np.random.default_rng(16)
    m = model_with_disturbance(rng)
    f = AdditiveFaults.from_model(m, sensors=["y0"])
    with pytest.raises(DesignError, match="rank-deficient"):
        # two noise-free sensors: their 6-dim noise-free window subspace meets the 5-dim parity space
        stochastic_parity(m, 2, f, np.diag([1.0, 0.0, 0.0]), Q=np.zeros((1, 1)))
    with pytest.raises(DesignError, match="symmetric"):
        stochastic_parity(m, 2, f, np.array([[1.0, 0.5, 0], [0, 1, 0], [0, 0, 1]]))
    with pytest.raises(DesignError, match="semidefinite"):
        stochastic_parity(m, 2, f, -np.eye(3))
    with pytest.raises(DesignError, match="order_s >= 1"):
        stochastic_parity(m, 0, f, np.eye(3))
    d = stochastic_parity(m, 2, f, np.eye(3))
    with pytest.raises(DesignError, match=r"\(0, 1\)"):
        make_stochastic_parity_detector(m, d, p_false_alarm=1.5)
