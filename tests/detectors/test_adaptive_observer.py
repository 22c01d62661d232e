"""Sidar's adaptive tracking observer (Sidar 1982, NASA TM-84240, eq. 22-36) and his sec. VI examples.

Gain reading: Sidar's step is 0.05 s ("8 sec (160 steps)"), so his m = 10, n = 5 read as per-step gains
of eq. 23 are the continuous gains 200, 100 /s of eq. 22; both are run. The bars are the statements of
sec. VI (``sidar_bars``). A strict xfail is a documented non-reproduction that fails the suite if it
starts to pass. The gain grids run vectorised (simulate_sidar), about 10 s each.
"""
from __future__ import annotations

import numpy as np
import pytest

from scipy.signal import place_poles

from fdi_sim.detectors.adaptive_observer import AdaptiveObserver, check_sidar_conditions, choose_sidar_gains, sidar_W
from fdi_sim.papers.sidar_examples import SIDAR_STEP_S, SidarReading, sidar_bars, sidar_gain_matrices, simulate_sidar
from fdi_sim.detectors.base import Detector
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel

H_S = 0.005  # RK4 step of the tests (the docs use 0.0025; the bars agree to 4 digits)
STATED_1 = (10.0, 5.0)  # m, n as printed, read as continuous gains [1/s]
PER_STEP_1 = (10.0 / SIDAR_STEP_S, 5.0 / SIDAR_STEP_S)  # the same per 0.05-s step of eq. 23 [1/s]
UNITY_2, PER_STEP_2 = (1.0, 1.0, 1.0), (1.0 / SIDAR_STEP_S,) * 3


def _run(example: int, gains, tracking: bool = False, reading: SidarReading = SidarReading()):
    return simulate_sidar(example, np.array(gains, float), tracking, reading, 20.0 if tracking else 12.0, h_s=H_S)


def _met(run) -> bool:
    return all(bool(b.met[0]) for b in sidar_bars(run))


