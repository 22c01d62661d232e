"""Registered observer-based detectors (imported by ``fdi_sim.detectors.catalogue``).

Every factory takes ``(model: LinearModel, **params)`` for one operating point and returns a
detector with the common contract (``id``, ``hypotheses``, ``reset(rng)``, ``step(t_s, u, y)``).
A continuous model is discretized at ``dt_s`` (default 1/120 s, the loop rate). Noise is given
as standard deviations per sample: ``process_std`` per state [state units], ``sensor_std`` per
output [output units]. When omitted, unit standard deviations are used (nothing is guessed) and
the chi-square statistic is then only a weighted norm: give the real values for a calibrated
false-alarm rate.
"""
from __future__ import annotations

from typing import Any, Mapping, Sequence

import numpy as np

from fdi_sim.detectors.adaptive_observer import AdaptiveObserver, choose_sidar_gains
from fdi_sim.detectors.beard_jones_filter import BeardJonesBank, BeardJonesFilter, plan_bank
from fdi_sim.detectors.kalman import KalmanDesign, KalmanInnovationDetector, MultipleModelBank, TimeVaryingKalmanDetector, steady_state_kalman
from fdi_sim.detectors.lmi_filter import LmiDetectionFilter, design_lmi_filter
from fdi_sim.detectors.noise import WINGSPAN_FT, suite_sensor_std
from fdi_sim.errors import DesignError
from fdi_sim.linear.model import LinearModel
from fdi_sim.registry import register

DEFAULT_DT_S = 1.0 / 120.0


def _dt(model: LinearModel, dt_s: float | None) -> float:
    return model.dt_s if model.is_discrete else float(DEFAULT_DT_S if dt_s is None else dt_s)


def _discrete(model: LinearModel, dt_s: float | None) -> LinearModel:
    return model if model.is_discrete else model.discretize(_dt(model, dt_s))


def _diag(std: Sequence[float] | float | None, size: int, what: str) -> np.ndarray:
    v = np.ones(size) if std is None else np.broadcast_to(np.asarray(std, float), (size,))
    if v.shape != (size,) or np.any(v < 0):
        raise DesignError(f"{what} needs {size} non-negative standard deviations, got {std!r}")
    return np.diag(v**2)


def _controls(model: LinearModel) -> list[str]:
    return [model.input_names[i] for i in model.control_columns()]


def _noise(md: LinearModel, process_std: Any, sensor_std: Any) -> tuple[np.ndarray, np.ndarray]:
    """Diagonal process and sensor noise covariances per sample; the sensor noise defaults to the
    aircraft's suite (:func:`fdi_sim.detectors.noise.suite_sensor_std`)."""
    if sensor_std is None:
        sensor_std = suite_sensor_std(md)
    return _diag(process_std, md.n_states, "process_std"), _diag(sensor_std, md.n_outputs, "sensor_std")


def _kalman(model: LinearModel, process_std: Any, sensor_std: Any, dt_s: float | None) -> KalmanDesign:
    """Steady-state Kalman filter of ``model`` (discretized at ``dt_s`` if continuous) with diagonal noise."""
    md = _discrete(model, dt_s)
    return steady_state_kalman(md, *_noise(md, process_std, sensor_std))


def make_beard_jones(model: LinearModel, faults: Sequence[str] | None = None, detection_pole_radps: float = -4.0,
                     completion_pole_radps: float = -6.0, dt_s: float | None = None, sensor_std: Any = None,
                     process_std: Any = None, alpha: float = 1e-3, max_angle_rad: float = 0.35) -> BeardJonesFilter | BeardJonesBank:
    """Beard-Jones filter for actuator faults; a bank if they cannot share one.

    The filter runs on the observable part of ``model``
    (:func:`~fdi_sim.detectors.beard_jones_filter.observable_realization`: the paired models of
    both aircraft lose their three accelerometer lag states, unobservable at ``z = 0``). ``faults``
    defaults to every control input whose feedthrough is not below the sensor noise
    (:func:`~fdi_sim.detectors.beard_jones_filter.default_faults`): elevator, aileron, rudder and
    throttle on the F-16, the three surfaces on the DHC-6 (its throttle moves the outputs of its own
    20 Hz sample by 0.08-0.28 noise sigma at full scale; name it in ``faults`` to get it anyway). An
    actuator with a feedthrough gets detection order 0 (residual ``D[:, j] n`` exactly); the
    detection pole applies to faults without one. Without ``process_std`` the residual covariance
    has no process noise (the filter's model is taken as exact).

    Parameters
    ----------
    model : LinearModel
        Discrete (the detectors' paired form), or continuous with ``dt_s``.
    faults : sequence of str, optional
        Input names; default :func:`~fdi_sim.detectors.beard_jones_filter.default_faults`.
    detection_pole_radps, completion_pole_radps : float
        Continuous-time poles [1/s], negative (``z = exp(s dt)``).
    dt_s : float, optional
        Sample time [s] of a continuous model.
    sensor_std : float or sequence, optional
        Measurement noise per output [output units]; default the aircraft's suite.
    process_std : float or sequence, optional
        Process noise per state and step [state units].
    alpha : float
        Per-sample false-alarm probability of the chi-square threshold [-].
    max_angle_rad : float
        Largest residual angle accepted for isolation [rad].
    """
    from fdi_sim.detectors.beard_jones_filter import default_faults

    R = _diag(sensor_std if sensor_std is not None else suite_sensor_std(model), model.n_outputs, "sensor_std")
    faults = list(faults) if faults is not None else default_faults(model, R)
    Q = _diag(process_std, model.n_states, "process_std") if process_std is not None else None
    designs = plan_bank(model, faults, detection_pole_radps=detection_pole_radps, completion_pole_radps=completion_pole_radps,
                        dt_s=None if model.is_discrete else _dt(model, dt_s), Q=Q, R=R)
    filters = [BeardJonesFilter(d, alpha, max_angle_rad) for d in designs]
    return filters[0] if len(filters) == 1 else BeardJonesBank(filters)


