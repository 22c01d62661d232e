"""kalman-gust-v1 calibrated on a scenario's fault-free training flights (``Sigma_m``), cached.

A detector's threshold is only as good as the flights it was set on. The result is cached on
disk (:mod:`fdi_sim.training.cache`), keyed by everything it depends on: the fault-free scenario,
the detector options, the rate, the number and length of the flights, the target, the sensor
suite file and the package version.
"""
from __future__ import annotations

import time
from typing import Any, Mapping, Sequence


from fdi_sim.errors import DesignError
from fdi_sim.scenario import Scenario
from fdi_sim.training.atlas import lookup as atlas_lookup, record as atlas_record
from fdi_sim.training.cache import (
    CachedCalibration, cache_dir, cache_lock, calibration_atlas_key, calibration_key, read_entry, write_entry,
)
from fdi_sim.training.flights import DEFAULT_TARGET, DEFAULT_TRAINING_FLIGHTS, DEFAULT_TRAINING_S, fly_training, training_seeds
from fdi_sim.detectors.gust_kalman import Calibration, GustKalmanDetector, calibrate
from fdi_sim.detectors.samples import log_samples
from fdi_sim.flightlog import TOPIC_SENSORS


def calibrated_gust_kalman(sc: Scenario, model: Any, *, rate_hz: float = 20.0, n_flights: int = DEFAULT_TRAINING_FLIGHTS,
                           duration_s: float = DEFAULT_TRAINING_S, target: float = DEFAULT_TARGET,
                           params: Mapping[str, Any] | None = None, use_cache: bool = True,
                           progress: bool = True, training_logs: Sequence[Any] | None = None) -> GustKalmanDetector:
    """``kalman-gust-v1`` designed at the scenario's point and calibrated on its fault-free flights.

    Parameters
    ----------
    sc : Scenario
        The scenario whose runs will be tested (its faults are removed for training).
    model : LinearModel
        The continuous linearization at its initial point (``schedule.continuous_at(op)``).
    rate_hz, n_flights, duration_s, target : float, int, float, float
        Detector rate [Hz], training flights, their length [s], per-sample target.
    params : mapping, optional
        Other options of :func:`fdi_sim.detectors.catalogue_observers.make_gust_kalman`.
    training_logs : sequence of FlightLog, optional
        The training flights already flown (seeds :func:`training_seeds`, ``duration_s`` each),
        for a caller that needs them for other detectors too; their length is checked.
    """
    return gust_kalman_calibration(sc, model, rate_hz=rate_hz, n_flights=n_flights, duration_s=duration_s,
                                   target=target, params=params, use_cache=use_cache, progress=progress,
                                   training_logs=training_logs).detector


def gust_kalman_calibration(sc: Scenario, model: Any, *, rate_hz: float = 20.0,
                            n_flights: int = DEFAULT_TRAINING_FLIGHTS, duration_s: float = DEFAULT_TRAINING_S,
                            target: float = DEFAULT_TARGET, params: Mapping[str, Any] | None = None,
                            use_cache: bool = True, progress: bool = True,
                            training_logs: Sequence[Any] | None = None, progress_label: str = "") -> CachedCalibration:
    """:func:`calibrated_gust_kalman`, also saying which cache entry it used and whether it flew.

    ``progress_label`` is put before the progress line of the training flights; the other
    parameters are those of :func:`calibrated_gust_kalman`.
    """
    from fdi_sim.detectors.catalogue_observers import make_gust_kalman

    t0 = time.perf_counter()
    params = dict(params or {})
    params.setdefault("turbulence", sc.model.atmosphere.turbulence if sc.model.atmosphere.turbulence != "none"
                      else "light")  # a calm-air design still carries small gust states
    det = make_gust_kalman(model, rate_hz=rate_hz, sim_rate_hz=sc.model.rate_hz, **params)
    key = calibration_key(sc, det.design, params, rate_hz, n_flights, duration_s, target)
    path = cache_dir() / f"{key}.json"
    with cache_lock(path, use_cache):  # another process computing this entry: wait, then read it
        cal = None
        entry = read_entry(path, use_cache)
        if entry is not None:
            try:
                cal = Calibration.from_dict(entry)
            except (ValueError, KeyError):
                cal = None  # a damaged cache entry is recomputed
        cached = cal is not None and cal.sigma_m.shape == (det.design.model.n_outputs,) * 2
        akey, afp = calibration_atlas_key(sc, det.design, params, rate_hz, n_flights, duration_s, target)
        if not cached and use_cache:  # the shipped atlas: the same entry, made by the project (fdi_sim.training.atlas)
            hit, _ = atlas_lookup(sc.aircraft, "gust", akey, afp)
            if hit is not None:
                try:
                    cal = Calibration.from_dict(hit["entry"])
                    cached = cal.sigma_m.shape == (det.design.model.n_outputs,) * 2
                except (ValueError, KeyError, TypeError):
                    cal, cached = None, False
        if not cached:
            seeds = training_seeds(n_flights)
            if training_logs is not None:
                logs = list(training_logs)
                flown = [float(lg.topics[TOPIC_SENSORS].t_s[-1]) for lg in logs]
                if len(logs) != n_flights or any(abs(f - duration_s) > 0.5 for f in flown):
                    raise DesignError(f"training_logs: {len(logs)} flights of {min(flown):g}-{max(flown):g} s given for "
                                      f"n_flights={n_flights} x duration_s={duration_s:g}")
            else:
                logs = fly_training(sc, seeds, duration_s, progress=progress, label=progress_label)
            flights = [log_samples(lg, det.design.model, rate_hz) for lg in logs]
            labels = [f"seed {s}, {duration_s:g} s, {sc.model.atmosphere.turbulence} turbulence, faults removed" for s in seeds]
            cal = calibrate(det.design, flights, target, labels)
            write_entry(path, cal.to_dict(), use_cache)
    assert cal is not None
    atlas_record("gust", akey, afp, cal.to_dict())
    detector = GustKalmanDetector(det.design, cal, min_cosine=det.min_cosine, use_analytic_threshold=det.use_analytic)
    return CachedCalibration(detector, key, path, cached, time.perf_counter() - t0)



#: options of kalman-gust-v1's calibration (the rest go to its design)
CALIBRATION_OPTIONS = ("n_flights", "duration_s", "target")