def _ex_matrices(example: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Observer A(theta_hat(0)), C and K of sec. VI, written out here independently of sidar_examples."""
    if example == 1:
        A, C, poles = np.array([[-1.5, 1.0], [0.0, 0.0]]), np.array([[1.0, 0.0]]), [-5 + 5j, -5 - 5j]
    else:
        A = np.array([[-0.5, 1.0, 0.0], [-2.0, 0.0, 1.0], [0.0, 0.0, 0.0]])
        C, poles = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), [-10.0, -8 + 8j, -8 - 8j]
    return A, C, place_poles(A.T, C.T, poles).gain_matrix.T


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
    # eq. 23 applied at its own sample: x_hat(1) = A0(0) xh(0) + B0(0) u(0) + K eps(0) with the updated A0, B0
    assert np.isclose(obs.x_hat[0], (0.5 - 1.0) * 2.0 + (1.0 - 0.75) * 3.0 + 0.2 * -1.0)
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


def test_eq_34_cannot_hold_in_either_example_for_any_gains() -> None:
    """w_nn = 0 for the unmeasured last state whatever M, N (C has a zero last column), so eq. 34c fails;
    Sidar's "m and n, according to conditions in equation (34)" cannot be literal."""
    rng = np.random.default_rng(34)
    for ex in (1, 2):
        A, C, K = _ex_matrices(ex)
        for _ in range(5):
            M, N = rng.normal(size=(2, ex + 1, ex)) * 10
            W = sidar_W(A, K, C, M, N, 1.0, 1.0)
            assert W[-1, -1] == 0.0
            rep = check_sidar_conditions(A, K, C, M, N, 2.0, 2.0, find_lyapunov=False)
            assert not rep.diag_ok[-1] and not rep.satisfied
    # example 1 with the stated gains: a common quadratic Lyapunov function still exists on the box (eq. 31)
    A, C, K = _ex_matrices(1)
    M, N, _, _ = sidar_gain_matrices(1, np.array(STATED_1))
    Q = check_sidar_conditions(A, K, C, M, N, 4.0, (4 / 3) ** 2).lyapunov_Q
    assert Q is not None and np.min(np.linalg.eigvalsh(Q)) > 0


def test_runtime_observer_is_the_studied_law() -> None:
    """AdaptiveObserver (the detector) runs exactly the law simulate_sidar studies: discrete mode with
    the Euler matrices == law "euler" to rounding; continuous mode within the y-interpolation error."""
    A0, C, K = _ex_matrices(2)
    B0 = np.array([[0.0], [0.0], [0.5]])
    A, B = np.array([[-1.0, 1.0, 0.0], [-3.0, 0.0, 1.0], [0.0, 0.0, 0.0]]), np.array([0.0, 0.0, 1.0])
    M, N, mA, mB = sidar_gain_matrices(2, np.array(UNITY_2))
    u_of = lambda t: np.sin(np.pi * t) + np.cos(t) / 3  # noqa: E731
    for law, dt in (("euler", SIDAR_STEP_S), ("continuous", 0.0025)):
        T = SIDAR_STEP_S
        if law == "euler":  # x(k+1) = (I + T A0) x + T B0 u + T K eps;  A0 += M eps x' is (I + T A0) += T M eps x'
            model = LinearModel(A=np.eye(3) + T * A0, B=T * B0, C=C, D=np.zeros((2, 1)), dt_s=T)
            obs = AdaptiveObserver(model, T * K, T * M, T * N, mA, mB[:, None], x0_hat=np.array([0.5, 1.0, 1.0]))
        else:
            model = LinearModel(A=A0, B=B0, C=C, D=np.zeros((2, 1)))
            obs = AdaptiveObserver(model, K, M, N, mA, mB[:, None], x0_hat=np.array([0.5, 1.0, 1.0]), input_hold="foh")
        run = simulate_sidar(2, np.array(UNITY_2), reading=SidarReading(law=law), t_end_s=3.0, h_s=0.0025, record_dt_s=dt)
        x, est = np.array([1.0, 0.0, 0.0]), []
        f = lambda t, xx: A @ xx + B * u_of(t)  # noqa: E731
        for k in range(int(round(3.0 / dt))):
            t = k * dt
            obs.step(t, np.array([u_of(t)]), C @ x)
            if law == "euler":
                x = x + dt * f(t, x)
            else:  # RK4 plant
                k1 = f(t, x)
                k2 = f(t + dt / 2, x + dt / 2 * k1)
                k3 = f(t + dt / 2, x + dt / 2 * k2)
                x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + f(t + dt, x + dt * k3))
            e = obs.estimates()
            Ac, Bc = ((e.A - np.eye(3)) / T, e.B / T) if law == "euler" else (e.A, e.B)
            est.append([-Ac[0, 0], Bc[2, 0], -Ac[1, 0]])
        err = np.abs(np.array(est) - run.params_hat[0, 1:len(est) + 1]).max()
        assert err < (1e-10 if law == "euler" else 5e-3), (law, err)


def test_fig_7_reproduced_with_per_step_gains() -> None:
    """Fig. 7 (tracking, a and b ramps): every statement met with m, n = 10, 5 per 0.05-s step."""
    run = _run(1, PER_STEP_1, tracking=True)
    bars = sidar_bars(run)
    assert len(bars) == 4 and all(b.met[0] for b in bars), [(b.text, b.measured[0]) for b in bars]


@pytest.mark.xfail(strict=True, reason="not reproduced: |eps| after 3.5 s 2.1e-2 (stated gains) / 2.0e-2 (per step), "
                   "paper 4e-3; a 65 % / 67 % off after 8 s, paper < 5 %")
@pytest.mark.parametrize("gains", [STATED_1, PER_STEP_1])
def test_fig_6_example_1(gains) -> None:
    assert _met(_run(1, gains))


@pytest.mark.slow  # gain grids, 5-15 s each
def test_fig_6_and_fig_7_exclude_each_other_through_the_initial_observer_state() -> None:
    """Per-step gains: with the printed x_hat(0) = (0.8, 1) fig. 7 holds and fig. 6 fails; with x_hat2(0) = 0
    fig. 6 holds (|eps| 2.6e-3, 3.8 %) and fig. 7 fails (5.4e-3 at 13 s, 15 %)."""
    other = SidarReading(x_hat0=(0.8, 0.0))
    assert not _met(_run(1, PER_STEP_1)) and _met(_run(1, PER_STEP_1, True))
    assert _met(_run(1, PER_STEP_1, reading=other)) and not _met(_run(1, PER_STEP_1, True, other))