def make_lmi_detection(model: LinearModel, fault: str | None = None, h_radps: float = 100.0, epsilon: float = 1e-7,
                       method: str = "least-squares", dt_s: float | None = None, sensor_std: Any = None,
                       alpha: float = 1e-3) -> LmiDetectionFilter:
    """LMI-optimal detection filter (continuous design, ZOH runtime) for one actuator fault.

    ``h_radps`` bounds the closed-loop poles (``-h <= Re s < 0``). The default 100 rad/s is feasible at
    every default-grid point of both aircraft with the sensor noise of their suites (20 rad/s, the
    earlier default, is infeasible at all 20 F-16 points and 18 of 30 DHC-6 points, 50 rad/s at the
    F-16 points tried: with gyro noise of 0.0014 rad/s the LQ filter is fast); at the 120 Hz ZOH runtime
    100 rad/s is 0.83 rad per step, well inside the discrete stability region.
    """
    if model.is_discrete:
        raise DesignError("lmi-detection-v1 is designed on a continuous model; pass the continuous linearization")
    fault = fault or _controls(model)[0]
    R = _diag(sensor_std if sensor_std is not None else suite_sensor_std(model), model.n_outputs, "sensor_std")
    design = design_lmi_filter(model, fault, R, h_radps, epsilon=epsilon, method=method)  # V = R as noise weighting
    return LmiDetectionFilter(model, design, fault, _dt(model, dt_s), alpha=alpha, Rd=R)


def make_kalman(model: LinearModel, process_std: Any = None, sensor_std: Any = None, dt_s: float | None = None,
                alpha: float = 1e-3, test: str = "nis", window_n: int = 200, n_lags: int = 5) -> KalmanInnovationDetector:
    """Steady-state Kalman filter with the NIS, bias or whiteness test."""
    return KalmanInnovationDetector(_kalman(model, process_std, sensor_std, dt_s), alpha, test, window_n, n_lags)  # type: ignore[arg-type]


def make_kalman_tv(model: LinearModel, process_std: Any = None, sensor_std: Any = None, dt_s: float | None = None,
                   alpha: float = 1e-3) -> TimeVaryingKalmanDetector:
    """Time-varying Kalman filter (covariance recursion) with the NIS test; ``set_model`` re-schedules it."""
    md = _discrete(model, dt_s)
    return TimeVaryingKalmanDetector(md, *_noise(md, process_std, sensor_std), alpha=alpha)


def make_mmae(model: LinearModel, alternatives: Mapping[str, LinearModel] | None = None, process_std: Any = None,
              sensor_std: Any = None, dt_s: float | None = None, alarm_probability: float = 0.95, p_min: float = 1e-4,
              effectiveness: float = 0.5) -> MultipleModelBank:
    """Multiple-model bank: ``model`` is the nominal hypothesis, ``alternatives`` the others (e.g. ``{"iced": ...}``).

    Without ``alternatives`` (a scenario file cannot give models) the hypotheses are the classic
    MMAE actuator set: one model per control input with that input's columns of ``B`` and ``D``
    scaled by ``effectiveness`` [-] (a loss of effectiveness of ``1 - effectiveness``), named by
    the input (``elevator_cmd_norm``), the names the bank isolates actuators by."""
    if not alternatives:
        import dataclasses

        if not 0.0 <= float(effectiveness) < 1.0:
            raise DesignError(f"effectiveness must be in [0, 1), got {effectiveness}")
        alternatives = {}
        for c in model.control_columns():
            B, D = np.array(model.B, dtype=float), np.array(model.D, dtype=float)
            B[:, c] *= effectiveness  # B_i = B diag(1, .., e, .., 1): the surface delivers e of the command
            D[:, c] *= effectiveness
            alternatives[model.input_names[c]] = dataclasses.replace(model, B=B, D=D)
        if not alternatives:
            raise DesignError("kalman-mmae-v1 needs alternatives={'name': LinearModel, ...} or a model with control "
                              "inputs")
    models = {"nominal": model, **dict(alternatives)}
    designs = [_kalman(m, process_std, sensor_std, dt_s) for m in models.values()]
    return MultipleModelBank(designs, list(models), 0, p_min, alarm_probability)


