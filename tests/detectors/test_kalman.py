"""Kalman innovation tests (Sidar 1982 sec. II-III, eq. 10) and the multiple-model bank.

Twin Otter: ``twin_otter_longitudinal_interim()`` (INTERIM model, see fdi_sim/papers/twin_otter_interim.py),
discretized at 1/120 s.
"""
from __future__ import annotations

import control
import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from scipy.stats import binomtest

from fdi_sim.detectors.adaptive_observer import AdaptiveObserver, choose_sidar_gains
from fdi_sim.detectors.base import Detector
from fdi_sim.detectors.kalman import (
    KalmanInnovationDetector,
    MultipleModelBank,
    TimeVaryingKalmanDetector,
    bias_test,
    nis,
    simulate_discrete,
    steady_state_kalman,
    whiteness_test,
)
from fdi_sim.papers.twin_otter_interim import twin_otter_longitudinal_interim
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel

DT = 1 / 120
QD = np.diag([0.02, 2e-4, 1e-3, 1e-5]) ** 2  # process noise per step: vt, alpha, q, theta
RD = np.diag([0.1, 0.002, 0.002, 0.002]) ** 2  # sensors: 0.1 ft/s, 2 mrad, 2 mrad/s, 2 mrad
ALPHA = 0.01


def _excitation(n: int, amp: float = 0.2) -> np.ndarray:
    t = np.arange(n) * DT
    de = amp * (np.sin(2 * np.pi * 0.3 * t) + np.sin(2 * np.pi * 0.8 * t) + np.sin(2 * np.pi * 1.7 * t))
    return np.column_stack([de, 0.1 * np.sin(2 * np.pi * 0.05 * t)])


@pytest.fixture(scope="module")
def clean():
    return twin_otter_longitudinal_interim().discretize(DT)


@pytest.fixture(scope="module")
def design(clean):
    return steady_state_kalman(clean, QD, RD)


def test_steady_state_filter_against_python_control_and_filterpy(clean, design) -> None:
    L, P, _ = control.dlqe(clean.A, np.eye(4), clean.C, QD, RD)
    assert np.allclose(L, design.predictor_gain, rtol=1e-8, atol=1e-12)  # dlqe returns the predictor gain A K
    kf = KalmanFilter(dim_x=4, dim_z=4)
    kf.F, kf.H, kf.Q, kf.R, kf.P = np.array(clean.A), np.array(clean.C), QD, RD, np.eye(4)
    for _ in range(4000):  # iterate the covariance recursion to convergence
        kf.predict()
        kf.update(np.zeros(4))
    assert np.allclose(kf.K, design.K, rtol=1e-6, atol=1e-10)
    assert np.allclose(kf.S, design.S, rtol=1e-8)


def test_time_varying_filter_matches_filterpy_step_by_step(clean) -> None:
    rng = np.random.default_rng(3)
    run = simulate_discrete(clean, _excitation(300), QD, RD, rng)
    P0 = np.diag([1.0, 1e-4, 1e-4, 1e-4])
    det = TimeVaryingKalmanDetector(clean, QD, RD, P0=P0, alpha=ALPHA)
    kf = KalmanFilter(dim_x=4, dim_z=4, dim_u=2)
    kf.F, kf.H, kf.B, kf.Q, kf.R, kf.P = np.array(clean.A), np.array(clean.C), np.array(clean.B), QD, RD, P0.copy()
    for k in range(300):
        r = det.step(run.t_s[k], run.u[k], run.y[k])
        kf.update((run.y[k] - clean.y0)[:, None])
        y = np.ravel(kf.y)
        assert np.allclose(r.r, y, atol=1e-12) and np.allclose(det.S, kf.S, rtol=1e-10)
        assert np.isclose(r.statistic, float(y @ np.linalg.solve(kf.S, y)))
        kf.predict(u=(run.u[k] - clean.u0)[:, None])


