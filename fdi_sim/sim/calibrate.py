"""Calibrate detectors on fault-free training flights of a scenario (and cache the result).

A detector's threshold is only as good as the flights it was set on. Here the training flights
are the scenario itself with its faults removed, flown with seeds that the scenario's own runs do
not use (:data:`TRAINING_SEED_BASE` + i), for ``duration_s`` each; the calibration records them.
The result is cached on disk (``$FDI_SIM_CACHE/fdi-sim/calibrations``), keyed by everything it
depends on: the fault-free scenario, the detector options, the rate, the number and length of
the flights, the target, the sensor suite file and the package version.
"""
from __future__ import annotations

import hashlib
import json
import os
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from fdi_sim import __version__
from fdi_sim.errors import DesignError
from fdi_sim.detectors.gust_kalman import Calibration, GustKalmanDetector, calibrate
from fdi_sim.detectors.samples import log_samples
from fdi_sim.flightlog import read_log
from fdi_sim.scenario import Scenario
from fdi_sim.scenario.loader import from_dict

#: training seeds are TRAINING_SEED_BASE + i: far from the small seeds scenarios and studies use
TRAINING_SEED_BASE = 1_000_000
DEFAULT_TRAINING_FLIGHTS = 24
DEFAULT_TRAINING_S = 300.0
#: per-sample false-alarm target at the detector rate; 1e-3 put alarms on the autopilot's doublets
#: (the linear model's largest misses), 1e-4 clears every shipped scenario's pre-fault maneuvers
DEFAULT_TARGET = 1e-4


def fault_free(sc: Scenario, seed: int, duration_s: float) -> Scenario:
    """The scenario without its faults, detectors and FDI bank, with full logs, another seed and duration."""
    data = json.loads(sc.to_json())
    data.update(faults=[], detectors=[], seed=int(seed), duration_s=float(duration_s))
    data.pop("fdi", None)  # no bank in a training flight (it would need training itself), full logs
    data.pop("log", None)
    data["maneuvers"] = [m for m in data.get("maneuvers", []) if float(m.get("t_start_s", 0.0)) < duration_s]
    return from_dict(data, source=f"{sc.source} (fault-free training flight, seed {seed})")


def training_seeds(n: int) -> tuple[int, ...]:
    return tuple(TRAINING_SEED_BASE + i for i in range(n))


def fly_training(sc: Scenario, seeds: Sequence[int], duration_s: float, progress: bool = True,
                 label: str = "") -> list[Any]:
    """Fly the fault-free training flights; return their logs (read back, files removed).

    Parameters
    ----------
    sc : Scenario
        Flown by :func:`fault_free` with each seed.
    seeds : sequence of int
    duration_s : float
        Length of each flight [s].
    progress : bool
        One line on stderr, rewritten after each flight (flights done, sim s per s, ETA), only
        when stderr is a terminal.
    label : str
        Put before the progress line (which calibration this is: ``"point 2/4 (h 12000 ft, vc 320 kt): "``).
    """
    from fdi_sim.sim.run import run

    logs = []
    t0 = time.perf_counter()
    show = progress and sys.stderr.isatty()
    with tempfile.TemporaryDirectory(prefix="fdi-sim-train-") as tmp:
        for i, seed in enumerate(seeds):
            res = run(fault_free(sc, seed, duration_s), tmp, progress=False)
            if res.status == "interrupted":  # Ctrl-C / SIGTERM during calibration: stop like any run
                raise KeyboardInterrupt(f"calibration interrupted during training flight seed {seed}")
            if res.status != "completed":
                raise DesignError(f"{sc.source}: fault-free training flight seed {seed} ended {res.status} "
                                  f"({res.summary.reason}); a detector cannot be calibrated on a scenario that does not "
                                  "fly without its faults")
            logs.append(read_log(res.log_path))
            Path(res.log_path).unlink()
            if show:
                el = time.perf_counter() - t0
                rate = (i + 1) * duration_s / el
                print(f"\r{label}calibration flights {i + 1}/{len(seeds)}  {rate:.0f} sim s/s  "
                      f"ETA {(len(seeds) - i - 1) * el / (i + 1):.0f} s", end="", file=sys.stderr, flush=True)
    if show:
        print(file=sys.stderr)
    return logs


