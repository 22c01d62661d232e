"""Offline detection: registered detectors over any flight log (``fdi-sim detect``).

For a log written by ``fdi-sim run``: the scenario text in its metadata gives the aircraft and
the trim point; the linearizer trims and linearizes that point (JSBSim, a few seconds); each
detector is designed from the model discretized at the detector rate and put in the standard
form of the samples' time convention (:func:`fdi_sim.detectors.samples.paired_model`); the
logged commands and measurements become samples by that convention
(:func:`fdi_sim.detectors.samples.log_samples`); each detector steps through them. Per detector
the report gives the samples, alarm samples and onsets, flight hours and, for each injected
fault (the log's fault truth), the onset, the first alarm after it, the delay and the isolation.
"""
from __future__ import annotations

import difflib
import json
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim import registry
from fdi_sim.detectors.samples import Samples, log_samples
from fdi_sim.detectors.spec import DetectorSpec, build_detector, check_options
from fdi_sim.errors import DesignError, ScenarioError
from fdi_sim.bank.members import DEFAULT_BANKS
from fdi_sim.flightlog import METADATA_SCENARIO, TOPIC_FAULT_EVENTS, fdi_topic, read_log
from fdi_sim.flightlog.copy import NewEventTopic, NewVectorTopic, write_extended
from fdi_sim.flightlog.reader import FlightLog
from fdi_sim.flightlog.schemas import ALARM_JSON_SCHEMA, TOPIC_FDI_ALARMS
from fdi_sim.decision.outcome import FaultOutcome, alarm_onsets, fault_outcome
from fdi_sim.training.gust import CALIBRATION_OPTIONS
from fdi_sim.training.models import LogModel, model_for_log
from fdi_sim.units import S_PER_H

DEFAULT_RATE_HZ = 20.0

#: named banks: the detectors ``docs/detectors.md`` finds working on these aircraft (``--bank``).
#: kalman-gust-v1 is calibrated on the log's own scenario (fault-free, 24 x 300 s, 1e-4 per sample);
#: the kinematic checks carry their calibrated thresholds per aircraft and turbulence level.
BANKS: dict[str, tuple[str, ...]] = {"default": DEFAULT_BANKS["f16"]}  # the same detectors on both aircraft


#: ``--bank scenario``: replay the bank the log's own scenario defines (the in-loop bank)
SCENARIO_BANK = "scenario"


def bank_specs(name: str) -> list[DetectorSpec]:
    """The detectors of a named bank."""
    if name not in BANKS:
        close = difflib.get_close_matches(name, list(BANKS), n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ScenarioError("--bank", name, f"unknown bank {name!r}{hint}", f"one of {', '.join(BANKS)}, "
                            f"{SCENARIO_BANK} (the log's own in-loop bank)")
    return [DetectorSpec(i) for i in BANKS[name]]


@dataclass(frozen=True, eq=False)
class DetectorTrace:
    """One detector over one log, at the detector rate."""

    id: str
    t_s: NDArray[np.float64]
    statistic: NDArray[np.float64]
    threshold: NDArray[np.float64]
    alarm: NDArray[np.bool_]
    valid: NDArray[np.bool_]
    isolation: tuple[str | None, ...]
    cost_us_per_sample: float


@dataclass(frozen=True)
class DetectorOutcome:
    """Counts for one detector over one log (``--json`` keys)."""

    id: str
    params: dict[str, Any]
    samples: int
    valid_samples: int
    alarm_samples: int
    alarm_fraction: float
    alarm_onsets: int
    flight_h: float
    onsets_per_h: float
    fault_free_samples: int
    fault_free_alarm_samples: int
    cost_us_per_sample: float
    faults: tuple[FaultOutcome, ...]
    error: str = ""


@dataclass(frozen=True)
class DetectReport:
    """What ``fdi-sim detect`` prints."""

    log_path: str
    aircraft: str
    rate_hz: float
    detectors: tuple[DetectorOutcome, ...]
    out_path: str | None = None

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=1, default=float)

    def format(self) -> str:
        lines = [f"log        {self.log_path} ({self.aircraft}, detectors at {self.rate_hz:g} Hz)"]
        for d in self.detectors:
            if d.error:
                lines.append(f"{d.id:24} not designed: {d.error}")
                continue
            lines.append(f"{d.id:24} {d.samples} samples ({d.flight_h * 60:.1f} min), alarm on {d.alarm_samples} "
                         f"({100 * d.alarm_fraction:.2f} %), {d.alarm_onsets} onsets ({d.onsets_per_h:.0f} /h); "
                         f"valid {d.valid_samples}; fault-free {d.fault_free_alarm_samples}/{d.fault_free_samples}; "
                         f"{d.cost_us_per_sample:.1f} us/sample")
            for f in d.faults:
                if f.first_alarm_s is None:
                    lines.append(f"  {f.label:22} onset {f.t_onset_s:.2f} s: not detected")
                else:
                    iso = f"isolated as {f.isolated_as}" + ("" if f.isolation_correct is None else
                                                            (" (right)" if f.isolation_correct else " (wrong)"))
                    lines.append(f"  {f.label:22} onset {f.t_onset_s:.2f} s: first alarm {f.first_alarm_s:.2f} s, "
                                 f"delay {f.delay_s:.2f} s, {iso if f.isolated_as else 'not isolated'}")
        if self.out_path:
            lines.append(f"out        {self.out_path}")
        return "\n".join(lines)