def test_discretised_observer_reading_is_biased() -> None:
    """Started at the true parameters and state, the consistent laws stay there exactly; an Euler observer on the
    samples of an exactly integrated plant drifts away (so its numbers in the readings table are not Sidar's law)."""
    for law in ("continuous", "sampled", "euler"):
        run = simulate_sidar(2, np.array(PER_STEP_2) * (1 if law == "continuous" else SIDAR_STEP_S), False,
                             SidarReading(law=law, start_matched=True), 5.0, h_s=H_S)
        assert np.abs(run.params_hat[0] - run.params_true).max() < 1e-9 and run.output_error_norm.max() < 1e-9
    run = simulate_sidar(2, np.array(UNITY_2), False, SidarReading(law="euler_observer", start_matched=True), 5.0, h_s=H_S)
    assert np.max(np.abs(run.params_hat[0, -1] - run.params_true[-1]) / run.params_true[-1]) > 0.01


@pytest.mark.xfail(strict=True, reason="not reproduced: |theta error| / |theta| after 10 s is 36 % (unity), 31 % (per step), "
                   "26 % (sampled, unity per step), paper < 10 %; the output error (1.7e-2..2.4e-2) meets 5e-2")
@pytest.mark.parametrize("gains, law", [(UNITY_2, "continuous"), (PER_STEP_2, "continuous"), ((1.0,) * 3, "sampled")])
def test_fig_8_example_2(gains, law) -> None:
    assert _met(_run(2, gains, reading=SidarReading(law=law)))


@pytest.mark.xfail(strict=True, reason="not reproduced: tracking |eps| 6.2e-2 (unity) / 5.1e-2 (per step), paper < 2e-2; "
                   "|theta error| after 14.5 s 68 % / 41 %, paper < 10 %")
@pytest.mark.parametrize("gains", [UNITY_2, PER_STEP_2])
def test_fig_9_example_2_tracking(gains) -> None:
    assert _met(_run(2, gains, tracking=True))


@pytest.mark.slow  # gain grids, 5-15 s each
def test_fig_9_met_from_a_matched_start_with_twenty_times_the_per_step_gains() -> None:
    """The one reading that meets fig. 9: the run starts at the true parameters and state (the ramps begin at
    1 s) and the gain is 400 /s (20 per step), 20 times the per-step reading of "unity"."""
    assert _met(_run(2, (400.0,) * 3, True, SidarReading(start_matched=True)))
    assert not _met(_run(2, PER_STEP_2, True, SidarReading(start_matched=True)))


SIDAR_GRID_1 = np.array([(m, n) for m in np.geomspace(1.0, 1e4, 17) for n in np.geomspace(1.0, 1e4, 17)])  # [1/s]


def _grid_ok(reading: SidarReading, tracking: bool) -> np.ndarray:
    bars = sidar_bars(simulate_sidar(1, SIDAR_GRID_1, tracking, reading, 20.0 if tracking else 12.0, h_s=H_S))
    return np.logical_and.reduce([b.met for b in bars])


@pytest.mark.slow  # gain grids, 5-15 s each
def test_no_gains_meet_fig_6_and_fig_7_together_with_the_printed_initial_state() -> None:
    """17 x 17 grid of m, n in 1..1e4 /s (literal reading): fig. 7 holds on a patch around the per-step gains,
    fig. 6 nowhere, so never both."""
    ok7 = _grid_ok(SidarReading(), True)
    assert ok7.sum() >= 5 and not _grid_ok(SidarReading(), False).any()


@pytest.mark.slow  # gain grids, 5-15 s each
def test_fig_6_and_fig_7_together_need_a_matched_initial_state_and_larger_gains() -> None:
    """With x_hat(0) = x(0) both figures hold on the grid, but only for m >= 316 /s (per-step reading: 200)."""
    rd = SidarReading(x_hat0=(1.0, 0.0))
    both = _grid_ok(rd, False) & _grid_ok(rd, True)
    assert both.any() and SIDAR_GRID_1[both, 0].min() > 250.0