def test_windowed_tests_false_alarm_and_power() -> None:
    rng = np.random.default_rng(11)
    S = np.array([[2.0, 0.3], [0.3, 0.5]])
    Lc = np.linalg.cholesky(S)
    n_win, N, a = 600, 100, 0.05
    bias_rej = white_rej = 0
    for _ in range(n_win):
        nu = rng.normal(size=(N, 2)) @ Lc.T
        bias_rej += bias_test(nu, S, a).reject
        white_rej += whiteness_test(nu, S, 3, a).reject
    for rej in (bias_rej, white_rej):  # under H0 the rejection rate is alpha (binomial interval)
        ci = binomtest(rej, n_win, a).proportion_ci(0.99)
        assert ci.low <= a <= ci.high
    nu = rng.normal(size=(N, 2)) @ Lc.T + np.array([0.5, 0.0])
    assert bias_test(nu, S, a).reject  # eq. 10a violated
    e = rng.normal(size=(N, 2))
    col = np.zeros_like(e)
    for k in range(1, N):
        col[k] = 0.7 * col[k - 1] + e[k]
    col = col * np.sqrt(1 - 0.49)
    assert whiteness_test(col @ Lc.T, S, 3, a).reject  # eq. 10b violated
    # independent statistic: direct double loop
    Z = np.linalg.solve(Lc, nu.T).T
    direct = sum(N * (sum(Z[k, i] * Z[k - j, l] for k in range(j, N)) / N) ** 2 for j in (1, 2) for i in range(2) for l in range(2))
    assert np.isclose(whiteness_test(nu, S, 2, a).statistic, direct)


def _far(det, run, burn_s: float = 0.0) -> tuple[int, int]:
    alarms = n = 0
    for k in range(len(run.t_s)):
        r = det.step(run.t_s[k], run.u[k], run.y[k])
        if run.t_s[k] >= burn_s:
            n += 1
            alarms += bool(r.alarm)
    return alarms, n


def _three_rates(clean, design, t_end_s: float, seed: int):
    iced = twin_otter_longitudinal_interim(icing_eta=0.2).discretize(DT)
    n = int(t_end_s / DT)
    u = _excitation(n)
    run_c = simulate_discrete(clean, u, QD, RD, np.random.default_rng(seed))
    run_i = simulate_discrete(iced, u, QD, RD, np.random.default_rng(seed + 1))
    matched = _far(KalmanInnovationDetector(design, alpha=ALPHA), run_c)
    mismatched = _far(KalmanInnovationDetector(design, alpha=ALPHA), run_i)
    mask_A = np.zeros((4, 4), bool)
    mask_A[0, 0] = True
    mask_A[1:3, 1:3] = True
    mask_B = np.zeros((4, 2), bool)
    mask_B[2, 0] = True
    g = np.array([3e-4, 0.3, 0.3, 0.3])  # per-row gains (Sidar's m, n), vt row small: its regressor is ~1000x larger
    gains = choose_sidar_gains(clean.A, design.predictor_gain, clean.C, g, g, 0.05, 0.2, mask_A, mask_B, dt_s=DT)
    assert gains.conditions.satisfied  # eq. 34 on the continuous equivalent
    obs = AdaptiveObserver(clean, design.predictor_gain, gains.M, gains.N, mask_A, mask_B, S=design.S, alpha=ALPHA)
    adaptive = _far(obs, run_i, burn_s=t_end_s / 2)
    return matched, mismatched, adaptive, obs


def _rate(an: tuple[int, int]) -> float:
    return an[0] / an[1]


def test_nis_false_alarm_rates_matched_mismatched_adaptive(clean, design) -> None:
    matched, mismatched, adaptive, obs = _three_rates(clean, design, 120.0, seed=3)
    ci = binomtest(*matched, ALPHA).proportion_ci(0.95)  # Clopper-Pearson
    assert ci.low <= ALPHA <= ci.high
    assert _rate(mismatched) > 3 * ALPHA  # Sidar sec. III: a mismatched model raises the FAR
    assert _rate(adaptive) < 1.6 * ALPHA and _rate(adaptive) < 0.4 * _rate(mismatched)
    est = obs.estimates()  # the adapted M_alpha and M_de carry the icing (true +29 %, +30 %)
    rel = dict(zip(est.names, est.relative_change))
    assert abs(rel["A[q_radps,alpha_rad]"] - 0.293) < 0.05 and abs(rel["B[q_radps,elevator_cmd_norm]"] - 0.296) < 0.12


