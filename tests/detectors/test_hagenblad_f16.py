"""The F-16 study of Hagenblad, Gustafsson & Klein, sec. 4 (eq. 23-28, Table 1, L = 3).

Reading used (PAPER_READING): measurement noise of Table 1, no process noise, unit fault
magnitudes in eq. 28. The default tests use reduced sample counts with binomial/order-statistic
tolerances; ``-m slow`` runs the full-size reproduction.
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from fdi_sim.papers.hagenblad_f16 import (
    A_EQ23,
    BU_EQ24,
    PAPER_ISOLATION_PARITY,
    PAPER_ISOLATION_PCA,
    PAPER_P_EQ28,
    PAPER_READING,
    PAPER_THRESHOLD_PARITY,
    PAPER_THRESHOLD_PCA,
    f16_design,
    f16_model,
    f16_parity_study,
    f16_pca_study,
    f16_reading,
    simulate_f16,
)
from fdi_sim.detectors.parity import observability_matrix
from fdi_sim.detectors.stochastic_parity import incorrect_diagnosis_matrix, threshold_by_simulation
from fdi_sim.errors import DesignError

READING = f16_reading(*PAPER_READING)


def test_printed_matrices_are_the_zoh_of_the_continuous_airc_model():
    """Eq. 23-24 are the 0.1 s zero-order hold of Maciejowski's AIRC model (independent source)."""
    exact = f16_model(exact=True)
    assert np.abs(exact.B - BU_EQ24).max() < 5e-5  # rounding to 4 decimals
    d = np.abs(exact.A - A_EQ23)
    assert d.max() < 1.1e-4 and np.unravel_index(d.argmax(), d.shape) == (0, 2)  # 0.11319 printed as 0.1133


def test_residual_dimension_and_undetectable_altitude_fault():
    """n_r = L n_y - n_x = 4 (eq. 7); fault 4 (altitude sensor bias) lies in range(O): undetectable."""
    d = f16_design(READING)
    assert d.n_residuals == 4
    assert list(d.detectable) == [True, True, True, False, True, True]
    assert np.all(d.mu_bar[3] == 0)
    # why: altitude is a pure integrator (first column of A is e1), so a constant altitude offset is a
    # state offset: O x = 1 ⊗ e1 has an exact solution
    O = observability_matrix(f16_model().A, f16_model().C, 2)
    target = np.tile([1.0, 0.0, 0.0], 3)
    x, *_ = np.linalg.lstsq(O, target, rcond=None)
    assert np.abs(O @ x - target).max() < 1e-12
    P = incorrect_diagnosis_matrix(d).P
    assert np.all(P[3] == 0) and np.all(P[:, 3] == 0)  # "can be considered zero", no division by zero


def test_eq28_is_reproduced_within_0_01():
    P = incorrect_diagnosis_matrix(f16_design(READING), READING.magnitudes).P
    assert np.abs(P - PAPER_P_EQ28).max() < 0.01
    # the hard pair is (2, 5), then (5, 6), as the paper says
    assert P[1, 4] == pytest.approx(0.402, abs=0.01) and P[4, 5] == pytest.approx(0.0564, abs=0.01)
    # the unrounded ZOH model moves P(2|5) 0.4085 -> 0.4098 and P(5|6) 0.0470 -> 0.0476 (docs/parity.md):
    # rounding of eq. 23-24 does not explain the remaining gap to the paper
    Pe = incorrect_diagnosis_matrix(f16_design(READING, exact=True), READING.magnitudes).P
    assert Pe[1, 4] == pytest.approx(0.4098, abs=5e-4) and P[1, 4] == pytest.approx(0.4085, abs=5e-4)
    assert Pe[4, 5] == pytest.approx(0.0476, abs=5e-4) and P[4, 5] == pytest.approx(0.0470, abs=5e-4)
    assert np.abs(Pe - PAPER_P_EQ28).max() < 0.01


def test_fault_vectors_fig1_and_fig2_claims():
    """Sec. 4: "residual r_4 contains almost no information" (Fig. 1 caption) and f2, f5 are "almost parallel"
    (after eq. 28). Here: the stacked mu_bar has singular values 118.6, 19.1, 0.32, 0 (fault information is
    three-dimensional) and cos(mu_bar_2, mu_bar_5) = 0.999, |mu_bar_5| = 6.3 (docs/parity.md)."""
    mu = f16_design(READING).mu_bar
    sv = np.linalg.svd(mu, compute_uv=False)
    np.testing.assert_allclose(sv[:3], [118.6, 19.05, 0.318], rtol=2e-3)
    assert sv[3] < 1e-12 * sv[0]
    cos25 = mu[1] @ mu[4] / (np.linalg.norm(mu[1]) * np.linalg.norm(mu[4]))
    assert cos25 == pytest.approx(0.9993, abs=1e-4) and np.linalg.norm(mu[4]) == pytest.approx(6.33, abs=0.01)