def make_adaptive_observer(model: LinearModel, adapt_A: Sequence[tuple[str, str]] | None = None,
                           adapt_B: Sequence[tuple[str, str]] | None = None, m_gain: Any = 0.01, n_gain: Any = 0.01,
                           process_std: Any = None, sensor_std: Any = None, dt_s: float | None = None,
                           alpha: float = 1e-3, normalized: bool = True) -> AdaptiveObserver:
    """Sidar's adaptive observer on the discrete Kalman filter (eq. 23); entries to adapt by (row, column) names.

    Default: the rows and columns of the measured states of ``A`` and the control columns of ``B``,
    and the normalized law with per-step gains 0.01 (``normalized=False`` is Sidar's own: its
    per-step loop gain ``m |xh|^2`` passes 2 and it diverges within 0.07-0.42 s on F-16 and DHC-6
    flights at 0.1 and 0.01; docs/observers.md).
    """
    design = _kalman(model, process_std, sensor_std, dt_s)
    md = design.model
    sn, inn = list(md.state_names), list(md.input_names)
    mask_A = np.zeros((md.n_states, md.n_states), bool)
    mask_B = np.zeros((md.n_states, md.n_inputs), bool)
    try:
        if adapt_A is None:
            seen = np.flatnonzero(np.linalg.norm(np.asarray(md.C), axis=0) > 0)
            mask_A[np.ix_(seen, seen)] = True
        for r, c in adapt_A or []:
            mask_A[sn.index(r), sn.index(c)] = True
        if adapt_B is None:
            mask_B[:, md.control_columns()] = True
        for r, c in adapt_B or []:
            mask_B[sn.index(r), inn.index(c)] = True
    except ValueError as exc:
        raise DesignError(f"unknown signal name in adapt_A/adapt_B ({exc}); states {sn}, inputs {inn}") from exc
    gains = choose_sidar_gains(md.A, design.predictor_gain, md.C, m_gain, n_gain, 1.0, 1.0, mask_A, mask_B, dt_s=md.dt_s)
    return AdaptiveObserver(md, design.predictor_gain, gains.M, gains.N, mask_A, mask_B, S=design.S, alpha=alpha,
                            normalized=normalized)


register("detector", "beard-jones-v1", "Beard-Jones fault detection filter(s) for actuator faults (patent App. A)", make_beard_jones)
register("detector", "lmi-detection-v1", "LMI-optimal LQ detection filter with eigenvector alignment (patent App. B)", make_lmi_detection)
register("detector", "kalman-nis-v1", "Steady-state Kalman filter, NIS / bias / whiteness innovation tests (Sidar eq. 10)", make_kalman)
register("detector", "kalman-tv-nis-v1", "Time-varying Kalman filter with the NIS chi-square test", make_kalman_tv)
register("detector", "kalman-mmae-v1", "Multiple-model Kalman bank with hypothesis probabilities (select the model that fits)", make_mmae)
register("detector", "adaptive-observer-v1", "Sidar's adaptive tracking observer; parameter estimates flag slow degradation", make_adaptive_observer)


def make_gust_kalman(model: LinearModel, calibration: Any = None, turbulence: str = "moderate", rate_hz: float = 20.0,
                     sim_rate_hz: float = 120.0, psiw_rad: float = 0.0, min_cosine: float = 0.7,
                     bias_drift: float = 1e-3, window_s: float = 1.0, use_analytic_threshold: bool = False):
    """Kalman filter with JSBSim's Dryden gusts and turn-on bias states, windowed innovation test,
    GLR-style signature isolation (``fdi_sim.detectors.gust_kalman``). ``calibration`` (a
    :class:`~fdi_sim.detectors.gust_kalman.Calibration` or its dict) comes from fault-free
    training flights: :func:`fdi_sim.training.gust.calibrated_gust_kalman` flies them."""
    from fdi_sim.detectors.gust_kalman import Calibration, GustKalmanDetector, SensorNoise, design_gust_kalman
    from fdi_sim.sensors import load_suite

    aircraft = (model.meta or {}).get("aircraft")
    if aircraft not in WINGSPAN_FT:
        raise DesignError(f"kalman-gust-v1 needs model.meta['aircraft'] in {sorted(WINGSPAN_FT)} (sensor suite, "
                          f"wing span); got {aircraft!r}")
    sensors = {s.name: SensorNoise(s.noise_std, s.bias_std, s.quantum or 0.0) for s in load_suite(aircraft)}
    design = design_gust_kalman(model, rate_hz=rate_hz, sim_rate_hz=sim_rate_hz, turbulence=turbulence,
                                wingspan_ft=WINGSPAN_FT[aircraft], sensors=sensors, psiw_rad=psiw_rad,
                                bias_drift=bias_drift, window_s=window_s)
    if isinstance(calibration, Mapping):
        calibration = Calibration.from_dict(calibration)
    return GustKalmanDetector(design, calibration, min_cosine=min_cosine, use_analytic_threshold=use_analytic_threshold)


register("detector", "kalman-gust-v1", "Kalman filter with JSBSim's Dryden gusts and sensor-bias states, 1 s windowed "
         "innovation test calibrated on fault-free flights, signature isolation with reject", make_gust_kalman)
