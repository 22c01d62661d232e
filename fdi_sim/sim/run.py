"""The simulation loop: the one module that wires the stages together.

Per step (dt = 1/rate_hz), at time t:
  truth x(t) -> sensors -> y(t) -> pilot (autopilot + maneuvers) -> commands u(t) -> JSBSim step
and everything is logged with time stamp t. A run ends ``completed``, ``diverged`` (NaN, ground
impact, departure beyond the scenario's limits), ``interrupted`` (Ctrl-C, SIGTERM) or ``error``;
once the flight has started the MCAP log is closed in ``finally`` in every case, so it is always
readable. A run that fails before it flies writes nothing at its log path.
"""
from __future__ import annotations

import ctypes
import importlib.metadata
import json
import math
import os
import platform
import signal
import struct
import sys
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Callable, Iterator, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim import registry, signals
from fdi_sim.aircraft import (
    COMMAND_SIGNALS, SURFACE_SIGNALS, Aircraft, Atmosphere, TrimResult, hold_trim_in_wind, trim,
)
from fdi_sim.aircraft.model import wind_ned_fps
from fdi_sim.aircraft.properties import truth_signals
from fdi_sim.errors import LogError, ScenarioError, SimulationDiverged, TrimError
from fdi_sim.faults.injector import FaultInjector
from fdi_sim.flightlog import (
    FAULT_EVENT_JSON_SCHEMA,
    METADATA_FAULTS,
    METADATA_SCENARIO,
    STATUS_JSON_SCHEMA,
    TOPIC_COMMANDS,
    TOPIC_FAULT_EVENTS,
    TOPIC_FAULTS,
    TOPIC_OPERATING_POINT,
    TOPIC_SENSORS,
    TOPIC_SENSORS_VALID,
    TOPIC_SIM_STATUS,
    TOPIC_SURFACES,
    TOPIC_TRUTH_STATE,
    FlightLog,
    FlightLogWriter,
    VectorTopic,
)
from fdi_sim.flightlog.records import MCAP_MAGIC
from fdi_sim.pilot.autopilot import AutopilotGains, AutopilotModes, Pilot, TrimPoint
from fdi_sim.scenario import Scenario
from fdi_sim.sensors import SensorSuite, apply_overrides, load_suite
import fdi_sim.sim._core as _core  # the module itself (from fdi_sim.sim import: a package cycle)
from fdi_sim.bank.members import bank_members
from fdi_sim.bank.runtime import BankAlarm, FaultDetection, FdiBank, fdi_outcomes
from fdi_sim.decision.outcome import not_monitored
from fdi_sim.units import DEG_PER_RAD, RAD_PER_DEG

OP_SIGNALS = ("h_ft", "vc_kts", "mach", "alpha_rad", "flaps_deg", "icing_eta")
# the pitch trim is set by the trim and held; logged so that detectors using the commands see the
# whole elevator command (elevator + pitch trim) without recovering it from the surface
PILOT_FIELDS = COMMAND_SIGNALS + ("h_ref_ft", "vc_ref_kts", "psi_ref_rad", "phi_ref_rad", "pitch_trim_cmd_norm")

class RunInterrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM arrived before the flight started: no log was written.

    A KeyboardInterrupt, so code that catches Ctrl-C keeps working.

    Parameters
    ----------
    reason : str
        Which signal.
    log_path : str
        The log path that was left as it was.
    """

    def __init__(self, reason: str, log_path: str) -> None:
        self.reason, self.log_path = reason, log_path
        super().__init__(f"{reason} before the flight started: no log written ({log_path} left as it was)")


class StopRequest:
    """SIGINT and SIGTERM during a run: an exception before the flight, a flag during it.

    Before :meth:`start_flight` a signal raises KeyboardInterrupt at once (a trim can take
    seconds and writes nothing that must survive). After it, the handler only sets
    :attr:`requested`, which the loop reads at the top of each step: the run ends between two
    steps, never inside a log write (issue 11: 10 of 52 Ctrl-C runs lost rows or their index).
    """

    __slots__ = ("requested", "reason", "_flying")

    def __init__(self) -> None:
        self.requested = False
        self.reason = ""
        self._flying = False

    def start_flight(self) -> None:
        """From now on a signal only sets the flag."""
        self._flying = True

    def _handle(self, signum: int, _frame: object) -> None:
        self.reason = self.reason or signals.REASONS.get(signum, f"stopped by signal {signum}")
        # the flag first: a KeyboardInterrupt raised while C++ calls back into Python (JSBSim's
        # logger during the trim) can be swallowed there; run() checks the flag before take-off
        self.requested = True
        if not self._flying:
            raise KeyboardInterrupt

    @contextmanager
    def installed(self) -> Iterator[StopRequest]:
        """Install the handler for SIGINT and SIGTERM (main thread only), restore on exit."""
        if threading.current_thread() is not threading.main_thread():
            yield self
            return
        before = {s: signal.getsignal(s) for s in signals.REASONS}
        for s in signals.REASONS:
            signal.signal(s, self._handle)
        if signals.stop_requested():  # a signal before this handler whose exception was dropped
            self.requested, self.reason = True, self.reason or signals.pending_reason
        try:
            yield self
        finally:
            for s, h in before.items():
                signal.signal(s, h if h is not None else signal.SIG_DFL)


@dataclass(frozen=True)
class RunSummary:
    """What a run did, for the terminal and for tests.

    Attributes
    ----------
    scenario, aircraft : str
    seed : int
    status : str
        ``completed``, ``diverged``, ``interrupted`` or ``error``.
    reason : str
        Why a run ended early ("" when completed).
    t_end_s : float
        Last simulated time logged [s].
    steps : int
        Rows logged on ``/truth/state`` (steps 0 .. steps-1).
    wall_s : float
        Wall-clock time of the loop [s].
    max_abs_dh_ft, max_abs_dvc_kts, max_abs_dphi_deg : float
        Largest deviation of truth from the pilot's references (altitude; calibrated airspeed
        relative to the steady air mass, i.e. gust removed; bank angle).
    trim_throttle_norm, trim_alpha_deg : float
    """

    scenario: str
    aircraft: str
    seed: int
    status: str
    reason: str
    t_end_s: float
    steps: int
    wall_s: float
    max_abs_dh_ft: float
    max_abs_dvc_kts: float
    max_abs_dphi_deg: float
    trim_throttle_norm: float
    trim_alpha_deg: float
    fdi_detectors: tuple[str, ...] = ()
    fdi_detections: tuple[FaultDetection, ...] = ()
    fdi_false_alarms: tuple[BankAlarm, ...] = ()
    fdi_reconfigurations: tuple[dict, ...] = ()
    fdi_notes: tuple[str, ...] = ()
    #: every alarm episode of every member (the false ones are also in fdi_false_alarms)
    fdi_alarms: tuple[BankAlarm, ...] = ()
    #: each member's threshold (the gust filter's at its first schedule point)
    fdi_thresholds: tuple[float, ...] = ()
    #: ``(label, target)`` of the injected faults no member has a hypothesis for
    #: (:func:`fdi_sim.decision.outcome.not_monitored`)
    fdi_not_monitored: tuple[tuple[str, str], ...] = ()
    #: which loop flew: ``"compiled"`` (:mod:`fdi_sim.sim._chunk`) or ``"python: <why not compiled>"``
    core: str = ""

    @property
    def realtime_factor(self) -> float:
        return self.t_end_s / self.wall_s if self.wall_s > 0 else math.inf

    def format(self) -> str:
        lines = [
            f"scenario   {self.scenario} ({self.aircraft}, seed {self.seed})",
            f"status     {self.status}" + (f": {self.reason}" if self.reason else ""),
            f"flown      {self.t_end_s:.2f} s simulated in {self.wall_s:.2f} s ({self.realtime_factor:.0f}x real time, {self.steps} steps)",
            f"trim       throttle {self.trim_throttle_norm:.3f}, alpha {self.trim_alpha_deg:.2f} deg",
            f"holds      max |dh| {self.max_abs_dh_ft:.1f} ft, max |dVc| {self.max_abs_dvc_kts:.2f} kt (gust removed), "
            f"max |dphi| {self.max_abs_dphi_deg:.2f} deg",
        ]
        if self.core:
            lines.append("core       compiled chunk core" if self.core == "compiled" else
                         f"core       Python loop ({self.core.removeprefix('python: ')})")
        if self.fdi_detectors:
            lines.append(f"fdi bank   {', '.join(self.fdi_detectors)}")
            lines += [f"           {n}" for n in self.fdi_notes]
            out = fdi_outcome_lines(self.fdi_detections, self.fdi_false_alarms)
            n_det = len(self.fdi_detections)
            lines += out[:n_det]
            lines += [f"  {lab:22} not monitored: no member of this bank has a hypothesis for {tgt!r}"
                      for lab, tgt in self.fdi_not_monitored]
            for r in self.fdi_reconfigurations:
                extra = (f", effectiveness {r['effectiveness']:.2f} +- {r['effectiveness_std']:.2f}, command x "
                         f"{r['scale']:.2f}" if "scale" in r else "")
                lines.append(f"  reconfigured {r['sensor']} at {r['t_s']:.2f} s ({r['action']}, by {r['detector']}{extra})")
            lines += out[n_det:]
        return "\n".join(lines)


@dataclass(frozen=True)
class RunResult:
    """The outcome of :func:`run`: where the log is, how the run ended, and its summary.

    ``rows`` is the in-memory log of a run flown with ``keep_rows`` (its measurement and
    command topics only), None otherwise.
    """

    log_path: Path
    status: str
    summary: RunSummary
    rows: FlightLog | None = None


class _Rows:
    """A per-step vector topic kept in memory: row ``i`` is ``(t_s, *values)`` of the ``i``-th write.

    The same float64 numbers the log's channel would hold (its CDR is ``float64`` throughout), so a
    training flight's samples equal those read back from its MCAP log, bit for bit. The row views
    are made once (12 ms for 36 000 rows): a write builds no object (0.29 us, against 0.71 us when
    each write sliced its row).
    """

    __slots__ = ("topic", "schema_name", "fields", "data", "_t_s", "_rows", "i")

    def __init__(self, topic: str, schema_name: str, fields: tuple[str, ...], n_rows: int) -> None:
        self.topic, self.schema_name, self.fields = topic, schema_name, fields
        self.data = np.empty((n_rows, len(fields)))
        self._t_s = self.data[:, 0]
        self._rows = [self.data[i, 1:] for i in range(n_rows)]
        self.i = 0

    def write(self, t_s: float, values: Sequence[float]) -> None:
        i = self.i
        self._t_s[i] = t_s
        self._rows[i][...] = values
        self.i = i + 1

    def write_rows(self, t_s: NDArray[np.float64], values: NDArray[np.float64]) -> None:
        """Several rows at once (the compiled core's chunk): the same numbers as one ``write`` each."""
        i, n = self.i, len(t_s)
        self.data[i:i + n, 0] = t_s
        self.data[i:i + n, 1:] = values
        self.i = i + n

    def topic_data(self) -> VectorTopic:
        data = self.data[:self.i]
        data.flags.writeable = False
        return VectorTopic(self.topic, self.schema_name, self.fields, data,
                           np.round(data[:, 0] * 1e9).astype(np.uint64))


def component_seeds(seed: int) -> tuple[np.random.SeedSequence, ...]:
    """A run's random streams from its scenario seed, one per component, in this order: sensors,
    pilot, JSBSim, faults, FDI (the one place that says so; an open-loop replay draws the faults'
    stream from here to match the loop)."""
    return tuple(np.random.SeedSequence(int(seed)).spawn(5))


def fdi_outcome_lines(detections: Sequence[FaultDetection], false_alarms: Sequence[BankAlarm]) -> list[str]:
    """The summary lines of the bank's detections per fault and member, and its false alarms."""
    lines = []
    for d in detections:
        if d.detected_t_s is None:
            lines.append(f"  {d.fault:22} onset {d.onset_t_s:.2f} s  {d.detector:24} not detected")
        else:
            iso = d.isolation or "not isolated"
            mark = "" if d.isolation_correct is None else (" (right)" if d.isolation_correct else " (wrong)")
            lines.append(f"  {d.fault:22} onset {d.onset_t_s:.2f} s  {d.detector:24} detected at "
                         f"{d.detected_t_s:.2f} s (delay {d.delay_s:.2f} s), isolated as {iso}{mark}")
    for a in false_alarms:
        end = "open" if a.end_t_s is None else f"to {a.end_t_s:.2f} s"
        lines.append(f"  FALSE ALARM {a.detector} at {a.onset_t_s:.2f} s ({end}), isolated as {a.isolation}")
    if not false_alarms:
        lines.append("  false alarms: none")
    return lines


def _versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for pkg in ("fdi-sim", "jsbsim", "numpy", "scipy", "mcap", "pydantic"):
        try:
            out[pkg] = importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            out[pkg] = "unknown"
    return out


def _default_log_path(sc: Scenario, out_dir: Path) -> Path:
    return out_dir / f"{sc.name}_seed{sc.seed}.mcap"


def build_pilot(sc: Scenario, tr: TrimResult, measurement_names: tuple[str, ...]) -> Pilot:
    maneuvers = [registry.get("maneuver", tid).factory(p) for tid, p in sc.maneuvers]
    tp = TrimPoint(
        tr.elevator_cmd_norm, tr.aileron_cmd_norm, tr.rudder_cmd_norm, tr.throttle_cmd_norm, tr.theta_rad,
        tr.phi_rad, sc.model.initial.psi_deg * RAD_PER_DEG, sc.model.initial.h_ft, tr.vc_kts,
    )
    ap = sc.model.autopilot
    return Pilot(AutopilotGains.for_aircraft(sc.aircraft), AutopilotModes(ap.altitude, ap.airspeed, ap.lateral), tp,
                 maneuvers, measurement_names, sc.dt_s)


def build_sensors(sc: Scenario, dt_s: float) -> SensorSuite:
    s = sc.model.sensors
    overrides = {k: v.model_dump(exclude_none=True) for k, v in s.overrides.items()}
    specs = load_suite(sc.aircraft, s.suite)  # suite and override names checked by the scenario loader
    return SensorSuite(apply_overrides(specs, s.noise_scale, s.biases, overrides), truth_signals(sc.aircraft), dt_s)


#: flush period of a log without the per-step topics ([log] per_step = false) [s]
MC_FLUSH_PERIOD_S = 10.0
#: metadata record describing the in-loop bank (members, designs, thresholds)
METADATA_FDI = "fdi"


def bank_metadata(bank: FdiBank) -> dict[str, str]:
    """The bank as strings for the log's metadata (what a replay and a reviewer need)."""
    members = [{"id": m.id, "kind": type(m.stream).__name__, "hypotheses": list(m.hypotheses),
                "outputs": list(m.output_names), "inputs": list(m.input_names), "residuals": list(m.residual_names),
                "estimates": list(m.estimate_names), "threshold": m.threshold} for m in bank.members]
    return {"members": json.dumps(members), "rate_hz": f"{bank.rate_hz:g}", "block_samples": str(bank.S),
            "decision": json.dumps({"rule": bank.decision.rule, "k": bank.decision.k, "n": bank.decision.n,
                                    "confirm_samples": bank.decision.confirm_samples}),
            "reconfigure": json.dumps(bank.reconfigure), "notes": json.dumps(list(bank.notes)),
            "calibration": json.dumps(getattr(bank, "calibration", None))}


#: ``bank_builder(sc, sensors, progress) -> FdiBank | None``: designs the scenario's bank when the
#: loop asks for it (``fdi_sim.training.build.build_loop_bank``; the loop never designs one itself)
BankBuilder = Callable[[Scenario, SensorSuite, "bool | None"], "FdiBank | None"]


def run(sc: Scenario, out_dir: str | Path = "runs", *, log_path: str | Path | None = None,
        progress: bool | None = None, force: bool = False, wall_limit_s: float | None = None,
        keep_rows: bool = False, bank_builder: BankBuilder | None = None) -> RunResult:
    """Fly a scenario and write its MCAP log.

    Parameters
    ----------
    sc : Scenario
    out_dir : path
        Folder of the log (created); ignored when ``log_path`` is given.
    log_path : path, optional
        Exact log file path.
    progress : bool, optional
        Show a progress bar with the simulated-time rate; default: on for runs longer than 30 s
        of simulated time when stderr is a terminal.
    force : bool
        Replace an existing file at the log path even if it is not an MCAP log (never the
        scenario file itself).
    wall_limit_s : float, optional
        Wall-clock limit of the flight [s] (a Monte Carlo study's per-run limit): when it passes,
        the run ends between two steps as if stopped, status ``interrupted``, reason
        ``wall-clock limit ...``. Works in any thread (a timer sets the stop flag).
    keep_rows : bool
        A training flight's log: the measurement and command topics are kept in memory
        (``RunResult.rows``, as :func:`fdi_sim.flightlog.read_log` would read them back) and
        no per-step topic is written to the file (a scenario with ``log.per_step = false`` keeps
        none).
    bank_builder : callable, optional
        Designs the scenario's FDI bank, called after the log is opened and before the trim, with
        the scenario, its sensor suite and ``progress`` (:func:`fdi_sim.training.fly` passes
        ``fdi_sim.training.build.build_loop_bank``). Required when the scenario has a bank
        (``[fdi] bank`` or ``[[detectors]]``): the loop flies banks, it does not design them.

    Returns
    -------
    RunResult
        ``summary.steps`` is the number of rows logged on ``/truth/state`` and ``summary.t_end_s``
        the time of the last one, whatever the ending.

    Raises
    ------
    RunInterrupted
        SIGINT or SIGTERM before the flight started (during the set-up or the trim): no log is
        written and a file already at the log path is left as it was.
    ScenarioError, LogError
        Bad input (an untrimmable point names the file and ``initial``); nothing is written.

    Notes
    -----
    Stopping (SIGINT = Ctrl-C, SIGTERM = ``kill``, ``timeout``, batch schedulers): while the
    aircraft flies, the signal only sets a flag that the loop reads at the top of each step, so
    the run ends between two steps with every topic holding the same steps; the log is then
    closed with status ``interrupted``. In threads other than the main one Python delivers no
    signals, and a KeyboardInterrupt raised inside the loop still ends the run the same way.
    """
    out = Path(log_path) if log_path is not None else _default_log_path(sc, Path(out_dir))
    check_log_path(out, sc.source, force=force)
    # one stream per component; the fault and FDI streams are spawned now so that adding faults or
    # detectors to a scenario never changes the sensor noise or the turbulence of the same seed
    ss_sensors, ss_pilot, ss_jsbsim, ss_faults, _ss_fdi = component_seeds(sc.seed)
    jsbsim_seed = int(ss_jsbsim.generate_state(1)[0] % (2**31 - 1))
    metadata = {
        METADATA_SCENARIO: {"name": sc.name, "seed": str(sc.seed), "source": sc.source, "text": sc.text,
                            "json": sc.to_json(), "aircraft": sc.aircraft, "rate_hz": str(sc.model.rate_hz)},
        "versions": _versions(),
    }
    # open the log first, under a temporary name beside the final one: an unwritable folder fails
    # before any simulation, and a run that fails to start (bad trim, bad cache folder, Ctrl-C
    # during the trim) leaves a file already at `out` untouched. The log is moved to `out` when
    # the flight starts.
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise LogError(str(out.parent), f"cannot create the output folder ({exc.strerror})") from None
    starting = out.with_name(f".{out.name}.starting-{os.getpid()}")
    stop = StopRequest()
    status, reason = "error", ""
    stats = np.zeros(3)
    steps = 0
    core_used = ""
    bank = None
    injector = None
    tr = None
    ch_truth = None
    kept: list[_Rows] = []
    wall0 = time.perf_counter()
    timer = None
    with stop.installed():
        flying = False
        writer = None
        try:
            # a full log loses at most 1 s to a SIGKILL; a Monte Carlo log (FDI topics only) 10 s: a
            # chunk a second cost 0.3 ms, 2.6 us a 120 Hz step, a third of the bank's cost
            writer = FlightLogWriter(starting, metadata=metadata,
                                     flush_period_s=1.0 if sc.model.log.per_step else MC_FLUSH_PERIOD_S)
            fault_defs = [registry.get("fault", tid).factory(p) for tid, p in sc.faults]
            ac = Aircraft(sc.aircraft, sc.dt_s, icing=any(d.family == "airframe" for d in fault_defs))
            ac.set_atmosphere(Atmosphere(), jsbsim_seed)
            sensors = build_sensors(sc, sc.dt_s)
            sensors.reset(np.random.default_rng(ss_sensors))
            # the bank before the aircraft is trimmed: its designs may fly calibration flights
            if bank_builder is not None:
                bank = bank_builder(sc, sensors, progress)
            elif bank_members(sc):
                raise ScenarioError(sc.source, "fdi", "this scenario has an FDI bank, which fdi_sim.sim.run flies "
                                    "but does not design", "fly it with fdi_sim.training.fly (as `fdi-sim run` "
                                    "does), or pass bank_builder")
            per_step = sc.model.log.per_step
            injector = None
            op = sc.operating_point()
            if fault_defs:
                injector = FaultInjector(fault_defs, ac, sensors.names, [s.rate_hz for s in sensors.specs],
                                         truth_signals(sc.aircraft), sc.dt_s, sc.duration_s)
                injector.reset(np.random.default_rng(ss_faults))
                eta0 = injector.initial_icing_eta()
                if eta0:  # iced from the start: trim with the ice on
                    ac.icing_writer()(eta0)
                    op = replace(op, icing_eta=eta0)
                writer.add_metadata(METADATA_FAULTS, {"catalog": json.dumps(injector.catalog())})
            try:
                tr = trim(ac, op)
            except TrimError as exc:  # name the scenario file and the section that sets the point
                raise exc.with_source(sc.source, "initial") from None
            a = sc.model.atmosphere
            atm = Atmosphere(a.turbulence, a.wind_from_deg, a.wind_speed_kts)
            # the trim flew in still air: the same air-relative state, now with the ground velocity of the wind
            hold_trim_in_wind(ac, tr, atm.wind_from_deg, atm.wind_speed_kts)
            ac.set_atmosphere(atm, jsbsim_seed)
            pilot = build_pilot(sc, tr, sensors.names)
            pilot.reset(np.random.default_rng(ss_pilot))
            ch_truth = ch_surf = ch_op = ch_cmd = ch_meas = None
            cmd_spec = (TOPIC_COMMANDS, "fdi_sim/msg/PilotCommands", ("t_s",) + PILOT_FIELDS)
            meas_spec = (TOPIC_SENSORS, "fdi_sim/msg/Measurements", ("t_s",) + sensors.names)
            if per_step and keep_rows:  # a training flight: only what its detector samples need, in memory
                n_rows = int(round(sc.duration_s / sc.dt_s)) + 1
                # truth, surfaces and operating point stay None: the loop neither reads nor builds them
                ch_cmd, ch_meas = _Rows(*cmd_spec, n_rows), _Rows(*meas_spec, n_rows)
                kept = [ch_cmd, ch_meas]
            elif per_step:  # without: status, fault events and the FDI topics only, as a Monte Carlo run logs
                ch_truth = writer.add_vector_channel(TOPIC_TRUTH_STATE, "fdi_sim/msg/TruthState", ("t_s",) + truth_signals(sc.aircraft))
                ch_surf = writer.add_vector_channel(TOPIC_SURFACES, "fdi_sim/msg/Surfaces", ("t_s",) + SURFACE_SIGNALS)
                ch_op = writer.add_vector_channel(TOPIC_OPERATING_POINT, "fdi_sim/msg/OperatingPoint", ("t_s",) + OP_SIGNALS)
                ch_cmd, ch_meas = writer.add_vector_channel(*cmd_spec), writer.add_vector_channel(*meas_spec)
            ch_status = writer.add_event_channel(TOPIC_SIM_STATUS, "fdi_sim/msg/SimStatus", STATUS_JSON_SCHEMA)
            ch_status.write(0.0, {"status": "running", "message": f"trimmed ({tr.method} trim), flying"})
            fault_channels = None
            if injector is not None:
                fault_channels = (
                    writer.add_vector_channel(TOPIC_FAULTS, "fdi_sim/msg/FaultTruth", ("t_s",) + injector.truth_fields)
                    if per_step else None,
                    writer.add_event_channel(TOPIC_FAULT_EVENTS, "fdi_sim/msg/FaultEvent", FAULT_EVENT_JSON_SCHEMA),
                    writer.add_vector_channel(TOPIC_SENSORS_VALID, "fdi_sim/msg/SensorValid", ("t_s",) + sensors.names)
                    if injector.has_dropout and per_step else None,
                )
            if bank is not None:
                bank.attach(writer, log_residuals=sc.model.fdi.log_residuals)
                bank.start_at(sc.model.initial.h_ft, tr.vc_kts)
                writer.add_metadata(METADATA_FDI, bank_metadata(bank))
            # the loop's core: compiled (bound to this JSBSim and loaded now, in the set-up) or Python
            native_core = _native_core(ac, injector)
            if native_core[0] is not None:
                import fdi_sim.sim._chunk as _chunk

                _chunk.prime(native_core[0], *sensors.compiled()[1:3], *pilot.compiled()[1:])
            if stop.requested:  # a signal whose KeyboardInterrupt was swallowed during the set-up
                raise KeyboardInterrupt
            # from here on a stop request only sets a flag that the loop reads once per step
            stop.start_flight()
            if wall_limit_s is not None:
                timer = threading.Timer(float(wall_limit_s), _time_up, (stop, float(wall_limit_s)))
                timer.daemon = True
                timer.start()
            writer.move_to(out)
            flying = True
            wall0 = time.perf_counter()  # the loop's wall time (the set-up, trim and bank design before it)
            status, reason, t_status_s, stats, steps, core_used = _loop(
                sc, ac, sensors, pilot, (ch_truth, ch_surf, ch_op, ch_cmd, ch_meas), progress, injector, fault_channels,
                stop, bank, per_step, writer=writer if (per_step and not keep_rows) else None, native_core=native_core)
            ch_status.write(t_status_s, {"status": status, "message": reason})
        except KeyboardInterrupt:
            if flying:  # raised by hand inside the loop's callees: still a finished log
                status, reason = "interrupted", stop.reason or "stopped by the user (Ctrl-C)"
            else:
                _discard(writer, starting, stop)
                raise RunInterrupted(stop.reason or "stopped by the user (Ctrl-C)", str(out)) from None
        except BaseException:
            if not flying:
                _discard(writer, starting, stop)
            raise
        finally:
            if timer is not None:
                timer.cancel()
            if flying:
                writer.close()
    wall = time.perf_counter() - wall0
    t_end_s = (steps - 1) * sc.dt_s if steps else 0.0
    fdi: dict = {}
    if bank is not None:
        faults = injector.catalog() if injector is not None else []
        det, false = fdi_outcomes(bank, faults, t_end_s)
        fdi = dict(fdi_detectors=tuple(m.id for m in bank.members), fdi_detections=det, fdi_false_alarms=false,
                   fdi_reconfigurations=tuple(bank.reconfig_events), fdi_notes=bank.notes,
                   fdi_alarms=tuple(bank.alarms),
                   fdi_thresholds=tuple(m["threshold"] for m in json.loads(bank_metadata(bank)["members"])),
                   fdi_not_monitored=not_monitored(bank.hypotheses, faults))
    summary = RunSummary(
        scenario=sc.name, aircraft=sc.aircraft, seed=sc.seed, status=status, reason=reason, t_end_s=t_end_s,
        steps=steps,
        wall_s=wall, max_abs_dh_ft=float(stats[0]), max_abs_dvc_kts=float(stats[1]), max_abs_dphi_deg=float(stats[2]),
        trim_throttle_norm=tr.throttle_cmd_norm if tr else math.nan,
        trim_alpha_deg=tr.alpha_rad * DEG_PER_RAD if tr else math.nan, core=core_used, **fdi,
    )
    rows = None
    if keep_rows:
        topics = {ch.topic: ch.topic_data() for ch in kept} if flying else {}
        t_last_s = float(topics[TOPIC_SENSORS].t_s[-1]) if topics and len(topics[TOPIC_SENSORS]) else 0.0
        rows = FlightLog(out, topics, {METADATA_SCENARIO: metadata[METADATA_SCENARIO]},
                         {t: len(v) for t, v in topics.items()}, 0.0, t_last_s)
    return RunResult(log_path=out, status=status, summary=summary, rows=rows)


def _time_up(stop: StopRequest, limit_s: float) -> None:
    stop.reason = stop.reason or f"wall-clock limit of {limit_s:g} s reached"
    stop.requested = True


def _discard(writer: FlightLogWriter | None, starting: Path, stop: StopRequest) -> None:
    """Drop the log of a run that never flew (the temporary file; nothing at the final path).

    A second Ctrl-C while discarding only sets the flag (it must not leave the temporary file).
    """
    stop.start_flight()
    if writer is not None:
        writer.abort()
    starting.unlink(missing_ok=True)


def check_log_path(out: Path, scenario_source: str, *, force: bool = False) -> None:
    """Refuse a log path that would destroy something that is not a flight log.

    Parameters
    ----------
    out : Path
        The log file to be written.
    scenario_source : str
        The scenario file (never overwritten, even with ``force``).
    force : bool
        Allow replacing an existing file that is not an MCAP log.

    Raises
    ------
    LogError
        ``out`` is the scenario file, a folder, or an existing file that is not MCAP (without
        ``force``).
    """
    if not out.exists() and not out.is_symlink():
        return
    if out.is_dir():
        raise LogError(str(out), "the log path is a folder; give a file name ending in .mcap (--log) or the folder as --out")
    src = Path(scenario_source)
    if src.exists() and out.exists() and os.path.samefile(out, src):
        raise LogError(str(out), "the log path is the scenario file itself; give another --log path")
    if force:
        return
    try:
        with open(out, "rb") as f:
            head = f.read(len(MCAP_MAGIC))
    except OSError as exc:
        raise LogError(str(out), f"an existing file is in the way and cannot be read ({exc.strerror}); "
                       "choose another --log path") from None
    if head != MCAP_MAGIC:
        raise LogError(str(out), "an existing file that is not an MCAP log is in the way; choose another --log "
                       "path, or pass --force (Python: force=True) to replace it")


def _loop(sc: Scenario, ac: Aircraft, sensors: SensorSuite, pilot: Pilot, channels: tuple, progress: bool | None,
          inj: FaultInjector | None, fault_channels: tuple | None, stop: StopRequest, bank: FdiBank | None = None,
          per_step: bool = True, writer: FlightLogWriter | None = None,
          native_core: tuple[object | None, str] = (None, "python")):
    """The per-step loop; returns (status, reason, time of the status [s], max deviations, steps,
    which core flew).

    A fault-free flight flies the compiled chunk core (:mod:`fdi_sim.sim._chunk`, many steps per
    compiled call, JSBSim called through its own symbols) where :mod:`fdi_sim.aircraft.native`
    allows it (``FDI_SIM_CORE``), with the same numbers as the Python loop below; otherwise, and
    for a faulty flight (the injector works on lists), the Python loop. ``writer`` (the log's, when
    it logs per step): the chunks end at its flush windows, so the log's bytes are the Python
    loop's. ``native_core``: :func:`_native_core`'s answer, made in the set-up.

    The truth, its divergence checks, the sensors, the pilot and the deviation statistics are one
    compiled call a step (:mod:`fdi_sim.sim._core`); a faulty flight measures and flies the pilot
    on lists (the injector's contract) and uses the core for the truth and the statistics.

    ``steps`` counts the steps whose measurements, commands and (with ``per_step``) log rows are
    complete: rows 0 .. steps-1. A training flight (``run(keep_rows=True)``) passes no truth,
    surface and operating-point channels: their rows are then neither read nor built. With a bank, every detector sample ``j`` is taken at step ``j n``
    (module :mod:`fdi_sim.bank.runtime`): the measurement row before the pilot, the command row after
    it, the block run before the pilot of its last step (so a reconfiguration acts on that step).
    """
    ch_truth, ch_surf, ch_op, ch_cmd, ch_meas = channels
    log_state = per_step and ch_truth is not None  # the truth, surface and operating-point topics
    ch_ftruth, ch_fevents, ch_valid = fault_channels if fault_channels else (None, None, None)
    # one compiled call a step (module fdi_sim.sim._core): the JSBSim properties are read flat (the
    # AGL altitude last) and packed behind the truth in x_buf, which the kernels see as x_arr; the
    # core builds the truth, checks it, measures, flies the pilot and keeps the deviations
    truth_names = truth_signals(sc.aircraft)  # the common signals, then the aircraft's engine gauges
    n_truth = len(truth_names)
    read_flat, plan = ac.flat_reader(truth_names, extra=("position/h-agl-ft",))
    n_flat = len(read_flat())
    x_buf = (ctypes.c_double * (n_truth + n_flat))()
    x_arr = np.ctypeslib.as_array(x_buf)
    x_truth = x_arr[:n_truth]  # the truth as the core wrote it (tolist: the log's and the injector's list)
    pack_flat, flat_at = struct.Struct(f"{n_flat}d").pack_into, 8 * n_truth  # 0.44 us; a ctypes slice: 0.77
    read_surf = ac.list_reader(SURFACE_SIGNALS)
    measure = sensors.step_list
    _, s_tab, s_off, refill = sensors.compiled()
    _, p_state, p_par = pilot.compiled()
    core = _core.step
    lim = sc.model.limits
    atm = sc.model.atmosphere
    wn, we, _ = wind_ned_fps(atm.wind_from_deg, atm.wind_speed_kts)  # steady air mass [ft/s]
    aux = _core.make_aux(truth_names, plan, n_flat, alpha_min_rad=lim.alpha_min_deg * RAD_PER_DEG,
                         alpha_max_rad=lim.alpha_max_deg * RAD_PER_DEG, phi_max_rad=lim.phi_max_deg * RAD_PER_DEG,
                         rate_max_radps=lim.rate_max_radps, vc_min_kts=lim.vc_min_kts, wind_north_fps=wn,
                         wind_east_fps=we)
    ALL, FIRST, SECOND, TRUTH, STATS, REFILL = (_core.ALL, _core.TRUTH | _core.MEASURE, _core.PILOT | _core.STATS,
                                                _core.TRUTH, _core.STATS, _core.REFILL)
    step_jsbsim = ac.stepper()
    y = y_buf = np.empty(len(sensors.names))  # the measurements of the fast path (refilled each step)
    u_arr = np.empty(9)  # the pilot's commands and references (refilled each step), then the trim
    write_cmd = ac.command_writer()
    idx = {n: i for i, n in enumerate(truth_names)}
    i_h, i_vc, i_alpha, i_mach = idx["h_ft"], idx["vc_kts"], idx["alpha_rad"], idx["mach"]
    flaps_deg = sc.model.initial.flaps_deg
    dt = sc.dt_s
    n_steps = int(round(sc.duration_s / dt))
    pitch_trim = ac.node("fcs/pitch-trim-cmd-norm").get_double_value()  # set by the trim, held (read once)
    u_arr[8] = pitch_trim
    bar = _progress_bar(sc, progress)
    status, reason = "completed", ""
    k = 0
    t_s = 0.0
    eta = 0.0
    last_shown = 0
    steps = 0
    # the bank's buffers: a sample every n_fdi steps, a block every K steps (never a division by 0
    # without a bank: those steps never come)
    cmd_views = None
    if bank is not None:
        n_fdi, K, S = bank.n, bank.K, bank.S
        cmd_rows, meas_rows, valid_rows = bank.cmd_rows, bank.meas_rows, bank.valid_rows
        # the fast path's rows (training.build.build_loop_bank gives the bank PILOT_FIELDS): the pilot's 8 outputs, then the trim
        cmd_rows[:, 8] = pitch_trim
        cmd_views = [cmd_rows[i] for i in range(K)]
    else:
        n_fdi = K = S = n_steps + 2
        cmd_rows = meas_rows = valid_rows = None
    next_sample = n_fdi
    corrected = False
    scale = None  # the bank's command rescale (elevator, aileron, rudder, throttle), once it sets one
    has_dropout = inj is not None and inj.has_dropout
    nat, core_used = native_core
    try:
        if nat is not None:
            done = [0]  # steps complete, for the finally below when a divergence is raised
            status, reason, t_s = _fly_chunks(
                nat, ac, truth_names, n_steps, dt, x_arr, y, u_arr, cmd_rows, bank, n_fdi, K, S, meas_rows, s_tab,
                s_off, p_state, p_par, aux, refill, per_step, log_state, channels, writer, flaps_deg,
                (i_h, i_vc, i_mach, i_alpha), stop, bar, done, lim)
            steps = done[0]
        for k in range(n_steps + 1) if nat is None else ():
            if stop.requested:  # between two steps: every topic holds steps 0 .. k-1
                status, reason = "interrupted", stop.reason
                t_s = (k - 1) * dt if k else 0.0
                break
            t_s = k * dt
            pack_flat(x_buf, flat_at, *read_flat())
            # with a bank the pilot writes straight into the bank's command row of this step
            u_row = cmd_views[k % K] if cmd_views is not None else u_arr
            # --- truth, divergence checks (NaN, ground, departure), sensors; pilot unless the bank samples
            if inj is None:  # the fast path: everything in one call on a step without a bank sample
                mode = ALL if k != next_sample and not corrected else FIRST
                code = core(mode, t_s, x_arr, y, u_row, s_tab, s_off, p_state, p_par, aux)
                if code == REFILL:  # the sensors' noise block ran out: nothing was measured
                    refill()
                    code = core(mode, t_s, x_arr, y, u_row, s_tab, s_off, p_state, p_par, aux)
            else:  # faults act on lists (the injector's contract)
                code = core(TRUTH, t_s, x_arr, y_buf, u_row, s_tab, s_off, p_state, p_par, aux)
            if code:
                raise SimulationDiverged(t_s, _core.divergence_reason(code, x_truth.tolist(), truth_names, lim))
            xl = x_truth.tolist() if log_state or inj is not None else None
            if inj is not None:
                y = measure(t_s, xl)
                inj.begin_step(t_s)
                y = inj.sensors(t_s, k, y, xl)
            # --- the FDI bank: the sample's measurement; at a block's end, the block ---------------
            if k == next_sample:
                jb = (k // n_fdi - 1) % S
                meas_rows[jb] = y
                if has_dropout:
                    valid_rows[jb] = inj.valid
                next_sample += n_fdi
                if k % K == 0 and bank.end_block(k, dt):  # the bank reconfigured: from this step on
                    corrected, scale = bool(bank.corrections), bank.command_scale
            if inj is None:
                if mode != ALL:  # the pilot after the bank's sample, on its (corrected) input
                    core(SECOND, t_s, x_arr, bank.pilot_input(y) if corrected else y, u_row, s_tab, s_off, p_state,
                         p_par, aux)
                cmd = u_row  # the logged row: the pilot's 8 outputs and the held pitch trim (written as is)
                el, ai, ru, th, _, _, _, _, _ = u_row.tolist()
                if scale is None:
                    write_cmd(el, ai, ru, th)
                else:  # an actuator's lost effectiveness made up (the log keeps the pilot's command)
                    write_cmd(el * scale[0], ai * scale[1], ru * scale[2], th * scale[3])
            else:  # faults: sensors -> pilot -> commands -> plant (surfaces, engines, icing)
                y_pilot = bank.pilot_input(y) if corrected else y
                _, el, ai, ru, th, h_ref, vc_ref, psi_ref, phi_ref = pilot.step(t_s, y_pilot)
                if scale is None:
                    write_cmd(*inj.commands(t_s, el, ai, ru, th))
                else:
                    write_cmd(*inj.commands(t_s, el * scale[0], ai * scale[1], ru * scale[2], th * scale[3]))
                inj.after_commands()
                inj.plant(t_s, xl)
                eta = inj.icing_eta
                cmd = (el, ai, ru, th, h_ref, vc_ref, psi_ref, phi_ref, pitch_trim)
                u_row[:] = cmd
                core(STATS, t_s, x_arr, y_buf, u_row, s_tab, s_off, p_state, p_par, aux)
            # --- log ------------------------------------------------------------------------
            if per_step:  # the order of the writes is the log's record order
                if log_state:
                    ch_truth.write(t_s, xl)
                ch_meas.write(t_s, y)
                if inj is not None:
                    ch_ftruth.write(t_s, inj.truth_row())
                    if ch_valid is not None:
                        ch_valid.write(t_s, inj.valid)
                ch_cmd.write(t_s, cmd)
                if log_state:
                    ch_op.write(t_s, (xl[i_h], xl[i_vc], xl[i_mach], xl[i_alpha], flaps_deg, eta))
            if inj is not None and inj.events:
                for te, ev in inj.pop_events():
                    ch_fevents.write(te, ev)
            steps = k + 1
            if k == n_steps:
                break
            if not step_jsbsim():
                raise SimulationDiverged(t_s, "JSBSim stopped the run")
            if log_state:
                ch_surf.write(t_s, read_surf())
            if bar is not None and k - last_shown >= 120:
                bar.update((k - last_shown) * dt)
                last_shown = k
    except SimulationDiverged as exc:
        status, reason, t_s = "diverged", exc.reason, exc.t_s
        if nat is not None:
            steps = done[0]
    except KeyboardInterrupt:  # raised inside a callee (no handler installed): end cleanly all the same
        status, reason = "interrupted", stop.reason or "stopped by the user (Ctrl-C)"
        if nat is not None:
            steps = done[0]
    finally:
        if bar is not None:
            bar.close()
        if bank is not None and steps:
            # the partial last block: samples whose step completed (the replay of the log sees the same)
            bank.flush(steps - 1, dt)
            bank.close((steps - 1) * dt)
    return status, reason, t_s, aux[[_core.MAX_DH, _core.MAX_DV, _core.MAX_DPHI]].copy(), steps, core_used


#: steps per compiled chunk at most: 1 s simulated, about 1-1.5 ms of wall time, so a stop request
#: and the progress bar are seen within that
CHUNK_STEPS = 120


def _native_core(ac: Aircraft, inj: FaultInjector | None) -> tuple[object | None, str]:
    """The compiled core's binding for this flight, or None and why not (``FDI_SIM_CORE``)."""
    from fdi_sim.aircraft.native import NativeUnavailable, core_mode

    if inj is not None:
        return None, "python: a faulty flight (the fault injector works on lists)"
    mode = core_mode()
    if mode == "python":
        return None, "python: FDI_SIM_CORE=python"
    try:
        return ac.native(), "compiled"
    except NativeUnavailable as exc:
        if mode == "compiled":
            raise NativeUnavailable(f"FDI_SIM_CORE=compiled, but the compiled core cannot run here: {exc}") from None
        return None, f"python: {exc}"


def _fly_chunks(nat, ac, truth_names, n_steps, dt_s, x_arr, y, u_arr, cmd_rows, bank, n_fdi, K, S, meas_rows, s_tab,
                s_off, p_state, p_par, aux, refill, per_step, log_state, channels, writer, flaps_deg, op_idx, stop,
                bar, done, lim):
    """The fast path through the compiled chunk core (:mod:`fdi_sim.sim._chunk`); returns (status,
    reason, time of the status [s]), ``done[0]`` the steps complete; raises SimulationDiverged as
    the Python loop does. Between two chunks: a stop request, the bank's blocks, the sensors' noise
    refill, the log rows (``write_rows``, one call per channel and chunk, within one flush window
    of ``writer``) and the progress bar."""
    import fdi_sim.sim._chunk as _chunk

    ch_truth, ch_surf, ch_op, ch_cmd, ch_meas = channels
    n_truth = len(truth_names)
    read_nodes, _ = ac.flat_nodes(truth_names, extra=("position/h-agl-ft",))
    rp = nat.node_pointers(read_nodes)
    cp = nat.node_pointers(ac.command_nodes())
    s_nodes, s_plan = ac.flat_nodes(SURFACE_SIGNALS) if log_state else ([], [])
    sp = nat.node_pointers(s_nodes) if s_nodes else np.zeros(0, dtype=np.uintp)
    CH = CHUNK_STEPS
    bt, btruth, bmeas, bcmd, bop, bsurf = _chunk.buffers(CH, n_truth, len(y), len(u_arr), max(1, len(sp)))
    use_bank = bank is not None
    rows = cmd_rows if use_bank else np.zeros((1, len(u_arr)))
    mrows = meas_rows if use_bank else np.zeros((1, len(y)))
    state = np.array([0, 0, 0, 0, n_fdi], dtype=np.int64)
    corr, yp, scale = np.zeros(len(y)), np.empty(len(y)), np.ones(4)
    corrected = has_scale = False
    msg_addr = nat.message.ctypes.data
    i_h, i_vc, i_mach, i_alpha = op_idx
    period_s = writer.flush_period_s if writer is not None else 0.0
    shown = 0
    while True:
        k = int(state[_chunk.S_K])
        if stop.requested and state[_chunk.S_PHASE] == 0:  # between two steps: every topic holds 0 .. k-1
            return "interrupted", stop.reason, (k - 1) * dt_s if k else 0.0
        k_end = min(k + CH, n_steps + 1)
        if writer is not None:  # rows of one chunk within one flush window (the Python loop's chunks)
            hi_s = writer.window_end_s
            if k * dt_s >= hi_s:  # this chunk's first write flushes: the window it opens
                hi_s = (math.floor(k * dt_s / period_s) + 1) * period_s
            while k_end > k + 1 and (k_end - 1) * dt_s >= hi_s:
                k_end -= 1
        state[_chunk.S_ROWS] = 0
        code = _chunk.run_chunk(state, k_end, n_steps, dt_s, nat.run_shim, nat.run, nat.fdm, msg_addr,
                                len(nat.message), nat.get, nat.set, rp, n_truth, cp, sp, x_arr, y, yp, u_arr, rows,
                                use_bank, n_fdi, K, S, mrows, corrected, corr, has_scale, scale, s_tab, s_off,
                                p_state, p_par, aux, per_step, log_state, bt, btruth, bmeas, bcmd, bop, bsurf,
                                flaps_deg, i_h, i_vc, i_mach, i_alpha)
        r = int(state[_chunk.S_ROWS])
        k_now = int(state[_chunk.S_K])
        done[0] = k_now  # rows 0 .. k_now - 1 complete (at BLOCK the step k_now is half done)
        if per_step and r:
            if log_state:
                ch_truth.write_rows(bt[:r], btruth[:r])
            ch_meas.write_rows(bt[:r], bmeas[:r])
            ch_cmd.write_rows(bt[:r], bcmd[:r])
            if log_state:
                ch_op.write_rows(bt[:r], bop[:r])
                n_s = r - 1 if code in (_chunk.END, _chunk.STOPPED, _chunk.EXCEPTION) else r  # no surfaces after the last step
                if n_s:
                    ch_surf.write_rows(bt[:n_s], _combine(bsurf[:n_s], s_plan))
        if bar is not None and k_now - shown >= 120:
            bar.update((k_now - shown) * dt_s)
            shown = k_now
        if code == _chunk.LIMIT:
            continue
        if code == _chunk.END:
            return "completed", "", (k_now - 1) * dt_s
        if code == _chunk.BLOCK:  # the bank's block at step k_now (its sample stored); the step resumes after it
            bank.end_block(k_now, dt_s)
            # the pilot's corrections and the command rescale, as the bank holds them after the block
            corrected = bool(bank.corrections)
            for c in bank.corrections:
                corr[c.index] = c.fault_estimate
            if bank.command_scale is not None:
                has_scale, scale[:] = True, bank.command_scale
            continue
        if code == _core.REFILL:  # the sensors' noise block ran out: nothing of the step was done
            refill()
            continue
        t_fail_s = (k_now - 1) * dt_s if code in (_chunk.STOPPED, _chunk.EXCEPTION) else k_now * dt_s
        if code == _chunk.STOPPED:
            raise SimulationDiverged(t_fail_s, "JSBSim stopped the run")
        if code == _chunk.EXCEPTION:
            raise SimulationDiverged(t_fail_s, f"JSBSim threw a C++ exception in FGFDMExec::Run(): "
                                     f"{nat.exception_message()}")
        raise SimulationDiverged(t_fail_s, _core.divergence_reason(code, x_arr[:n_truth].tolist(), truth_names, lim))


def _combine(flat: NDArray[np.float64], plan: Sequence[tuple[int, int, float | None]]) -> NDArray[np.float64]:
    """Signals from their flat property reads, per row (:meth:`Aircraft.list_reader`'s values bit
    for bit: a summed signal is ``0 + a + b``, Python's ``sum``; a scaled one ``factor * value``)."""
    out = np.empty((flat.shape[0], len(plan)))
    for i, (a, b, f) in enumerate(plan):
        if b - a == 1:
            v = flat[:, a]
        else:
            v = np.zeros(flat.shape[0])
            for j in range(a, b):
                v = v + flat[:, j]
        out[:, i] = v if f is None else f * v
    return out


def _progress_bar(sc: Scenario, progress: bool | None):
    if progress is None:
        progress = sc.duration_s > 30 and sys.stderr.isatty()
    if not progress:
        return None
    from tqdm import tqdm

    return tqdm(total=sc.duration_s, unit="sim s", desc=sc.name, leave=False, dynamic_ncols=True,
                bar_format="{l_bar}{bar}| {n:.0f}/{total:.0f} sim s [{elapsed}<{remaining}, {rate_fmt}]")
