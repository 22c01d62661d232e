"""Registered parity-family detectors: parity, robust parity, stochastic parity, PCA.

Each factory takes ``(model: LinearModel, **params)`` and returns a detector with the common
``reset(rng)`` / ``step(t_s, u, y) -> Residual`` contract (:class:`WindowParityDetector`).
"""
from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.detectors.parity import AdditiveFaults, fault_signatures, minimum_order, parity_detector, parity_space
from fdi_sim.detectors.pca import estimate_fault_signatures, make_pca_detector, pca_train, series_windows
from fdi_sim.detectors.robust_parity import make_robust_parity_detector, robust_parity
from fdi_sim.detectors.stochastic_parity import (
    make_stochastic_parity_detector,
    noise_window_covariance,
    stochastic_parity,
)
from fdi_sim.detectors.window_detector import WindowParityDetector
from fdi_sim.detectors.noise import gust_sqrt, suite_sensor_std
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel
from fdi_sim.registry import register

__all__ = ["make_parity", "make_pca", "make_robust_parity", "make_stochastic_parity"]


def _faults(model: LinearModel, actuators: Sequence[str], sensors: Sequence[str]) -> AdditiveFaults | None:
    return AdditiveFaults.from_model(model, actuators, sensors) if (actuators or sensors) else None


def _order(model: LinearModel, order_s: int | None) -> int:
    """The given parity order, or the model's minimum order."""
    return minimum_order(model.A, model.C) if order_s is None else int(order_s)


def make_parity(
    model: LinearModel,
    order_s: int | None = None,
    R: NDArray | None = None,
    threshold: float | None = None,
    p_false_alarm: float = 0.05,
    actuators: Sequence[str] = (),
    sensors: Sequence[str] = (),
    reject_angle_rad: float = np.pi,
) -> WindowParityDetector:
    """Parity checks ``r = W'(Y - H U)`` of the model's exact parity space (Lou et al. 1986, eq. 3-8).

    ``order_s`` defaults to the minimum order. With a measurement-noise covariance ``R`` the
    statistic is ``r'(W'SW)^-1 r`` (chi-square threshold for ``p_false_alarm``); without it give
    ``threshold`` on ``r'r``. Named actuators/sensors give isolation by angle.
    """
    s = _order(model, order_s)
    space = parity_space(model, s)
    if R is None and threshold is None:  # the aircraft's sensor suite (fdi_sim.detectors.noise)
        std = suite_sensor_std(model)
        R = None if std is None else np.diag(std ** 2)
    cov = None if R is None else space.W.T @ noise_window_covariance(model, s, R) @ space.W  # W'SW
    faults = _faults(model, actuators, sensors)
    return parity_detector(
        "parity-v1", model, space, cov_r=cov, threshold=threshold, p_false_alarm=p_false_alarm,
        signatures=fault_signatures(model, faults, s, space.W) if faults else None,
        hypotheses=faults.names if faults else (), reject_angle_rad=reject_angle_rad,
    )


def make_robust_parity(
    model: LinearModel,
    perturbed: Sequence[LinearModel] = (),
    order_s: int | None = None,
    n_relations: int | None = None,
    weights: Sequence[float] | None = None,
    threshold: float | None = None,
    p_false_alarm: float = 0.05,
    turbulence: str = "moderate",
    **design: Any,
) -> WindowParityDetector:
    """The p most robust relations over ``[model, *perturbed]`` (Lou et al. 1986, sec. 3-4.2).

    ``design`` passes ``state_sqrt``, ``inputs``, ``input_sqrt``, ``disturbance_sqrt``,
    ``measurement_sqrt``, ``output_scale``, ``input_scale`` to :func:`robust_parity`. The statistic
    is whitened by the design's average residual covariance. Defaults from the aircraft
    (``fdi_sim.detectors.noise``): the measurement noise of its sensor suite, and the gust columns
    sized by JSBSim's Dryden intensities at the model's trim for ``turbulence`` (the same
    disturbance directions ``kalman-gust-v1`` carries as states, here as white noise).
    """
    if "measurement_sqrt" not in design:
        std = suite_sensor_std(model)
        if std is not None:
            design["measurement_sqrt"] = np.diag(std)
    if "disturbance_sqrt" not in design:
        g = gust_sqrt(model, turbulence)
        if g is not None and g.shape[0] == int(np.sum([k == "disturbance" for k in model.input_kinds])):
            design["disturbance_sqrt"] = np.maximum(g, 1e-6 * np.eye(len(g)))  # calm air: tiny, not singular
    d = robust_parity([model, *perturbed], _order(model, order_s), n_relations, weights, **design)
    return make_robust_parity_detector(model, d, threshold=threshold, p_false_alarm=p_false_alarm)


