"""Stochastic parity space: normalized residuals, chi-square detection, angle isolation.

Hagenblad, Gustafsson & Klein (seed 003), sec. 2. For

    x(t+1) = A x + B_u u + B_f f + B_v v,   y = C x + D_u u + D_f f + e,
    Cov(v) = Q, Cov(e) = R                                            (eq. 1)

the parity residual over a window of L = s + 1 samples is ``r = W' (Y - H_u U)`` with
``W' O = 0`` (eq. 5-6). Its fault-free covariance is ``W' S W`` with

    S = H_v (I_L ⊗ Q) H_v' + I_L ⊗ R                                  (eq. 9)

and the normalized residual ``r_bar = (W' S W)^(-1/2) r`` (eq. 10) is N(0, I) without fault
(eq. 12), so ``r_bar' r_bar`` is chi-square with n_r degrees of freedom (eq. 13; the threshold is
:func:`fdi_sim.decision.chi2.chi2_threshold`). A constant unit fault i moves its mean to
``mu_bar_i = W_bar' H_f F^i`` (eq. 11).

Algorithm 1 (on-line): detect with ``r_bar' r_bar > h``, isolate with the smallest angle to
the ``mu_bar_i``, optionally reject when no angle is small enough.
Algorithm 2 (off-line): the probability of diagnosis i given fault j, eq. 14.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.stats import norm, quantile_test

from fdi_sim.detectors.parity import (
    AdditiveFaults,
    ParitySpace,
    fault_signatures,
    input_columns,
    input_toeplitz,
    parity_detector,
    parity_space,
)
from fdi_sim.detectors.window_detector import (
    WindowParityDetector,
    _inverse_sqrt,
    best_hypothesis,
    residual_angles_rad,
    unit_directions,
)
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel

__all__ = [
    "DiagnosisMatrix",
    "Isolation",
    "StochasticParity",
    "ThresholdEstimate",
    "incorrect_diagnosis_matrix",
    "isolate_by_angle",
    "isolation_rates",
    "make_stochastic_parity_detector",
    "noise_window_covariance",
    "stochastic_parity",
    "threshold_by_simulation",
]

#: a fault whose parity-space image is below this fraction of its raw window image is undetectable
DETECTABILITY_RTOL: float = 1e-9


def _check_cov(M: NDArray, size: int, what: str) -> NDArray[np.float64]:
    M = np.atleast_2d(np.asarray(M, float))
    if M.shape != (size, size):
        raise DesignError(f"{what} must be ({size}, {size}), got {M.shape}")
    if not np.allclose(M, M.T, atol=1e-14 * max(np.abs(M).max(), 1.0)):
        raise DesignError(f"{what} must be symmetric")
    if np.linalg.eigvalsh((M + M.T) / 2)[0] < -1e-12 * max(np.abs(M).max(), 1e-300):
        raise DesignError(f"{what} must be positive semidefinite (it is a covariance)")
    return (M + M.T) / 2


def noise_window_covariance(
    model: LinearModel, order_s: int, R: NDArray, Bv: NDArray | None = None, Q: NDArray | None = None
) -> NDArray[np.float64]:
    """Window noise covariance ``S = H_v (I_L ⊗ Q) H_v' + I_L ⊗ R`` (Hagenblad et al. eq. 9).

    Parameters
    ----------
    model : LinearModel
        Discrete model (A, C used).
    order_s : int
        Parity order s (L = s + 1).
    R : NDArray
        Measurement-noise covariance (r, r) [output units squared].
    Bv : NDArray, optional
        (n, n_v) process-noise entry; default the model's disturbance input columns.
    Q : NDArray, optional
        Process-noise covariance (n_v, n_v); default identity (unit-covariance disturbances).
    """
    L = order_s + 1
    R = _check_cov(R, model.n_outputs, "measurement noise covariance R")
    if Bv is None:
        Bv = model.B[:, input_columns(model, "disturbance")]
    Bv = np.asarray(Bv, float).reshape(model.n_states, -1)
    S = np.kron(np.eye(L), R)
    if Bv.shape[1]:
        Q = np.eye(Bv.shape[1]) if Q is None else _check_cov(Q, Bv.shape[1], "process noise covariance Q")
        Hv = input_toeplitz(model.A, Bv, model.C, np.zeros((model.n_outputs, Bv.shape[1])), order_s)
        S = S + Hv @ np.kron(np.eye(L), Q) @ Hv.T  # S = H_v (I ⊗ Q) H_v' + I ⊗ R
    return S


@dataclass(frozen=True, eq=False)
class StochasticParity:
    """A parity space normalized by its window noise, and the fault vectors in it (Hagenblad et al. eq. 5-11).

    Attributes
    ----------
    space : ParitySpace
        The parity space of order s with known inputs: ``W`` (``W' O = 0``), ``H_u``, ``order_s``
        (the paper's window is L = s + 1), ``known_inputs``.
    S : NDArray
        Window noise covariance (eq. 9).
    W_bar : NDArray
        Normalized basis ``W (W'SW)^(-1/2)`` (eq. 10); ``W_bar' S W_bar = I``.
    mu_bar : NDArray
        (n_f, n_r) normalized unit-fault vectors (eq. 11), rows in ``fault_names`` order.
    fault_names : tuple of str
        Hypothesis names.
    detectable : NDArray of bool
        False for a fault whose window image lies in the range of O (zero residual, e.g. a bias
        on a measured integrator: Hagenblad et al. fault 4).
    """

    space: ParitySpace
    S: NDArray[np.float64]
    W_bar: NDArray[np.float64]
    mu_bar: NDArray[np.float64]
    fault_names: tuple[str, ...]
    detectable: NDArray[np.bool_]

    @property
    def order_s(self) -> int:
        return self.space.order_s

    @property
    def W(self) -> NDArray[np.float64]:
        """Orthonormal parity basis ((s+1) r, n_r)."""
        return self.space.W

    @property
    def H_u(self) -> NDArray[np.float64]:
        """Toeplitz matrix of the known inputs (eq. 2)."""
        return self.space.H

    @property
    def known_inputs(self) -> tuple[int, ...]:
        return self.space.known_inputs

    @property
    def n_residuals(self) -> int:
        """Residual dimension n_r (at most ``L n_y - n_x``, eq. 7)."""
        return self.W_bar.shape[1]

    def residual(self, Y: NDArray, U: NDArray) -> NDArray[np.float64]:
        """Normalized residual ``r_bar = W_bar' (Y - H_u U)`` of stacked windows (eq. 10b)."""
        return self.space.input_adjusted(Y, U) @ self.W_bar


def stochastic_parity(
    model: LinearModel,
    order_s: int,
    faults: AdditiveFaults,
    R: NDArray,
    Bv: NDArray | None = None,
    Q: NDArray | None = None,
    known_inputs: Sequence[int] | None = None,
) -> StochasticParity:
    """Design the normalized parity space and the normalized fault vectors (eq. 5-11).

    Parameters
    ----------
    model : LinearModel
        Discrete model; its control columns are the known inputs ``u``.
    order_s : int
        Parity order s (window L = s + 1).
    faults : AdditiveFaults
        ``B_f``, ``D_f`` and names of the faults (eq. 1).
    R, Bv, Q
        Noise model, see :func:`noise_window_covariance`.
    known_inputs : sequence of int, optional
        Input columns measured by the detector (default: the control columns).

    Raises
    ------
    DesignError
        Order too short, a covariance that is not symmetric PSD, or ``W' S W`` singular (a parity
        direction without any noise: give every output some measurement noise).
    """
    space = parity_space(model, order_s, known_inputs)
    S = noise_window_covariance(model, order_s, R, Bv, Q)
    W = space.W
    try:
        Mis = _inverse_sqrt(W.T @ S @ W, "residual covariance W'SW")  # Cov(r) = W' S W (eq. 8)
    except DesignError as exc:
        raise DesignError(f"{exc} (rank-deficient noise covariance: check R and Q)") from None
    W_bar = W @ Mis  # W_bar = W (W'SW)^(-1/2)  (eq. 10)
    mu_bar = fault_signatures(model, faults, order_s, W_bar)  # mu_bar_i = W_bar' H_f F^i (eq. 11)
    raw = fault_signatures(model, faults, order_s, np.eye(W.shape[0]))  # H_f F^i itself
    in_parity = np.linalg.norm(fault_signatures(model, faults, order_s, W), axis=1)
    detectable = in_parity > DETECTABILITY_RTOL * np.linalg.norm(raw, axis=1)
    mu_bar = np.where(detectable[:, None], mu_bar, 0.0)
    return StochasticParity(space=space, S=S, W_bar=W_bar, mu_bar=mu_bar, fault_names=faults.names,
                            detectable=detectable)


@dataclass(frozen=True)
class Isolation:
    """Result of angle isolation of one residual.

    Attributes
    ----------
    index : int or None
        Row of the chosen fault vector, or None (rejected, zero residual, or no detectable fault).
    angles_rad : NDArray
        Angle to each fault vector [rad] (nan for undetectable faults and for a zero residual).
    """

    index: int | None
    angles_rad: NDArray[np.float64]


def isolate_by_angle(
    r_bar: NDArray, mu_bar: NDArray, detectable: NDArray | None = None, reject_angle_rad: float = np.pi
) -> Isolation:
    """Isolation step of Algorithm 1: ``argmin_i angle(r_bar, mu_bar_i)`` with a reject option.

    ``argmin_i || r/|r| - mu_i/|mu_i| ||^2`` equals the smallest angle (Hagenblad et al., Alg. 1).
    The same rule as the running detector (:func:`~fdi_sim.detectors.window_detector.best_hypothesis`).
    """
    ang = residual_angles_rad(r_bar, unit_directions(mu_bar, detectable))
    best = int(best_hypothesis(ang, reject_angle_rad))
    return Isolation(index=best if best >= 0 else None, angles_rad=ang)


@dataclass(frozen=True, eq=False)
class DiagnosisMatrix:
    """Probability of diagnosis i given fault j (Hagenblad et al. Algorithm 2, eq. 14).

    Attributes
    ----------
    P : NDArray
        (n_f, n_f); ``P[i, j] = prob(diagnosis i | fault m_j f^j)``. Off-diagonal entries are
        eq. 14; the diagonal is one minus the rest of its column (as in the paper's eq. 28),
        clipped at 0 where the pairwise approximation over-counts (many confusable faults).
        Rows and columns of undetectable faults are zero.
    magnitudes : NDArray
        Fault magnitudes m_j used.
    fault_names : tuple of str
    detectable : NDArray of bool
    """

    P: NDArray[np.float64]
    magnitudes: NDArray[np.float64]
    fault_names: tuple[str, ...]
    detectable: NDArray[np.bool_]


def incorrect_diagnosis_matrix(
    design: StochasticParity, magnitudes: float | Sequence[float] = 1.0
) -> DiagnosisMatrix:
    """Algorithm 2: ``P(i|j) = Q(m_j || mu_j - <mu_j, mu_j+mu_i>/<mu_j+mu_i, mu_j+mu_i> (mu_j+mu_i) ||)``.

    The paper writes ``1/2 erfc(x)`` with its own erfc, ``erfc(x) = 2 ∫_x^∞ N(0,1) pdf``, so
    ``1/2 erfc(x)`` is the Gaussian tail ``Q(x) = norm.sf(x)`` (eq. 14). Approximate for more
    than two faults. An undetectable fault has a zero row and column ("can be considered zero").
    """
    mu = design.mu_bar
    nf = mu.shape[0]
    m = np.broadcast_to(np.asarray(magnitudes, float), (nf,)).copy()
    P = np.zeros((nf, nf))
    det = np.flatnonzero(design.detectable)
    for j in det:
        for i in det[det != j]:
            s = mu[j] + mu[i]
            ss = float(s @ s)
            if ss > 0.0:  # (mu_i = -mu_j: opposite directions are never confused)
                d = mu[j] - (mu[j] @ s) / ss * s  # component of mu_j orthogonal to mu_j + mu_i
                P[i, j] = norm.sf(m[j] * np.linalg.norm(d))
        P[j, j] = max(0.0, 1.0 - P[:, j].sum())  # clipped when the pairwise terms over-count
    return DiagnosisMatrix(P=P, magnitudes=m, fault_names=design.fault_names, detectable=design.detectable.copy())


def make_stochastic_parity_detector(
    model: LinearModel,
    design: StochasticParity,
    threshold: float | None = None,
    p_false_alarm: float = 0.05,
    reject_angle_rad: float = np.pi,
    detector_id: str = "parity-stochastic-v1",
) -> WindowParityDetector:
    """Algorithm 1 as a running detector: ``r_bar = W_bar'(Y - H_u U)``, ``r_bar'r_bar > h``, angle isolation.

    The residual is already white (eq. 12), so the chi-square threshold for ``p_false_alarm``
    is the default ``h``; pass ``threshold`` to use one calibrated by simulation.
    """
    return parity_detector(
        detector_id, model, design.space, W=design.W_bar, cov_r=np.eye(design.n_residuals), threshold=threshold,
        p_false_alarm=p_false_alarm, signatures=design.mu_bar, hypotheses=design.fault_names,
        reject_angle_rad=reject_angle_rad,
    )


@dataclass(frozen=True)
class ThresholdEstimate:
    """A threshold calibrated by simulation to a target false-alarm probability.

    Attributes
    ----------
    h : float
        Empirical ``1 - p_false_alarm`` quantile of the fault-free statistic.
    h_low, h_high : float
        Distribution-free confidence interval of that quantile (order statistics with binomial
        ranks; valid for independent samples).
    n_samples : int
    p_false_alarm : float
    """

    h: float
    h_low: float
    h_high: float
    n_samples: int
    p_false_alarm: float


def threshold_by_simulation(statistics: NDArray, p_false_alarm: float, confidence: float = 0.95) -> ThresholdEstimate:
    """Empirical threshold h with ``P(stat > h) = p_false_alarm`` from independent fault-free samples.

    The interval is scipy's distribution-free one for a quantile (``quantile_test``: order
    statistics at binomial ranks), which holds for any continuous distribution.
    """
    x = np.asarray(statistics, float).ravel()
    n = x.size
    if not 0.0 < p_false_alarm < 1.0:
        raise DesignError(f"p_false_alarm must be in (0, 1), got {p_false_alarm}")
    if n * min(p_false_alarm, 1 - p_false_alarm) < 5:
        raise DesignError(f"{n} samples are too few to estimate a {p_false_alarm} tail; use at least {int(np.ceil(5 / p_false_alarm))}")
    q = 1.0 - p_false_alarm
    ci = quantile_test(x, p=q).confidence_interval(confidence)
    return ThresholdEstimate(h=float(np.quantile(x, q)), h_low=float(ci.low), h_high=float(ci.high),
                             n_samples=n, p_false_alarm=p_false_alarm)


def isolation_rates(
    r_bar: NDArray, mu_bar: NDArray, detectable: NDArray, threshold: float, reject_angle_rad: float = np.pi
) -> NDArray[np.float64]:
    """Fraction of residuals (rows of ``r_bar``) that alarm and are isolated to each hypothesis.

    Returns (n_f + 1,) fractions: one per hypothesis, then "alarm without isolation" (rejected).
    Vectorized form of the detection and isolation steps of Algorithm 1, with the detector's
    own rule (:func:`~fdi_sim.detectors.window_detector.best_hypothesis`).
    """
    r = np.atleast_2d(np.asarray(r_bar, float))
    dirs = unit_directions(mu_bar, detectable)
    alarm = np.einsum("ij,ij->i", r, r) > threshold
    n_h = dirs.shape[0]
    best = best_hypothesis(residual_angles_rad(r, dirs), reject_angle_rad)
    label = np.where(best >= 0, best, n_h)  # n_h = alarm without isolation
    return np.bincount(label[alarm], minlength=n_h + 1) / r.shape[0]
