"""Sensor faults superimposed on logged flights: an open-loop replay through an FDI bank.

A fault-free full log (``fdi-sim run`` with ``[log] per_step = true``) holds, per simulation
step ``k`` at ``t_s = k dt``, the held, sampled sensor measurement ``y(t)`` (``/sensors/measurements``:
the suite's output, which is what the pilot and the bank saw), the truth ``x(t)``
(``/truth/state``) and the pilot's commands ``u(t)`` (``/commands``). :func:`superimpose` feeds
``y`` and ``x`` of every step, in order, through the loop's own
:class:`~fdi_sim.faults.injector.FaultInjector` (``begin_step`` then ``sensors``, as
:func:`fdi_sim.sim.run._loop` calls it), so a fault's law, profile, ramp, intermittency, noise
draws and its sample-and-hold at the sensor's rate (a new value at steps ``k % (rate_sim /
rate_sensor) == 0`` only) are the in-loop ones; then it replays the faulty rows and the logged
commands through the bank (:meth:`~fdi_sim.bank.runtime.FdiBank.replay`, bit-identical to the loop)
and scores detections with :func:`~fdi_sim.bank.runtime.fdi_outcomes`, the loop's rule.

**Open loop.** The autopilot flew on the healthy sensors. The commands the bank sees are the
logged fault-free ones, and the flight path is the fault-free one, so a fault's closed-loop
effects are absent: the autopilot reacting to a biased gyro (a pitch-rate bias makes the pitch
damper command a pitch rate of the opposite sign), the attitude and the air data changing with
it, and the commands carrying the fault into the model-based residuals. Every result says so
(:attr:`SuperimposedResult.open_loop`, :attr:`SuperimposedResult.note`). Only sensor faults can
be superimposed; actuator, engine and airframe faults change the flight itself and are refused.

**Reconfiguration.** The bank's side of a reconfiguration (a confirmed sensor excluded from the
filter's measurement update) is replayed as in the loop, because it only depends on the bank's
inputs; the pilot's side (``y - f_hat`` given to the pilot) cannot act, since the commands are
logged. By default the bank reconfigures as its scenario says (``[fdi] reconfigure``): after a
correction the closed-loop pilot flies on nearly healthy measurements, which is what the logged
commands are, so the open-loop replay is closest to the loop that way. The reconfigurations the
bank decided are listed (:attr:`SuperimposedResult.reconfigurations`) as *decided, not fed back*.
``reconfigure=False`` replays the detection and isolation alone.

:func:`loop_fault_rng` gives the fault stream ``fdi-sim run`` draws for a seed, so a fault
superimposed with it gets the windows and noise it would get flown in that run's loop.
:func:`superimpose_study` does the same for every full log of a study's results folder.
"""
from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.errors import LogError, ScenarioError
from fdi_sim.flightlog import (
    METADATA_SCENARIO, TOPIC_COMMANDS, TOPIC_SENSORS, TOPIC_SENSORS_VALID, TOPIC_TRUTH_STATE, FlightLog, read_log,
)
from fdi_sim.bank.runtime import BankAlarm, FaultDetection, fdi_outcomes

#: what every superimposed result says about itself
OPEN_LOOP_NOTE = (
    "open loop: sensor faults superimposed on the logged measurements of a fault-free flight; the "
    "autopilot flew on the healthy sensors and the bank sees the logged fault-free commands, so the "
    "fault's closed-loop effects (the autopilot reacting to a biased gyro, the flight path and the "
    "commands changing with it) are absent")
#: the fault families an open-loop replay can superimpose (the others change the flight)
SUPERIMPOSABLE = ("sensor",)
#: bank choices: the bank the log's scenario flew with, or the aircraft's default bank
BANKS = ("scenario", "default")
#: the order ``fdi_sim.sim.run.run`` spawns its streams from SeedSequence(seed): sensors, pilot,
#: JSBSim, faults, FDI (:func:`loop_fault_rng` takes the faults' one)


def loop_fault_rng(seed: int) -> np.random.Generator:
    """The generator ``fdi-sim run`` resets its fault injector with for a scenario seed.

    Superimposing with it draws the same intermittent windows and the same noise and outlier
    samples as flying the faults in that scenario's loop (``fdi_sim.sim.run.run``: streams
    spawned from ``SeedSequence(seed)`` in the order sensors, pilot, JSBSim, faults, FDI).

    Parameters
    ----------
    seed : int
        The scenario's ``seed``.
    """
    from fdi_sim.sim.run import component_seeds

    return np.random.default_rng(component_seeds(seed)[3])