def make_stochastic_parity(
    model: LinearModel,
    R: NDArray | None = None,
    order_s: int | None = None,
    Bv: NDArray | None = None,
    Q: NDArray | None = None,
    actuators: Sequence[str] = (),
    sensors: Sequence[str] = (),
    threshold: float | None = None,
    p_false_alarm: float = 0.05,
    reject_angle_rad: float = np.pi,
) -> WindowParityDetector:
    """Hagenblad et al. Algorithm 1: normalized parity residual, chi-square test, angle isolation.

    ``R`` defaults to the aircraft's sensor suite (:func:`fdi_sim.detectors.noise.suite_sensor_std`)."""
    if R is None:
        std = suite_sensor_std(model)
        if std is None:
            raise DesignError("parity-stochastic-v1 needs R (the measurement-noise covariance) for a model "
                              "without meta['aircraft']")
        R = np.diag(std ** 2)
    faults = _faults(model, actuators, sensors)
    if faults is None:
        # detection only: a zero-signature placeholder keeps the design code path single
        faults = AdditiveFaults(Bf=np.zeros((model.n_states, 0)), Df=np.zeros((model.n_outputs, 0)), names=())
    d = stochastic_parity(model, _order(model, order_s), faults, R, Bv, Q)
    return make_stochastic_parity_detector(model, d, threshold, p_false_alarm, reject_angle_rad)


def make_pca(
    model: LinearModel,
    train_u: NDArray,
    train_y: NDArray,
    window_L: int = 3,
    n_residuals: int | None = None,
    fault_data: Mapping[str, tuple[NDArray, NDArray]] | None = None,
    threshold: float | None = None,
    p_false_alarm: float = 0.05,
    reject_angle_rad: float = np.pi,
) -> WindowParityDetector:
    """PCA residuals trained on a fault-free log (Hagenblad et al. sec. 3, eq. 15-22).

    ``train_u`` (T, m_known) and ``train_y`` (T, r) are absolute samples; the model supplies trim
    values and names. ``n_residuals`` defaults to ``L r - n`` (the parity dimension, eq. 7);
    ``fault_data`` maps hypothesis names to ``(u, y)`` logs with that fault (eq. 22).
    """
    u0, y0 = model.u0[model.control_columns()], model.y0
    nr = window_L * model.n_outputs - model.n_states if n_residuals is None else int(n_residuals)
    u_names = [model.input_names[i] for i in model.control_columns()]
    names = [f"{n}[k-{window_L - 1 - j}]" for sig in (model.output_names, u_names) for j in range(window_L) for n in sig]
    # exact relations in the log (a command held at 0, the autopilot's u = K y) are dropped, see pca_train
    pca = pca_train(series_windows(train_u, train_y, window_L, u0, y0), nr, column_names=names)
    names = tuple(fault_data or ())
    sig = estimate_fault_signatures(
        pca, [series_windows(*fault_data[name], window_L, u0, y0) for name in names]) if names else None
    return make_pca_detector(model, pca, window_L, sig, names, threshold, p_false_alarm, reject_angle_rad)


register("detector", "parity-v1", "Chow-Willsky parity checks W'(Y - H U) of one model, known inputs", make_parity)
register("detector", "parity-robust-v1", "Lou-Willsky-Verghese optimally robust parity relations over a model set",
         make_robust_parity)
register("detector", "parity-stochastic-v1", "Hagenblad stochastic parity: normalized residual, chi2 test, angle isolation",
         make_stochastic_parity)
register("detector", "pca-v1", "PCA residual space trained on fault-free logs, chi2 test, angle isolation", make_pca)