@pytest.mark.slow  # gain grids, 5-15 s each
def test_fig_8_needs_a_gain_of_about_800_per_second() -> None:
    """No common gain in 0.1..3000 /s meets fig. 8; over a 17^3 grid of (a, b, c) gains 10^(0.1 + 0.2 k) /s
    (1.26..2512) every combination that does has a gain >= 794 /s (none at 501 or below), e.g. a 50, b 794,
    c 794 /s."""
    g = np.geomspace(0.1, 3e3, 23)
    bars = sidar_bars(simulate_sidar(2, np.repeat(g[:, None], 3, axis=1), False, SidarReading(), 12.0, h_s=H_S))
    assert not np.logical_and.reduce([b.met for b in bars]).any()
    gv = 10.0 ** (0.1 + 0.2 * np.arange(17))
    g3 = np.array([(a, b, c) for a in gv for b in gv for c in gv])
    bars = sidar_bars(simulate_sidar(2, g3, False, SidarReading(), 12.0, h_s=H_S))
    ok = np.logical_and.reduce([b.met for b in bars])
    assert ok.any() and 700.0 < g3[ok].max(axis=1).min() < 800.0


def test_bars_and_examples_are_the_text_of_sec_VI() -> None:
    """Limits, time windows and example data of sidar_bars / simulate_sidar against Sidar 1982 (seed
    ``004``), sec. VI "Discussion of simulation results" (a) and (b); a wrong constant fails here, not
    silently in the reproduction tests that use them.

    Fig. 6: "less than 4x10^-3 after 3.5 sec", "within 95% accuracy, after 8 sec.". Fig. 7: ramps a
    1.0 -> 3.2 over 1-12 s, b 2.0 -> 3.6 over 4-12 s; "during the tracking phase ... less than
    2.5x10^-2" (from fig. 6's 3.5 s on: our reading), "one second after the end of the parameter
    variations ... less than 4x10^-3 ... better than 90%", "steady state ... 98-99%". Fig. 8: "less than
    5x10^-2, after 2.75 sec", "less than 10%, after 10 sec.". Fig. 9: tracking "less than 2x10^-2",
    after t = 12 "less than 10^-2 within 1.4 sec", "less than 10%, within 2.5 sec".
    """
    from fdi_sim.papers.sidar_examples import SidarBatch

    inf = np.inf
    expected = {  # figure: (limit, window start [s], window end [s]) per statement, in order
        6: [(4e-3, 3.5, inf), (0.05, 8.0, inf)],
        7: [(2.5e-2, 3.5, 12.0), (4e-3, 13.0, inf), (0.10, 13.0, 13.0), (0.02, 20.0, inf)],
        8: [(5e-2, 2.75, inf), (0.10, 10.0, inf)],
        9: [(2e-2, 2.75, 12.0), (1e-2, 13.4, inf), (0.10, 14.5, inf)],
    }
    t = np.arange(401) * 0.05  # 0..20 s
    e = np.stack([np.exp(-t), t])  # row 0 falls (its max is at a window's start), row 1 rises (at its end)
    for fig, bars in expected.items():
        example, tracking = (1 if fig < 8 else 2), fig in (7, 9)
        theta = np.ones((t.size, example + 1))
        hat = theta[None] * (1.0 + e[:, :, None])  # relative error e(t) of every parameter, and of the norm
        run = SidarBatch(example, tracking, SidarReading(), np.ones((2, example + 1)), t, e, hat, theta, ("a",) * (example + 1))
        got = sidar_bars(run)
        assert [b.figure for b in got] == [fig] * len(bars)
        for b, (limit, t0, t1) in zip(got, bars):
            assert b.limit == limit, (fig, b.text)
            np.testing.assert_allclose(b.measured, [np.exp(-t0), min(t1, t[-1])], rtol=1e-9, atol=1e-12, err_msg=f"fig. {fig}: {b.text}")
    ramps = simulate_sidar(1, np.array(STATED_1), True, SidarReading(law="euler"), 13.0)
    at = {tt: ramps.params_true[np.argmin(np.abs(ramps.t_s - tt))] for tt in (0.0, 1.0, 4.0, 12.0, 13.0)}
    np.testing.assert_allclose([at[tt] for tt in at], [[1, 2], [1, 2], [1.6, 2], [3.2, 3.6], [3.2, 3.6]], atol=1e-12)
    ex2 = simulate_sidar(2, np.array(UNITY_2), reading=SidarReading(law="euler"), t_end_s=0.1)
    np.testing.assert_allclose(ex2.params_true[0], [1.0, 1.0, 3.0])  # a_n, b_n, c_n
    np.testing.assert_allclose(ex2.params_hat[0, 0], [0.5, 0.5, 2.0])  # a_0(0), b_0(0), c_0(0)


