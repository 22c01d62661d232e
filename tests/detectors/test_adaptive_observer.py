"""Sidar's adaptive tracking observer (Sidar 1982, NASA TM-84240, eq. 22-36, sec. VI examples).

Gain reading: Sidar's examples run at 0.05 s per step ("8 sec (160 steps)") with the discrete law eq. 23,
so his per-step gains m = 10, n = 5 are the continuous gains 200, 100 of eq. 22. Both readings are run.
What reproduces and what does not is asserted either way (strict xfail = a documented non-reproduction
that fails the suite if it starts to pass).
"""
from __future__ import annotations

import numpy as np
import pytest

from fdi_sim.detectors.adaptive_observer import (
    AdaptiveObserver,
    check_sidar_conditions,
    choose_sidar_gains,
    run_sidar_example,
    sidar_W,
)
from fdi_sim.detectors.base import Detector
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel

PER_STEP_S = 0.05  # Sidar's step


def _rel(run) -> np.ndarray:
    return np.max(np.abs(run.params_hat - run.params_true) / np.abs(run.params_true), axis=1)


def test_matched_observer_does_not_drift() -> None:
    A = np.array([[0.9, 0.1], [-0.2, 0.8]])
    B = np.array([[0.0], [0.1]])
    model = LinearModel(A=A, B=B, C=np.eye(2), D=np.zeros((2, 1)), dt_s=0.05)
    obs = AdaptiveObserver(model, 0.3 * np.eye(2), np.eye(2), np.eye(2))
    assert isinstance(obs, Detector)
    x = np.zeros(2)
    for k in range(200):
        u = np.array([np.sin(0.3 * k)])
        r = obs.step(k * 0.05, u, x)
        x = A @ x + B @ u
        assert np.all(r.r == 0.0)
    est = obs.estimates()
    assert np.array_equal(est.A, A) and np.array_equal(est.B, B) and np.all(est.relative_change == 0)


def test_discrete_law_eq_23_by_hand() -> None:
    A = np.array([[0.5]])
    model = LinearModel(A=A, B=np.array([[1.0]]), C=np.eye(1), D=np.zeros((1, 1)), dt_s=0.1)
    obs = AdaptiveObserver(model, np.array([[0.2]]), np.array([[0.5]]), np.array([[0.25]]), x0_hat=np.array([2.0]))
    r = obs.step(0.0, np.array([3.0]), np.array([1.0]))  # eps = 1 - 2 = -1
    assert r.r[0] == -1.0
    est = obs.estimates()
    assert np.isclose(est.A[0, 0], 0.5 + 0.5 * -1.0 * 2.0)  # A0 += M eps xh'
    assert np.isclose(est.B[0, 0], 1.0 + 0.25 * -1.0 * 3.0)  # B0 += N eps u'
    assert np.isclose(obs.x_hat[0], 0.5 * 2.0 + 1.0 * 3.0 + 0.2 * -1.0)
    # masked: only the adapted entries move, each by eq. 23 (full matrices M eps xh', N eps u', masked by hand)
    A2, B2, M, N = np.array([[0.9, 0.1], [0.0, 0.8]]), np.array([[0.0], [0.5]]), np.array([[0.3, 0.0], [0.1, 0.2]]), np.eye(2)
    mask_A, mask_B = np.array([[True, False], [True, True]]), np.array([[False], [True]])
    model2 = LinearModel(A=A2, B=B2, C=np.eye(2), D=np.zeros((2, 1)), dt_s=0.1)
    obs2 = AdaptiveObserver(model2, np.zeros((2, 2)), M, N, mask_A, mask_B, x0_hat=np.array([1.0, -2.0]))
    eps, xh, u = np.array([0.5, 1.5]) - np.array([1.0, -2.0]), np.array([1.0, -2.0]), np.array([4.0])
    obs2.step(0.0, u, np.array([0.5, 1.5]))
    est = obs2.estimates()
    assert np.allclose(est.A, A2 + np.outer(M @ eps, xh) * mask_A) and np.allclose(est.B, B2 + np.outer(N @ eps, u) * mask_B)
    assert est.names == ("A[x0,x0]", "A[x1,x0]", "A[x1,x1]", "B[x1,u0]")


def test_conditions_eq_34_against_a_hand_computation() -> None:
    A = np.array([[-3.0, 1.0], [0.5, -2.0]])
    K, C = np.zeros((2, 2)), np.eye(2)
    g = choose_sidar_gains(A, K, C, 2.0, 1.0, xhat_norm2_max=1.0, u_norm2_max=1.0, n_inputs=1)
    assert np.allclose(g.M, 2 * np.eye(2)) and g.conditions.satisfied and g.conditions.negative_definite
    W = sidar_W(A, K, C, g.M, g.N, 1.0, 1.0)
    assert np.allclose(W, A - 3.0 * np.eye(2))  # eq. 27 with M C = 2 I, N C = I
    # w_12 + w_21 = 1.5 > 2 sqrt(w_11 w_22) = 2 sqrt(6) is false: eq. 34d holds; make it fail
    bad = np.array([[-0.1, 5.0], [5.0, -0.1]])
    rep = check_sidar_conditions(bad, K, C, np.zeros((2, 2)), np.zeros((2, 2)), 0.0, 0.0, find_lyapunov=False)
    assert rep.diag_ok.all() and not rep.cross_ok[0, 1] and not rep.satisfied
    assert not rep.negative_definite  # independent: eig(bad + bad') > 0
    assert np.max(np.linalg.eigvalsh(bad + bad.T)) > 0