@dataclass(frozen=True)
class SuperimposedResult:
    """One logged flight replayed through a bank with sensor faults superimposed (open loop).

    Attributes
    ----------
    log_path : str
    scenario, aircraft : str
    seed : int
        The logged flight's scenario seed.
    bank : str
        ``"scenario"`` or ``"default"``.
    reconfigure : bool
        Whether the bank reconfigured (its own side only: module docstring).
    detectors : tuple of str
        Bank member ids.
    thresholds : tuple of float
        Each member's threshold [-] (the gust filter's at its first schedule point).
    faults : tuple of dict
        The injector's catalog: ``label``, ``type``, ``target``, ``params``, ``windows_s`` [s].
    steps : int
        Logged rows replayed.
    t_end_s : float
        Time of the last row [s].
    t_s : ndarray
        Detector sample times [s].
    traces : mapping
        Per member id, the per-sample arrays of ``/fdi/<id>/statistic``
        (:data:`fdi_sim.bank.runtime.TRACE_FIELDS`: ``statistic`` [-], ``threshold`` [-], ``exceedance``,
        ``alarm``, ``valid``, ``isolation`` (hypothesis index, -1: none), ``point``) and ``t_s`` [s];
        empty with ``keep_traces=False``.
    alarms : tuple of BankAlarm
        Every alarm episode of every member.
    detections : tuple of FaultDetection
        Per fault and member: first alarm from the onset, delay [s], isolation (the loop's rule).
    false_alarms : tuple of BankAlarm
        Alarm episodes beginning outside every fault window (and its grace time).
    reconfigurations : tuple of dict
        What the bank decided; *not* fed back to the pilot (the commands are logged).
    measurement_names : tuple of str
    measurements : ndarray or None
        The faulty measurement rows (steps, sensors), in the log's units; with ``keep_measurements``.
    fault_truth_fields : tuple of str
        ``<label>_active``, ``<label>_level``, ``<label>_error`` per fault (as the loop logs on ``/faults/active``).
    fault_truth : ndarray or None
        Their rows (steps, 3 x faults); with ``keep_measurements``.
    open_loop : bool
        Always True: the flight did not see the faults.
    note : str
        What open loop leaves out, for any report of the result.
    """

    log_path: str
    scenario: str
    aircraft: str
    seed: int
    bank: str
    reconfigure: bool
    detectors: tuple[str, ...]
    thresholds: tuple[float, ...]
    faults: tuple[dict[str, Any], ...]
    steps: int
    t_end_s: float
    t_s: NDArray[np.float64]
    traces: Mapping[str, Mapping[str, NDArray]]
    alarms: tuple[BankAlarm, ...]
    detections: tuple[FaultDetection, ...]
    false_alarms: tuple[BankAlarm, ...]
    reconfigurations: tuple[dict[str, Any], ...] = ()
    measurement_names: tuple[str, ...] = ()
    measurements: NDArray[np.float64] | None = field(default=None, repr=False)
    fault_truth_fields: tuple[str, ...] = ()
    fault_truth: NDArray[np.float64] | None = field(default=None, repr=False)
    open_loop: bool = True
    note: str = OPEN_LOOP_NOTE

    def detection(self, fault: str, detector: str) -> FaultDetection:
        """The outcome of one fault (label) for one member."""
        for d in self.detections:
            if d.fault == fault and d.detector == detector:
                return d
        raise KeyError(f"no outcome for fault {fault!r} and detector {detector!r}; faults "
                       f"{sorted({d.fault for d in self.detections})}, detectors {list(self.detectors)}")

    def format(self) -> str:
        """A text report; its first line says the replay is open loop."""
        lines = [f"OPEN LOOP  {self.note}",
                 f"log        {self.log_path} ({self.scenario}, {self.aircraft}, seed {self.seed}, "
                 f"{self.t_end_s:.2f} s, {self.steps} rows)",
                 f"bank       {self.bank}: {', '.join(self.detectors)} (reconfiguration "
                 f"{'on, bank side only' if self.reconfigure else 'off'})"]
        for f in self.faults:
            lines.append(f"fault      {f['label']}: {f['type']} on {f['target']}, windows {f['windows_s']} s")
        from fdi_sim.sim.run import fdi_outcome_lines

        out = fdi_outcome_lines(self.detections, self.false_alarms)
        lines += out[:len(self.detections)]
        for r in self.reconfigurations:
            lines.append(f"  would reconfigure {r['sensor']} at {r['t_s']:.2f} s ({r['action']}, by {r['detector']}; "
                         "not fed back: open loop)")
        lines += out[len(self.detections):]
        return "\n".join(lines)