def fault_windows(log: FlightLog) -> list[dict[str, Any]]:
    """The injected faults of a log: label, type, target and windows [s] (from ``/faults/events``)."""
    t = log.topics.get(TOPIC_FAULT_EVENTS)
    if t is None:
        return []
    for e in t.events:
        if e.payload.get("event") == "catalog":
            return [dict(f) for f in e.payload.get("faults", [])]
    return []


def run_detector(det: Any, ident: str, samples: Samples, model: Any) -> DetectorTrace:
    """Step a detector through the samples (absolute u, y in the model's order, disturbances 0)."""
    n = samples.n
    m_in = tuple(model.input_names)
    cols = [m_in.index(nm) for nm in samples.input_names]
    u_abs = np.tile(np.asarray(model.u0, dtype=float), (n, 1))
    u_abs[:, cols] += samples.du
    y_abs = np.where(samples.valid, samples.dy + samples.y0, np.nan)  # a dropout is not a measurement
    stat = np.full(n, np.nan)
    thr = np.full(n, np.nan)
    alarm = np.zeros(n, dtype=bool)
    valid = np.zeros(n, dtype=bool)
    iso: list[str | None] = [None] * n
    if hasattr(det, "reset"):
        det.reset(np.random.default_rng(0))
    t0 = time.perf_counter()
    for j in range(n):
        r = det.step(float(samples.t_s[j]), u_abs[j], y_abs[j])
        ok = bool(r.valid and math.isfinite(r.statistic))  # a NaN statistic is never a valid "no alarm"
        stat[j], thr[j], valid[j] = r.statistic, r.threshold, ok
        alarm[j] = bool(r.alarm) and ok
        iso[j] = r.isolation if alarm[j] else None
    cost = (time.perf_counter() - t0) / max(n, 1) * 1e6
    return DetectorTrace(ident, samples.t_s, stat, thr, alarm, valid, tuple(iso), cost)