@pytest.mark.slow
def test_nis_false_alarm_rates_long(clean, design) -> None:
    matched, mismatched, adaptive, _ = _three_rates(clean, design, 600.0, seed=5)
    for an in (matched, adaptive):
        ci = binomtest(*an, ALPHA).proportion_ci(0.95)
        assert ci.low <= ALPHA <= ci.high
    assert _rate(mismatched) > 3 * ALPHA


def test_multiple_model_bank_selects_the_iced_model(clean, design) -> None:
    iced = twin_otter_longitudinal_interim(icing_eta=0.2).discretize(DT)
    d_iced = steady_state_kalman(iced, QD, RD)
    n = int(20 / DT)
    for truth, expect in ((iced, "iced"), (clean, None)):
        bank = MultipleModelBank([design, d_iced], ["clean", "iced"], alarm_probability=0.99)
        assert isinstance(bank, Detector)
        bank.reset(np.random.default_rng(0))
        run = simulate_discrete(truth, _excitation(n), QD, RD, np.random.default_rng(9))
        out = [bank.step(run.t_s[k], run.u[k], run.y[k]) for k in range(n)]
        late = out[n // 2:]
        if expect:
            assert np.mean([r.alarm and r.isolation == "iced" for r in late]) > 0.95
            assert min(r.scores[1] for r in late) > 0.5
        else:
            assert not any(r.alarm for r in late) and max(r.scores[1] for r in late) < 0.5


def test_detectors_follow_the_contract(design) -> None:
    for test in ("nis", "bias", "whiteness"):
        det = KalmanInnovationDetector(design, test=test, window_n=50)
        assert isinstance(det, Detector)
        det.reset(np.random.default_rng(0))
        r = det.step(0.0, design.model.u0, design.model.y0)
        assert r.valid == (test == "nis") and r.dof == (4 if test != "whiteness" else 16 * 5)
    assert np.isclose(nis(np.array([1.0, 2.0]), np.diag([1.0, 4.0])), 2.0)


def test_windowed_detector_statistic_is_the_window_test_of_its_last_innovations(clean, design) -> None:
    run = simulate_discrete(clean, _excitation(130), QD, RD, np.random.default_rng(4))
    dets = {t: KalmanInnovationDetector(design, alpha=ALPHA, test=t, window_n=40, n_lags=3) for t in ("bias", "whiteness")}
    nus = []
    for k in range(130):
        out = {t: d.step(run.t_s[k], run.u[k], run.y[k]) for t, d in dets.items()}
        nus.append(out["bias"].r)
        assert out["bias"].valid == (k >= 39)
        if k >= 39:  # the ring buffer wraps three times over the run
            W = np.array(nus[-40:])
            assert np.isclose(out["bias"].statistic, bias_test(W, design.S, ALPHA).statistic, rtol=1e-10)
            assert np.isclose(out["whiteness"].statistic, whiteness_test(W, design.S, 3, ALPHA).statistic, rtol=1e-10)
    bias, white = dets["whiteness"].window_tests()
    assert np.isclose(bias.statistic, out["bias"].statistic) and np.isclose(white.statistic, out["whiteness"].statistic)
    assert white.dof == 16 * 3 and white.threshold == out["whiteness"].threshold


def test_bad_input_raises(clean) -> None:
    with pytest.raises(DesignError, match="positive definite"):
        steady_state_kalman(clean, QD, -RD)
    with pytest.raises(DesignError, match="dt_s"):
        steady_state_kalman(twin_otter_longitudinal_interim(), QD, RD)
    unstable_unobs = LinearModel(A=np.diag([1.5, 0.5]), B=np.zeros((2, 1)), C=np.array([[0.0, 1.0]]), D=np.zeros((1, 1)), dt_s=0.1)
    with pytest.raises(DesignError, match="detectable|Riccati"):
        steady_state_kalman(unstable_unobs, np.eye(2), np.eye(1))
    with pytest.raises(DesignError, match="test must be"):
        KalmanInnovationDetector(steady_state_kalman(clean, QD, RD), test="cusum")
    with pytest.raises(DesignError, match="n_lags"):
        KalmanInnovationDetector(steady_state_kalman(clean, QD, RD), test="whiteness", window_n=5, n_lags=5)