def check_superimposable(faults: Sequence[Mapping[str, Any]], source: str) -> None:
    """Refuse entries an open-loop replay cannot superimpose, naming the entry and why.

    Parameters
    ----------
    faults : sequence of mapping
        ``[[faults]]`` entries as a scenario file gives them (``type``, ``target``, ...).
    source : str
        Where they come from, for the message.

    Raises
    ------
    ScenarioError
        An entry that is not a table, or whose type is an actuator, engine or airframe fault.
        (Unknown types and bad keys are left to the scenario loader, which names them.)
    """
    from fdi_sim.faults.catalogue import FAULTS

    for i, e in enumerate(faults):
        key = f"faults[{i}]"
        if not isinstance(e, Mapping):
            raise ScenarioError(source, key, f"a fault entry must be a table of keys, got {type(e).__name__}",
                                'give e.g. {"type": "sensor-bias-v1", "target": "q_radps", "bias_degps": 2.0, '
                                '"t_start_s": 20.0}')
        tid = e.get("type")
        if tid in FAULTS and FAULTS[tid][0] not in SUPERIMPOSABLE:
            family = FAULTS[tid][0]
            what = {"actuator": "moves a surface or the throttle", "engine": "changes the thrust",
                    "airframe": "changes the aerodynamics"}.get(family, "changes the flight")
            raise ScenarioError(source, f"{key}.type",
                                f"{tid} on {e.get('target')!r} is an {family} fault: it {what}, so it changes the "
                                "flight itself, which an open-loop replay of logged measurements cannot show",
                                "fly it in the loop (add it to the scenario's [[faults]] and run `fdi-sim run`); "
                                "superimpose sensor-* faults only")


