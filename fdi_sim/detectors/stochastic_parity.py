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

The last section evaluates residual generators statistically under model mismatch: the
false-alarm rate of nominal-model against robust parity relations (Lou et al. 1986) at equal
detection of one fault, with exact Gaussian residual moments.
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
    observability_matrix,
    parity_space,
)
from fdi_sim.detectors.robust_parity import _check_same_size, design_block, robust_parity
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel

__all__ = [
    "DiagnosisMatrix",
    "NominalVsRobust",
    "RelationSetResult",
    "Isolation",
    "StochasticParity",
    "ThresholdEstimate",
    "chi2_threshold",
    "compare_nominal_vs_robust",
    "incorrect_diagnosis_matrix",
    "isolate_by_angle",
    "isolation_rates",
    "make_stochastic_parity_detector",
    "noise_window_covariance",
    "residual_moments",
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


def residual_moments(
    P: NDArray, model: LinearModel, order_s: int, faults: AdditiveFaults | None = None,
    fault: NDArray | None = None, **noise,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Exact mean and covariance of ``r = P' [Y; U]`` when ``model`` generates the data.

    Covariance ``P' R_q R_q' P`` with :func:`design_block` at the stationary state (eq. 26, 32:
    ``J = E||r||^2`` is its trace). A persistent constant fault ``f`` (vector over the columns
    of ``faults``) shifts the state to ``x_f = (I - A)^-1 B_f f`` and the window mean to
    ``O x_f + H_f (1 ⊗ f)``; the measured inputs do not contain it. ``noise`` takes
    ``input_sqrt``, ``disturbance_sqrt``, ``measurement_sqrt``.
    """
    P = np.asarray(P, float)
    Rq = design_block(model, order_s, "stationary", "known", **noise)
    ny = (order_s + 1) * model.n_outputs
    if Rq.shape[0] != P.shape[0]:
        raise DesignError(f"relations have {P.shape[0]} rows but the window of this model has {Rq.shape[0]}")
    cov = P.T @ Rq @ Rq.T @ P
    mean = np.zeros(P.shape[1])
    if faults is not None and fault is not None:
        f = np.asarray(fault, float).ravel()
        xf = np.linalg.solve(np.eye(model.n_states) - model.A, faults.Bf @ f)  # x_f = (I - A)^-1 B_f f
        Hf = input_toeplitz(model.A, faults.Bf, model.C, faults.Df, order_s)
        mean = P[:ny].T @ (observability_matrix(model.A, model.C, order_s) @ xf + Hf @ np.tile(f, order_s + 1))
    return mean, cov


@dataclass(frozen=True, eq=False)
class RelationSetResult:
    """Performance of one relation set in :func:`compare_nominal_vs_robust`.

    Attributes
    ----------
    name : str
        "nominal" or "robust".
    n_relations : int
    threshold : float
        On ``t = r' Sigma_0^-1 r`` (Sigma_0: fault-free covariance on the nominal model).
    detection : float
        Detection probability of the fault on the detection model at that threshold.
    false_alarm : NDArray
        Fault-free false-alarm probability per sample on each evaluated model.
    false_alarm_ci : NDArray
        (n_models, 2) Clopper-Pearson 95 % intervals of ``false_alarm``.
    """

    name: str
    n_relations: int
    threshold: float
    detection: float
    false_alarm: NDArray[np.float64]
    false_alarm_ci: NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class NominalVsRobust:
    """Nominal-model parity relations against robust ones at equal detection of one fault."""

    nominal: RelationSetResult
    robust: RelationSetResult
    model_labels: tuple[str, ...]
    detection_target: float
    fault_name: str
    n_samples: int


def compare_nominal_vs_robust(
    nominal: LinearModel,
    perturbed: Sequence[LinearModel],
    order_s: int,
    faults: AdditiveFaults,
    fault: int,
    fault_size: float,
    rng: np.random.Generator,
    detection: float = 0.9,
    n_relations: int | None = None,
    weights: Sequence[float] | None = None,
    n_samples: int = 100_000,
    labels: Sequence[str] | None = None,
    detect_on: int = 0,
    scale_by_noise: bool = True,
    **noise,
) -> NominalVsRobust:
    """False-alarm rates of nominal and robust relations when both detect one fault equally well.

    Nominal relations: the exact parity space of ``nominal`` with known inputs,
    ``[W; -H'W]`` (eq. 4). Robust relations: :func:`robust_parity` over ``[nominal, *perturbed]``
    with stationary state scaling and the same noise (eq. 35, 41), ``n_relations`` of them
    (default: as many as the nominal set). Each set is tested with ``t = r' Sigma_0^-1 r``; its
    threshold is set so the fault of size ``fault_size`` is detected with probability
    ``detection`` on model ``detect_on`` (0 = nominal, k = perturbed[k-1]); then the fault-free
    false-alarm probability is measured on every model. Residuals are Gaussian with the exact
    moments of :func:`residual_moments`, sampled ``n_samples`` times per case. With
    ``scale_by_noise`` the robust SVD works in units of the sensor-noise and input standard
    deviations (``output_scale``/``input_scale`` of :func:`robust_parity`).
    """
    from scipy.stats import beta

    models = [nominal, *perturbed]
    _check_same_size(models)
    labels = tuple(labels) if labels is not None else ("nominal",) + tuple(f"perturbed[{k}]" for k in range(len(perturbed)))
    if len(labels) != len(models):
        raise DesignError(f"{len(labels)} labels for {len(models)} models")
    if not 0.0 < detection < 1.0:
        raise DesignError(f"detection must be in (0, 1), got {detection}")
    if not 0 <= int(fault) < faults.n_faults:
        raise DesignError(f"fault index {fault} outside 0..{faults.n_faults - 1} ({', '.join(faults.names)})")
    space = parity_space(nominal, order_s)
    P_nom = np.vstack([space.W, -space.H.T @ space.W])  # r = W'(Y - H U) = [W; -H'W]' [Y; U]
    p = space.n_relations if n_relations is None else int(n_relations)
    scales = {}
    if scale_by_noise:
        for key, arg in (("output_scale", "measurement_sqrt"), ("input_scale", "input_sqrt")):
            if noise.get(arg) is not None:
                M = np.atleast_2d(np.asarray(noise[arg], float))
                scales[key] = np.sqrt(np.diag(M @ M.T))
    rob = robust_parity(models, order_s, p, weights, "stationary", "known", **noise, **scales)
    f = np.zeros(faults.n_faults)
    f[fault] = fault_size
    results = []
    for name, P in (("nominal", P_nom), ("robust", rob.P)):
        _, cov0 = residual_moments(P, nominal, order_s, **noise)
        Wh = _inverse_sqrt(cov0, f"{name} fault-free residual covariance")
        mf, covf = residual_moments(P, models[detect_on], order_s, faults, f, **noise)
        z = rng.standard_normal((n_samples, P.shape[1]))
        tf = np.sum(((mf + z @ _psd_sqrt(covf).T) @ Wh) ** 2, axis=1)
        h = float(np.quantile(tf, 1.0 - detection))
        far, ci = [], []
        for m in models:
            _, cq = residual_moments(P, m, order_s, **noise)
            z = rng.standard_normal((n_samples, P.shape[1]))
            k = int(np.sum(np.sum((z @ _psd_sqrt(cq).T @ Wh) ** 2, axis=1) > h))
            far.append(k / n_samples)
            ci.append((beta.ppf(0.025, k, n_samples - k + 1) if k else 0.0,
                       beta.ppf(0.975, k + 1, n_samples - k) if k < n_samples else 1.0))
        results.append(RelationSetResult(name=name, n_relations=P.shape[1], threshold=h,
                                         detection=float(np.mean(tf > h)), false_alarm=np.array(far),
                                         false_alarm_ci=np.array(ci)))
    return NominalVsRobust(nominal=results[0], robust=results[1], model_labels=labels, detection_target=detection,
                           fault_name=faults.names[fault], n_samples=n_samples)


def _psd_sqrt(M: NDArray) -> NDArray[np.float64]:
    """A square root ``G`` with ``G G' = M`` of a symmetric positive semidefinite matrix (eigh)."""
    ev, V = np.linalg.eigh((M + M.T) / 2)
    return V * np.sqrt(np.clip(ev, 0.0, None))