def test_state_noise_in_the_simulation_but_not_in_the_design_moves_h_far_from_9_3():
    """docs/parity.md excludes a design/simulation noise mismatch: designed with R only (PAPER_READING) but
    simulated with 1e-4 noise on every state, the 5 % threshold is about 376 instead of the paper's 9.3."""
    design = f16_design(READING)
    w = simulate_f16(f16_reading("all-states", "unit"), None, 20000, np.random.default_rng(54))
    r = design.residual(w.Y, w.U)
    th = threshold_by_simulation(np.einsum("ij,ij->i", r, r), 0.05)
    assert 340 < th.h_low <= th.h <= th.h_high < 410


@pytest.mark.parametrize("process,sizes,min_dev", [
    ("all-states", "unit", 0.3), ("speed-disturbance", "unit", 0.2), ("none", "table", 0.2),
])
def test_other_readings_do_not_give_eq28(process, sizes, min_dev):
    """Process noise of 1e-4 on the states, or Table 1 fault sizes in eq. 14, move eq. 28 far away."""
    rd = f16_reading(process, sizes)
    P = incorrect_diagnosis_matrix(f16_design(rd), rd.magnitudes).P
    assert np.abs(P - PAPER_P_EQ28).max() > min_dev


def test_parity_threshold_and_isolation_reduced_size():
    """Threshold for 0.05 false alarms by simulation near 9.3, isolation probabilities near
    (1, 1, 0.96, 0.05, 0.72, 1). 20 000 windows per case."""
    res = f16_parity_study(READING, 20000, np.random.default_rng(50))
    th = res.threshold
    assert th.h_low <= chi2.ppf(0.95, 4) <= th.h_high  # the calibrated h is the chi2(4) quantile, 9.49
    assert abs(th.h - PAPER_THRESHOLD_PARITY) < 0.45  # paper's 9.3 (2 % below chi2)
    ok = [0, 1, 2, 3, 5]
    assert np.abs(res.p_correct[ok] - PAPER_ISOLATION_PARITY[ok]).max() < 0.1
    # fault 5 follows eq. 14 (our P(5|5) and the paper's 0.5415 agree), not the paper's simulated 0.72
    p55 = res.P_eq14.P[4, 4]
    assert abs(res.p_correct[4] - p55) < 4 * np.sqrt(p55 * (1 - p55) / 20000) + 0.01


@pytest.mark.xfail(strict=True, reason="paper simulates 0.72 for fault 5 but its own eq. 28 gives 0.54; we get 0.55")
def test_fault5_isolation_matches_paper_simulation():
    res = f16_parity_study(READING, 5000, np.random.default_rng(51))
    assert abs(res.p_correct[4] - PAPER_ISOLATION_PARITY[4]) < 0.1


def test_pca_threshold_and_isolation_reduced_size():
    """PCA variant: threshold near 9.7, isolation near (1, 1, 0.96, 0.05, 0.67, 1)."""
    res = f16_pca_study(READING, 20000, 20000, np.random.default_rng(52))
    assert abs(res.threshold.h - PAPER_THRESHOLD_PCA) < 0.45
    assert not res.detectable[3]  # the estimated altitude-fault signature is ~0, as in Fig. 3
    ok = [0, 1, 2, 3, 5]
    assert np.abs(res.p_correct[ok] - PAPER_ISOLATION_PCA[ok]).max() < 0.1
    assert 0.45 < res.p_correct[4] < 0.62  # paper 0.67; parity gives 0.55 here, PCA about the same


def test_bad_reading_names():
    with pytest.raises(DesignError, match="process must be"):
        f16_reading("some", "unit")
    with pytest.raises(DesignError, match="fault_sizes"):
        f16_reading("none", "big")


@pytest.mark.slow
def test_full_size_reproduction():
    """200 000 windows per case (a few seconds)."""
    rng = np.random.default_rng(53)
    res = f16_parity_study(READING, 200_000, rng)
    pca = f16_pca_study(READING, 100_000, 200_000, rng)
    print("\nparity h = %.3f [%.3f, %.3f]" % (res.threshold.h, res.threshold.h_low, res.threshold.h_high))
    print("parity P(correct) =", np.round(res.p_correct, 3), " paper", PAPER_ISOLATION_PARITY)
    print("PCA    h = %.3f [%.3f, %.3f]" % (pca.threshold.h, pca.threshold.h_low, pca.threshold.h_high))
    print("PCA    P(correct) =", np.round(pca.p_correct, 3), " paper", PAPER_ISOLATION_PCA)
    assert res.threshold.h_low <= chi2.ppf(0.95, 4) <= res.threshold.h_high
    ok = [0, 1, 2, 3, 5]
    assert np.abs(res.p_correct[ok] - PAPER_ISOLATION_PARITY[ok]).max() < 0.1
    assert np.abs(pca.p_correct[ok] - PAPER_ISOLATION_PCA[ok]).max() < 0.1
    assert abs(res.p_correct[4] - res.P_eq14.P[4, 4]) < 0.01