def superimpose(log: str | Path | FlightLog, faults: Sequence[Mapping[str, Any]], rng: np.random.Generator, *,
                bank: str = "scenario", reconfigure: bool | None = None, keep_traces: bool = True,
                keep_measurements: bool = False, progress: bool = False) -> SuperimposedResult:
    """Replay a logged fault-free flight through a bank with sensor faults superimposed (open loop).

    Parameters
    ----------
    log : path or FlightLog
        A full log of ``fdi-sim run`` (``[log] per_step = true``) of a scenario without faults.
    faults : sequence of mapping
        ``[[faults]]`` entries as in a scenario file (``type``, ``target``, the magnitude with its
        unit, ``t_start_s`` [s], ...), sensor faults only; validated as the scenario loader
        validates a scenario's (targets in the suite, units, one fault per target at a time, onset
        before the flight's end). Empty: the bank over the logged rows as they are.
    rng : numpy.random.Generator
        The faults' stream (random intermittent windows, noise and outlier draws);
        :func:`loop_fault_rng` of the log's seed gives the loop's.
    bank : {"scenario", "default"}
        The bank the log's scenario flew with, or the aircraft's default bank for that scenario
        (designs and thresholds from the cache, or designed and calibrated now).
    reconfigure : bool, optional
        Let the bank reconfigure (its own side: the module docstring); default: as the scenario's
        ``[fdi] reconfigure``.
    keep_traces : bool
        Keep every member's per-sample statistic and decisions (:attr:`SuperimposedResult.traces`).
    keep_measurements : bool
        Keep the faulty measurement rows and the fault truth rows.
    progress : bool
        A progress line while a bank is designed or calibrated.

    Returns
    -------
    SuperimposedResult

    Raises
    ------
    ScenarioError
        A fault entry that is not a sensor fault (named, with why), or that the scenario loader
        refuses (named, with the fix).
    LogError
        Not a full log of ``fdi-sim run``, a log whose flight had faults, or a log whose scenario
        has no bank with ``bank="scenario"``.
    """
    from fdi_sim.scenario.loader import from_dict
    from fdi_sim.training.build import bank_for_log

    if bank not in BANKS:
        raise ValueError(f"bank must be one of {BANKS}, got {bank!r}")
    lg = log if isinstance(log, FlightLog) else read_log(log)
    path = str(lg.path)
    source = f"{path} (superimposed faults)"
    check_superimposable(faults, source)
    data = _scenario_data(lg)
    if data.get("faults"):
        labels = [f"{e.get('type')} on {e.get('target')}" for e in data["faults"]]
        raise LogError(path, f"its flight had faults ({', '.join(labels)}): its measurements are not the healthy "
                       "ones a superimposed fault corrupts; superimpose on a fault-free flight")
    for topic in (TOPIC_SENSORS, TOPIC_COMMANDS, TOPIC_TRUTH_STATE):
        if topic not in lg.topics:
            raise LogError(path, f"no {topic} topic: superimposing needs a full log ([log] per_step = true; in a "
                           "study [output] full_logs = true)")
    sc = from_dict({**data, "faults": [dict(e) for e in faults]}, source=source)  # the loader's checks

    from fdi_sim import registry
    from fdi_sim.aircraft.properties import truth_signals
    from fdi_sim.faults.injector import FaultInjector
    from fdi_sim.sim.run import build_sensors

    meas_t, cmd_t, truth_t = lg.topics[TOPIC_SENSORS], lg.topics[TOPIC_COMMANDS], lg.topics[TOPIC_TRUTH_STATE]
    meas_names = tuple(f for f in meas_t.fields if f != "t_s")
    truth_names = truth_signals(sc.aircraft)
    specs = {s.name: s for s in build_sensors(sc, sc.dt_s).specs}
    missing = [n for n in meas_names if n not in specs] + [n for n in truth_names if n not in truth_t.fields]
    if missing:
        raise LogError(path, f"its topics do not match its scenario's sensor suite and truth ({', '.join(missing)}): "
                       "a log of another fdi-sim version?")
    K = min(len(meas_t.t_s), len(cmd_t.t_s), len(truth_t.t_s))
    if K < 2:
        raise LogError(path, f"only {K} logged rows: nothing to replay")
    y = np.column_stack([np.asarray(meas_t[n][:K], dtype=np.float64) for n in meas_names])
    x = np.column_stack([np.asarray(truth_t[n][:K], dtype=np.float64) for n in truth_names])
    dt = sc.dt_s

    # --- the loop's injector over the logged rows: begin_step, then sensors (fdi_sim.sim.run._loop)
    defs = [registry.get("fault", tid).factory(p) for tid, p in sc.faults]
    valid = None
    ftruth = np.zeros((K, 3 * len(defs)))
    labels: tuple[str, ...] = ()
    catalog: list[dict[str, Any]] = []
    if defs:
        inj = FaultInjector(defs, None, meas_names, [specs[n].rate_hz for n in meas_names], truth_names, dt,
                            sc.duration_s)  # no aircraft: sensor faults never touch it
        inj.reset(rng)
        catalog = inj.catalog()
        labels = inj.truth_fields
        valid = np.ones((K, len(meas_names)), dtype=np.bool_) if inj.has_dropout else None
        for k in range(K):
            t_s = k * dt  # the loop's time stamp, bit for bit
            inj.begin_step(t_s)
            inj.sensors(t_s, k, y[k], x[k])  # the row is changed in place
            ftruth[k] = inj.truth_row()
            if valid is not None:
                valid[k] = inj.valid > 0.5
    if valid is None and TOPIC_SENSORS_VALID in lg.topics:
        vt = lg.topics[TOPIC_SENSORS_VALID]
        valid = np.column_stack([np.asarray(vt[n][:K]) > 0.5 if n in vt.fields else np.ones(K, bool)
                                 for n in meas_names])

    # --- the bank over the faulty rows and the logged commands (as fdi_sim.training.build.replay_log does)
    b = bank_for_log(lg, bank=None if bank == "scenario" else bank, progress=progress)
    if reconfigure is not None:
        b.reconfigure = bool(reconfigure)
    col = {n: i for i, n in enumerate(meas_names)}
    yb = y[:, [col[n] for n in b.meas_names]]
    vb = None if valid is None else valid[:, [col[n] for n in b.meas_names]]
    u = np.column_stack([np.asarray(cmd_t[n][:K], dtype=np.float64) for n in b.cmd_names])
    t_rows = np.asarray(meas_t.t_s[:K], dtype=np.float64)
    b.reset()
    b.keep_trace(keep_traces)
    b.replay(u, yb, vb, float(np.median(np.diff(t_rows))), t_rows_s=t_rows)
    t_end_s = float(t_rows[-1])
    det, false = fdi_outcomes(b, catalog, t_end_s)
    t_samples = t_rows[b.n * np.arange(1, b.samples_done + 1)]
    traces: dict[str, Mapping[str, NDArray]] = {}
    if keep_traces:
        for mid, v in b.trace().items():
            traces[mid] = MappingProxyType({**v, "t_s": t_samples})
    thresholds = tuple(m.threshold for m in b.members)
    return SuperimposedResult(
        log_path=path, scenario=sc.name, aircraft=sc.aircraft, seed=sc.seed, bank=bank, reconfigure=b.reconfigure,
        detectors=tuple(m.id for m in b.members), thresholds=thresholds, faults=tuple(catalog), steps=K,
        t_end_s=t_end_s, t_s=t_samples, traces=MappingProxyType(traces), alarms=tuple(b.alarms), detections=det,
        false_alarms=false, reconfigurations=tuple(dict(r) for r in b.reconfig_events), measurement_names=meas_names,
        measurements=y if keep_measurements else None, fault_truth_fields=labels,
        fault_truth=ftruth if keep_measurements else None)