def _run_spec(spec: DetectorSpec, lm: LogModel, log: FlightLog, samples: Samples, rate_hz: float,
              rates: Mapping[str, float]) -> DetectorTrace:
    """Design one detector for this log and run it (vectorised where the detector offers ``run``)."""
    sc = lm.scenario
    if spec.id == "kalman-gust-v1":  # designed at the log's point, calibrated on its fault-free flights
        from fdi_sim.training.gust import calibrated_gust_kalman

        check_options(spec, extra=CALIBRATION_OPTIONS)
        opts = {k: v for k, v in spec.params.items() if k in CALIBRATION_OPTIONS}
        design_opts = {k: v for k, v in spec.params.items() if k not in CALIBRATION_OPTIONS + ("rate_hz",)}
        det = calibrated_gust_kalman(sc, lm.continuous(), rate_hz=rate_hz, params=design_opts, **opts)
        return run_vectorised(det, spec.id, log_samples(log, det.design.model, rate_hz, sensor_rates_hz=rates),
                              det.threshold)
    if spec.id.startswith("kinematic-"):  # measurement checks: absolute measurements, the log's conditions
        from fdi_sim.detectors.kinematic import MeasurementSet

        params = {"turbulence": sc.model.atmosphere.turbulence, "aircraft": sc.aircraft, **spec.params}
        det = build_detector(DetectorSpec(spec.id, params), None)
        return run_vectorised(det, spec.id, log_samples(log, MeasurementSet(), rate_hz, sensor_rates_hz=rates),
                              float(det.design.threshold))
    if spec.id == "engine-gauges-v1":  # the engines' gauges against each other: the log's measurements
        from fdi_sim.detectors.kinematic import MeasurementSet

        det = build_detector(DetectorSpec(spec.id, {"aircraft": sc.aircraft, "rate_hz": rate_hz, **spec.params}), None)
        gauges = MeasurementSet(output_names=tuple(det.output_names))
        return run_stream(det, spec.id, log_samples(log, gauges, rate_hz, sensor_rates_hz=rates), gauges)
    det = build_detector(spec, lm.model)
    from fdi_sim.detectors.stream import StreamingDetector

    if isinstance(det, StreamingDetector):  # a plugin's stream: one block over the whole log
        return run_stream(det, spec.id, samples, lm.model)
    return run_detector(det, spec.id, samples, lm.model)


def run_stream(stream: Any, ident: str, samples: Samples, model: Any) -> DetectorTrace:
    """A :class:`~fdi_sim.detectors.stream.StreamingDetector` over the samples as one block
    (absolute commands and measurements in its columns; the alarm is ``valid and statistic >
    threshold`` per sample, as :func:`run_detector` reports a per-sample detector)."""
    from fdi_sim.detectors.stream import BlockOutputs

    n = samples.n
    u_abs = np.tile(np.asarray(model.u0, dtype=float), (n, 1))
    m_in = tuple(model.input_names)
    u_abs[:, [m_in.index(nm) for nm in samples.input_names]] += samples.du
    u = np.ascontiguousarray(u_abs[:, [m_in.index(nm) for nm in stream.input_names]])
    idx = [samples.output_names.index(nm) for nm in stream.output_names]
    y = np.ascontiguousarray((samples.dy + samples.y0)[:, idx])
    ok = np.ascontiguousarray(samples.valid[:, idx])
    fresh = np.ascontiguousarray(samples.fresh[:, idx])
    out = BlockOutputs.allocate(n, len(stream.residual_names), len(stream.estimate_names))
    stream.reset()
    t0 = time.perf_counter()
    stream.process_block(np.ascontiguousarray(samples.t_s, dtype=float), u, y, ok, fresh, out)
    cost = (time.perf_counter() - t0) / max(n, 1) * 1e6
    alarm = out.valid & (out.statistic > out.threshold)
    iso = tuple(stream.hypotheses[h] if a and h >= 0 else None for a, h in zip(alarm, out.hypothesis))
    return DetectorTrace(ident, samples.t_s, out.statistic.copy(), out.threshold.copy(), alarm, out.valid.copy(), iso,
                         cost)


def run_vectorised(det: Any, ident: str, samples: Samples, threshold: float) -> DetectorTrace:
    """A detector with a whole-flight ``run(samples)`` (kalman-gust, the kinematic checks), timed."""
    t0 = time.perf_counter()
    r = det.run(samples)
    cost = (time.perf_counter() - t0) / max(samples.n, 1) * 1e6
    return DetectorTrace(ident, r.t_s, r.statistic, np.full(samples.n, threshold), np.asarray(r.alarm, dtype=bool),
                         np.asarray(r.valid, dtype=bool), tuple(r.isolation), cost)


