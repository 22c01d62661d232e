"""Beard-Jones detection filters against Miller & Ribbens (US 6,643,569 B2), App. A, eq. 2.47-2.54."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla
from scipy.signal import place_poles

from fdi_sim.detectors.base import Detector
from fdi_sim.detectors.beard_jones import angle_rad, beard_jones_gain, detection_space, output_separability
from fdi_sim.detectors.beard_jones_filter import BeardJonesBank, BeardJonesFilter, design_detection_filter, plan_bank
from fdi_sim.papers.twin_otter_interim import twin_otter_longitudinal_interim
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel

# the patent's example (eq. 2.47), the same as Beard's and White's
A3 = np.array([[0.0, 3.0, 4.0], [1.0, 2.0, 3.0], [0.0, 2.0, 5.0]])
C3 = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
F3 = np.array([1.0, -0.5, 0.5])


def _same_direction(a: np.ndarray, b: np.ndarray) -> float:
    return angle_rad(np.asarray(a, float), np.asarray(b, float))


def test_detection_space_eq_2_48_and_independent_null_space() -> None:
    ds = detection_space(A3, C3, F3)
    # eq. 2.48: D_f = (-0.816, 0.408, -0.408), printed to 3 decimals
    assert ds.order == 1
    assert np.allclose(np.sign(ds.basis[0, 0]) * -ds.basis[:, 0], [-0.816, 0.408, -0.408], atol=1e-3)
    # independent: build C', K', M with numpy's pinv and take scipy's null space
    cf = C3 @ F3
    cfp = np.linalg.pinv(cf[:, None])
    Cp = (np.eye(2) - np.outer(cf, cfp)) @ C3
    Kp = A3 - np.outer(A3 @ F3, cfp @ C3)
    M = np.vstack([Cp @ np.linalg.matrix_power(Kp, j) for j in range(3)])
    N = sla.null_space(M)
    assert N.shape[1] == 1 and _same_direction(N[:, 0], ds.basis[:, 0]) < 1e-9
    # completion space: orthogonal complement, dimension n - k (Definition 2.1.4)
    assert ds.completion.shape == (3, 2) and np.allclose(ds.completion.T @ ds.basis, 0, atol=1e-12)
    # generator: order 1, C g != 0, f = 1 * g (eq. 2.19). The patent's eq. 2.22 prints g = (1, 0, 0),
    # which violates its own eq. 2.12 (C g = 0) for this system; we do not reproduce that typo.
    assert np.allclose(ds.generator, F3) and np.linalg.norm(C3 @ ds.generator) > 0
    assert np.allclose(C3 @ np.array([1.0, 0.0, 0.0]), 0.0)


def test_matrices_of_eq_2_49() -> None:
    d = beard_jones_gain(A3, C3, F3[:, None], [[-8.0]], [-4.0, -5.0])
    Ai = A3 - d.L_detection @ C3
    # eq. 2.49 prints A_i[0, 2] = -.45; the formula eq. 2.46 gives -4.5 (a dropped digit), all else as printed
    assert np.allclose(Ai, [[0, 11.5, -4.5], [1, -0.5, 5.5], [0, 7.5, -0.5]], atol=1e-12)
    cf = d.output_directions  # the design's own C f (eq. 2.45: C_i = (I - Cf (Cf)^+) C)
    Ci = (np.eye(2) - cf @ np.linalg.pinv(cf)) @ C3
    assert np.allclose(Ci, [[0, 0.5, 0.5], [0, 0.5, 0.5]], atol=1e-12)
    assert np.allclose(d.L_detection, [[-8.5, 8.5], [2.5, -2.5], [-5.5, 5.5]], atol=1e-12)
    # independent: eq. 2.44 with f -> D_f, computed here from the printed detection space
    g = np.array([-0.816, 0.408, -0.408]) / np.linalg.norm([-0.816, 0.408, -0.408])
    Li = np.outer(A3 @ g + 8.0 * g, np.linalg.pinv((C3 @ g)[:, None]))
    assert np.allclose(Li, d.L_detection, atol=2e-3)


def test_final_gain_eq_2_50_to_2_54() -> None:
    d = beard_jones_gain(A3, C3, F3[:, None], [[-8.0]], [-4.0, -5.0])
    assert np.allclose(np.sort(np.linalg.eigvals(d.A_cl).real), [-8, -5, -4], atol=1e-9)  # eq. 2.54
    assert d.fixed_poles.size == 0 and d.max_direction_error_rad < 1e-9
    # the patent's final closed loop (eq. 2.51-2.52): its eigenvalues and eigenvectors (eq. 2.53-2.54)
    LC_pat = np.array([[0, 23, 40], [0, 11, 6], [0, 2, 13.0]])
    Acl_pat = np.array([[0, -20, -36], [1, -9, -3], [0, 0, -8.0]])
    assert np.allclose(A3 - LC_pat, Acl_pat)
    ev, vec = np.linalg.eig(Acl_pat)
    V_pat = {-4.0: [1.91, 0.383, 0.0], -5.0: [1.73, 0.433, 0.0], -8.0: [0.816, -0.408, 0.408]}
    for lam, v in V_pat.items():
        i = int(np.argmin(abs(ev - lam)))
        assert abs(ev[i] - lam) < 1e-9 and _same_direction(vec[:, i].real, v) < 3e-3
    # the gain of eq. 2.50 is unique up to L_p's component along the unobservable (detection) direction:
    # ours is the minimum-norm member, the patent's MATLAB place picked another. The difference is g s'.
    diff = d.A_cl - Acl_pat
    u, s, vt = np.linalg.svd(diff)
    assert s[1] < 1e-9 * s[0]
    assert _same_direction(u[:, 0], d.spaces[0].basis[:, 0]) < 1e-9
    assert _same_direction(vt[0], [0.0, 0.5, 0.5]) < 1e-9
    # the patent's own gain also passes our detection-gain check (Lemma 2.1.1, eq. 2.8)
    K = np.column_stack([np.linalg.matrix_power(Acl_pat, j) @ F3 for j in range(3)])
    assert np.linalg.matrix_rank(C3 @ K, tol=1e-9) == 1


def _error_trajectory(Acl: np.ndarray, f: np.ndarray, n_of_t, dt: float, steps: int) -> np.ndarray:
    """Exact ZOH simulation of de/dt = Acl e + f n(t) from e = 0."""
    n = Acl.shape[0]
    blk = np.zeros((n + 1, n + 1))
    blk[:n, :n], blk[:n, n] = Acl * dt, f * dt
    E = sla.expm(blk)
    Phi, gam = E[:n, :n], E[:n, n]
    e, out = np.zeros(n), []
    for k in range(steps):
        e = Phi @ e + gam * n_of_t(k * dt)
        out.append(e.copy())
    return np.array(out)


def test_residual_stays_on_Cf_through_the_transient() -> None:
    d = beard_jones_gain(A3, C3, F3[:, None], [[-8.0]], [-4.0, -5.0])
    cf = C3 @ F3
    for n_of_t in (lambda t: 1.0, lambda t: np.sin(3.0 * t) + 0.5 * np.cos(11.0 * t)):
        E = _error_trajectory(d.A_cl, F3, n_of_t, 1e-3, 3000)
        R = E @ C3.T
        big = np.linalg.norm(R, axis=1) > 1e-9
        assert big.sum() > 2500
        assert max(_same_direction(r, cf) for r in R[big]) < 1e-8
    # a plain observer with the same poles does not keep the direction: the test can fail
    Lp = place_poles(A3.T, C3.T, [-4.0, -5.0, -8.0]).gain_matrix.T
    R = _error_trajectory(A3 - Lp @ C3, F3, lambda t: 1.0, 1e-3, 3000) @ C3.T
    assert max(_same_direction(r, cf) for r in R[10:]) > 0.05


def test_unobservable_pair_raises() -> None:
    A = np.diag([-1.0, -2.0, -3.0])
    C = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    with pytest.raises(DesignError, match="not observable"):
        beard_jones_gain(A, C, np.array([[1.0], [0.0], [0.0]]), [[-5.0]], [-6.0, -7.0])


def test_not_output_separable_says_which_and_suggests_A_k_f() -> None:
    f2 = np.array([0.0, -1.0, 1.0])  # C f2 is parallel to C f
    with pytest.raises(DesignError, match=r"f0, f1.*not output separable"):
        beard_jones_gain(A3, C3, np.column_stack([F3, f2]), [[-8.0], [-9.0]], [-4.0])
    with pytest.raises(DesignError, match=r"C f = 0.*A\^1 f = \[0\.0, 1\.0, 0\.0\]"):
        beard_jones_gain(A3, C3, np.array([[1.0], [0.0], [0.0]]), [[-8.0, -9.0]], [-4.0])
    sep = output_separability(A3, C3, np.column_stack([F3, f2]))
    assert not sep.separable and sep.rank == 1 and sep.dependent == ((0, 1),)


def test_shifted_direction_generator_eq_2_11_2_20() -> None:
    f = np.array([1.0, 0.0, 0.0])  # C f = 0, C A f != 0: mu = 1
    ds = detection_space(A3, C3, f)
    assert ds.mu == 1 and ds.order == 2
    g, k = ds.generator, ds.order
    assert np.allclose(C3 @ g, 0, atol=1e-12)  # eq. 2.11
    assert np.linalg.norm(C3 @ A3 @ g) > 1e-6  # eq. 2.12
    assert np.allclose(ds.alpha[k - ds.mu - 1], 1.0)  # eq. 2.18 normalisation, eq. 2.20
    d = beard_jones_gain(A3, C3, f[:, None], [[-6.0, -7.0]], [-5.0], allow_shift=True)
    assert np.allclose(np.sort(d.poles.real), [-7, -6, -5], atol=1e-8)
    R = _error_trajectory(d.A_cl, f, lambda t: 1.0, 1e-3, 2000) @ C3.T
    big = np.linalg.norm(R, axis=1) > 1e-12
    assert max(_same_direction(r, C3 @ A3 @ f) for r in R[big]) < 1e-7


def test_two_faults_one_filter_against_independent_rank_check() -> None:
    rng = np.random.default_rng(7)
    A = rng.normal(size=(5, 5))
    C = rng.normal(size=(3, 5))
    F = rng.normal(size=(5, 2))
    d = beard_jones_gain(A, C, F, [[-3.0], [-4.0]], [-5.0, -6.0, -7.0])
    assert np.allclose(np.sort(d.poles.real), [-7, -6, -5, -4, -3], atol=1e-7)
    for i in range(2):  # Lemma 2.1.1: rank C [f, Acl f, ..., Acl^(n-1) f] = 1, by numpy SVD
        K = np.column_stack([np.linalg.matrix_power(d.A_cl, j) @ F[:, i] for j in range(5)])
        s = np.linalg.svd(C @ K, compute_uv=False)
        assert s[1] < 1e-8 * s[0]


def test_bank_when_faults_share_an_output_direction() -> None:
    B = np.column_stack([F3, [0.0, -1.0, 1.0]])  # C b2 is parallel to C b1
    Ad = np.eye(3) + 0.01 * (A3 - 10 * np.eye(3))  # a discrete model keeps the directions as given
    model = LinearModel(A=Ad, B=B, C=C3, D=np.zeros((2, 2)), dt_s=0.01, input_names=("a_cmd_norm", "b_cmd_norm"))
    designs = plan_bank(model, ["a_cmd_norm", "b_cmd_norm"])
    assert [d.gain.names for d in designs] == [("a_cmd_norm",), ("b_cmd_norm",)]
    bank = BeardJonesBank([BeardJonesFilter(d) for d in designs])
    assert isinstance(bank, Detector) and bank.hypotheses == ("a_cmd_norm", "b_cmd_norm")
    # the bank's record, rebuilt from the same filters stepped one by one
    alone = [BeardJonesFilter(d) for d in designs]
    x = np.zeros(3)
    for k in range(120):
        u = np.array([0.3 * np.sin(0.2 * k), 0.0])
        got, parts = bank.step(k * 0.01, u, C3 @ x), [f.step(k * 0.01, u, C3 @ x) for f in alone]
        x = Ad @ x + B @ (u + (np.array([0.0, 2.0]) if k >= 40 else 0.0))
        ratios = [p.statistic / p.threshold for p in parts]
        j = int(np.argmax(ratios))
        assert np.array_equal(got.r, np.concatenate([p.r for p in parts]))
        assert np.array_equal(got.scores, np.concatenate([p.scores for p in parts]), equal_nan=True)
        assert got.statistic == ratios[j] and got.alarm == parts[j].alarm and got.isolation == parts[j].isolation
    assert got.alarm


def test_single_output_detection_space_is_the_whole_state() -> None:
    # one output: C' = (I - Cf (Cf)^+) C is rounding noise (~1e-16 for this seed), D_f = R^n (order n); a purely
    # relative rank tolerance (scipy's null_space) would call the noise full rank and report an empty detection space
    rng = np.random.default_rng(0)
    A, C, f = rng.normal(size=(3, 3)), rng.normal(size=(1, 3)), rng.normal(size=3)
    ds = detection_space(A, C, f)
    assert ds.order == 3 and ds.basis.shape == (3, 3)
    d = beard_jones_gain(A, C, f[:, None], [[-4.0, -5.0, -6.0]], [])
    assert np.allclose(np.sort(d.poles.real), [-6.0, -5.0, -4.0], atol=1e-7)


def _simulate_twin_otter_fault(fault: str, bias: float, dt: float = 1 / 120, steps: int = 600):
    m = twin_otter_longitudinal_interim()
    md = m.discretize(dt)
    R = np.diag([0.1, 0.002, 0.002, 0.002]) ** 2  # sensor noise: 0.1 ft/s, 0.002 rad, 0.002 rad/s, 0.002 rad
    design = design_detection_filter(m, ["elevator_cmd_norm", "throttle_cmd_norm"], dt_s=dt, R=R)
    filt = BeardJonesFilter(design, alpha=1e-3)
    filt.reset(np.random.default_rng(0))
    x = np.zeros(4)
    j = m.input_names.index(fault)
    out = []
    for k in range(steps):
        t = k * dt
        u = np.array([0.05 * np.sin(2.0 * t), 0.1 * np.sin(0.7 * t)])
        u_flown = u.copy()
        if t >= 1.0:
            u_flown[j] += bias
        y = md.C @ x + m.y0
        out.append(filt.step(t, u + m.u0, y))
        x = md.A @ x + md.B @ u_flown
    return design, out


@pytest.mark.parametrize(("fault", "bias"), [("elevator_cmd_norm", 0.05), ("throttle_cmd_norm", 0.5)])
def test_twin_otter_filter_isolates_actuator_faults(fault: str, bias: float) -> None:
    design, out = _simulate_twin_otter_fault(fault, bias)
    assert design.gain.discrete and np.all(np.abs(design.gain.poles) < 1)
    before = [r for r in out if r.t_s < 1.0]
    after = [r for r in out if r.t_s > 1.02]
    assert max(np.linalg.norm(r.r) for r in before) < 1e-10  # matched, noise-free: zero residual
    i = design.gain.names.index(fault)
    assert max(r.scores[i] for r in after) < 1e-6  # residual on C f_i all the time
    W = np.linalg.inv(np.linalg.cholesky(design.S))  # scores are angles in S^-1/2-whitened coordinates
    for r in after[::50]:
        want = [angle_rad(W @ r.r, W @ design.gain.output_directions[:, h]) for h in range(2)]
        assert np.allclose(r.scores, want, rtol=1e-9, atol=1e-12)
        assert np.isclose(r.statistic, r.r @ np.linalg.solve(design.S, r.r))
    assert min(r.scores[1 - i] for r in after) > 0.1
    assert any(r.alarm for r in after) and {r.isolation for r in after if r.alarm} == {fault}
