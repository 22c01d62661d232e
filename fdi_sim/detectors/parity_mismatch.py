"""Parity relations under model mismatch: exact residual moments, nominal against robust relations.

Evaluates residual generators statistically when the flown model differs from the design
model: the exact Gaussian moments of any relation set ``r = P' [Y; U]`` on any model
(:func:`residual_moments`, via the window second moment ``R_q R_q'`` of Lou, Willsky & Verghese
1986, eq. 26-41), and the false-alarm rate of nominal-model parity relations against robust ones
(Lou et al. sec. 3-4) when both detect one fault equally well (:func:`compare_nominal_vs_robust`).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.stats import binomtest

from fdi_sim.detectors.parity import AdditiveFaults, input_toeplitz, observability_matrix, parity_space
from fdi_sim.detectors.robust_parity import check_same_size, design_block, robust_parity
from fdi_sim.detectors.window_detector import _inverse_sqrt, _psd_sqrt
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel

__all__ = [
    "NominalVsRobust",
    "RelationSetResult",
    "ResidualMoments",
    "compare_nominal_vs_robust",
    "residual_moments",
]


@dataclass(frozen=True, eq=False)
class ResidualMoments:
    """Mean and covariance of a relation set's residual ``r = P' [Y; U]`` on one model.

    Attributes
    ----------
    mean : NDArray
        (p,) ``E r`` [relation units].
    cov : NDArray
        (p, p) ``Cov r``.
    """

    mean: NDArray[np.float64]
    cov: NDArray[np.float64]


def residual_moments(
    P: NDArray, model: LinearModel, order_s: int, faults: AdditiveFaults | None = None,
    fault: NDArray | None = None, **noise: NDArray | None,
) -> ResidualMoments:
    """Exact mean and covariance of ``r = P' [Y; U]`` when ``model`` generates the data.

    Covariance ``P' R_q R_q' P`` with :func:`~fdi_sim.detectors.robust_parity.design_block` at
    the stationary state (eq. 26, 32: ``J = E||r||^2`` is its trace). A persistent constant fault
    ``f`` (vector over the columns of ``faults``) shifts the state to ``x_f = (I - A)^-1 B_f f``
    and the window mean to ``O x_f + H_f (1 ⊗ f)``; the measured inputs do not contain it.
    ``noise`` takes ``input_sqrt``, ``disturbance_sqrt``, ``measurement_sqrt``.
    """
    P = np.asarray(P, float)
    Rq = design_block(model, order_s, "stationary", "known", **noise)
    if Rq.shape[0] != P.shape[0]:
        raise DesignError(f"relations have {P.shape[0]} rows but the window of this model has {Rq.shape[0]}")
    cov = P.T @ Rq @ Rq.T @ P
    mean = np.zeros(P.shape[1])
    if faults is not None and fault is not None:
        f = np.asarray(fault, float).ravel()
        xf = np.linalg.solve(np.eye(model.n_states) - model.A, faults.Bf @ f)  # x_f = (I - A)^-1 B_f f
        Hf = input_toeplitz(model.A, faults.Bf, model.C, faults.Df, order_s)
        ny = (order_s + 1) * model.n_outputs
        mean = P[:ny].T @ (observability_matrix(model.A, model.C, order_s) @ xf + Hf @ np.tile(f, order_s + 1))
    return ResidualMoments(mean=mean, cov=cov)


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
    **noise: NDArray | None,
) -> NominalVsRobust:
    """False-alarm rates of nominal and robust relations when both detect one fault equally well.

    Nominal relations: the exact parity space of ``nominal`` with known inputs,
    ``[W; -H'W]`` (eq. 4). Robust relations: :func:`~fdi_sim.detectors.robust_parity.robust_parity`
    over ``[nominal, *perturbed]`` with stationary state scaling and the same noise (eq. 35, 41),
    ``n_relations`` of them (default: as many as the nominal set). Each set is tested with
    ``t = r' Sigma_0^-1 r``; its threshold is set so the fault of size ``fault_size`` [units of the
    fault column] is detected with probability ``detection`` on model ``detect_on`` (0 = nominal,
    k = perturbed[k-1]); then the fault-free false-alarm probability is measured on every model.
    Residuals are Gaussian with the exact moments of :func:`residual_moments`, sampled
    ``n_samples`` times per case. With ``scale_by_noise`` the robust SVD works in units of the
    sensor-noise and input standard deviations (``output_scale``/``input_scale`` of
    :func:`~fdi_sim.detectors.robust_parity.robust_parity`).
    """
    models = [nominal, *perturbed]
    check_same_size(models)
    labels = tuple(labels) if labels is not None else ("nominal",) + tuple(f"perturbed[{k}]" for k in range(len(perturbed)))
    if len(labels) != len(models):
        raise DesignError(f"{len(labels)} labels for {len(models)} models")
    if not 0.0 < detection < 1.0:
        raise DesignError(f"detection must be in (0, 1), got {detection}")
    if not 0 <= int(fault) < faults.n_faults:
        raise DesignError(f"fault index {fault} outside 0..{faults.n_faults - 1} ({', '.join(faults.names)})")
    space = parity_space(nominal, order_s)
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
    nominal_result, robust_result = [  # in this order: both draw from rng
        _equal_detection(name, P, models, order_s, faults, f, detect_on, detection, n_samples, rng, noise)
        for name, P in (("nominal", space.relations()), ("robust", rob.P))  # r = W'(Y - H U) = [W; -H'W]'[Y; U]
    ]
    return NominalVsRobust(nominal=nominal_result, robust=robust_result, model_labels=labels,
                           detection_target=detection, fault_name=faults.names[fault], n_samples=n_samples)


def _equal_detection(
    name: str, P: NDArray, models: list[LinearModel], order_s: int, faults: AdditiveFaults, f: NDArray,
    detect_on: int, detection: float, n_samples: int, rng: np.random.Generator, noise: dict,
) -> RelationSetResult:
    """One relation set: threshold for ``detection`` of ``f`` on ``models[detect_on]``, then FA per model."""
    Wh = _inverse_sqrt(residual_moments(P, models[0], order_s, **noise).cov, f"{name} fault-free residual covariance")
    faulty = residual_moments(P, models[detect_on], order_s, faults, f, **noise)
    z = rng.standard_normal((n_samples, P.shape[1]))
    t_fault = np.sum(((faulty.mean + z @ _psd_sqrt(faulty.cov).T) @ Wh) ** 2, axis=1)  # t = r' Sigma_0^-1 r
    h = float(np.quantile(t_fault, 1.0 - detection))
    far, ci = [], []
    for m in models:
        G = _psd_sqrt(residual_moments(P, m, order_s, **noise).cov)
        z = rng.standard_normal((n_samples, P.shape[1]))
        k = int(np.sum(np.sum((z @ G.T @ Wh) ** 2, axis=1) > h))
        far.append(k / n_samples)
        interval = binomtest(k, n_samples).proportion_ci(0.95, method="exact")  # Clopper-Pearson
        ci.append((interval.low, interval.high))
    return RelationSetResult(name=name, n_relations=P.shape[1], threshold=h, detection=float(np.mean(t_fault > h)),
                             false_alarm=np.array(far), false_alarm_ci=np.array(ci))
