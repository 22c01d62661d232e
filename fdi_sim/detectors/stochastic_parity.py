"""Stochastic parity space: normalized residuals, chi-square detection, angle isolation.

Hagenblad, Gustafsson & Klein (seed 003), sec. 2. For

    x(t+1) = A x + B_u u + B_f f + B_v v,   y = C x + D_u u + D_f f + e,
    Cov(v) = Q, Cov(e) = R                                            (eq. 1)

the parity residual over a window of L = s + 1 samples is ``r = W' (Y - H_u U)`` with
``W' O = 0`` (eq. 5-6). Its fault-free covariance is ``W' S W`` with

    S = H_v (I_L ⊗ Q) H_v' + I_L ⊗ R                                  (eq. 9)

and the normalized residual ``r_bar = (W' S W)^(-1/2) r`` (eq. 10) is N(0, I) without fault
(eq. 12), so ``r_bar' r_bar`` is chi-square with n_r degrees of freedom (eq. 13). A constant
unit fault i moves its mean to ``mu_bar_i = W_bar' H_f F^i`` (eq. 11).

Algorithm 1 (on-line): detect with ``r_bar' r_bar > h``, isolate with the smallest angle to
the ``mu_bar_i``, optionally reject when no angle is small enough.
Algorithm 2 (off-line): the probability of diagnosis i given fault j, eq. 14.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2, norm

from fdi_sim.detectors.parity import (
    AdditiveFaults,
    WindowParityDetector,
    _inverse_sqrt,
    fault_signatures,
    input_toeplitz,
    parity_space,
)
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel

__all__ = [
    "DiagnosisMatrix",
    "Isolation",
    "StochasticParity",
    "ThresholdEstimate",
    "chi2_threshold",
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
        dist = [i for i, k in enumerate(model.input_kinds) if k == "disturbance"]
        Bv = model.B[:, dist]
    Bv = np.asarray(Bv, float).reshape(model.n_states, -1)
    S = np.kron(np.eye(L), R)
    if Bv.shape[1]:
        Q = np.eye(Bv.shape[1]) if Q is None else _check_cov(Q, Bv.shape[1], "process noise covariance Q")
        Hv = input_toeplitz(model.A, Bv, model.C, np.zeros((model.n_outputs, Bv.shape[1])), order_s)
        S = S + Hv @ np.kron(np.eye(L), Q) @ Hv.T  # S = H_v (I ⊗ Q) H_v' + I ⊗ R
    return S


@dataclass(frozen=True, eq=False)
class StochasticParity:
    """A normalized parity space and its fault vectors (Hagenblad et al. eq. 5-11).

    Attributes
    ----------
    order_s : int
        Parity order s; the paper's window is L = s + 1.
    W : NDArray
        Orthonormal parity basis ((s+1) r, n_r), ``W' O = 0``.
    W_bar : NDArray
        Normalized basis ``W (W'SW)^(-1/2)`` (eq. 10); ``W_bar' S W_bar = I``.
    H_u : NDArray
        Toeplitz matrix of the known inputs (eq. 2).
    S : NDArray
        Window noise covariance (eq. 9).
    mu_bar : NDArray
        (n_f, n_r) normalized unit-fault vectors (eq. 11), rows in ``fault_names`` order.
    fault_names : tuple of str
        Hypothesis names.
    detectable : NDArray of bool
        False for a fault whose window image lies in the range of O (zero residual, e.g. a bias
        on a measured integrator: Hagenblad et al. fault 4).
    known_inputs : tuple of int
        Model input columns in ``H_u``.
    """

    order_s: int
    W: NDArray[np.float64]
    W_bar: NDArray[np.float64]
    H_u: NDArray[np.float64]
    S: NDArray[np.float64]
    mu_bar: NDArray[np.float64]
    fault_names: tuple[str, ...]
    detectable: NDArray[np.bool_]
    known_inputs: tuple[int, ...]

    @property
    def n_residuals(self) -> int:
        """Residual dimension n_r (at most ``L n_y - n_x``, eq. 7)."""
        return self.W_bar.shape[1]

    def residual(self, Y: NDArray, U: NDArray) -> NDArray[np.float64]:
        """Normalized residual ``r_bar = W_bar' (Y - H_u U)`` of stacked windows (eq. 10b)."""
        return (np.asarray(Y, float) - np.asarray(U, float) @ self.H_u.T) @ self.W_bar


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
    M = W.T @ S @ W  # Cov(r) = W' S W (eq. 8)
    try:
        Mis = _inverse_sqrt(M, "residual covariance W'SW")
    except DesignError as exc:
        raise DesignError(f"{exc} (rank-deficient noise covariance: check R and Q)") from None
    W_bar = W @ Mis  # W_bar = W (W'SW)^(-1/2)  (eq. 10)
    mu_bar = fault_signatures(model, faults, order_s, W_bar)  # mu_bar_i = W_bar' H_f F^i (eq. 11)
    raw = fault_signatures(model, faults, order_s, np.eye(W.shape[0]))  # H_f F^i itself
    in_parity = np.linalg.norm(fault_signatures(model, faults, order_s, W), axis=1)
    detectable = in_parity > DETECTABILITY_RTOL * np.linalg.norm(raw, axis=1)
    mu_bar = np.where(detectable[:, None], mu_bar, 0.0)
    return StochasticParity(order_s=space.order_s, W=W, W_bar=W_bar, H_u=space.H, S=S, mu_bar=mu_bar,
                            fault_names=faults.names, detectable=detectable, known_inputs=space.known_inputs)


def chi2_threshold(dof: int, p_false_alarm: float) -> float:
    """Threshold h with ``P(chi2(dof) > h) = p_false_alarm`` (Hagenblad et al. eq. 13)."""
    if not 0.0 < p_false_alarm < 1.0:
        raise DesignError(f"p_false_alarm must be in (0, 1), got {p_false_alarm}")
    if dof < 1:
        raise DesignError(f"chi-square test needs at least 1 degree of freedom, got {dof}")
    return float(chi2.isf(p_false_alarm, dof))


@dataclass(frozen=True)
class Isolation:
    """Result of angle isolation of one residual.

    Attributes
    ----------
    index : int or None
        Row of the chosen fault vector, or None (rejected, or no detectable fault).
    angles_rad : NDArray
        Angle to each fault vector [rad] (nan for undetectable faults).
    """

    index: int | None
    angles_rad: NDArray[np.float64]


def isolate_by_angle(
    r_bar: NDArray, mu_bar: NDArray, detectable: NDArray | None = None, reject_angle_rad: float = np.pi
) -> Isolation:
    """Isolation step of Algorithm 1: ``argmin_i angle(r_bar, mu_bar_i)`` with a reject option.

    ``argmin_i || r/|r| - mu_i/|mu_i| ||^2`` equals the smallest angle (Hagenblad et al., Alg. 1).
    """
    mu_bar = np.atleast_2d(np.asarray(mu_bar, float))
    norms = np.linalg.norm(mu_bar, axis=1)
    det = norms > 0 if detectable is None else np.asarray(detectable, bool) & (norms > 0)
    r = np.asarray(r_bar, float)
    nr = float(np.linalg.norm(r))
    if nr == 0 or not det.any():
        return Isolation(index=None, angles_rad=np.full(mu_bar.shape[0], np.nan))
    cos = mu_bar @ r / (np.maximum(norms, 1e-300) * nr)
    ang = np.where(det, np.arccos(np.clip(cos, -1, 1)), np.nan)
    best = int(np.nanargmin(ang))
    return Isolation(index=best if ang[best] <= reject_angle_rad else None, angles_rad=ang)


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
    for j in range(nf):
        if not design.detectable[j]:
            continue
        for i in range(nf):
            if i == j or not design.detectable[i]:
                continue
            s = mu[j] + mu[i]
            ss = float(s @ s)
            if ss == 0.0:  # mu_i = -mu_j: opposite directions are never confused
                continue
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
    Wb = design.W_bar
    p = Wb.shape[1]
    return WindowParityDetector(
        detector_id=detector_id, order_s=design.order_s, proj_y=Wb.T, proj_u=-Wb.T @ design.H_u,
        known_inputs=design.known_inputs, u0=model.u0, y0=model.y0, cov_r=np.eye(p),
        threshold=chi2_threshold(p, p_false_alarm) if threshold is None else threshold,
        signatures=design.mu_bar, hypotheses=design.fault_names, reject_angle_rad=reject_angle_rad,
    )


@dataclass(frozen=True)
class ThresholdEstimate:
    """A threshold calibrated by simulation to a target false-alarm probability.

    Attributes
    ----------
    h : float
        Empirical ``1 - p_false_alarm`` quantile of the fault-free statistic.
    h_low, h_high : float
        Distribution-free 95 % confidence interval of that quantile (order statistics with
        binomial ranks; valid for independent samples).
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

    The confidence interval uses ranks ``binom.ppf((1 -/+ confidence) / 2, n, 1 - p_false_alarm)``
    of the sorted sample, which holds for any continuous distribution.
    """
    from scipy.stats import binom

    x = np.sort(np.asarray(statistics, float).ravel())
    n = x.size
    if not 0.0 < p_false_alarm < 1.0:
        raise DesignError(f"p_false_alarm must be in (0, 1), got {p_false_alarm}")
    if n * min(p_false_alarm, 1 - p_false_alarm) < 5:
        raise DesignError(f"{n} samples are too few to estimate a {p_false_alarm} tail; use at least {int(np.ceil(5 / p_false_alarm))}")
    q = 1.0 - p_false_alarm
    h = float(np.quantile(x, q))
    lo = int(binom.ppf((1 - confidence) / 2, n, q))
    hi = int(binom.ppf((1 + confidence) / 2, n, q))
    return ThresholdEstimate(h=h, h_low=float(x[max(lo - 1, 0)]), h_high=float(x[min(hi, n - 1)]),
                             n_samples=n, p_false_alarm=p_false_alarm)


def isolation_rates(
    r_bar: NDArray, mu_bar: NDArray, detectable: NDArray, threshold: float, reject_angle_rad: float = np.pi
) -> NDArray[np.float64]:
    """Fraction of residuals (rows of ``r_bar``) that alarm and are isolated to each hypothesis.

    Returns (n_f + 1,) fractions: one per hypothesis, then "alarm without isolation" (rejected).
    Vectorized form of the detection and isolation steps of Algorithm 1.
    """
    r = np.atleast_2d(np.asarray(r_bar, float))
    mu = np.atleast_2d(np.asarray(mu_bar, float))
    det = np.asarray(detectable, bool) & (np.linalg.norm(mu, axis=1) > 0)
    alarm = np.einsum("ij,ij->i", r, r) > threshold
    out = np.zeros(mu.shape[0] + 1)
    if not det.any():
        out[-1] = alarm.mean()
        return out
    dirs = mu[det] / np.linalg.norm(mu[det], axis=1)[:, None]
    cos = (r @ dirs.T) / np.maximum(np.linalg.norm(r, axis=1), 1e-300)[:, None]
    best = cos.argmax(axis=1)
    accepted = np.arccos(np.clip(cos[np.arange(len(r)), best], -1, 1)) <= reject_angle_rad
    idx = np.flatnonzero(det)[best]
    for k in range(mu.shape[0]):
        out[k] = np.mean(alarm & accepted & (idx == k))
    out[-1] = np.mean(alarm & ~accepted)
    return out
