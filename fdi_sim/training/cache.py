"""The calibration cache on disk (``$FDI_SIM_CACHE/fdi-sim/calibrations``): entries keyed by
everything a calibration depends on, written atomically, one process computing an entry at a time.
An entry is JSON (:func:`read_entry`, :func:`write_entry`) or numpy arrays (:func:`read_arrays`,
:func:`write_arrays`); the keys of every entry made from a scenario's training flights start from
:func:`scenario_parts`.
"""
from __future__ import annotations

import fcntl
import hashlib
import json
import os
import zipfile
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO, Callable, Iterable, Iterator, Mapping, Sequence

import numpy as np

from fdi_sim import __version__
from fdi_sim.scenario import Scenario
from fdi_sim.detectors.gust_kalman import GustKalmanDetector
from fdi_sim.training.flights import fault_free


def cache_dir() -> Path:
    base = os.environ.get("FDI_SIM_CACHE") or os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "fdi-sim" / "calibrations"


def scenario_parts(sc: Scenario, duration_s: float) -> dict[str, Any]:
    """What every cache entry made from a scenario's fault-free training flights depends on.

    One function for the calibrations' keys (:func:`calibration_key`) and pca-v1's training data's
    (:func:`fdi_sim.training.build._pca_training_key`), so the two cannot drift apart. The keys
    join these parts with their own under ``sort_keys``: the names and values here are part of every
    key on disk, and a change to them misses every cache entry made before.

    Parameters
    ----------
    sc : Scenario
        The scenario whose fault-free training flights make the entry.
    duration_s : float
        The length of each training flight [s].

    Returns
    -------
    dict
        ``"scenario"``: the fault-free training scenario (:func:`fdi_sim.training.flights.fault_free`,
        seed 0) as JSON without its name and description (they change no flight); ``"suite"``: the
        text of the scenario's sensor suite file; ``"version"``: the package version.
    """
    from fdi_sim.sensors.suite import suite_path

    suite = Path(suite_path(sc.aircraft, sc.model.sensors.suite)).read_text()
    return {"scenario": training_scenario_json(sc, duration_s), "suite": suite, "version": __version__}


def training_scenario_json(sc: Scenario, duration_s: float, drop: Sequence[str] = ("name", "description")) -> dict[str, Any]:
    """The fault-free training scenario (:func:`fdi_sim.training.flights.fault_free`, seed 0, flights of
    ``duration_s`` [s]) as JSON without the keys ``drop`` (its name and description change no flight;
    the thresholds' keys also drop ``fdi``, which their own parts hold): the scenario part of every key
    made from a scenario's training flights."""
    ff = json.loads(fault_free(sc, 0, duration_s).to_json())
    for k in drop:
        ff.pop(k, None)
    return ff


def arrays_digest(arrays: Iterable[Any]) -> str:
    """sha256 (hex) of the arrays' float64 bytes in order (a model's or a design's matrices in a key)."""
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a, dtype=np.float64).tobytes())
    return h.hexdigest()


def _calibration_parts(sc: Scenario, design: Any, params: Mapping[str, Any], rate_hz: float, n: int,
                       duration_s: float, target: float) -> tuple[dict[str, Any], list[Any]]:
    """What a calibration depends on: the inputs (JSON-able) and the design's arrays."""
    from fdi_sim.sensors.suite import suite_path

    default_suite = Path(suite_path(sc.aircraft, "default")).read_text()
    m = design.model
    arrays = [m.A, m.B, m.C, m.D, m.u0, m.y0, design.gains[-1], design.signatures]
    parts = {**scenario_parts(sc, duration_s), "params": dict(params), "rate_hz": rate_hz, "n": n,
             "window_n": design.window_n, "n_gains": len(design.gains), "duration_s": duration_s,
             "target": target, "default_suite": default_suite}
    return parts, arrays


def calibration_key(sc: Scenario, design: Any, params: Mapping[str, Any], rate_hz: float, n: int,
                    duration_s: float, target: float) -> str:
    """What a calibration depends on, hashed: the fault-free scenario, the design itself (its
    model matrices, gains and window, so a changed linearizer or default invalidates it), the
    options, the rate, the number and length of the training flights, the target, the sensor
    suite file the design and the flights use, and the package version."""
    parts, arrays = _calibration_parts(sc, design, params, rate_hz, n, duration_s, target)
    blob = json.dumps({**parts, "design": arrays_digest(arrays)}, sort_keys=True, default=str)
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


def _commit(path: Path, write: Callable[[BinaryIO], None], use: bool) -> None:
    """Write a cache entry at ``path`` through ``write`` into a temporary file, then rename it there
    (a crash leaves no half-written entry); an unwritable cache only costs the next call the flights
    again."""
    if not use:
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".tmp{os.getpid()}")
        with open(tmp, "wb") as fh:  # a file object: np.savez would add ".npz" to a name without it
            write(fh)
        os.replace(tmp, path)
    except OSError:
        pass


def write_entry(path: Path, obj: Any, use: bool = True) -> None:
    """Write the JSON cache entry ``obj`` at ``path`` (:func:`_commit`)."""
    _commit(path, lambda fh: fh.write(json.dumps(obj).encode()), use)


def read_arrays(path: Path, names: Sequence[str], use: bool = True) -> dict[str, np.ndarray] | None:
    """The numpy-array cache entry at ``path`` (``.npz``), as ``{name: array}`` for ``names``.

    None without ``use``, when absent, or when damaged (not an ``.npz``, truncated, or without one of
    ``names``): like a damaged JSON entry (:func:`read_entry`), it is recomputed, not a crash.
    """
    if not use or not path.is_file():
        return None
    try:
        with np.load(path) as z:  # allow_pickle stays False: an entry holds plain arrays only
            return {nm: np.asarray(z[nm]) for nm in names}
    except (ValueError, OSError, EOFError, KeyError, zipfile.BadZipFile):
        return None


def write_arrays(path: Path, arrays: Mapping[str, Any], use: bool = True) -> None:
    """Write the numpy-array cache entry ``arrays`` at ``path`` (``.npz``, uncompressed; :func:`_commit`)."""
    _commit(path, lambda fh: np.savez(fh, **arrays), use)


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

