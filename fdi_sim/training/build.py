"""Building a scenario's FDI bank: its members' designs and thresholds, and flying a scenario with it.

How a member is *designed* differs by detector family (:func:`member_stream`); how it *runs* does
not (:mod:`fdi_sim.detectors.stream`). Designs and thresholds are made at the bank's design
conditions (:func:`design_scenario`), cached on disk, and cost training flights only where the
cache or a shipped thresholds file does not cover them. :func:`fly` is ``fdi_sim.sim.run`` with
the scenario's bank.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from fdi_sim import registry
from fdi_sim.errors import DesignError, ScenarioError
from fdi_sim.scenario import Scenario
from fdi_sim.bank.members import per_sample_target
from fdi_sim.training.flights import LazyTraining
from fdi_sim.training.schedule import design_choice
from fdi_sim.training.thresholds import (
    MemberThresholdError, _replay_log, apply_study_thresholds, apply_turbulence_schedule, calibrate_thresholds,
    note_no_match, thresholds_source,
)
from fdi_sim.scenario.loader import from_dict
from fdi_sim.threads import single_blas_thread
from fdi_sim.bank.members import ENTRY_KEYS, MemberSpec, bank_members
from fdi_sim.bank.runtime import FdiBank
from fdi_sim.sensors import SensorSuite
from fdi_sim.sim.run import PILOT_FIELDS, run, RunResult


#: per-process memo of gust-filter schedules (design scenario -> schedule, note), or None (off): a
#: Monte Carlo worker turns it on (fdi_sim.study.execute.fly_run): the design (DARE, linearization,
#: 0.25 s) was 3/4 of a short run's set-up; off elsewhere, so a changed cache is always read again
DESIGN_MEMO: dict[str, tuple[Any, str]] | None = None


@single_blas_thread
def build_bank(sc: Scenario, *, meas_names: Sequence[str], cmd_names: Sequence[str],
               sensor_rates_hz: dict[str, float], pilot_sensors: Sequence[str], progress: bool = True,
               training_logs: Sequence[Any] | None = None) -> Any:
    """The scenario's :class:`~fdi_sim.bank.runtime.FdiBank`, designed and calibrated (cached on disk).

    Raises
    ------
    ScenarioError
        An unknown detector id, or a plugin that fails its contract check.
    DesignError
        A detector that cannot be designed (``on_design_failure = "refuse"``; with ``"skip"`` it is
        left out and the bank's notes say why), with where and why.
    """
    from fdi_sim.bank.runtime import DecisionConfig, FdiBank

    members = bank_members(sc)
    if not members:
        return None
    sc, design_note = design_choice(sc)  # designs, training flights and thresholds: at the design conditions
    f = sc.model.fdi
    # the training flights are flown at most once, and only if some calibration is not cached
    logs = training_logs if training_logs is not None else LazyTraining(sc, progress)
    ctx = MemberContext(sc, tuple(cmd_names), tuple(meas_names), progress, logs)
    streams: list[Any] = []
    notes = [f"design: {design_note}"] if design_note else []
    for m in members:
        try:
            stream, note = member_stream(ctx, m)
        except DesignError as exc:
            if f.on_design_failure != "skip":
                raise
            notes.append(f"{m.id}: skipped, it cannot be designed here ({exc})")  # on_design_failure = "skip"
            continue
        streams.append(stream)
        notes.append(note)
    if not streams:
        raise DesignError(f"{sc.source}: no member of the bank could be designed: {'; '.join(notes)}")
    if f.decision == "angle-magnitude":
        bad = [s.id for s in streams if not s.fault_directions]
        if bad:
            raise ScenarioError(sc.source, "fdi.decision", f"angle-magnitude needs fault directions (C D_f), which "
                                f"{', '.join(bad)} do not give", 'use decision = "persistence", or members with '
                                "fault directions only ([[detectors]] without bank = \"default\")")
    S = int(round(f.block_s * f.rate_hz))
    decision = DecisionConfig(f.persistence_k, f.persistence_n, max(1, int(round(f.confirm_s * f.rate_hz))), f.decision)
    while True:  # once, or again without a member whose threshold cannot be set (on_design_failure = "skip")
        bank = FdiBank(streams, cmd_names=cmd_names, meas_names=meas_names, sensor_rates_hz=sensor_rates_hz,
                       sim_rate_hz=float(sc.model.rate_hz), rate_hz=f.rate_hz, block_samples=S, decision=decision,
                       reconfigure=f.reconfigure, pilot_sensors=pilot_sensors, notes=tuple(notes), arm_s=f.arm_s)
        try:
            _set_thresholds(sc, bank, logs, progress, design_note)
            return bank
        except MemberThresholdError as exc:
            if f.on_design_failure != "skip" or len(streams) == 1:
                raise
            streams = [st for st in streams if st.id != exc.member]
            notes = [n if not n.startswith(f"{exc.member}:") else f"{exc.member}: skipped, no threshold ({exc})"
                     for n in notes]


def _set_thresholds(sc: Scenario, bank: Any, logs: Any, progress: bool, design_note: str = "") -> None:
    """Every member's threshold: from the scenario's thresholds file where it covers the bank,
    else trained on the fault-free flights (:mod:`fdi_sim.training.thresholds`)."""
    f = sc.model.fdi
    p = per_sample_target(f.far_per_h, len(bank.members), f.rate_hz)
    path, explicit = thresholds_source(sc)
    if path is not None:
        trained: list[bool] = []

        def retrain() -> None:  # the bank's trained thresholds, once (the file's match on another CPU)
            if not trained:
                calibrate_thresholds(sc, bank, p, training_logs=logs, progress=progress)
                trained.append(True)

        note = apply_study_thresholds(sc, bank, path, explicit=explicit, retrain=retrain)
        if note is None:  # the default's file does not cover this design: trained, and the log says why
            retrain()
            bank.calibration = {**bank.calibration, "source": _trained_source(bank), "note": note_no_match(sc, path)}
    else:
        calibrate_thresholds(sc, bank, p, training_logs=logs, progress=progress)
        bank.calibration = {**bank.calibration, "source": _trained_source(bank)}
    apply_turbulence_schedule(sc, bank, p)
    if design_note:
        bank.calibration = {**bank.calibration, "design": design_note}


def _trained_source(bank: Any) -> str:
    """``"atlas"`` when the trained thresholds came from the shipped atlas (no flight), else ``"trained"``."""
    return "atlas" if "atlas" in (bank.calibration or {}) else "trained"


@dataclass
class MemberContext:
    """What designing one member of a scenario's bank may use.

    Attributes
    ----------
    sc : Scenario
        The design scenario (:func:`design_scenario`).
    cmd_names, meas_names : tuple of str
        The commands and measurements the loop logs (a member reads a subset).
    progress : bool
        Show progress bars (training flights, schedule designs).
    training_logs : sequence
        The fault-free training flights (lazy: flown on first use).
    """

    sc: Scenario
    cmd_names: tuple[str, ...]
    meas_names: tuple[str, ...]
    progress: bool
    training_logs: Any
    _lm: Any = None

    def log_model(self) -> Any:
        """The scenario's initial point trimmed and linearized (:func:`fdi_sim.training.models.model_for_scenario`),
        made once: ``.model`` at the bank's rate in the samples' form, ``.continuous()``."""
        if self._lm is None:
            from fdi_sim.training.models import model_for_scenario

            self._lm = model_for_scenario(self.sc, self.sc.model.fdi.rate_hz)
        return self._lm

    def model(self) -> Any:
        """The linear model at the scenario's initial point, at the bank's rate, in the samples' form."""
        return self.log_model().model


def member_stream(ctx: MemberContext, m: MemberSpec) -> tuple[Any, str]:
    """One member's :class:`~fdi_sim.detectors.stream.StreamingDetector` and a note for the log.

    How a detector is *designed* differs by family; how it *runs* does not. The gust filter is
    gain-scheduled over the flight's points and calibrated on training flights
    (:func:`_gust_stream`); the kinematic checks take the aircraft and turbulence
    (:func:`_kinematic_stream`); every other detector, built in or a plugin, is built by its
    registered factory from the linear model at the initial point (:func:`_model_stream`).
    """
    builder = _DESIGNERS.get(m.id, _model_stream)
    return builder(ctx, m)


def _continuous_stream(ctx: MemberContext, m: MemberSpec) -> tuple[Any, str]:
    """A detector designed on the continuous linearization, run at the bank's rate (lmi-detection-v1:
    its LMI is a continuous-time design; the detector card designs it the same way)."""
    return _model_stream(ctx, m, design_model=ctx.log_model().continuous(),
                         extra={"dt_s": 1.0 / float(ctx.sc.model.fdi.rate_hz)})


def _pca_stream(ctx: MemberContext, m: MemberSpec) -> tuple[Any, str]:
    """pca-v1: its residual space is learned from data, the first fault-free training flight (the
    same flights the thresholds are set on; the detector card trains it the same way)."""
    return _model_stream(ctx, m, extra=_pca_training(ctx))


def _pca_training(ctx: MemberContext) -> dict[str, np.ndarray]:
    """pca-v1's training data: the first fault-free training flight's inputs and outputs at the
    bank's rate, ``{"train_u": (N, m), "train_y": (N, p)}`` in absolute units, cached on disk when
    the flights are the scenario's own (:class:`~fdi_sim.training.flights.LazyTraining`). Why: with
    its thresholds cached, a bank with pca-v1 still flew all its training flights for this one (17 s
    of the set-up of an F-16 run with 3.3 s of flight). Given training logs (a card's) are used as
    they are, not cached."""
    from fdi_sim.detectors.samples import log_samples
    from fdi_sim.training.cache import cache_dir, cache_lock, read_arrays, write_arrays

    model = ctx.model()

    def arrays() -> dict[str, np.ndarray]:
        first = next(iter(ctx.training_logs))
        s = log_samples(first, model, float(ctx.sc.model.fdi.rate_hz))
        cols = [list(model.input_names).index(nm) for nm in s.input_names]
        return {"train_u": s.du + np.asarray(model.u0, dtype=float)[cols], "train_y": s.dy + s.y0}

    if not isinstance(ctx.training_logs, LazyTraining):
        return arrays()
    path = cache_dir() / f"pca-train-{_pca_training_key(ctx.sc, model)}.npz"
    with cache_lock(path):  # a study's other worker making the same entry: wait, then read it
        out = read_arrays(path, ("train_u", "train_y"))  # None when absent or damaged: made again
        if out is None:
            out = arrays()
            write_arrays(path, out)
    return out


def _pca_training_key(sc: Scenario, model: Any) -> str:
    """What pca-v1's training data depends on: the fault-free training scenario (as the thresholds'
    key has it), the training seeds and length, the bank's rate, the sensor suite file, the model the
    samples are taken against (matrices, operating point, signal names) and the package version."""
    from fdi_sim.training.cache import arrays_digest, scenario_parts
    from fdi_sim.training.flights import training_seeds

    f = sc.model.fdi
    parts = {**scenario_parts(sc, f.calibration_duration_s), "seeds": list(training_seeds(f.calibration_flights)),
             "T": f.calibration_duration_s, "rate_hz": float(f.rate_hz),
             "names": [list(model.input_names), list(model.output_names)],
             "model": arrays_digest((model.A, model.B, model.C, model.D, model.u0, model.y0))}
    return hashlib.sha256(json.dumps(parts, sort_keys=True, default=str).encode()).hexdigest()[:24]


def _model_stream(ctx: MemberContext, m: MemberSpec, *, design_model: Any = None,
                  extra: dict[str, Any] | None = None) -> tuple[Any, str]:
    """A detector designed by its registry factory from the initial point's model. A factory that
    returns a :class:`~fdi_sim.detectors.stream.StreamingDetector` (a plugin's) runs as it is; a
    per-sample detector runs through its compiled stream where one exists
    (:func:`fdi_sim.detectors.seed_streams.compiled_stream`), else through
    :class:`~fdi_sim.detectors.step_stream.StepStream`."""
    from fdi_sim.detectors.step_stream import StepStream
    from fdi_sim.detectors.stream import StreamingDetector
    from fdi_sim.detectors.spec import build_detector, DetectorSpec

    sc = ctx.sc
    params = {k: v for k, v in m.params.items() if k != "type"}  # n_flights, ...: kalman-gust-v1's, refused here
    model = ctx.model()
    where = f"h {sc.model.initial.h_ft:g} ft"
    try:
        det = build_detector(DetectorSpec(m.id, {**(extra or {}), **params}),
                             model if design_model is None else design_model)
    except DesignError as exc:
        raise DesignError(f"{sc.source}: {m.id} cannot be designed at the initial point ({where}): {exc}") from None
    except (TypeError, ValueError) as exc:  # a plugin factory's own refusal of its options: bad input
        if registry.get("detector", m.id).origin == "fdi-sim":
            raise
        raise ScenarioError(sc.source, m.source, f"plugin detector {m.id} refused its options: "
                            f"{type(exc).__name__}: {exc}", "fix the [[detectors]] entry's options") from None
    if isinstance(det, StreamingDetector):
        stream, how = det, "its own stream"
    else:
        from fdi_sim.detectors.seed_streams import compiled_stream

        stream = compiled_stream(det, model, ctx.cmd_names, m.id)
        how = "compiled stream"
        if stream is None:
            stream, how = StepStream(det, model, ctx.cmd_names, params, id=m.id), "per-sample step (Python)"
    if str(getattr(stream, "id", "")) != m.id:
        raise DesignError(f"{m.id}: the factory returned a detector whose id is {getattr(stream, 'id', None)!r}; a "
                          "member's id is its registered id")
    origin = registry.get("detector", m.id).origin
    if origin != "fdi-sim":  # a plugin: checked before it flies (the built-ins are checked by the suite)
        from fdi_sim.detectors.check import CORRECTNESS, check_stream, contract_inputs

        fails = check_stream(stream, contract_inputs(stream, model, rate_hz=sc.model.fdi.rate_hz))
        wrong = [f for f in fails if f.check in CORRECTNESS]
        if wrong:  # refused whatever on_design_failure says: its numbers would be wrong, not missing
            raise ScenarioError(sc.source, m.source, f"plugin detector {m.id} ({origin}) fails its contract check: "
                                + "; ".join(str(f) for f in wrong), "fix the plugin (fdi_sim.detectors.check."
                                "check_stream runs the same checks), or remove it from the scenario")
        how = f"plugin from {origin}" + "".join(f"; {f}" for f in fails)
    return stream, f"{m.id}: one design at the initial point ({where}), {how}"


def _gust_stream(ctx: MemberContext, m: MemberSpec) -> tuple[Any, str]:
    """kalman-gust-v1: gain-scheduled over the flight's points, ``Sigma_m`` from training flights."""
    sc, progress, training_logs = ctx.sc, ctx.progress, ctx.training_logs
    from fdi_sim.detectors.gust_kalman_stream import GustKalmanStream
    from fdi_sim.detectors.scheduled import GustKalmanSchedule
    from fdi_sim.training.gust import calibrated_gust_kalman
    from fdi_sim.training.models import model_for_scenario
    from fdi_sim.training.gust import CALIBRATION_OPTIONS

    f = sc.model.fdi
    # the bank sets the threshold itself (calibrate_thresholds); of the filter's own calibration it
    # uses Sigma_m only, so its quantile target just has to be one the flights can give
    n_samples = f.calibration_flights * max(1.0, f.calibration_duration_s - 5.0) * f.rate_hz
    cal_opts = {"n_flights": f.calibration_flights, "duration_s": f.calibration_duration_s,
                "target": max(1e-4, 20.0 / n_samples)}
    cal_opts.update({k: v for k, v in m.params.items() if k in CALIBRATION_OPTIONS})
    design_opts = {k: v for k, v in m.params.items() if k not in CALIBRATION_OPTIONS + ("rate_hz", "min_cosine")}
    min_cos = float(m.params.get("min_cosine", 0.7))
    from fdi_sim.training.schedule import design_schedule, schedule_points

    memo_key = None
    if DESIGN_MEMO is not None:  # a study worker: the same design for many runs, made once per process
        from fdi_sim.training.cache import cache_dir

        d = json.loads(sc.to_json())
        for k in ("seed", "name", "description", "faults"):  # the design sees no faults
            d.pop(k, None)
        memo_key = hashlib.sha256(json.dumps([d, m.id, sorted(m.params.items()), str(cache_dir())], sort_keys=True,
                                             default=str).encode()).hexdigest()
        if memo_key in DESIGN_MEMO:
            sched, note = DESIGN_MEMO[memo_key]
            return GustKalmanStream(sched, min_cosine=min_cos, id=m.id), note
    points = schedule_points(sc) if f.schedule == "auto" else []
    if len(points) > 1:
        sched = design_schedule(sc, points, rate_hz=f.rate_hz, params=design_opts, on_failure=f.on_design_failure,
                                progress=progress, **cal_opts)
        note = f"{m.id}: gain-scheduled over {sched.n_points} points ({'; '.join(sched.label(i) for i in range(sched.n_points))})"
    else:
        try:
            lm = model_for_scenario(sc, f.rate_hz)
            det = calibrated_gust_kalman(sc, lm.continuous(), rate_hz=f.rate_hz, params=design_opts, progress=progress,
                                         training_logs=training_logs, **cal_opts)
        except DesignError as exc:
            raise DesignError(f"{sc.source}: {m.id} cannot be designed at the initial point "
                              f"(h {sc.model.initial.h_ft:g} ft): {exc}") from None
        sched = GustKalmanSchedule.single(det.design, det.calibration)
        note = f"{m.id}: one design at the initial point ({sched.label(0)})"
    if memo_key is not None:
        DESIGN_MEMO[memo_key] = (sched, note)  # the stream copies what it needs: the schedule is not changed
    return GustKalmanStream(sched, min_cosine=min_cos, id=m.id), note


def _kinematic_stream(ctx: MemberContext, m: MemberSpec) -> tuple[Any, str]:
    """A kinematic check: its catalogue design for the aircraft and the turbulence level."""
    sc = ctx.sc
    from fdi_sim.detectors.kinematic_stream import KinematicStream
    from fdi_sim.detectors.spec import build_detector, DetectorSpec

    params = {"turbulence": sc.model.atmosphere.turbulence, "aircraft": sc.aircraft,
              **{k: v for k, v in m.params.items() if k not in ENTRY_KEYS}}
    det = build_detector(DetectorSpec(m.id, params), None)
    return KinematicStream(det), f"{m.id}: {det.design.kind} check ({sc.model.atmosphere.turbulence} turbulence)"


def _engine_gauge_stream(ctx: MemberContext, m: MemberSpec) -> tuple[Any, str]:
    """engine-gauges-v1: the aircraft's sensor suite gives its scales; no model, no training."""
    from fdi_sim.detectors.spec import build_detector, DetectorSpec

    sc = ctx.sc
    params = {"aircraft": sc.aircraft, "rate_hz": float(sc.model.fdi.rate_hz), "suite": sc.model.sensors.suite,
              **{k: v for k, v in m.params.items() if k not in ENTRY_KEYS}}
    det = build_detector(DetectorSpec(m.id, params), None)
    return det, f"{m.id}: the two engines' gauges against each other"


#: how each detector family is designed for a bank (:func:`member_stream`); every other id: its factory
_DESIGNERS: dict[str, Callable[[MemberContext, MemberSpec], tuple[Any, str]]] = {
    "kalman-gust-v1": _gust_stream,
    "lmi-detection-v1": _continuous_stream,
    "pca-v1": _pca_stream,
    "engine-gauges-v1": _engine_gauge_stream,
    **{f"kinematic-{k}-v1": _kinematic_stream for k in ("attitude", "altitude", "airspeed", "flow-angles")},
}


def bank_for_log(log: Any, *, progress: bool = False, bank: str | None = None) -> Any:
    """The bank a log's scenario flew with (or, with ``bank="default"``, the default bank for that
    scenario), rebuilt: designs and thresholds from the cache, or computed the same way, with the
    log's measurement and command columns.

    Raises
    ------
    LogError
        The log has no scenario metadata, or its scenario has no bank.
    """
    from fdi_sim.errors import LogError
    from fdi_sim.flightlog import METADATA_SCENARIO, TOPIC_COMMANDS, TOPIC_SENSORS

    meta = log.metadata.get(METADATA_SCENARIO)
    if not meta or "json" not in meta:
        raise LogError(str(log.path), "no 'scenario' metadata record: not a log written by `fdi-sim run`")
    data = json.loads(meta["json"])
    if bank is not None:
        data["fdi"] = {**data.get("fdi", {}), "bank": bank}
    sc = from_dict(data, source=f"{log.path} (scenario metadata)")
    if not bank_members(sc):
        raise LogError(str(log.path), "its scenario has no FDI bank ([fdi] bank or [[detectors]]); give --detector "
                       "or --bank default instead")
    for topic in (TOPIC_COMMANDS, TOPIC_SENSORS):
        if topic not in log.topics:
            raise LogError(str(log.path), f"no {topic} topic (a run logged with [log] per_step = false cannot be "
                           "replayed: its FDI topics are the record)")
    meas_names = tuple(f for f in log.topics[TOPIC_SENSORS].fields if f != "t_s")
    cmd_names = tuple(f for f in log.topics[TOPIC_COMMANDS].fields if f != "t_s")
    from fdi_sim.sim.run import build_sensors

    suite = build_sensors(sc, sc.dt_s).specs  # the scenario's overrides too (a rate changes the freshness)
    return build_bank(sc, meas_names=meas_names, cmd_names=cmd_names,
                      sensor_rates_hz={s.name: s.rate_hz for s in suite}, pilot_sensors=meas_names, progress=progress)


def replay_log(log: Any, bank: Any | None = None) -> dict[str, dict[str, np.ndarray]]:
    """Replay a log through its scenario's bank: per member id, the per-sample arrays
    (:data:`fdi_sim.bank.runtime.TRACE_FIELDS` and ``t_s``). For a log flown with the bank these equal
    its ``/fdi/<id>/statistic`` topics bit for bit (the kernels do not depend on the blocking)."""
    bank = bank if bank is not None else bank_for_log(log)
    _replay_log(bank, log)
    out = bank.trace()
    n = bank.n
    t_rows = np.asarray(log.topics["/sensors/measurements"].t_s, dtype=float)
    t = t_rows[n * np.arange(1, bank.samples_done + 1)]
    for v in out.values():
        v["t_s"] = t
    return out


def build_loop_bank(sc: Scenario, sensors: SensorSuite, progress: bool | None) -> FdiBank | None:
    """The scenario's bank (None without one); designs and calibrations come from the cache or are
    computed now (training flights, with a progress line on a terminal)."""
    if not bank_members(sc):
        return None
    # the loop's fast path has the pilot write its 8 outputs into the bank's rows: PILOT_FIELDS order
    return build_bank(sc, meas_names=sensors.names, cmd_names=PILOT_FIELDS,
                      sensor_rates_hz={s.name: s.rate_hz for s in sensors.specs}, pilot_sensors=sensors.names,
                      progress=progress is not False)


def fly(sc: Scenario, out_dir: str | Path = "runs", **kwargs: Any) -> RunResult:
    """:func:`fdi_sim.sim.run.run` with the scenario's bank (designed by :func:`build_loop_bank`):
    what ``fdi-sim run`` and a study's runs fly. Keywords as ``run``'s."""
    return run(sc, out_dir, bank_builder=build_loop_bank, **kwargs)