def test_example_1_structure_cannot_meet_eq_34_but_has_a_lyapunov_certificate() -> None:
    run = run_sidar_example(1, t_end_s=0.05)
    c = run.conditions
    assert not c.satisfied and not c.diag_ok[1]  # w_22 = 0: x2 is not measured, eq. 34c is impossible
    Q = c.lyapunov_Q
    assert Q is not None  # but a common quadratic Lyapunov function exists on the box (eq. 31)
    assert np.min(np.linalg.eigvalsh(Q)) > 0


def test_bad_input() -> None:
    model = LinearModel(A=-np.eye(2), B=np.ones((2, 1)), C=np.eye(2), D=np.zeros((2, 1)))
    with pytest.raises(DesignError, match="input_hold"):
        AdaptiveObserver(model, np.eye(2), np.eye(2), np.eye(2), input_hold="cubic")
    with pytest.raises(DesignError, match=">= 0"):
        choose_sidar_gains(-np.eye(2), np.zeros((2, 2)), np.eye(2), -1.0, 1.0, 1.0, 1.0, n_inputs=1)
    with pytest.raises(DesignError, match="examples 1 and 2"):
        run_sidar_example(3)


def test_fig_7_tracking_example_1_per_step_gains() -> None:
    """Fig. 7 / sec. VI(a): |eps| < 2.5e-2 while tracking, < 4e-3 one second after, accuracy > 90 % then, 98-99 % later."""
    run = run_sidar_example(1, tracking=True, m_gain=10 / PER_STEP_S, n_gain=5 / PER_STEP_S, t_end_s=20.0, substeps=4)
    t, e = run.t_s, run.output_error_norm
    assert e[(t >= 1.0) & (t <= 12.0)].max() < 2.5e-2
    assert e[t >= 13.0].max() < 4e-3
    assert _rel(run)[np.searchsorted(t, 13.0)] < 0.10
    assert _rel(run)[-1] < 0.02


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="not reproduced: with m=10, n=5 (continuous) |eps| after 3.5 s is 2.1e-2 and the "
                   "parameters are 65 % off after 8 s; per-step reading (200, 100): 2.0e-2 and 70 %")
@pytest.mark.parametrize("gains", [(10.0, 5.0), (10 / PER_STEP_S, 5 / PER_STEP_S)])
def test_fig_6_example_1(gains) -> None:
    run = run_sidar_example(1, m_gain=gains[0], n_gain=gains[1], t_end_s=12.0)
    t = run.t_s
    assert run.output_error_norm[t >= 3.5].max() < 4e-3 and _rel(run)[t >= 8.0].max() < 0.05


@pytest.mark.slow
def test_example_1_converges_slowly_with_per_step_gains() -> None:
    run = run_sidar_example(1, m_gain=10 / PER_STEP_S, n_gain=5 / PER_STEP_S, t_end_s=60.0)
    assert _rel(run)[run.t_s >= 50.0].max() < 0.02


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="not reproduced: |eps| after 2.75 s 1.7e-2 (paper 5e-2: met) but the parameter "
                   "error norm stays 36 % (unity gains) or 31 % (per-step 20) after 10 s, paper < 10 %")
@pytest.mark.parametrize("gain", [1.0, 1 / PER_STEP_S])
def test_fig_8_example_2(gain) -> None:
    run = run_sidar_example(2, m_gain=gain, n_gain=gain, t_end_s=12.0)
    t = run.t_s
    err = np.linalg.norm(run.params_hat - run.params_true, axis=1) / np.linalg.norm(run.params_true, axis=1)
    assert run.output_error_norm[t >= 2.75].max() < 5e-2 and err[t >= 10.0].max() < 0.10


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="not reproduced: tracking output error reaches 6e-2 (paper < 2e-2), parameter error "
                   "stays above 40 % after 14.5 s (paper < 10 %)")
def test_fig_9_example_2_tracking() -> None:
    run = run_sidar_example(2, tracking=True, t_end_s=16.0)
    t = run.t_s
    err = np.linalg.norm(run.params_hat - run.params_true, axis=1) / np.linalg.norm(run.params_true, axis=1)
    assert run.output_error_norm[(t >= 1.4) & (t <= 12)].max() < 2e-2 and err[t >= 14.5].max() < 0.10


def test_registered_observer_detectors_follow_the_contract() -> None:
    from fdi_sim import registry
    from fdi_sim.detectors.twin_otter_interim import twin_otter_longitudinal_interim

    m = twin_otter_longitudinal_interim()
    noise = {"process_std": [0.02, 2e-4, 1e-3, 1e-5], "sensor_std": [0.1, 0.002, 0.002, 0.002]}
    params = {
        "beard-jones-v1": {"sensor_std": noise["sensor_std"]},
        "lmi-detection-v1": {"sensor_std": [1.0, 0.002, 0.002, 0.002], "method": "direct"},
        "kalman-nis-v1": noise, "kalman-tv-nis-v1": noise,
        "kalman-mmae-v1": {**noise, "alternatives": {"iced": twin_otter_longitudinal_interim(0.2)}},
        "adaptive-observer-v1": {**noise, "m_gain": [3e-4, 0.3, 0.3, 0.3], "n_gain": [3e-4, 0.3, 0.3, 0.3]},
    }
    ids = set(registry.ids("detector"))
    assert set(params) <= ids
    for pid, kw in params.items():
        det = registry.get("detector", pid).factory(m, **kw)
        assert isinstance(det, Detector) and det.id == pid
        det.reset(np.random.default_rng(0))
        outs = [det.step(k / 120, m.u0, m.y0) for k in range(3)]  # trim in, trim out: no alarm
        assert all(not r.alarm and np.all(np.isfinite(r.r)) for r in outs)
        assert outs[0].scores is None or len(outs[0].scores) == len(det.hypotheses)
    with pytest.raises(DesignError, match="alternatives"):
        registry.get("detector", "kalman-mmae-v1").factory(m)
