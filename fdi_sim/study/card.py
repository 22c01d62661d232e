"""The detector card: every registered detector on fault-free flights it was not tuned on, and on
every shipped fault scenario (``docs/make_detector_card.py`` writes ``docs/detectors.md``).

Protocol
--------
- Conditions: each aircraft at its cruise scenario's point (F-16 10 kft / 400 KTAS, DHC-6
  5000 ft / 120 KIAS, with the scenario's doublets), turbulence none, light and moderate.
- Training flights: the scenario without faults, seeds ``1e6 + i`` (``fdi_sim.training.flights``),
  ``n_train`` x ``duration_s``. Test flights: seeds ``CARD_SEEDS``, the seed registry's
  "bank-development-1" set (never fitted on, but looked at while the tail method was chosen: a
  development set, not a hold-out, :mod:`fdi_sim.seeds`).
- Every detector is designed at 20 Hz from the paired model of the point (``kalman-gust-v1`` and
  ``lmi-detection-v1`` from the continuous one). Two thresholds: the detector's own (analytic for
  the model-based ones, the shipped calibration for the kinematic checks), and the card's: the
  empirical ``1 - target`` quantile of the statistic on the training flights.
- False-alarm fraction per sample on the held-out flights with its Clopper-Pearson 95 % interval;
  the detector meets the target if the count is at most the upper end of the binomial 95 %
  interval of ``target x samples`` (fewer false alarms than the target is not a failure).
- Fault scenarios: the scenario flown as shipped; each detector designed at its point,
  calibrated on its own fault-free training flights at the same target; first alarm after the
  onset, delay, isolation (most frequent hypothesis in the first second of alarm), alarms before
  the onset.
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from fdi_sim.seeds import seeds as registry_seeds
from fdi_sim import registry
from fdi_sim.decision.intervals import binomial_upper, clopper_pearson  # noqa: F401 - re-exported for the card
from fdi_sim.detectors.samples import log_samples
from fdi_sim.errors import FdiSimError
from fdi_sim.flightlog import read_log
from fdi_sim.scenario import Scenario, load
from fdi_sim.scenario.shipped import shipped_dir
from fdi_sim.training.flights import DEFAULT_TARGET, fly_training, training_seeds
from fdi_sim.decision.outcome import alarm_onsets, fault_outcome
from fdi_sim.detectors.spec import build_detector, DetectorSpec
from fdi_sim.offline.detect import DetectorTrace, fault_windows, run_detector, run_stream, run_vectorised
from fdi_sim.training.models import LogModel, model_for_scenario

RATE_HZ = 20.0
#: the card's fault-free flights: the registry's "bank-development-1" set (development: the tail
#: method was chosen on them)
CARD_SEEDS: tuple[int, ...] = registry_seeds("bank-development-1")
LEVELS = ("none", "light", "moderate")
CRUISE = {"f16": "f16_cruise_doublets", "DHC6": "dhc6_cruise_doublets"}
#: detectors that need something the card cannot give them from a model alone
NOT_APPLICABLE = {"kalman-mmae-v1": "needs alternative models (e.g. iced) as hypotheses: not a fault-free card entry"}


@dataclass(frozen=True)
class FalseAlarms:
    """One detector in one condition, on the held-out flights."""

    detector: str
    aircraft: str
    turbulence: str
    target: float
    samples: int
    own_threshold_alarms: int
    calibrated_alarms: int
    calibrated_threshold: float
    own_threshold: float
    onsets_per_h: float
    cost_us_per_sample: float
    meets_target: bool
    error: str = ""

    @property
    def fraction(self) -> float:
        return self.calibrated_alarms / self.samples if self.samples else math.nan

    @property
    def own_fraction(self) -> float:
        return self.own_threshold_alarms / self.samples if self.samples else math.nan


@dataclass(frozen=True)
class FaultResult:
    """One detector on one shipped fault scenario (calibrated threshold)."""

    scenario: str
    detector: str
    label: str
    target: str
    t_onset_s: float
    alarms_before_onset: int
    first_alarm_s: float | None
    delay_s: float | None
    isolated_as: str | None
    isolation_correct: bool | None
    error: str = ""


def detector_ids() -> list[str]:
    registry.load_builtin_plugins()
    return sorted(s.id for s in registry.all_plugins() if s.kind == "detector")


def _log_model(sc: Scenario) -> LogModel:
    return model_for_scenario(sc, RATE_HZ)


class _Runner:
    """Designs one detector for a scenario and runs it over logs: statistic traces."""

    def __init__(self, ident: str, lm: LogModel, training: Sequence[Any], target: float, duration_s: float) -> None:
        self.id, self.lm, self.target = ident, lm, target
        self.analytic = None
        sc = lm.scenario
        self._measure = None
        if ident == "kalman-gust-v1":
            from fdi_sim.training.gust import calibrated_gust_kalman

            self.det = calibrated_gust_kalman(sc, lm.continuous(), rate_hz=RATE_HZ, n_flights=len(training),
                                              duration_s=duration_s, target=target, training_logs=training,
                                              progress=False)
            from fdi_sim.detectors.gust_kalman import GustKalmanDetector, analytic_calibration

            # its "own" threshold for the card is the design's prediction (Sigma_m = S / W, chi-square)
            self.analytic = GustKalmanDetector(self.det.design, analytic_calibration(self.det.design, target))
            self._model = self.det.design.model
        elif ident.startswith("kinematic-"):
            from fdi_sim.detectors.kinematic import MeasurementSet

            self.det = build_detector(DetectorSpec(ident, {"turbulence": sc.model.atmosphere.turbulence,
                                                           "aircraft": sc.aircraft}), None)
            self._model = MeasurementSet()
        elif ident == "engine-gauges-v1":  # the engines' gauges: the log's measurements, no model
            from fdi_sim.detectors.kinematic import MeasurementSet

            self.det = build_detector(DetectorSpec(ident, {"aircraft": sc.aircraft, "rate_hz": RATE_HZ}), None)
            self._model = MeasurementSet(output_names=tuple(self.det.output_names))
        elif ident == "lmi-detection-v1":
            self.det = build_detector(DetectorSpec(ident, {"dt_s": 1.0 / RATE_HZ}), lm.continuous())
            self._model = lm.model
        elif ident == "pca-v1":
            s = log_samples(training[0], lm.model, RATE_HZ)
            cols = [list(lm.model.input_names).index(n) for n in s.input_names]
            u_abs = s.du + np.asarray(lm.model.u0)[cols]
            self.det = build_detector(DetectorSpec(ident, {"train_u": u_abs, "train_y": s.dy + s.y0}), lm.model)
            self._model = lm.model
        else:
            self.det = build_detector(DetectorSpec(ident, {}), lm.model)
            self._model = lm.model

    def trace(self, log: Any) -> DetectorTrace:
        s = log_samples(log, self._model, RATE_HZ)
        if hasattr(self.det, "run"):  # kalman-gust-v1, the kinematic checks
            thr = self.det.threshold if self.id == "kalman-gust-v1" else float(self.det.design.threshold)
            return run_vectorised(self.det, self.id, s, thr)
        if hasattr(self.det, "process_block"):  # a stream only (the engine-gauge check)
            return run_stream(self.det, self.id, s, self._model)
        return run_detector(self.det, self.id, s, self._model)


def calibrated_threshold(traces: Sequence[DetectorTrace], target: float) -> float:
    """Empirical ``1 - target`` quantile of the valid statistics."""
    x = np.concatenate([t.statistic[t.valid & np.isfinite(t.statistic)] for t in traces])
    if x.size * target < 5:
        return math.nan
    return float(np.quantile(x, 1.0 - target))


def _alarm(tr: DetectorTrace, thr: float) -> np.ndarray:
    return tr.valid & np.isfinite(tr.statistic) & (np.nan_to_num(tr.statistic, nan=-np.inf) > thr)


def condition_card(aircraft: str, turbulence: str, ids: Sequence[str], *, n_train: int, duration_s: float,
                   target: float = DEFAULT_TARGET, held_out: Sequence[int] = CARD_SEEDS,
                   say: Callable[[str], None] = print) -> list[FalseAlarms]:
    """False alarms of every detector at one condition (module docstring)."""
    sc = cruise_scenario(aircraft, turbulence, duration_s)
    t0 = time.perf_counter()
    training = fly_training(sc, training_seeds(n_train), duration_s, progress=False)
    held = fly_training(sc, held_out, duration_s, progress=False)
    say(f"{aircraft} {turbulence}: {len(training)} + {len(held)} flights in {time.perf_counter() - t0:.0f} s")
    lm = _log_model(sc)
    out = []
    for ident in ids:
        t1 = time.perf_counter()
        if ident in NOT_APPLICABLE:
            out.append(FalseAlarms(ident, aircraft, turbulence, target, 0, 0, 0, math.nan, math.nan, math.nan, 0.0,
                                   False, NOT_APPLICABLE[ident]))
            continue
        try:
            runner = _Runner(ident, lm, training, target, duration_s)
            tr_train = [runner.trace(lg) for lg in training]
            tr_held = [runner.trace(lg) for lg in held]
        except (FdiSimError, ValueError, TypeError, np.linalg.LinAlgError) as exc:
            out.append(FalseAlarms(ident, aircraft, turbulence, target, 0, 0, 0, math.nan, math.nan, math.nan, 0.0,
                                   False, f"{type(exc).__name__}: {exc}"[:300]))
            say(f"  {ident:26} not designed: {str(exc)[:120]}")
            continue
        thr = calibrated_threshold(tr_train, target)
        n = int(sum(int(t.valid.sum()) for t in tr_held))
        own = float(np.nanmedian(np.concatenate([t.threshold for t in tr_held]))) if tr_held else math.nan
        if runner.analytic is not None:  # kalman-gust-v1: its design's own prediction
            own = runner.analytic.threshold
            k_own = int(sum(int(runner.analytic.run(log_samples(lg, runner.det.design.model, RATE_HZ)).alarm.sum())
                            for lg in held))
        else:  # the detector's own decisions (its design threshold, or the shipped calibration)
            k_own = int(sum(int(t.alarm.sum()) for t in tr_held))
        alarms = [_alarm(t, thr) for t in tr_held]
        k = int(sum(int(a.sum()) for a in alarms))
        onsets = sum(alarm_onsets(a) for a in alarms)
        hours = sum(len(t.t_s) for t in tr_held) / RATE_HZ / 3600.0
        cost = float(np.median([t.cost_us_per_sample for t in tr_held]))
        meets = bool(n > 0 and math.isfinite(thr) and k <= binomial_upper(n, target))
        out.append(FalseAlarms(ident, aircraft, turbulence, target, n, k_own, k, thr, own, onsets / hours if hours else 0.0,
                               cost, meets))
        say(f"  {ident:26} held-out {k}/{n} ({k / max(n, 1):.1e}) calibrated, {k_own} with its own threshold; "
            f"{'meets' if meets else 'misses'} {target:g}  [{time.perf_counter() - t1:.0f} s]")
    return out


def cruise_scenario(aircraft: str, turbulence: str, duration_s: float) -> Scenario:
    from fdi_sim.scenario.loader import from_dict

    sc = load(shipped_dir() / f"{CRUISE[aircraft]}.toml")
    data = json.loads(sc.to_json())
    data["atmosphere"]["turbulence"] = turbulence
    data["duration_s"] = float(duration_s)
    return from_dict(data, source=f"{sc.source} (turbulence {turbulence})")


def fault_card(scenario_path: str | Path, ids: Sequence[str], *, n_train: int, duration_s: float,
               target: float = DEFAULT_TARGET, say: Callable[[str], None] = print
               ) -> tuple[list[FaultResult], dict[str, DetectorTrace], dict[str, float]]:
    """Every detector on one shipped fault scenario; also the traces and thresholds (for figures)."""
    import tempfile

    from fdi_sim.training import fly

    sc = load(scenario_path)
    with tempfile.TemporaryDirectory() as tmp:
        res = fly(sc, tmp, progress=False)
        if res.status == "interrupted":
            raise KeyboardInterrupt(f"{sc.name} interrupted")
        log = read_log(res.log_path)  # a diverged run (the fault's physics) is still a whole log
    training = fly_training(sc, training_seeds(n_train), duration_s, progress=False)
    lm = _log_model(sc)
    faults = fault_windows(log)
    out, traces, thresholds = [], {}, {}
    for ident in ids:
        if ident in NOT_APPLICABLE:
            continue
        try:
            runner = _Runner(ident, lm, training, target, duration_s)
            thr = calibrated_threshold([runner.trace(lg) for lg in training], target)
            tr = runner.trace(log)
        except (FdiSimError, ValueError, TypeError, np.linalg.LinAlgError) as exc:
            for f in faults:
                out.append(FaultResult(sc.name, ident, f["label"], f.get("target", ""), float(f["windows_s"][0][0]),
                                       0, None, None, None, None, f"{type(exc).__name__}: {exc}"[:200]))
            continue
        traces[ident], thresholds[ident] = tr, thr
        alarm = _alarm(tr, thr) if math.isfinite(thr) else np.zeros(len(tr.t_s), dtype=bool)
        for f in faults:
            fo = fault_outcome(f, tr.t_s, alarm, tr.isolation)
            before = int((alarm & (tr.t_s < fo.t_onset_s)).sum())
            res = FaultResult(sc.name, ident, fo.label, fo.target, fo.t_onset_s, before, fo.first_alarm_s, fo.delay_s,
                              fo.isolated_as, fo.isolation_correct)
            out.append(res)
            say(f"  {sc.name:24} {ident:26} before {before:3d}  delay "
                f"{'-' if res.delay_s is None else f'{res.delay_s:.2f} s':>8}  isolated {res.isolated_as}")
    return out, traces, thresholds


def to_json(rows: Sequence[Any]) -> list[dict[str, Any]]:
    return [asdict(r) for r in rows]
