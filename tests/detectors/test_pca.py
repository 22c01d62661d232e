"""PCA residuals (Hagenblad, Gustafsson & Klein, sec. 3, eq. 15-22)."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sl

from fdi_sim.papers.hagenblad_f16 import f16_faults, f16_model, f16_reading, simulate_f16
from fdi_sim.detectors.parity import input_toeplitz, parity_space
from fdi_sim.detectors.pca import (
    estimate_fault_signatures,
    make_pca_detector,
    pca_train,
    pca_train_from_series,
    sliding_windows,
    stack_data_windows,
    suggest_residual_dimension,
)
from fdi_sim.errors import DesignError
from fdi_sim.registry import get


@pytest.fixture(scope="module")
def f16_training():
    w = simulate_f16(f16_reading("none", "unit"), None, 20000, np.random.default_rng(40))
    return stack_data_windows(w.Y, w.U)


def test_split_properties_and_eigenvalues_against_eigh(f16_training):
    """Eq. 16-17: eigenvalues of R_Z = Z'Z/N (numpy eigvalsh, independent); O'O = I, O'W = 0, WW' + OO' = I."""
    Z = f16_training
    pca = pca_train(Z, 4)
    ev = np.linalg.eigvalsh(Z.T @ Z / Z.shape[0])[::-1]
    np.testing.assert_allclose(pca.eigenvalues, ev, rtol=1e-8, atol=1e-12 * ev[0])
    O, W = pca.basis_model, pca.W
    np.testing.assert_allclose(O.T @ O, np.eye(14), atol=1e-10)
    np.testing.assert_allclose(W.T @ W, np.eye(4), atol=1e-10)
    assert np.abs(O.T @ W).max() < 1e-10
    np.testing.assert_allclose(W @ W.T + O @ O.T, np.eye(18), atol=1e-10)
    zhat, ztil = pca.split(Z[:5])
    np.testing.assert_allclose(zhat + ztil, Z[:5], atol=1e-10)  # eq. 15, 18
    rb = pca.normalized_residual(Z)
    np.testing.assert_allclose(rb.T @ rb / Z.shape[0], np.eye(4), atol=1e-8)  # eq. 20 on the training data


def test_residual_space_is_the_parity_space(f16_training):
    """With low noise, span(W) -> span([W_p; -H_u'W_p]) of the model-based parity space (eq. 5 vs 19)."""
    pca = pca_train(f16_training, 4)
    ang = sl.subspace_angles(pca.W, parity_space(f16_model(), 2).relations())
    assert np.max(ang) < 1e-3  # radians (4e-4 here, docs/parity.md); the noise leaves a small tilt


def test_dimension_choice_from_the_eigenvalues(f16_training):
    pca = pca_train(f16_training, 4)
    assert suggest_residual_dimension(pca.eigenvalues) == 4
    ev = pca.eigenvalues
    assert ev[13] / ev[14] > 100  # a clear gap between model and residual spaces (>2 decades)


def test_fault_signatures_are_the_model_based_mean_shift(f16_training):
    """Eq. 22 estimated from data with fault i (elevator actuator, pitch sensor) equals D_r^-1/2 W' of the
    model's window image of the fault, [H_f (1 ⊗ e_i); 0] (eq. 8, 21), up to the noise of a mean of
    4000 unit-covariance residuals (se 0.016); the state part O x drops out because W spans the parity space."""
    pca = pca_train(f16_training, 4)
    model, faults = f16_model(), f16_faults()
    Hf = input_toeplitz(model.A, faults.Bf, model.C, faults.Df, 2)
    rd = f16_reading("none", "unit")
    rng = np.random.default_rng(41)
    for j in (2, 5):
        sig = estimate_fault_signatures(pca, [simulate_f16(rd, j, 4000, rng).Z])[0]
        shift = np.concatenate([Hf @ np.tile(np.eye(6)[j], 3), np.zeros(9)])
        np.testing.assert_allclose(sig, shift @ pca.W / np.sqrt(pca.D_r), atol=0.08)  # |sig| = 6.6 and 12.5


