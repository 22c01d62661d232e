"""The calibration cache on disk (``$FDI_SIM_CACHE/fdi-sim/calibrations``): entries keyed by
everything a calibration depends on, written atomically, one process computing an entry at a time.
"""
from __future__ import annotations

import fcntl
import hashlib
import json
import os
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator, Mapping

import numpy as np

from fdi_sim import __version__
from fdi_sim.scenario import Scenario
from fdi_sim.detectors.gust_kalman import GustKalmanDetector
from fdi_sim.training.flights import fault_free


def cache_dir() -> Path:
    base = os.environ.get("FDI_SIM_CACHE") or os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "fdi-sim" / "calibrations"


def _calibration_parts(sc: Scenario, design: Any, params: Mapping[str, Any], rate_hz: float, n: int,
                       duration_s: float, target: float) -> tuple[dict[str, Any], list[Any]]:
    """What a calibration depends on: the inputs (JSON-able) and the design's arrays."""
    from fdi_sim.sensors.suite import suite_path

    ff = json.loads(fault_free(sc, 0, duration_s).to_json())
    ff.pop("name", None)
    ff.pop("description", None)
    suite = Path(suite_path(sc.aircraft, sc.model.sensors.suite)).read_text()
    default_suite = Path(suite_path(sc.aircraft, "default")).read_text()
    m = design.model
    arrays = [m.A, m.B, m.C, m.D, m.u0, m.y0, design.gains[-1], design.signatures]
    parts = {"scenario": ff, "params": dict(params), "rate_hz": rate_hz, "n": n, "window_n": design.window_n,
             "n_gains": len(design.gains), "duration_s": duration_s, "target": target, "suite": suite,
             "default_suite": default_suite, "version": __version__}
    return parts, arrays


def calibration_key(sc: Scenario, design: Any, params: Mapping[str, Any], rate_hz: float, n: int,
                    duration_s: float, target: float) -> str:
    """What a calibration depends on, hashed: the fault-free scenario, the design itself (its
    model matrices, gains and window, so a changed linearizer or default invalidates it), the
    options, the rate, the number and length of the training flights, the target, the sensor
    suite file the design and the flights use, and the package version."""
    parts, arrays = _calibration_parts(sc, design, params, rate_hz, n, duration_s, target)
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    blob = json.dumps({**parts, "design": h.hexdigest()}, sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:24]


def calibration_atlas_key(sc: Scenario, design: Any, params: Mapping[str, Any], rate_hz: float, n: int,
                          duration_s: float, target: float) -> tuple[str, list[list[float]]]:
    """The atlas key of a calibration (:func:`calibration_key` without the design's bits) and the
    design's fingerprint (:func:`fdi_sim.training.atlas.fingerprint`)."""
    from fdi_sim.training.atlas import fingerprint, inputs_key

    parts, arrays = _calibration_parts(sc, design, params, rate_hz, n, duration_s, target)
    shapes = [list(np.shape(a)) for a in arrays]
    return inputs_key({**parts, "shapes": shapes}), fingerprint(arrays)


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


def read_entry(path: Path, use: bool = True) -> Any:
    """The JSON cache entry at ``path`` (None without ``use``, when absent, or when damaged: a
    damaged entry is recomputed)."""
    if not use or not path.is_file():
        return None
    try:
        return json.loads(path.read_text())
    except (ValueError, OSError):
        return None


def write_entry(path: Path, obj: Any, use: bool = True) -> None:
    """Write the JSON cache entry ``obj`` at ``path``, committed by rename (a crash leaves no
    half-written entry); an unwritable cache only costs the next call the flights again."""
    if not use:
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".tmp{os.getpid()}")
        tmp.write_text(json.dumps(obj))
        os.replace(tmp, path)
    except OSError:
        pass


@contextmanager
def cache_lock(path: Path, use: bool = True) -> Iterator[None]:
    """Hold an exclusive lock on ``<path>.lock`` while the cache entry ``path`` is read or computed.

    A second process that needs the same entry (the test suite's xdist workers, a study's Dask
    workers, two runs started at once) waits for the first and then reads its entry instead of
    flying the same training flights again. ``fcntl`` locks end with their process, so a crash
    leaves no stale lock. Without ``use``, or where the lock file cannot be made (an unwritable
    cache), nothing is locked.
    """
    fh = None
    if use:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fh = open(path.with_suffix(".lock"), "w")
            fcntl.flock(fh, fcntl.LOCK_EX)
        except OSError:
            if fh is not None:
                fh.close()
            fh = None
    try:
        yield
    finally:
        if fh is not None:
            fh.close()  # closing the file releases the lock