def outcome(trace: DetectorTrace, spec: DetectorSpec, faults: Sequence[Mapping[str, Any]], rate_hz: float) -> DetectorOutcome:
    """Counts, onsets and per-fault detection of one trace."""
    a = trace.alarm
    onsets = alarm_onsets(a)
    faulty = np.zeros(len(a), dtype=bool)
    for f in faults:
        for w0, w1 in f.get("windows_s", []):
            faulty |= (trace.t_s >= w0) & (trace.t_s < w1)
    flight_h = len(a) / rate_hz / S_PER_H
    outs = [fault_outcome(f, trace.t_s, a, trace.isolation) for f in faults if f.get("windows_s")]
    return DetectorOutcome(
        id=spec.id, params=dict(spec.params), samples=len(a), valid_samples=int(trace.valid.sum()),
        alarm_samples=int(a.sum()), alarm_fraction=float(a.mean()) if len(a) else 0.0, alarm_onsets=onsets,
        flight_h=flight_h, onsets_per_h=onsets / flight_h if flight_h else 0.0,
        fault_free_samples=int((~faulty).sum()), fault_free_alarm_samples=int((a & ~faulty).sum()),
        cost_us_per_sample=trace.cost_us_per_sample, faults=tuple(outs))


def detect_log(path: str | Path, specs: Sequence[DetectorSpec], rate_hz: float = DEFAULT_RATE_HZ,
               out: str | Path | None = None) -> tuple[DetectReport, list[DetectorTrace]]:
    """Run detectors over a flight log.

    Parameters
    ----------
    path : path
        A log written by ``fdi-sim run``.
    specs : sequence of DetectorSpec
        The detectors; at least one.
    rate_hz : float
        Detector rate [Hz]; must divide the log's rate.
    out : path, optional
        Write the input's topics plus ``/fdi/<id>/statistic`` (statistic, threshold, alarm,
        valid per sample) and ``/fdi/alarms`` (every alarm transition: raised with its isolation,
        cleared) here.

    Returns
    -------
    (DetectReport, list of DetectorTrace)
        A detector that cannot be designed is reported with its reason (``error``), not raised.
    """
    if not specs:
        raise ScenarioError("--detector", "", "no detector given", "pass --detector ID (see `fdi-sim plugins`)")
    log = read_log(path)
    lm = model_for_log(log, rate_hz)
    model, aircraft = lm.model, lm.aircraft
    from fdi_sim.sensors import load_suite

    rates = {s.name: s.rate_hz for s in load_suite(aircraft)}
    samples = log_samples(log, model, rate_hz, sensor_rates_hz=rates)
    faults = fault_windows(log)
    outcomes, traces = [], []
    for spec in specs:
        registry.get("detector", spec.id)  # an unknown id is bad input, with its "did you mean"
        try:
            tr = _run_spec(spec, lm, log, samples, rate_hz, rates)
        except (DesignError, TypeError, ValueError) as exc:
            if isinstance(exc, ScenarioError):
                raise
            outcomes.append(DetectorOutcome(spec.id, dict(spec.params), samples.n, 0, 0, 0.0, 0, 0.0, 0.0, 0, 0, 0.0, (),
                                            error=str(exc)))
            continue
        traces.append(tr)
        outcomes.append(outcome(tr, spec, faults, rate_hz))
    out_path = None
    if out is not None:
        out_path = str(_write(log, Path(out), traces, rate_hz))
    return DetectReport(str(path), aircraft, float(rate_hz), tuple(outcomes), out_path), traces


