"""Optimally robust parity relations (Lou, Willsky & Verghese 1986, sec. 3-5; Chow et al. 1984, sec. 3-4)."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sl
from hypothesis import given, settings
from hypothesis import strategies as st

from fdi_sim.detectors.parity import (
    AdditiveFaults,
    input_toeplitz,
    observability_matrix,
    parity_space,
    select_outputs,
)
from fdi_sim.detectors.parity_mismatch import compare_nominal_vs_robust, residual_moments
from fdi_sim.detectors.robust_parity import (
    design_block,
    detection_robustness,
    example_icing_models,
    make_robust_parity_detector,
    robust_parity,
    robustness_cost,
    s_svd,
    stationary_state_sqrt,
)
from fdi_sim.detectors.stochastic_parity import noise_window_covariance
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel


def model_set(rng: np.random.Generator, Q: int = 3, n: int = 3, r: int = 3, spread: float = 0.05):
    A0 = rng.standard_normal((n, n))
    A0 *= 0.8 / max(abs(np.linalg.eigvals(A0)))
    B, C = rng.standard_normal((n, 2)), rng.standard_normal((r, n))
    out = []
    for _ in range(Q):
        A = A0 + spread * rng.standard_normal((n, n))
        out.append(LinearModel(A=A, B=B, C=C + spread * rng.standard_normal((r, n)), D=np.zeros((r, 2)), dt_s=0.1))
    return out


def test_one_exact_model_gives_the_exact_parity_space():
    """Q = 1, no noise: sigma_1..p = 0 and span(P) = null(O') (sec. 3, footnote of eq. 21)."""
    m = model_set(np.random.default_rng(20), Q=1)[0]
    s = 2
    d = robust_parity([m], s, inputs="ignore")
    O = observability_matrix(m.A, m.C, s)
    ref = sl.null_space(O.T)
    assert d.n_relations == ref.shape[1] == 6
    assert np.all(d.sigma[:6] < 1e-12 * d.sigma[-1]) and d.sigma[6] > 1e-3 * d.sigma[-1]
    assert np.max(sl.subspace_angles(d.P, ref)) < 1e-8
    # with known inputs the relations live in [Y; U] and span null([[O, H], [0, I]]') (eq. 36-41)
    dk = robust_parity([m], s, inputs="known")
    H = input_toeplitz(m.A, m.B, m.C, m.D, s)
    G = np.block([[O, H], [np.zeros((H.shape[1], O.shape[1])), np.eye(H.shape[1])]])
    assert np.all(dk.sigma[:6] < 1e-12 * dk.sigma[-1])
    assert np.max(sl.subspace_angles(dk.P, sl.null_space(G.T))) < 1e-8
    assert np.max(sl.subspace_angles(dk.P, parity_space(m, s).relations())) < 1e-8


def test_singular_values_match_numpy_svd_of_the_stacked_matrix():
    """T = [Z_1 ... Z_Q], Z_q = O_q M_q (eq. 14-16), built here by hand; weights as sqrt(a_q) (eq. 24)."""
    rng = np.random.default_rng(21)
    ms = model_set(rng)
    M = np.diag([1.0, 2.0, 0.5])
    a = [0.5, 0.3, 0.2]
    d = robust_parity(ms, 1, weights=a, state_sqrt=M, inputs="ignore", n_relations=2)
    Z = np.hstack([np.sqrt(aq) * observability_matrix(m.A, m.C, 1) @ M for aq, m in zip(a, ms)])
    sv = np.linalg.svd(Z, compute_uv=False)
    np.testing.assert_allclose(np.sort(d.sigma), np.sort(sv), rtol=1e-10, atol=1e-14)


def test_objective_equals_sum_of_smallest_squared_singular_values():
    """J(P) = ||P'T||_F^2 at the optimum is sum_{i<=p} sigma_i^2 (eq. 22-23, A.3), which is the sum of the
    p smallest eigenvalues of T T' (numpy eigvalsh, independent)."""
    rng = np.random.default_rng(22)
    ms = model_set(rng, Q=4, spread=0.2)
    d = robust_parity(ms, 2, inputs="ignore", measurement_sqrt=0.1 * np.eye(3), n_relations=3)
    ev = np.linalg.eigvalsh(d.T @ d.T.T)
    for p in range(1, 9):
        Pp = d.U[:, :p]
        assert robustness_cost(Pp, d.T) == pytest.approx(np.sum(d.sigma_sq[:p]), rel=1e-9)
        assert robustness_cost(Pp, d.T) == pytest.approx(np.sum(ev[:p]), rel=1e-8)
    assert d.J_star == pytest.approx(np.sum(ev[:3]), rel=1e-8)
    curve = d.curve()
    assert curve[0] == 0 and np.all(np.diff(curve) >= 0) and np.all(np.diff(curve, 2) >= -1e-12)  # convex (sec. 5.1)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), p=st.integers(1, 8))
def test_no_orthonormal_relation_set_beats_the_svd(seed, p):
    rng = np.random.default_rng(seed)
    ms = model_set(np.random.default_rng(23), Q=3, spread=0.2)
    d = robust_parity(ms, 2, inputs="ignore", n_relations=p)
    Qr, _ = np.linalg.qr(rng.standard_normal((d.T.shape[0], p)))
    assert robustness_cost(Qr, d.T) >= d.J_star * (1 - 1e-12)


def test_weights_are_prior_probabilities():
    """a_q of eq. 24 = repeating model q in proportion: weights (2/3, 1/3) equal the list [m1, m1, m2]."""
    ms = model_set(np.random.default_rng(24), Q=2, spread=0.2)
    d1 = robust_parity(ms, 1, weights=[2 / 3, 1 / 3], inputs="ignore", n_relations=2)
    d2 = robust_parity([ms[0], ms[0], ms[1]], 1, inputs="ignore", n_relations=2)
    np.testing.assert_allclose(d1.sigma, d2.sigma, atol=1e-12)
    assert np.max(sl.subspace_angles(d1.P, d2.P)) < 1e-8


def test_noise_extension_second_moment():
    """Eq. 30-35: T T' = sum_q a_q (Z_q Z_q' + H_q H_q'); compare with O M M' O' + S of Hagenblad eq. 9."""
    rng = np.random.default_rng(25)
    base = model_set(rng, Q=2)
    ms = [LinearModel(A=m.A, B=m.B, C=m.C, D=m.D, dt_s=0.1, input_kinds=("control", "disturbance")) for m in base]
    R = np.diag([0.1, 0.2, 0.3])
    d = robust_parity(ms, 2, inputs="ignore", disturbance_sqrt=[[0.7]], measurement_sqrt=np.sqrt(R), n_relations=2)
    ref = sum(0.5 * (observability_matrix(m.A, m.C, 2) @ observability_matrix(m.A, m.C, 2).T
                     + noise_window_covariance(m, 2, R, Bv=m.B[:, 1:], Q=[[0.49]])) for m in ms)
    np.testing.assert_allclose(d.T @ d.T.T, ref, atol=1e-12)


ICING_NOISE = dict(input_sqrt=np.diag([0.05, 0.1]), disturbance_sqrt=np.array([[2.0]]),
                   measurement_sqrt=np.diag([0.05, 5e-4, 5e-4, 5e-4, 0.02]))


def stationary_windows(model: LinearModel, L: int, n_runs: int, rng: np.random.Generator):
    """Windows [Y; U] of L samples of ``model`` under ICING_NOISE, each run started in the stationary state.

    The state covariance is checked here against its Lyapunov equation S = A S A' + G G' (Lou eq. 29),
    G = [B_u Su, B_d Sd] built by hand, so starting from it needs no burn-in.
    """
    su, sd, sm = np.diag(ICING_NOISE["input_sqrt"]), 2.0, np.diag(ICING_NOISE["measurement_sqrt"])
    M = stationary_state_sqrt(model, ICING_NOISE["input_sqrt"], ICING_NOISE["disturbance_sqrt"])
    S = M @ M.T
    G = np.hstack([model.B[:, :2] * su, model.B[:, 2:] * sd])
    np.testing.assert_allclose(S, model.A @ S @ model.A.T + G @ G.T, atol=1e-10 * np.abs(S).max())
    x = rng.standard_normal((n_runs, model.n_states)) @ M.T
    Ys, Us = [], []
    for _ in range(L):
        u = rng.standard_normal((n_runs, 2)) * su
        uu = np.hstack([u, sd * rng.standard_normal((n_runs, 1))])
        Ys.append(x @ model.C.T + uu @ model.D.T + rng.standard_normal((n_runs, 5)) * sm)
        Us.append(u)
        x = x @ model.A.T + uu @ model.B.T
    return np.hstack([np.hstack(Ys), np.hstack(Us)])


def test_known_input_block_is_the_window_second_moment():
    """R_q R_q' = E[[Y; U][Y; U]'] at the stationary state (eq. 29, 37-41), against simulated windows."""
    m = example_icing_models((0.0,), dt_s=0.05)[0]
    Rq = design_block(m, 1, "stationary", "known", **ICING_NOISE)
    n = 40_000
    X = stationary_windows(m, 2, n, np.random.default_rng(26))
    emp = X.T @ X / n
    ref = Rq @ Rq.T
    d = np.sqrt(np.outer(np.diag(ref), np.diag(ref)))
    assert np.max(np.abs(emp - ref) / d) < 0.035  # correlation-scale error of 196 entries; se <= sqrt(2/n) = 0.007


def test_sensor_set_curves_sec_5_1():
    """Adding a duplicate of a sensor adds a perfect static relation: J*(1) drops to the noise level."""
    m = example_icing_models((0.0, 0.1))
    base = [select_outputs(x, ("u_mps", "q_radps", "theta_rad")) for x in m]
    dup = [LinearModel(A=x.A, B=x.B, C=np.vstack([x.C, x.C[1]]), D=np.vstack([x.D, x.D[1]]), dt_s=x.dt_s,
                       input_kinds=x.input_kinds) for x in base]
    c_base = robust_parity(base, 1, inputs="ignore", n_relations=1).curve()
    c_dup = robust_parity(dup, 1, inputs="ignore", n_relations=1).curve()
    assert c_dup[1] < 1e-20 < c_base[1]
    with pytest.raises(DesignError, match="unknown output"):
        select_outputs(m[0], ("nz_g",))


def test_s_svd_and_detection_versus_robustness():
    """Eq. 48-61 on the setting of Lou's eq. 46-47 and Fig. 3: y2 = a y1, with (our intervals)
    a in [0.9, 1.1] unfailed and [1.9, 2.1] failed."""
    def static(a):
        return LinearModel(A=[[0.5]], B=[[0.0]], C=[[1.0], [a]], D=[[0.0], [0.0]], dt_s=1.0)
    d = detection_robustness([static(a) for a in (0.9, 1.0, 1.1)], [static(a) for a in (1.9, 2.0, 2.1)], 0,
                             inputs="ignore")
    M = (d.H * d.signs) @ d.H.T
    np.testing.assert_allclose(d.lam, sl.eigh(M, eigvals_only=True), atol=1e-12)
    assert d.n_useful == 1 and d.lam[0] < 0 < d.lam[1]
    P = d.P[:, 0]
    assert d.J_star == pytest.approx(P @ M @ P)
    # brute force over all unit relations p = (cos t, sin t): J(t) = sum (p'z_q)^2 - (p'zbar_q)^2 (eq. 48)
    t = np.linspace(0, np.pi, 20001)
    pts = np.stack([np.cos(t), np.sin(t)], 1)
    J = sum((pts @ [1, a]) ** 2 for a in (0.9, 1.0, 1.1)) / 3 - sum((pts @ [1, a]) ** 2 for a in (1.9, 2.0, 2.1)) / 3
    assert J.min() == pytest.approx(d.J_star, rel=1e-6)
    assert abs(abs(pts[J.argmin()] @ P) - 1) < 1e-6
    assert abs(P @ [1, 2]) > 1.5 * abs(P @ [1, 1])  # larger under failure than without
    rng = np.random.default_rng(27)
    H = rng.standard_normal((4, 4))
    sg = np.array([-1.0, -1.0, 1.0, 1.0])
    f = s_svd(H, sg)
    np.testing.assert_allclose(f.U @ np.diag(f.sigma) @ f.V, H, atol=1e-10)  # eq. 61
    np.testing.assert_allclose(f.V @ np.diag(sg) @ f.V.T, np.diag(f.sign), atol=1e-10)  # eq. 60
    assert sorted(f.sign) == sorted(sg)  # Sylvester's law of inertia: the signature of S is kept
    with pytest.raises(DesignError, match="singular"):
        s_svd(np.ones((2, 2)), [1.0, -1.0])


def test_mismatched_models_and_bad_options_are_refused():
    ms = model_set(np.random.default_rng(28), Q=2)
    small = LinearModel(A=np.eye(2) * 0.5, B=np.ones((2, 2)), C=np.ones((3, 2)), D=np.zeros((3, 2)), dt_s=0.1)
    with pytest.raises(DesignError, match="same size"):
        robust_parity([ms[0], small], 1)
    with pytest.raises(DesignError, match="positive"):
        robust_parity(ms, 1, weights=[1.0, -1.0])
    with pytest.raises(DesignError, match="between 1 and"):
        robust_parity(ms, 1, n_relations=99)
    unstable = LinearModel(A=np.eye(3) * 1.01, B=ms[0].B, C=ms[0].C, D=ms[0].D, dt_s=0.1)
    with pytest.raises(DesignError, match="spectral radius"):
        robust_parity([unstable], 1, state_sqrt="stationary")
    with pytest.raises(DesignError, match="no exact parity relation"):
        robust_parity(ms, 0)


def test_detector_runs_the_robust_relations():
    """The detector's statistic is r'(P'TT'P)^-1 r, the average residual covariance over the model set
    (eq. 26), which for the SVD relations is diag(sigma_1^2 .. sigma_p^2)."""
    ms = model_set(np.random.default_rng(29), Q=2)
    d = robust_parity(ms, 2, measurement_sqrt=0.01 * np.eye(3))
    det = make_robust_parity_detector(ms[0], d)
    rng = np.random.default_rng(30)
    Y, U = rng.standard_normal((3, 3)), rng.standard_normal((3, 2))
    for k in range(3):
        out = det.step(0.1 * k, U[k], Y[k])
    r = d.residual(Y.ravel()[None], U.ravel()[None])[0]
    cov = d.P.T @ d.T @ d.T.T @ d.P  # no scaling here, so P = U_p
    np.testing.assert_allclose(cov, np.diag(d.sigma_sq[: d.n_relations]), atol=1e-12 * cov.max())
    assert out.statistic == pytest.approx(r @ np.linalg.solve(cov, r), rel=1e-8)
    np.testing.assert_allclose(det.whiten @ r, out.r, atol=1e-10)


def test_residual_moments_against_time_domain_simulation():
    """Nominal relations on the iced (eta 0.1) model: the covariance used in the comparison equals the one
    of residuals computed from simulated fault-free flights (statistical check, 40 000 windows)."""
    clean, iced = example_icing_models((0.0, 0.1))
    P = parity_space(clean, 2).relations()
    cov = residual_moments(P, iced, 2, **ICING_NOISE).cov
    n = 40_000
    r = stationary_windows(iced, 3, n, np.random.default_rng(31)) @ P
    emp = r.T @ r / n
    np.testing.assert_allclose(np.diag(emp), np.diag(cov), rtol=0.03)  # se of a variance sqrt(2/n) = 0.7 %


def test_robust_relations_cut_false_alarms_on_iced_flight_at_equal_detection():
    """Synthetic clean/iced set (eta 0, 0.05, 0.1): at 0.9 detection of a 0.01 rad elevator bias on the clean
    model, the most robust order-2 relation raises far fewer alarms on fault-free eta = 0.1 flight."""
    ms = example_icing_models()
    faults = AdditiveFaults.from_model(ms[0], actuators=["elevator_rad"])
    res = compare_nominal_vs_robust(ms[0], ms[1:], 2, faults, 0, 0.01, np.random.default_rng(32), detection=0.9,
                                    n_relations=1, n_samples=40000, labels=("clean", "eta0.05", "eta0.1"),
                                    **ICING_NOISE)
    for r in (res.nominal, res.robust):
        assert abs(r.detection - 0.9) < 0.01
    assert res.nominal.n_relations == 11 and res.robust.n_relations == 1
    nom_lo = res.nominal.false_alarm_ci[2, 0]
    rob_hi = res.robust.false_alarm_ci[2, 1]
    assert rob_hi < nom_lo, (res.nominal.false_alarm, res.robust.false_alarm)
    assert res.nominal.false_alarm[2] > 10 * max(res.robust.false_alarm[2], 1 / 40000)