def test_sampled_law_meets_fig_7_only_with_the_update_at_its_own_sample() -> None:
    """Sec. VI (a), p. 12-13, fig. 7: eq. 23 every 0.05 s with the printed m, n = 10, 5 per step meets every
    fig. 7 statement when ``A0(k) = A0(k-1) + M eps(k) xh(k)'`` is flown over [t_k, t_k+1]; held one step
    longer (the module's law before issue 12) the tracking error passes the paper's 2.5e-2."""
    own = sidar_bars(_run(1, STATED_1, True, SidarReading(law="sampled")))
    late = sidar_bars(_run(1, STATED_1, True, SidarReading(law="sampled", update="next_sample")))
    assert all(b.met[0] for b in own), [(b.text, b.measured[0]) for b in own]
    assert not late[0].met[0] and late[0].measured[0] > 2 * own[0].measured[0]


def test_equal_adaptation_gains_floor_the_fig_8_error() -> None:
    """Sec. VI (b), fig. 8, "all chosen as unity" read as every entry of M equal: rows 1 and 2 of M eps are
    equal and a0, c0 share the regressor x_hat1, so they get identical updates and c0 - a0 stays at its
    start 2.0 - 0.5 = 1.5 (the plant's is 2). Then |theta_hat - theta| / |theta| >= min over a of
    |(a - 1, a + 1.5 - 3)| / |(1, 1, 3)| = 0.25 sqrt(2) / sqrt(11) = 10.7 %, above the paper's 10 %."""
    run = _run(2, (1000.0,) * 3, reading=SidarReading(outputs="all"))
    a, c = run.params_hat[0, :, 0], run.params_hat[0, :, 2]
    np.testing.assert_allclose(c - a, 1.5, atol=1e-9)
    floor = np.hypot(0.25, 0.25) / np.linalg.norm([1.0, 1.0, 3.0])
    err = np.linalg.norm(run.params_hat[0] - run.params_true, axis=1) / np.linalg.norm(run.params_true, axis=1)
    assert 0.106 < floor < 0.107 and err.min() >= floor - 1e-12
    assert not sidar_bars(run)[1].met[0]


def test_unequal_gains_meet_fig_8_and_fig_9_from_the_printed_start() -> None:
    """Sec. VI (b), figs. 8 and 9: with a 1000, b 1000, c 100 /s (continuous eq. 22, printed theta_hat(0) and
    x_hat(0)) every statement holds: |eps| < 5e-2 after 2.75 s and < 10 % after 10 s (fig. 8); tracking
    |eps| < 2e-2, < 1e-2 after 13.4 s, < 10 % after 14.5 s (fig. 9)."""
    for tracking in (False, True):
        bars = sidar_bars(_run(2, (1000.0, 1000.0, 100.0), tracking))
        assert all(b.met[0] for b in bars), (tracking, [(b.text, b.measured[0]) for b in bars])


def _diverging_observer() -> AdaptiveObserver:
    A = np.array([[0.95, 0.05], [0.0, 0.9]])
    model = LinearModel(A=A, B=np.array([[0.0], [0.1]]), C=np.eye(2), D=np.zeros((2, 1)), dt_s=0.05)
    return AdaptiveObserver(model, 0.2 * np.eye(2), 0.5 * np.eye(2), 0.5 * np.eye(2), S=np.eye(2))


