"""The FDI bank in the loop: detectors, decisions, failure log and reconfiguration, block by block.

Time convention (:mod:`fdi_sim.detectors.samples`): detector sample ``j`` is taken at simulation
step ``k = j n`` (``n = sim_rate / rate``), with the measurement read at the top of step ``k`` and
the commands averaged over steps ``(j-1) n .. j n - 1`` (the interval ending at ``t_j``). The loop
hands the bank, per step, the command row of that step (:attr:`FdiBank.cmd_rows`, a ring of one
block) and, at every sample step, the measurement row (:attr:`FdiBank.meas_rows`); every
``block_samples`` samples (``block_s``, 0.5 s by default) it calls :meth:`FdiBank.end_block`,
which runs every member's stream once over the block (:mod:`fdi_sim.detectors.stream`), the decision rule, the failure log
and the reconfiguration, and writes the ``/fdi`` topics. A decision about sample ``j`` is therefore
*acted on* (reconfiguration) at the end of its block, at most ``block_s`` after ``t_j``; its time
stamp is ``t_j``. Replaying a log (:meth:`FdiBank.replay`) feeds the logged rows through the same
functions, and every kernel is invariant to how samples are cut into blocks, so in-loop and replay
agree bit for bit, with reconfiguration too (the bank reads the logged sensor measurements and the
logged pilot commands; what it replaced for the pilot is in ``/fdi/reconfiguration``).

Decision (per member): the sample's *exceedance* is ``valid and statistic > threshold``; the
alarm is k-of-n persistence over the exceedances (``k = n = 1``: the exceedance itself). While an
alarm lasts, the member's per-sample isolations vote; the isolation is the hypothesis with the
most votes so far (first to reach it on a tie), confirmed after ``confirm_samples`` votes.

Failure log (Miller & Ribbens, FIG. 4): one binary signal per hypothesis, on while some member's
alarm is isolated to it; its rising and falling edges are the events of ``/fdi/failure_log``
(onset, end, duration, kind, nature: a hypothesis with a second onset is intermittent); an entry
still on at the end of the flight gets an ``ongoing`` end event (:meth:`FdiBank.close`).

Reconfiguration (FIG. 2, signal G), when a member with estimates (kalman-gust) confirms a sensor:
the sensor is excluded from the filter's measurement update (latched: a failed sensor is not
re-admitted in flight), the filter's estimate of the sensor's fault ``f_hat = mean(y - y_hat)``
over the last window is updated at every block, and the pilot receives ``y - f_hat`` instead of
``y`` from the next step on (a bias is removed at full bandwidth; a drift is followed with the
window's lag).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.decision.failure_log import FailureLogger
from fdi_sim.detectors.stream import BlockOutputs, EstimatesActuators
from fdi_sim.bank.kernels import average_commands, decide, gather_columns, statistic_rows, take_columns
from fdi_sim.bank.topics import RECONFIG_JSON_SCHEMA, STAT_FIELDS, TOPIC_FDI_RECONFIG, msg_name
from fdi_sim.bank.turbulence import ThresholdSchedule, scheduled_threshold, turbulence_estimate
from fdi_sim.decision.outcome import LATE_GRACE_S, fault_outcome
from fdi_sim.errors import DesignError

#: the commands an actuator reconfiguration can rescale, in the loop's write order
ACTUATOR_INPUTS = ("elevator_cmd_norm", "aileron_cmd_norm", "rudder_cmd_norm", "throttle_cmd_norm")
#: the largest rescale (an effectiveness estimate below 1/3 is not made up: the stops would cut it)
MAX_COMMAND_SCALE = 3.0


@dataclass(frozen=True)
class DecisionConfig:
    """The bank's decision rule.

    Attributes
    ----------
    k, n : int
        k-of-n persistence on the exceedances (1, 1: the exceedance itself).
    confirm_samples : int
        Votes an isolation needs before reconfiguration acts on it [samples].
    rule : str
        ``"persistence"``, or ``"angle-magnitude"``: the patent's two-step rule (seed 002): a
        sample counts only if the statistic exceeds the threshold *and* the residual lies within
        the angle bound of a fault direction (the detector's signature cosine >= its
        ``min_cosine``); then k-of-n as above.
    """

    k: int = 3
    n: int = 5
    confirm_samples: int = 10
    rule: str = "persistence"

    def __post_init__(self) -> None:
        if self.rule not in ("persistence", "angle-magnitude"):
            raise DesignError(f"unknown decision rule {self.rule!r}; persistence or angle-magnitude")
        if not (1 <= self.k <= self.n):
            raise DesignError(f"persistence needs 1 <= k <= n, got k={self.k}, n={self.n}")
        if self.confirm_samples < 1:
            raise DesignError(f"confirm_samples must be >= 1, got {self.confirm_samples}")


@dataclass(frozen=True)
class BankAlarm:
    """One alarm episode of one member (for the run summary)."""

    detector: str
    onset_t_s: float
    end_t_s: float | None
    isolation: str | None


#: per-member arrays kept by :meth:`FdiBank.keep_trace` (trace name -> attribute)
TRACE_ATTR = {"statistic": "stat", "threshold": "thr", "exceedance": "exceed", "alarm": "alarm", "valid": "valid",
              "isolation": "iso", "point": "point"}
TRACE_FIELDS = tuple(TRACE_ATTR)


class _Member:
    """One detector of the bank: its stream (:class:`~fdi_sim.detectors.stream.StreamingDetector`),
    column maps, block buffers and decision state. Nothing here depends on what kind of detector
    the stream is: its capabilities are its attributes (``estimate_names``, ``independent``,
    ``fault_directions``)."""

    def __init__(self, stream: Any, meas_names: Sequence[str], cmd_names: Sequence[str],
                 every: Mapping[str, int], S: int, decision: DecisionConfig) -> None:
        self.stream, self.id = stream, str(stream.id)
        self.hypotheses = tuple(stream.hypotheses)
        names = tuple(stream.output_names)
        missing = [nm for nm in names if nm not in meas_names]
        if missing:
            raise DesignError(f"{self.id} needs the measurements {missing}, which the sensor suite does not have")
        missing = [nm for nm in stream.input_names if nm not in cmd_names]
        if missing:
            raise DesignError(f"{self.id} needs the commands {missing}, which the loop does not log")
        self.output_names = names
        self.input_names = tuple(stream.input_names)
        self.residual_names = tuple(stream.residual_names)
        self.estimate_names = tuple(stream.estimate_names)
        bad = [nm for nm in self.estimate_names if nm not in names]
        if bad:
            raise DesignError(f"{self.id} estimates {bad}, which are not among its outputs {list(names)}")
        self.cols = np.array([list(meas_names).index(nm) for nm in names], dtype=np.int64)
        self.in_cols = np.array([list(cmd_names).index(nm) for nm in self.input_names], dtype=np.int64)
        self.every = np.array([max(1, int(every.get(nm, 1))) for nm in names], dtype=np.int64)
        self.excluded = np.zeros(len(names), dtype=np.bool_)
        p = len(names)
        self.y = np.empty((S, p))
        self.ok = np.empty((S, p), dtype=np.bool_)
        self.fresh = np.empty((S, p), dtype=np.bool_)
        self.u = np.empty((S, len(self.in_cols)))
        self.out = BlockOutputs.allocate(S, len(self.residual_names), len(self.estimate_names))
        o = self.out
        self.stat, self.thr, self.valid, self.hyp, self.point = o.statistic, o.threshold, o.valid, o.hypothesis, o.point
        self.nu, self.yhat, self.cos = o.residual, o.estimate, o.cosine
        self.exceed = np.empty(S, dtype=np.bool_)
        self.alarm = np.empty(S, dtype=np.bool_)
        self.iso = np.empty(S, dtype=np.int64)
        self.rows = np.empty((S, 7))  # the statistic topic's rows (STAT_FIELDS after t_s)
        self.lead = np.zeros(S, dtype=np.int64)  # the isolation leader's votes per sample
        self.full_S = S
        self.decision = decision
        self.angle_rule = decision.rule == "angle-magnitude"
        self.direct = bool(stream.independent)
        self.estimates_actuators = isinstance(stream, EstimatesActuators)
        self.keep = False
        self.j_start = 0
        self.sched: tuple[NDArray[np.float64], ...] | None = None  # (log sigma, log threshold, threshold)
        self.reset()

    @property
    def threshold(self) -> float:
        """The alarm threshold on the statistic [-] (:meth:`set_threshold`)."""
        return float(self.stream.threshold)

    def set_threshold(self, value: float) -> None:
        """The alarm threshold on the statistic, through the stream's contract."""
        self.stream.set_threshold(float(value))

    def trace_series(self) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """The statistic of every sample since :meth:`FdiBank.keep_trace`, and whether each was
        armed and valid (calibration)."""
        if not self.trace["statistic"]:
            return np.zeros(0), np.zeros(0, dtype=bool)
        return np.concatenate(self.trace["statistic"]), np.concatenate(self.trace["valid"])

    def reset(self) -> None:
        self.stream.reset()
        self.trace = {k: [] for k in TRACE_FIELDS}
        self.excluded[:] = False
        d = self.decision
        self.ring = np.zeros(d.n, dtype=np.int64)
        self.st = np.array([0, 0, 0, -1, 0, 0], dtype=np.int64)
        self.votes = np.zeros(max(1, len(self.hypotheses)), dtype=np.int64)
        self.was_on = False
        self.sparse: list[tuple[int, NDArray[np.bool_], NDArray[np.int64]]] = []  # (first sample, alarm, isolation)
        self.samples = 0

    def run(self, u_avg: NDArray[np.float64], meas: NDArray[np.float64], valid: NDArray[np.bool_], row0: int,
            n: int, S: int, t: NDArray[np.float64], unarmed: int = 0,
            sigma: NDArray[np.float64] | None = None) -> None:
        if S == self.full_S:  # the loop's case: the arrays themselves (slicing costs ~0.2 us a view)
            y, ok, fresh, u, out, ex, al, iso, lead = (self.y, self.ok, self.fresh, self.u, self.out, self.exceed,
                                                       self.alarm, self.iso, self.lead)
        else:
            y, ok, fresh, u, ex, al, iso, lead = (a[:S] for a in (self.y, self.ok, self.fresh, self.u, self.exceed,
                                                                  self.alarm, self.iso, self.lead))
            out = self.out.rows(S)
        gather_columns(meas, valid, self.cols, self.excluded, self.every, row0, n, y, ok, fresh)
        take_columns(u_avg, self.in_cols, u)
        if self.estimates_actuators:  # the block's first sample, for the effectiveness estimator
            self.j_start = int(self.stream.samples_seen)
        self.stream.process_block(t[:S] if S != t.shape[0] else t, u, y, ok, fresh, out)
        if self.sched is not None and sigma is not None:  # thresholds on the estimated turbulence
            scheduled_threshold(sigma, self.sched[0], self.sched[1], self.sched[2], out.threshold)
        if unarmed:  # before the bank is armed the statistic is logged, never decided on
            out.valid[:unarmed] = False
        decide(out.statistic, out.threshold, out.valid, out.hypothesis, self.decision.k, self.angle_rule, self.ring,
                self.st, self.votes, ex, al, iso, lead)
        if self.keep:
            for k in TRACE_FIELDS:
                self.trace[k].append(getattr(self, TRACE_ATTR[k])[:S].copy())
        elif self.st[5] or self.was_on:  # the decisions of blocks with an alarm (the others: none), for the summary
            self.sparse.append((row0 // n, al.copy(), iso.copy()))
        self.samples += S


@dataclass
class _Channels:
    stat: Any = None
    resid: Any = None
    est: Any = None


@dataclass
class Correction:
    """A reconfigured sensor: the pilot gets ``y - fault_estimate`` for it."""

    sensor: str
    index: int
    t_s: float
    detector: str
    fault_estimate: float = 0.0


class FdiBank:
    """Detectors, decision, failure log and reconfiguration, run in blocks (module docstring).

    Parameters
    ----------
    streams : sequence
        The members, each a :class:`~fdi_sim.detectors.stream.StreamingDetector`.
    cmd_names, meas_names : sequence of str
        Columns of :attr:`cmd_rows` and :attr:`meas_rows` (the logged commands and measurements).
    sensor_rates_hz : mapping
        Sampling rate per measurement [Hz] (freshness).
    sim_rate_hz, rate_hz : float
        Simulation and detector rates [Hz].
    block_samples : int
        Samples per block.
    decision : DecisionConfig
    reconfigure : bool
        Replace confirmed faulty sensors in the pilot's input.
    pilot_sensors : sequence of str
        The measurements the pilot reads (reconfiguration only acts on those).
    arm_s : float
        The bank decides from this time on [s]: before it the filters settle on the sensors'
        turn-on biases (measured on the F-16 in light turbulence: every training sample with the
        statistic over 60 lay in the first 3.2 s, and with them in, the fitted tail was heavy, shape
        0.58, instead of the exponential tail, shape -0.02, of the armed samples).
    """

    def __init__(self, streams: Sequence[Any], *, cmd_names: Sequence[str], meas_names: Sequence[str],
                 sensor_rates_hz: Mapping[str, float], sim_rate_hz: float, rate_hz: float, block_samples: int = 5,
                 decision: DecisionConfig = DecisionConfig(), reconfigure: bool = False,
                 pilot_sensors: Sequence[str] = (), notes: Sequence[str] = (), arm_s: float = 5.0) -> None:
        from fdi_sim.detectors.samples import decimation

        self.n = decimation(sim_rate_hz, rate_hz)
        self.rate_hz, self.sim_rate_hz = float(rate_hz), float(sim_rate_hz)
        self.S = int(block_samples)
        if self.S < 1:
            raise DesignError(f"block_samples must be >= 1, got {block_samples}")
        self.K = self.n * self.S
        self.arm_samples = int(round(arm_s * rate_hz))
        self.cmd_names, self.meas_names = tuple(cmd_names), tuple(meas_names)
        every = {nm: int(round(sim_rate_hz / r)) for nm, r in sensor_rates_hz.items() if r}
        self.decision = decision
        if decision.rule == "angle-magnitude":
            bad = [str(getattr(st, "id", "?")) for st in streams if not getattr(st, "fault_directions", False)]
            if bad:
                raise DesignError(f"the angle-magnitude rule needs fault directions (C D_f), which {', '.join(bad)} "
                                  "do not give (a kinematic check has a residual per sensor, no direction); use "
                                  "decision = \"persistence\", or members with fault directions only")
        self.members = [_Member(s, self.meas_names, self.cmd_names, every, self.S, decision) for s in streams]
        ids = [m.id for m in self.members]
        if len(set(ids)) != len(ids):
            raise DesignError(f"detector ids in a bank must be unique: {ids}")
        self.reconfigure = bool(reconfigure)
        self.pilot_sensors = tuple(pilot_sensors)
        self.notes = tuple(notes)
        hyps: list[str] = []
        for m in self.members:
            hyps += [h for h in m.hypotheses if h not in hyps]
        self.hypotheses = tuple(hyps)
        self._hyp_index = [np.array([self.hypotheses.index(h) for h in m.hypotheses], dtype=np.int64) for m in self.members]
        self.cmd_rows = np.zeros((self.K, len(self.cmd_names)))
        self.meas_rows = np.zeros((self.S, len(self.meas_names)))
        self.valid_rows = np.ones((self.S, len(self.meas_names)), dtype=np.bool_)
        self._u_avg = np.zeros((self.S, len(self.cmd_names)))
        self._t = np.empty(self.S)
        self._writer = None
        self._ch_reconf = None
        self.schedule: ThresholdSchedule | None = None
        self._sched_col = -1
        self._sched_state = np.zeros(4)
        self._sigma = np.empty(self.S)
        self._sigma_trace: list[NDArray[np.float64]] = []
        self.reset()

    # --- lifecycle -----------------------------------------------------------------------------
    def reset(self) -> None:
        """Fresh detectors and decisions, empty failure log, no reconfiguration."""
        for m in self.members:
            m.reset()
        self.samples_done = 0
        self._t_trace: list[NDArray[np.float64]] = []
        self._sched_state[:] = 0.0
        self._sigma_trace = []
        self.valid_rows[:] = True
        self.failure_log = FailureLogger(self.hypotheses)
        self._sig = np.zeros(len(self.hypotheses), dtype=np.bool_)
        self._onsets = np.zeros(len(self.hypotheses), dtype=np.int64)
        self._sig_detectors: list[set[str]] = [set() for _ in self.hypotheses]
        self.alarms: list[BankAlarm] = []
        self._open: dict[str, int] = {}
        self.corrections: list[Correction] = []
        self._corrected: set[str] = set()
        self._confirmed: dict[str, set[str]] = {}
        self._estimators: dict[str, tuple[_Member, Any, float]] = {}  # actuator -> (member, estimator, start)
        self.command_scale: tuple[float, float, float, float] | None = None
        self.reconfig_events: list[dict[str, Any]] = []

    def set_schedule(self, schedule: ThresholdSchedule | None) -> None:
        """Schedule the members' thresholds on the estimated turbulence
        (:mod:`fdi_sim.bank.turbulence`), or stop (None). A member the schedule does not name keeps
        its threshold; a named one's stream threshold is set to its lowest, so that it isolates
        wherever the scheduled threshold can be exceeded.

        Raises
        ------
        DesignError
            The schedule's signal is not a measurement of the bank, or it names no member.
        """
        if schedule is None:
            self.schedule, self._sched_col = None, -1
            for m in self.members:
                m.sched = None
            return
        if schedule.signal not in self.meas_names:
            raise DesignError(f"the threshold schedule reads {schedule.signal}, which the bank does not measure")
        named = [m for m in self.members if m.id in schedule.thresholds]
        if not named:
            raise DesignError(f"the threshold schedule names none of the bank's members {[m.id for m in self.members]}")
        self.schedule, self._sched_col = schedule, self.meas_names.index(schedule.signal)
        for m in self.members:
            if m.id in schedule.thresholds:
                m.sched = schedule.log_tables(m.id)
                m.set_threshold(float(m.sched[2][0]))
            else:
                m.sched = None
        self.reset()

    def sigma_trace(self) -> NDArray[np.float64]:
        """The turbulence estimate of every sample since reset, while a trace is kept (empty
        without a schedule)."""
        return np.concatenate(self._sigma_trace) if self._sigma_trace else np.zeros(0)

    def keep_trace(self, keep: bool = True) -> None:
        """Keep every block's statistic, threshold, decision and isolation (replay, calibration,
        tests); :meth:`trace` returns them."""
        for m in self.members:
            m.keep = bool(keep)

    def trace(self) -> dict[str, dict[str, NDArray]]:
        """Per member id, the kept arrays (:data:`TRACE_FIELDS`) over all samples since reset."""
        return {m.id: {k: (np.concatenate(v) if v else np.zeros(0)) for k, v in m.trace.items()} for m in self.members}

    def decisions(self) -> tuple[NDArray[np.float64], dict[str, tuple[NDArray[np.bool_], tuple[str | None, ...]]]]:
        """Sample times [s] and, per member id, the alarm and the isolated hypothesis of every sample."""
        t = np.concatenate(self._t_trace) if self._t_trace else np.zeros(0)
        out = {}
        for m in self.members:
            if m.trace["alarm"]:  # a kept trace (replay, calibration, tests)
                a = np.concatenate(m.trace["alarm"])
                i = np.concatenate(m.trace["isolation"])
            else:
                a = np.zeros(m.samples, dtype=bool)
                i = np.full(m.samples, -1, dtype=np.int64)
                for j0, al, iso in m.sparse:
                    a[j0:j0 + len(al)] = al
                    i[j0:j0 + len(al)] = iso
            out[m.id] = (a, tuple(m.hypotheses[k] if on and k >= 0 else None for k, on in zip(i, a)))
        return t, out

    def start_at(self, h_ft: float, vc_kts: float) -> None:
        """Start the scheduled members at the point nearest the flight's start."""
        for m in self.members:
            if hasattr(m.stream, "start_at"):
                m.stream.start_at(h_ft, vc_kts)

    def attach(self, writer: Any, *, log_residuals: bool = True) -> None:
        """Open the bank's topics on a :class:`~fdi_sim.flightlog.FlightLogWriter`."""
        from fdi_sim.flightlog import FAILURE_LOG_JSON_SCHEMA, TOPIC_FDI_ALARMS, TOPIC_FDI_FAILURE_LOG, fdi_topic
        from fdi_sim.flightlog.schemas import ALARM_JSON_SCHEMA

        self._writer = writer
        self._chans = []
        for m in self.members:
            ch = _Channels()
            ch.stat = writer.add_vector_channel(fdi_topic(m.id, "statistic"), "fdi_sim/msg/DetectorStatistic",
                                                STAT_FIELDS)
            if log_residuals:
                ch.resid = writer.add_vector_channel(fdi_topic(m.id, "residual"), msg_name(m.id, "Residual"),
                                                     ("t_s",) + tuple(m.residual_names))
                if m.estimate_names:
                    ch.est = writer.add_vector_channel(fdi_topic(m.id, "estimate"), msg_name(m.id, "Estimate"),
                                                       ("t_s",) + tuple(m.estimate_names))
            self._chans.append(ch)
        self._ch_alarms = writer.add_event_channel(TOPIC_FDI_ALARMS, "fdi_sim/msg/Alarm", ALARM_JSON_SCHEMA)
        self._ch_flog = writer.add_event_channel(TOPIC_FDI_FAILURE_LOG, "fdi_sim/msg/FailureLogEntry",
                                                 FAILURE_LOG_JSON_SCHEMA)
        self._ch_reconf = writer.add_event_channel(TOPIC_FDI_RECONFIG, "fdi_sim/msg/Reconfiguration",
                                                   RECONFIG_JSON_SCHEMA) if self.reconfigure else None

    # --- the loop's side ------------------------------------------------------------------------
    def end_block(self, k: int, dt_s: float) -> bool:
        """The block ending at step ``k`` (its last measurement row taken at step ``k``); returns
        True when the pilot's corrections changed."""
        S = self.S
        average_commands(self.cmd_rows, self.n, self._u_avg)
        j0 = self.samples_done
        for i in range(S):
            self._t[i] = (j0 + 1 + i) * self.n * dt_s
        self._t_trace.append(self._t.copy())
        return self._run(self._u_avg, self.meas_rows, self.valid_rows, self._t, S)

    def flush(self, k_last: int, dt_s: float) -> None:
        """The last, partial block: samples whose measurement was taken up to step ``k_last``."""
        j_end = k_last // self.n
        S = j_end - self.samples_done
        if S <= 0:
            return
        average_commands(self.cmd_rows[: S * self.n], self.n, self._u_avg[:S])
        for i in range(S):
            self._t[i] = (self.samples_done + 1 + i) * self.n * dt_s
        self._t_trace.append(self._t[:S].copy())
        self._run(self._u_avg[:S], self.meas_rows[:S], self.valid_rows[:S], self._t[:S], S)

    def pilot_input(self, y: Any) -> Any:
        """The measurements the pilot receives: ``y`` (a list or an array, the same kind back) with
        the reconfigured sensors corrected."""
        yp = y.copy() if isinstance(y, np.ndarray) else list(y)
        for c in self.corrections:
            yp[c.index] = y[c.index] - c.fault_estimate
        return yp

    # --- replay ---------------------------------------------------------------------------------
    def replay(self, cmd: NDArray[np.float64], meas: NDArray[np.float64], valid: NDArray[np.bool_] | None,
               dt_s: float, t_rows_s: NDArray[np.float64] | None = None) -> None:
        """Feed logged rows (every step: ``cmd`` (K, commands), ``meas`` (K, measurements)) through
        the same block functions as the loop."""
        n, S = self.n, self.S
        K = min(len(cmd), len(meas))
        J = (K - 1) // n
        u_avg = np.empty((J, len(self.cmd_names)))
        average_commands(np.ascontiguousarray(cmd[: J * n], dtype=np.float64), n, u_avg)
        rows = n * np.arange(1, J + 1)
        m_s = np.ascontiguousarray(meas[rows], dtype=np.float64)
        v_s = np.ones_like(m_s, dtype=np.bool_) if valid is None else np.ascontiguousarray(valid[rows], dtype=np.bool_)
        t = rows * dt_s if t_rows_s is None else np.asarray(t_rows_s, dtype=float)[rows]
        self._t_trace.append(np.asarray(t, dtype=float).copy())
        for j0 in range(0, J, S):
            b = min(S, J - j0)
            self._run(u_avg[j0:j0 + b], m_s[j0:j0 + b], v_s[j0:j0 + b], t[j0:j0 + b], b)

    # --- one block --------------------------------------------------------------------------------
    def _run(self, u_avg: NDArray[np.float64], meas: NDArray[np.float64], valid: NDArray[np.bool_],
             t: NDArray[np.float64], S: int) -> bool:
        row0 = self.samples_done * self.n
        active = False
        unarmed = min(S, max(0, self.arm_samples - self.samples_done))
        sigma = None
        if self.schedule is not None:
            sigma = self._sigma if S == self.S else self._sigma[:S]
            c = self._sched_col
            turbulence_estimate(meas[:S, c], valid[:S, c], self._sched_state,
                                1.0 / (self.schedule.tau_s * self.rate_hz), self.schedule.clip ** 2, sigma)
            if self.members and self.members[0].keep:
                self._sigma_trace.append(sigma.copy())
        for m in self.members:
            m.run(u_avg, meas, valid, row0, self.n, S, t, unarmed, sigma)
            if m.was_on or m.st[5]:  # in alarm before the block or at some sample of it
                active = True
        changed = False
        if active:
            changed = self._events(t, S)
        if self.corrections:
            self._update_corrections(meas, S)
        if self._estimators and self._update_estimators(t, S):
            changed = True
        if self._writer is not None:
            self._log(t, S)
        self.samples_done += S
        return changed

    def _events(self, t: NDArray[np.float64], S: int) -> bool:
        """Alarm transitions, isolation changes and failure-log edges of a block with activity."""
        changed = False
        sig_rows = np.zeros((S, len(self.hypotheses)), dtype=np.bool_)
        for mi, m in enumerate(self.members):
            a, iso = m.alarm[:S], m.iso[:S]
            hidx = self._hyp_index[mi]
            for j in range(S):
                on = bool(a[j])
                if on and iso[j] >= 0:
                    sig_rows[j, hidx[iso[j]]] = True
                if on and not m.was_on:
                    self._alarm_event(m, float(t[j]), True, j)
                    self._open[m.id] = len(self.alarms)
                    self.alarms.append(BankAlarm(m.id, float(t[j]), None, None))
                elif not on and m.was_on:
                    self._alarm_event(m, float(t[j]), False, j)
                    for by in self._confirmed.values():  # a confirmation lasts as long as its alarm
                        by.discard(m.id)
                    i = self._open.pop(m.id)
                    self.alarms[i] = BankAlarm(m.id, self.alarms[i].onset_t_s, float(t[j]), self.alarms[i].isolation)
                if on and iso[j] >= 0:
                    i = self._open[m.id]
                    name = m.hypotheses[iso[j]]
                    if self.alarms[i].isolation != name:
                        self.alarms[i] = BankAlarm(m.id, self.alarms[i].onset_t_s, None, name)
                        self._alarm_event(m, float(t[j]), True, j, isolated=True)
                    if self.reconfigure and m.lead[j] >= self.decision.confirm_samples:  # votes at sample j
                        self._confirmed.setdefault(name, set()).add(m.id)
                        if self._should_correct(name):
                            self._reconfigure_sensor(name, float(t[j]))
                            changed = True
                        elif (name in ACTUATOR_INPUTS and name in m.input_names and name not in self._estimators
                              and m.estimates_actuators):
                            self._start_estimator(m, name, float(t[j]))
                m.was_on = on
        for j in range(S):
            if not np.array_equal(sig_rows[j], self._sig):
                for h in np.flatnonzero(sig_rows[j] != self._sig):
                    name = self.hypotheses[h]
                    if sig_rows[j, h]:
                        dets = sorted(m.id for mi, m in enumerate(self.members)
                                      if m.alarm[j] and m.iso[j] >= 0 and m.hypotheses[m.iso[j]] == name)
                        self._sig_detectors[h] = set(dets)
                        self._onsets[h] += 1
                        ev = {"event": "onset", "hypothesis": name, "onset_t_s": float(t[j]), "duration_s": None,
                              "kind": self._kind(name), "detector": ",".join(dets), "nature": self._nature(h)}
                    else:
                        onset = self.failure_log._onset[h]
                        ev = {"event": "end", "hypothesis": name, "onset_t_s": float(onset),
                              "duration_s": float(t[j]) - float(onset), "kind": self._kind(name),
                              "detector": ",".join(sorted(self._sig_detectors[h])), "nature": self._nature(h)}
                    if self._writer is not None:
                        self._ch_flog.write(float(t[j]), ev)
                self.failure_log.step(float(t[j]), sig_rows[j])
                self._sig = sig_rows[j].copy()
        return changed

    def _alarm_event(self, m: _Member, t_s: float, on: bool, j: int, isolated: bool = False) -> None:
        if self._writer is None:
            return
        i = m.iso[j]
        ev: dict[str, Any] = {"detector": m.id, "alarm": on,
                              "isolation": m.hypotheses[i] if on and i >= 0 else None}
        for key, x in (("statistic", m.stat[j]), ("threshold", m.thr[j])):
            if math.isfinite(x):
                ev[key] = float(x)
        if isolated:
            ev["event"] = "isolated"
        self._ch_alarms.write(t_s, ev)

    def _nature(self, h: int) -> str:
        """Persistent, or intermittent once the hypothesis has had a second onset (as known so far)."""
        return "intermittent" if self._onsets[h] > 1 else "persistent"

    def close(self, t_s: float) -> None:
        """The end of the flight at ``t_s`` [s]: every failure-log entry still on gets its end
        (``ongoing``) event, so the log says how long each lasted."""
        for h in np.flatnonzero(self._sig):
            onset = float(self.failure_log._onset[h])
            ev = {"event": "end", "hypothesis": self.hypotheses[h], "onset_t_s": onset, "duration_s": t_s - onset,
                  "kind": self._kind(self.hypotheses[h]), "detector": ",".join(sorted(self._sig_detectors[h])),
                  "nature": self._nature(h), "ongoing": True}
            if self._writer is not None:
                self._ch_flog.write(t_s, ev)

    def _kind(self, name: str) -> str:
        if name.endswith("_cmd_norm"):
            return "actuator (" + name.removesuffix("_cmd_norm") + ")"
        if name.startswith("engine_"):
            return "engine"
        return "sensor"

    def _estimator(self, name: str) -> _Member | None:
        """The member that estimates a sensor from the others (a filter that measures it)."""
        return next((m for m in self.members if name in m.estimate_names), None)

    def _should_correct(self, name: str) -> bool:
        """Correct a sensor once a kinematic check (exact kinematics, no model) or two members have
        confirmed it, if the pilot reads it and a filter can estimate it. The gust filter alone does
        not suffice: it confuses a pitch-gyro bias with a pitch-attitude bias (the attitude is the
        gyro's integral), and acting on the wrong one would remove a good sensor. Nor does the
        flow-angle check alone: it computes alpha and beta from the pitot airspeed and the attitude,
        so a drifting airspeed makes it name the alpha vane (measured on the DHC-6 pitot drift)."""
        if name in self._corrected or name not in self.pilot_sensors or self._estimator(name) is None:
            return False
        by = self._confirmed.get(name, set())
        direct = any(m.id in by and m.direct for m in self.members)
        return direct or len(by) >= 2

    def _reconfigure_sensor(self, name: str, t_s: float) -> None:
        m = self._estimator(name)
        c = m.output_names.index(name)  # excluded from the member's measurement update
        m.excluded[c] = True
        corr = Correction(name, self.meas_names.index(name), t_s, m.id)
        self.corrections.append(corr)
        self._corrected.add(name)
        ev = {"action": "exclude-and-correct", "sensor": name, "detector": m.id, "t_s": t_s,
              "confirmed_by": ",".join(sorted(self._confirmed.get(name, ())))}
        self.reconfig_events.append(ev)
        if self._ch_reconf is not None:
            self._ch_reconf.write(t_s, ev)

    def _start_estimator(self, m: _Member, name: str, t_s: float) -> None:
        """An actuator confirmed by a filter: estimate its effectiveness from the next block on."""
        self._estimators[name] = (m, m.stream.effectiveness_estimator(name), t_s)

    def _update_estimators(self, t: NDArray[np.float64], S: int) -> bool:
        """Feed the effectiveness estimators; rescale a command once its estimate allows it (latched:
        after the rescale the delivered deflection is no longer the estimator's model)."""
        changed = False
        for name, (m, est, t0) in list(self._estimators.items()):
            if est is None:
                continue
            est.update(m.u[:S], m.nu[:S], m.point[:S], m.j_start)
            if est.usable():
                e, sd, _ = est.estimate
                scale = list(self.command_scale or (1.0, 1.0, 1.0, 1.0))
                i = ACTUATOR_INPUTS.index(name)
                scale[i] = min(MAX_COMMAND_SCALE, 1.0 / e)
                self.command_scale = tuple(scale)
                ev = {"action": "rescale-command", "sensor": name, "detector": m.id, "t_s": float(t[S - 1]),
                      "effectiveness": float(e), "effectiveness_std": float(sd), "scale": scale[i],
                      "confirmed_by": m.id}
                self.reconfig_events.append(ev)
                if self._ch_reconf is not None:
                    self._ch_reconf.write(float(t[S - 1]), ev)
                self._estimators[name] = (m, None, t0)
                changed = True
        return changed

    def _update_corrections(self, meas: NDArray[np.float64], S: int) -> None:
        """``f_hat = mean(y - y_hat)`` over the block's fresh samples, per corrected sensor (the filter
        no longer uses the sensor, so ``y_hat`` is its estimate from the others)."""
        for c in self.corrections:
            m = next(mm for mm in self.members if mm.id == c.detector)
            d = m.y[:S, m.output_names.index(c.sensor)] - m.yhat[:S, m.estimate_names.index(c.sensor)]
            d = d[np.isfinite(d)]
            if d.size:
                c.fault_estimate = float(d.mean())

    def _log(self, t: NDArray[np.float64], S: int) -> None:
        for m in self.members:
            if S == m.full_S:  # the loop's case: the arrays themselves (eight slices cost ~1.5 us)
                statistic_rows(m.stat, m.thr, m.exceed, m.alarm, m.valid, m.iso, m.point, m.rows)
            else:
                statistic_rows(m.stat[:S], m.thr[:S], m.exceed[:S], m.alarm[:S], m.valid[:S], m.iso[:S], m.point[:S],
                           m.rows[:S])
        # every channel's rows before the writer's flush boundary first, then the rest: each chunk
        # then holds the same sample times on every /fdi channel (writer.window_end_s)
        end = self._writer.window_end_s
        cut = S if t[S - 1] < end else int(np.searchsorted(t[:S], end, side="left"))
        for a, b in ((0, cut), (cut, S)):
            if a == b:
                continue
            for m, ch in zip(self.members, self._chans):
                ch.stat.write_rows(t[a:b], m.rows[a:b])
                if ch.resid is not None:
                    ch.resid.write_rows(t[a:b], m.nu[a:b])
                if ch.est is not None:
                    ch.est.write_rows(t[a:b], m.yhat[a:b])


@dataclass(frozen=True)
class FaultDetection:
    """One injected fault as one bank member saw it (the run summary)."""

    fault: str
    target: str
    detector: str
    onset_t_s: float
    detected_t_s: float | None
    delay_s: float | None
    isolation: str | None
    isolation_correct: bool | None


def fdi_outcomes(bank: FdiBank, faults: Sequence[Mapping[str, Any]], t_end_s: float
                 ) -> tuple[tuple[FaultDetection, ...], tuple[BankAlarm, ...]]:
    """Per injected fault and member: the first alarm from the fault's onset, the delay and the
    isolation (:func:`fdi_sim.decision.outcome.fault_outcome`, the rule ``fdi-sim detect`` reports
    with); and the false alarms: alarm episodes that begin outside every fault window and its
    :data:`LATE_GRACE_S`.

    Parameters
    ----------
    bank : FdiBank
        After the flight.
    faults : sequence of mapping
        ``label``, ``target``, ``windows_s`` per fault (the injector's catalog).
    t_end_s : float
        End of the flight [s] (an open window ends there).
    """
    t, dec = bank.decisions()
    out = []
    windows = [(float(a), min(float(b), t_end_s)) for f in faults for a, b in f.get("windows_s", [])]
    for f in faults:
        if not f.get("windows_s"):
            continue
        for mid, (a, iso) in dec.items():
            o = fault_outcome(f, t, a, iso)
            out.append(FaultDetection(f["label"], f.get("target", ""), mid, o.t_onset_s, o.first_alarm_s, o.delay_s,
                                      o.isolated_as, o.isolation_correct))
    false = tuple(e for e in bank.alarms if not any(w0 <= e.onset_t_s <= w1 + LATE_GRACE_S for w0, w1 in windows))
    return tuple(out), false