def _scenario_data(lg: FlightLog) -> dict[str, Any]:
    meta = lg.metadata.get(METADATA_SCENARIO)
    if not meta or "json" not in meta:
        raise LogError(str(lg.path), "no 'scenario' metadata record: not a log written by `fdi-sim run`")
    return json.loads(meta["json"])


# --- a study's folder -------------------------------------------------------------------------------
@dataclass(frozen=True)
class StudySuperimposed:
    """Sensor faults superimposed on every full log of a study (open loop).

    Attributes
    ----------
    out_dir : str
    results : tuple of (int, SuperimposedResult)
        Per replayed run: its index and its result (traces and rows not kept).
    skipped : tuple of (int, str)
        Runs not replayed and why (no full log, a failed run, a flight with faults).
    open_loop : bool
    note : str
    """

    out_dir: str
    results: tuple[tuple[int, SuperimposedResult], ...]
    skipped: tuple[tuple[int, str], ...]
    open_loop: bool = True
    note: str = OPEN_LOOP_NOTE

    def detection_rate(self, detector: str) -> tuple[int, int]:
        """``(detected, outcomes)`` of one member over every fault of every replayed run."""
        ds = [d for _, r in self.results for d in r.detections if d.detector == detector]
        return sum(d.detected_t_s is not None for d in ds), len(ds)

    def delays_s(self, detector: str) -> NDArray[np.float64]:
        """One member's detection delays [s] over every detected fault of every replayed run."""
        return np.array([d.delay_s for _, r in self.results for d in r.detections
                         if d.detector == detector and d.delay_s is not None], dtype=float)


def superimpose_study(out_dir: str | Path, faults: Sequence[Mapping[str, Any]], rng: np.random.Generator, *,
                      bank: str = "scenario", reconfigure: bool | None = None,
                      progress: bool = False) -> StudySuperimposed:
    """:func:`superimpose` over every run of a study's results folder that has a full log.

    Parameters
    ----------
    out_dir : path
        A study's results folder (``runs/NNNNNN.json`` records, ``runs/NNNNNN.mcap`` logs; full
        logs with ``[output] full_logs = true``).
    faults : sequence of mapping
        The sensor faults, the same entries for every run.
    rng : numpy.random.Generator
        One number is drawn from it; run ``i``'s faults get
        ``default_rng(SeedSequence([that number, i]))``, so a run's draws depend on its index only,
        not on which other runs the folder holds.
    bank, reconfigure, progress
        As :func:`superimpose`.

    Returns
    -------
    StudySuperimposed

    Raises
    ------
    LogError
        No ``runs`` folder under ``out_dir``.
    ScenarioError
        A fault entry that cannot be superimposed (checked before any run is replayed).
    """
    out = Path(out_dir)
    runs = out / "runs"
    if not runs.is_dir():
        raise LogError(str(out), "no runs/ folder: not a study's results folder")
    check_superimposable(faults, f"{out} (superimposed faults)")
    base = int(rng.integers(2**63))
    results, skipped = [], []
    for rec_path in sorted(runs.glob("[0-9]*.json")):
        try:
            index = int(rec_path.stem)
            rec = json.loads(rec_path.read_text())
        except (ValueError, OSError) as exc:
            skipped.append((-1, f"{rec_path.name}: unreadable record ({exc})"))
            continue
        if rec.get("status") == "error":
            skipped.append((index, f"the run failed: {rec.get('reason', '')}"))
            continue
        if rec.get("faults"):
            skipped.append((index, "its flight had faults"))
            continue
        log_name = rec.get("log")
        if not log_name or not (runs / log_name).is_file():
            skipped.append((index, "no log kept"))
            continue
        lg = read_log(runs / log_name)
        if TOPIC_SENSORS not in lg.topics:
            skipped.append((index, "a statistics log, not a full log ([output] full_logs = false)"))
            continue
        r = superimpose(lg, faults, np.random.default_rng(np.random.SeedSequence([base, index])), bank=bank,
                        reconfigure=reconfigure, keep_traces=False, progress=progress)
        results.append((index, r))
    return StudySuperimposed(str(out), tuple(results), tuple(skipped))
