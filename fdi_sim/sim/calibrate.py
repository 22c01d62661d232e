"""Calibrate detectors on fault-free training flights of a scenario (and cache the result); the
thresholds file a calibration study writes (:class:`StudyThresholds`, read by the bank).

A detector's threshold is only as good as the flights it was set on. Here the training flights
are the scenario itself with its faults removed, flown with seeds that the scenario's own runs do
not use (:data:`TRAINING_SEED_BASE` + i), for ``duration_s`` each; the calibration records them.
The result is cached on disk (``$FDI_SIM_CACHE/fdi-sim/calibrations``), keyed by everything it
depends on: the fault-free scenario, the detector options, the rate, the number and length of
the flights, the target, the sensor suite file and the package version.
"""
from __future__ import annotations

import fcntl
import hashlib
import json
import os
import sys
import tempfile
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator, Mapping, Sequence

import numpy as np

from fdi_sim import __version__
from fdi_sim.errors import DesignError
from fdi_sim.detectors.gust_kalman import Calibration, GustKalmanDetector, calibrate
from fdi_sim.detectors.samples import log_samples
from fdi_sim.flightlog import TOPIC_SENSORS
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
    """Fly the fault-free training flights; return their logs: the measurement and command topics,
    kept in memory as the log would hold them (``run(..., keep_rows=True)``: no per-step topic is
    written or read back, which was half a training flight's cost).

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
            res = run(fault_free(sc, seed, duration_s), tmp, progress=False, keep_rows=True)
            if res.status == "interrupted":  # Ctrl-C / SIGTERM during calibration: stop like any run
                raise KeyboardInterrupt(f"calibration interrupted during training flight seed {seed}")
            if res.status != "completed":
                raise DesignError(f"{sc.source}: fault-free training flight seed {seed} ended {res.status} "
                                  f"({res.summary.reason}); a detector cannot be calibrated on a scenario that does not "
                                  "fly without its faults")
            logs.append(res.rows)  # measurements and commands, kept in memory: no topic written or read back
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
    detector = GustKalmanDetector(det.design, cal, min_cosine=det.min_cosine, use_analytic_threshold=det.use_analytic)
    return CachedCalibration(detector, key, path, cached, time.perf_counter() - t0)


# --- thresholds from a calibration study (the file `fdi-sim study STUDY --calibrate OUT.toml` writes) ---
#: the ``kind`` of a thresholds file
THRESHOLDS_KIND = "fdi-thresholds"
#: the shipped file's name in ``aircraft/<aircraft>/`` (package data)
THRESHOLDS_FILE = "fdi_thresholds.toml"


@dataclass(frozen=True)
class HeldRate:
    """False alarms of one member (or of the bank) on one half of a study's runs.

    Attributes
    ----------
    runs : int
    false_alarms : int
    exposure_h : float
        Armed fault-free flight hours [h].
    far_per_h : float
        ``false_alarms / exposure_h`` [1/h].
    ci_per_h : tuple of float
        Exact Poisson interval at the file's confidence [1/h].
    target_inside : bool
        The target rate lies in ``ci_per_h``.
    """

    runs: int
    false_alarms: int
    exposure_h: float
    far_per_h: float
    ci_per_h: tuple[float, float]
    target_inside: bool


@dataclass(frozen=True)
class StudyMemberThreshold:
    """One member's threshold calibrated on a study.

    Attributes
    ----------
    id : str
    threshold : float
        The calibrated threshold on the member's statistic [-].
    trained_threshold : float
        The threshold the study's runs flew (the bank's training flights) [-].
    scale : float
        ``threshold / trained_threshold`` [-].
    target_per_h : float
        The member's share of the bank's rate [1/h].
    calibration, held_out : HeldRate
        On the calibration half at ``threshold``, and on the held-out half.
    method : str
        How the threshold was set on the calibration half (the tail fit's description).
    rate_ratio : float
        Held-out rate over the calibration half's at ``threshold`` [-] (inf when that half has none).
    rate_ratio_ci : tuple of float
        Its exact conditional interval, scaled by the runs' dispersion [-].
    consistent : bool
        1 lies in ``rate_ratio_ci``: the two halves agree, allowing for both counts' sampling error.
    """

    id: str
    threshold: float
    trained_threshold: float
    scale: float
    target_per_h: float
    calibration: HeldRate
    held_out: HeldRate
    method: str
    rate_ratio: float
    rate_ratio_ci: tuple[float, float]
    consistent: bool


@dataclass(frozen=True)
class StudyThresholds:
    """A thresholds file: a default bank's thresholds from a calibration study, with provenance.

    Attributes
    ----------
    aircraft : str
    study, study_identity : str
        The study's name and identity hash (``study.json`` of its results folder).
    runs : int
        Completed runs used (both halves).
    flight_h : float
        Their flight hours [h].
    version : str
        fdi-sim version that wrote the file.
    design_h_ft, design_vc_kts : float
        The bank's design node [ft], [kt].
    design_turbulence : str
    design_wind_speed_kts, design_noise_scale : float
        [kt], [-].
    design_hash : str
        :func:`fdi_sim.sim.bank_design.design_hash` of the bank the study flew.
    rate_hz : float
        Detector rate [Hz].
    persistence_k, persistence_n : int
        The decision rule the thresholds were calibrated with.
    far_per_h : float
        The bank's target rate [1/h]; each member's is ``far_per_h / members``.
    split : str
        ``even``: calibrated on the even run indices, held out the odd ones.
    confidence : float
    members : tuple of StudyMemberThreshold
    bank_calibration, bank_held_out : HeldRate
        The bank (OR of its members at their thresholds) against ``far_per_h``.
    method : str
    """

    aircraft: str
    study: str
    study_identity: str
    runs: int
    flight_h: float
    version: str
    design_h_ft: float
    design_vc_kts: float
    design_turbulence: str
    design_wind_speed_kts: float
    design_noise_scale: float
    design_hash: str
    rate_hz: float
    persistence_k: int
    persistence_n: int
    far_per_h: float
    split: str
    confidence: float
    members: tuple[StudyMemberThreshold, ...]
    bank_calibration: HeldRate
    bank_held_out: HeldRate
    method: str

    def member_method(self, member_id: str) -> str:
        """The method string a bank records for a member that uses this file's threshold."""
        m = next(x for x in self.members if x.id == member_id)
        h = m.held_out
        return (f"calibration study {self.study} ({self.runs} runs, {self.flight_h:.1f} h), held-out rate "
                f"{h.far_per_h:.3g} per h [{h.ci_per_h[0]:.3g}, {h.ci_per_h[1]:.3g}] ({h.false_alarms} in "
                f"{h.exposure_h:.1f} h, target {m.target_per_h:.3g}; calibrated on the {self.split} runs: "
                f"{m.calibration.false_alarms} in {m.calibration.exposure_h:.1f} h, rate ratio "
                f"[{m.rate_ratio_ci[0]:.3g}, {m.rate_ratio_ci[1]:.3g}]; study {self.study_identity}; {m.method})")


def _strict(cls: type, d: Any, source: str, where: str) -> dict[str, Any]:
    """``d``'s keys must be exactly ``cls``'s fields (the file is strict data)."""
    from dataclasses import fields

    from fdi_sim.errors import ScenarioError

    if not isinstance(d, dict):
        raise ScenarioError(source, where, f"expected a table, got {type(d).__name__}",
                            "write the file with `fdi-sim study STUDY --calibrate OUT.toml`")
    names = [f.name for f in fields(cls)]
    extra = sorted(set(d) - set(names))
    missing = [n for n in names if n not in d]
    if extra or missing:
        key = f"{where}.{(extra or missing)[0]}" if where else (extra or missing)[0]
        raise ScenarioError(source, key, ("unknown key" + "s" * (len(extra) > 1) + f" {', '.join(extra)}" if extra
                                          else f"missing key{'s' * (len(missing) > 1)} {', '.join(missing)}"),
                            f"a thresholds file has exactly the keys {', '.join(names)}; write it again with "
                            "`fdi-sim study STUDY --calibrate OUT.toml`")
    return d


def _held(d: Any, source: str, where: str) -> HeldRate:
    d = _strict(HeldRate, d, source, where)
    try:
        return HeldRate(int(d["runs"]), int(d["false_alarms"]), float(d["exposure_h"]), float(d["far_per_h"]),
                        (float(d["ci_per_h"][0]), float(d["ci_per_h"][1])), bool(d["target_inside"]))
    except (TypeError, ValueError, IndexError) as exc:
        from fdi_sim.errors import ScenarioError

        raise ScenarioError(source, where, f"a value of the wrong type ({exc})",
                            "write the file again with `fdi-sim study STUDY --calibrate OUT.toml`") from None


def thresholds_to_dict(t: StudyThresholds) -> dict[str, Any]:
    """The TOML tables of a thresholds file."""
    from dataclasses import asdict

    d = asdict(t)
    d = {"kind": THRESHOLDS_KIND, **d}
    for h in [d["bank_calibration"], d["bank_held_out"]] + [x for m in d["members"] for x in (m["calibration"], m["held_out"])]:
        h["ci_per_h"] = list(h["ci_per_h"])
    for m in d["members"]:
        m["rate_ratio_ci"] = list(m["rate_ratio_ci"])
    d["members"] = list(d["members"])
    return d


def write_thresholds(t: StudyThresholds, path: str | Path) -> Path:
    """Write a thresholds file (TOML, committed by rename)."""
    import tomli_w

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    head = (f"# fdi-sim thresholds file: written by `fdi-sim study {t.study} --calibrate`, do not edit by hand\n"
            f"# {t.method}\n")
    b = t.bank_held_out
    head += (f"# held-out half: the bank {b.false_alarms} false alarms in {b.exposure_h:.1f} h = {b.far_per_h:.3g} per h "
             f"[{b.ci_per_h[0]:.3g}, {b.ci_per_h[1]:.3g}], target {t.far_per_h:g} "
             f"{'inside' if b.target_inside else 'OUTSIDE'}; members outside: "
             f"{', '.join(m.id for m in t.members if not m.held_out.target_inside) or 'none'}\n")
    tmp = path.with_suffix(f".tmp{os.getpid()}")
    tmp.write_text(head + tomli_w.dumps(thresholds_to_dict(t)))
    os.replace(tmp, path)
    return path


def read_thresholds(path: str | Path) -> StudyThresholds:
    """Read a thresholds file (strict: every key, no other).

    Raises
    ------
    ScenarioError
        A missing or unreadable file, another kind, an unknown or missing key; naming the file and key.
    """
    import tomllib

    from fdi_sim.errors import ScenarioError

    src = str(path)
    try:
        d = tomllib.loads(Path(path).read_text())
    except OSError as exc:
        raise ScenarioError(src, "", f"cannot read the thresholds file ({exc.strerror or exc})",
                            "give the path of a file written by `fdi-sim study STUDY --calibrate OUT.toml`, "
                            "or thresholds = \"trained\"") from None
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(src, "", f"not valid TOML ({exc})", "write it again with `fdi-sim study STUDY "
                            "--calibrate OUT.toml`") from None
    if d.pop("kind", None) != THRESHOLDS_KIND:
        raise ScenarioError(src, "kind", f"not a thresholds file (kind must be {THRESHOLDS_KIND!r})",
                            "give a file written by `fdi-sim study STUDY --calibrate OUT.toml`")
    d = _strict(StudyThresholds, d, src, "")
    members = []
    for i, m in enumerate(d["members"] if isinstance(d["members"], list) else [None]):
        m = _strict(StudyMemberThreshold, m, src, f"members[{i}]")
        members.append(StudyMemberThreshold(
            str(m["id"]), float(m["threshold"]), float(m["trained_threshold"]), float(m["scale"]),
            float(m["target_per_h"]), _held(m["calibration"], src, f"members[{i}].calibration"),
            _held(m["held_out"], src, f"members[{i}].held_out"), str(m["method"]), float(m["rate_ratio"]),
            (float(m["rate_ratio_ci"][0]), float(m["rate_ratio_ci"][1])), bool(m["consistent"])))
    try:
        return StudyThresholds(
            str(d["aircraft"]), str(d["study"]), str(d["study_identity"]), int(d["runs"]), float(d["flight_h"]),
            str(d["version"]), float(d["design_h_ft"]), float(d["design_vc_kts"]), str(d["design_turbulence"]),
            float(d["design_wind_speed_kts"]), float(d["design_noise_scale"]), str(d["design_hash"]),
            float(d["rate_hz"]), int(d["persistence_k"]), int(d["persistence_n"]), float(d["far_per_h"]),
            str(d["split"]), float(d["confidence"]), tuple(members),
            _held(d["bank_calibration"], src, "bank_calibration"), _held(d["bank_held_out"], src, "bank_held_out"),
            str(d["method"]))
    except (TypeError, ValueError) as exc:
        raise ScenarioError(src, "", f"a value of the wrong type ({exc})",
                            "write the file again with `fdi-sim study STUDY --calibrate OUT.toml`") from None