def test_a_diverging_observer_is_reported_invalid_never_a_valid_no_alarm() -> None:
    """Per-step gain 0.5 with |y| ~ 10: the unnormalized law's loop gain m |xh|^2 ~ 50 >> 2 (eq. 24), so the
    state overflows. From the first non-finite step on every Residual is invalid and raises no alarm; reset
    clears it."""
    y_of = lambda k: 10.0 * np.array([np.sin(0.3 * k), np.cos(0.2 * k)])  # noqa: E731
    obs = _diverging_observer()
    out = [obs.step(0.05 * k, np.array([1.0]), y_of(k)) for k in range(400)]
    bad = [k for k, r in enumerate(out) if not r.valid]
    assert bad and obs.diverged_t_s == pytest.approx(0.05 * bad[0])
    assert bad == list(range(bad[0], 400))  # never valid again
    assert all(not r.alarm and r.isolation is None for r in out[bad[0]:])
    assert all(np.isfinite(r.statistic) for r in out[:bad[0]]) and not np.isfinite(out[-1].statistic)
    obs.reset()
    assert obs.diverged_t_s is None and obs.step(0.0, np.array([1.0]), y_of(0)).valid


def test_finite_or_invalid() -> None:
    from fdi_sim.detectors.base import Residual, finite_or_invalid

    ok = Residual(0.0, np.array([1.0]), 1.0, 1, 3.0, False)
    assert finite_or_invalid(ok) is ok
    for r, stat in ((np.array([np.nan]), 1.0), (np.array([1.0]), np.inf), (np.array([1.0]), np.nan)):
        got = finite_or_invalid(Residual(0.0, r, stat, 1, 3.0, True, "h0"))
        assert not got.valid and not got.alarm and got.isolation is None


@pytest.fixture(scope="module")
def jsbsim_flights(tmp_path_factory) -> dict:
    """10-s fault-free JSBSim flights in light turbulence, each with the model linearized at its own point,
    read back from their MCAP logs as (u(k-1), y(k)) pairs (DESIGN.md time convention)."""
    from fdi_sim.aircraft import Aircraft
    from fdi_sim.flightlog import read_log
    from fdi_sim.linear.linearize import linearize
    from fdi_sim.operating_point import OperatingPoint
    from fdi_sim.scenario import loads
    from fdi_sim.training import fly

    out = {}
    for ac, op, init in (("f16", OperatingPoint("f16", 10000.0, vt_kts=400.0), "h_ft = 10000.0\nvt_kts = 400.0"),
                         ("DHC6", OperatingPoint("DHC6", 5000.0, vc_kts=120.0), "h_ft = 5000.0\nvc_kts = 120.0")):
        model = linearize(Aircraft(ac), op).model
        text = (f'name = "ao_{ac}"\naircraft = "{ac}"\nduration_s = 10.0\nseed = 3\n[initial]\n{init}\n'
                '[atmosphere]\nturbulence = "light"\n')
        res = fly(loads(text, "ao.toml"), tmp_path_factory.mktemp(ac))
        log = read_log(res.log_path)
        meas, cmd = log.topics["/sensors/measurements"], log.topics["/commands/pilot"]
        y = np.stack([meas[o] for o in model.output_names], axis=1)
        u = np.stack([cmd[c] if c in cmd.fields else np.full(len(cmd), model.u0[j])  # gust columns: trim (0)
                      for j, c in enumerate(model.input_names)], axis=1)
        out[ac] = (model, meas.t_s[1:], u[:-1], y[1:])
    return out


@pytest.mark.parametrize("aircraft", ["f16", "DHC6"])
def test_default_adaptive_observer_survives_a_jsbsim_flight(jsbsim_flights, aircraft) -> None:
    """Sidar's unnormalized law at the old default (per-step m = n = 0.1) overflows within 0.1 s on a JSBSim
    flight (|xh|^2 of 50-5000 in ft, ft/s, rad makes m |xh|^2 >> 2) and is then reported invalid; the
    factory's default (normalized, 0.01) stays valid for the whole 10 s."""
    from fdi_sim import registry

    model, t_s, u, y = jsbsim_flights[aircraft]
    make = registry.get("detector", "adaptive-observer-v1").factory
    sidar = make(model, m_gain=0.1, n_gain=0.1, normalized=False)
    res = [sidar.step(t, uk, yk) for t, uk, yk in zip(t_s, u, y)]
    assert sidar.diverged_t_s is not None and sidar.diverged_t_s - t_s[0] < 0.5
    assert not any(r.valid for r in res[-10:]) and not any(r.alarm for r in res if not r.valid)
    default = make(model)
    res = [default.step(t, uk, yk) for t, uk, yk in zip(t_s, u, y)]
    assert default.diverged_t_s is None and all(r.valid and np.isfinite(r.statistic) for r in res)