def _write(log: FlightLog, out: Path, traces: Sequence[DetectorTrace], rate_hz: float) -> Path:
    """The input's topics plus the offline results; under ``/fdi/offline/`` when the log already
    has an in-loop bank's ``/fdi`` topics (the two never share a topic or a schema name)."""
    vectors, alarms = [], []
    inloop = any(t.startswith("/fdi/") for t in log.topics)
    for tr in traces:
        vals = np.column_stack([tr.statistic, tr.threshold, tr.alarm.astype(float), tr.valid.astype(float)])
        topic = f"/fdi/offline/{tr.id}/statistic" if inloop else fdi_topic(tr.id, "statistic")
        vectors.append(NewVectorTopic(topic, "fdi_sim/msg/OfflineDetectorStatistic",
                                      ("statistic", "threshold", "alarm", "valid"), tr.t_s, vals))
        a = tr.alarm
        before = np.concatenate(([False], a[:-1]))
        for j in np.flatnonzero(a != before):  # every transition: raised (with its isolation) and cleared
            ev = {"detector": tr.id, "alarm": bool(a[j]), "isolation": tr.isolation[j]}
            for key, x in (("statistic", tr.statistic[j]), ("threshold", tr.threshold[j])):
                if math.isfinite(x):  # a non-finite statistic is left out, not written as a number
                    ev[key] = float(x)
            alarms.append((float(tr.t_s[j]), ev))
    alarms.sort(key=lambda e: e[0])
    events = [NewEventTopic("/fdi/offline/alarms" if inloop else TOPIC_FDI_ALARMS, "fdi_sim/msg/OfflineAlarm",
                            ALARM_JSON_SCHEMA, tuple(alarms))]
    meta = {"detect": {"rate_hz": f"{rate_hz:g}", "detectors": json.dumps([t.id for t in traces]),
                       "source": str(log.path)}}
    return write_extended(log, out, vectors, events, meta)


def replay_bank(path: str | Path, bank: str | None = None) -> tuple[DetectReport, dict[str, Any]]:
    """``fdi-sim detect LOG --bank scenario``: the log's in-loop bank replayed over its rows
    (``bank="default"``: the default in-loop bank of the log's scenario, whatever it flew with).

    Returns the report and, per member, whether the replay equals the log's
    ``/fdi/<id>/statistic`` topic bit for bit (statistic, threshold, decision, isolation, point,
    time) where the log has it.
    """
    from fdi_sim.training.build import bank_for_log, replay_log

    log = read_log(path)
    name, bank = bank, bank_for_log(log, bank=bank, progress=True)
    t0 = time.perf_counter()
    traces = replay_log(log, bank)
    cost = (time.perf_counter() - t0) / max(1, bank.samples_done * len(bank.members)) * 1e6
    faults = fault_windows(log)
    outcomes, same = [], {}
    for m in bank.members:
        v = traces[m.id]
        iso = tuple(m.hypotheses[i] if a and i >= 0 else None for i, a in zip(v["isolation"], v["alarm"]))
        tr = DetectorTrace(m.id, v["t_s"], v["statistic"], v["threshold"], v["alarm"].astype(bool),
                           v["valid"].astype(bool), iso, cost)
        outcomes.append(outcome(tr, DetectorSpec(m.id), faults, bank.rate_hz))
        topic = fdi_topic(m.id, "statistic")
        if topic in log.topics and bank_name_is_the_logs(log, name):
            tp = log.topics[topic]
            same[m.id] = all(np.array_equal(np.asarray(tp[k], dtype=float), np.asarray(v[k], dtype=float), equal_nan=True)
                             for k in ("t_s", "statistic", "threshold", "exceedance", "alarm", "valid", "isolation", "point"))
    return DetectReport(str(path), bank.meas_names and log.metadata.get(METADATA_SCENARIO, {}).get("aircraft", "?"),
                        bank.rate_hz, tuple(outcomes)), same


def bank_name_is_the_logs(log: FlightLog, bank: str | None) -> bool:
    """Whether the replayed bank is the one the log flew with (then its /fdi topics must match)."""
    if bank is None:
        return True
    meta = json.loads(log.metadata.get(METADATA_SCENARIO, {}).get("json", "{}"))
    return meta.get("fdi", {}).get("bank", "none") == bank and not meta.get("detectors")