def cache_dir() -> Path:
    base = os.environ.get("FDI_SIM_CACHE") or os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "fdi-sim" / "calibrations"


def calibration_key(sc: Scenario, design: Any, params: Mapping[str, Any], rate_hz: float, n: int,
                    duration_s: float, target: float) -> str:
    """What a calibration depends on, hashed: the fault-free scenario, the design itself (its
    model matrices, gains and window, so a changed linearizer or default invalidates it), the
    options, the rate, the number and length of the training flights, the target, the sensor
    suite file the design and the flights use, and the package version."""
    from fdi_sim.sensors.suite import suite_path

    ff = json.loads(fault_free(sc, 0, duration_s).to_json())
    ff.pop("name", None)
    ff.pop("description", None)
    suite = Path(suite_path(sc.aircraft, sc.model.sensors.suite)).read_text()
    default_suite = Path(suite_path(sc.aircraft, "default")).read_text()
    h = hashlib.sha256()
    m = design.model
    for a in (m.A, m.B, m.C, m.D, m.u0, m.y0, design.gains[-1], design.signatures):
        h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    blob = json.dumps({"scenario": ff, "params": dict(params), "rate_hz": rate_hz, "n": n, "window_n": design.window_n,
                       "n_gains": len(design.gains), "duration_s": duration_s, "target": target, "suite": suite,
                       "default_suite": default_suite, "version": __version__, "design": h.hexdigest()},
                      sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:24]


@dataclass(frozen=True, eq=False)
class CachedCalibration:
    """A calibrated ``kalman-gust-v1`` and where its calibration came from.

    Attributes
    ----------
    detector : GustKalmanDetector
    key : str
        The cache key (:func:`calibration_key`).
    path : Path
        The cache entry ``<cache_dir>/<key>.json`` (written unless ``use_cache`` was False).
    cached : bool
        True when the calibration was read from the cache (no flight flown).
    wall_s : float
        Time the calibration took (flights, samples and quantile; or the cache read) [s].
    """

    detector: GustKalmanDetector
    key: str
    path: Path
    cached: bool
    wall_s: float


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
    cal = None
    if use_cache and path.is_file():
        try:
            cal = Calibration.from_dict(json.loads(path.read_text()))
        except (ValueError, KeyError, OSError):
            cal = None  # a damaged cache entry is recomputed
    cached = cal is not None and cal.sigma_m.shape == (det.design.model.n_outputs,) * 2
    if not cached:
        seeds = training_seeds(n_flights)
        if training_logs is not None:
            logs = list(training_logs)
            flown = [float(lg.topics["/truth/state"].t_s[-1]) for lg in logs]
            if len(logs) != n_flights or any(abs(f - duration_s) > 0.5 for f in flown):
                raise DesignError(f"training_logs: {len(logs)} flights of {min(flown):g}-{max(flown):g} s given for "
                                  f"n_flights={n_flights} x duration_s={duration_s:g}")
        else:
            logs = fly_training(sc, seeds, duration_s, progress=progress, label=progress_label)
        flights = [log_samples(lg, det.design.model, rate_hz) for lg in logs]
        labels = [f"seed {s}, {duration_s:g} s, {sc.model.atmosphere.turbulence} turbulence, faults removed" for s in seeds]
        cal = calibrate(det.design, flights, target, labels)
        if use_cache:
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
                tmp = path.with_suffix(f".tmp{os.getpid()}")
                tmp.write_text(json.dumps(cal.to_dict()))
                os.replace(tmp, path)  # committed by rename: a crash leaves no half-written entry
            except OSError:
                pass  # an unwritable cache only costs the next call the flights again
    assert cal is not None
    detector = GustKalmanDetector(det.design, cal, min_cosine=det.min_cosine, use_analytic_threshold=det.use_analytic)
    return CachedCalibration(detector, key, path, cached, time.perf_counter() - t0)