def test_bad_input() -> None:
    model = LinearModel(A=-np.eye(2), B=np.ones((2, 1)), C=np.eye(2), D=np.zeros((2, 1)))
    with pytest.raises(DesignError, match="input_hold"):
        AdaptiveObserver(model, np.eye(2), np.eye(2), np.eye(2), input_hold="cubic")
    with pytest.raises(DesignError, match=">= 0"):
        choose_sidar_gains(-np.eye(2), np.zeros((2, 2)), np.eye(2), -1.0, 1.0, 1.0, 1.0, n_inputs=1)
    with pytest.raises(DesignError, match="examples 1 and 2"):
        simulate_sidar(3, np.ones(2))  # type: ignore[arg-type]
    with pytest.raises(DesignError, match="3 gains"):
        simulate_sidar(2, np.ones(2))
    with pytest.raises(DesignError, match="unknown law"):
        simulate_sidar(1, np.ones(2), reading=SidarReading(law="rk2"), t_end_s=0.1)  # type: ignore[arg-type]
    with pytest.raises(DesignError, match="ends at"):
        sidar_bars(simulate_sidar(1, np.ones(2), t_end_s=1.0))


def test_registered_observer_detectors_follow_the_contract() -> None:
    from fdi_sim import registry
    from fdi_sim.papers.twin_otter_interim import twin_otter_longitudinal_interim

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
    # without alternatives (a scenario cannot give models): one loss-of-effectiveness model per control input
    mm = registry.get("detector", "kalman-mmae-v1").factory(m, **noise)
    assert mm.hypotheses == ("nominal",) + tuple(m.input_names[c] for c in m.control_columns())
    with pytest.raises(DesignError, match="effectiveness"):
        registry.get("detector", "kalman-mmae-v1").factory(m, effectiveness=1.0)


@pytest.mark.xfail(strict=True, reason="the default (normalized law, per-step 0.01) diverges at about 55 s on the "
                   "F-16's 60-s light-turbulence flight (docs/observers.md, block adaptive-jsbsim): its estimates, "
                   "not its error loop, go unstable; no fix yet (issue 23)")
def test_default_adaptive_observer_survives_a_whole_minute_on_the_f16(tmp_path) -> None:
    """The bar the 10-s test above cannot see: the factory's default stays finite for a whole 60-s F-16
    flight (10 kft / 400 KTAS, light turbulence, seed 3, as docs/make_observer_table.py flies it)."""
    from fdi_sim import registry
    from fdi_sim.aircraft import Aircraft
    from fdi_sim.flightlog import read_log
    from fdi_sim.linear.linearize import linearize
    from fdi_sim.operating_point import OperatingPoint
    from fdi_sim.scenario import loads
    from fdi_sim.training import fly

    model = linearize(Aircraft("f16"), OperatingPoint("f16", 10000.0, vt_kts=400.0)).model
    text = ('name = "ao_f16_60"\naircraft = "f16"\nduration_s = 60.0\nseed = 3\n[initial]\nh_ft = 10000.0\n'
            'vt_kts = 400.0\n[atmosphere]\nturbulence = "light"\n')
    log = read_log(fly(loads(text, "ao.toml"), tmp_path).log_path)
    meas, cmd = log.topics["/sensors/measurements"], log.topics["/commands/pilot"]
    y = np.stack([meas[o] for o in model.output_names], axis=1)
    u = np.stack([cmd[c] if c in cmd.fields else np.full(len(cmd), model.u0[j])
                  for j, c in enumerate(model.input_names)], axis=1)
    default = registry.get("detector", "adaptive-observer-v1").factory(model)
    for t, uk, yk in zip(meas.t_s[1:], u[:-1], y[1:]):
        default.step(t, uk, yk)
    assert default.diverged_t_s is None, f"diverged at {default.diverged_t_s - meas.t_s[1]:.2f} s"