def test_detector_matches_batch_residuals_and_uses_trims(f16_training):
    model = f16_model()
    pca = pca_train(f16_training, 4)
    det = make_pca_detector(model, pca, 3)
    rng = np.random.default_rng(42)
    u, y = rng.standard_normal((10, 3)), rng.standard_normal((10, 3))
    outs = [det.step(0.1 * k, u[k], y[k]) for k in range(10)]
    Z = stack_data_windows(sliding_windows(y, 3), sliding_windows(u, 3))
    np.testing.assert_allclose(np.array([o.r for o in outs[2:]]), pca.normalized_residual(Z), atol=1e-9)
    assert [o.valid for o in outs[:3]] == [False, False, True]


def test_training_from_a_log_through_the_registry():
    """pca-v1 factory: train on a fault-free log, signatures from a faulty log, isolate the fault."""
    from fdi_sim.linear.model import LinearModel

    base = f16_model()
    model = LinearModel(A=base.A, B=base.B, C=base.C, D=base.D, dt_s=base.dt_s, output_names=base.output_names,
                        input_names=base.input_names, u0=[1.0, 2.0, 3.0], y0=[100.0, 200.0, 5.0])
    rng = np.random.default_rng(43)

    def log(fault_d, n=3000):
        x, us, ys = np.zeros(5), [], []
        for _ in range(n):
            u = rng.standard_normal(3)
            ys.append(model.C @ x + fault_d + rng.standard_normal(3) * np.sqrt([1e-4, 1e-6, 1e-6]) + model.y0)
            us.append(u + model.u0)
            x = model.A @ x + model.B @ u
        return np.array(us), np.array(ys)

    u0, y0 = log(np.zeros(3), 6000)
    fault = {"pitch_sensor": log(np.array([0, 0, 1.0])), "speed_sensor": log(np.array([0, 1.0, 0]))}
    det = get("detector", "pca-v1").factory(model, u0, y0, window_L=3, fault_data=fault)
    assert det.hypotheses == ("pitch_sensor", "speed_sensor")
    uf, yf = log(np.array([0, 0, 1.0]), 200)
    outs = [det.step(0.1 * k, uf[k], yf[k]) for k in range(200)]
    assert np.mean([o.isolation == "pitch_sensor" for o in outs[2:]]) > 0.95
    pca = pca_train_from_series(u0, y0, 3, 4, model.u0, model.y0)
    assert pca.n_samples == 6000 - 2
    with pytest.raises(DesignError, match=r"\(0, 1\)"):
        get("detector", "pca-v1").factory(model, u0, y0, window_L=3, p_false_alarm=1.5)


def test_bad_training_input():
    Z = np.random.default_rng(44).standard_normal((100, 6))
    with pytest.raises(DesignError, match="between 1 and 5"):
        pca_train(Z, 6)
    with pytest.raises(DesignError, match="at least 6"):
        pca_train(Z[:4], 2)
    # exactly collinear columns (three copies of the sum of the first three: 3 exact relations) are
    # dropped with a note, not refused (issue 12: the autopilot makes such relations); asking for
    # more residuals than the 6 - 3 - 1 left raises and names them
    collinear = np.hstack([Z[:, :3], Z[:, :3] @ np.ones((3, 3))])
    pca = pca_train(collinear, 2)
    assert pca.exact_relations.shape == (6, 3) and "3 exact linear relation" in pca.notes[0]
    assert np.abs(collinear @ pca.exact_relations).max() < 1e-12 * np.abs(collinear).max()
    assert np.abs(pca.W.T @ pca.exact_relations).max() < 1e-12  # no residual along a relation
    assert pca.D_r.min() > 0.01  # the normalization of eq. 20 divides by real variances only
    with pytest.raises(DesignError, match="after dropping 3 exact"):
        pca_train(collinear, 3)
    with pytest.raises(DesignError, match="at least L=3"):
        sliding_windows(np.ones((2, 3)), 3)
