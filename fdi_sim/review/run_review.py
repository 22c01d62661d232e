"""The review of one run, from its MCAP log alone (``fdi-sim review LOG``).

:func:`review_log` reads a log written by ``fdi-sim run`` (or ``fdi-sim detect --out``) and
returns a :class:`RunReview`: what flew (aircraft, scenario, seed, duration, rate), how the run
ended in words, the injected faults with their true intervals, and per detector its alarm
episodes, each fault's first alarm, delay and isolation, and its false alarms per armed
fault-free hour with the exact Poisson (Garwood) interval, next to the bank's design rate.

The numbers follow the live run summary's rules, so a review equals what ``fdi-sim run`` printed:

- detection per (fault, detector): :func:`fdi_sim.decision.outcome.fault_outcome` over the logged
  ``alarm`` and ``isolation`` columns of ``/fdi/<id>/statistic``;
- a false alarm: an alarm episode beginning outside every fault window ``[w0, min(w1, t_end) +
  LATE_GRACE_S]`` (:func:`fdi_sim.bank.runtime.fdi_outcomes`);
- exposure: the armed fault-free time ``[arm_s, t_end]`` minus those windows
  (:func:`fdi_sim.study.stats.exposure_s`), the rate's denominator.

Nothing here reads a live object (STYLE.md rule 13): a log reviews days later on another machine.
"""
from __future__ import annotations

import json
import math
import shutil
import tempfile
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from fdi_sim.errors import LogError, ReviewError
from fdi_sim.flightlog import (
    METADATA_SCENARIO,
    TOPIC_FAULT_EVENTS,
    TOPIC_FDI_ALARMS,
    TOPIC_FDI_FAILURE_LOG,
    TOPIC_SIM_STATUS,
    TOPIC_TRUTH_STATE,
    read_log,
    repair_log,
)
from fdi_sim.flightlog.reader import FlightLog
from fdi_sim.bank.runtime import FaultDetection
from fdi_sim.decision.outcome import LATE_GRACE_S
from fdi_sim.units import S_PER_H

TOPIC_RECONFIGURATION = "/fdi/reconfiguration"
MCAP_MAGIC = b"\x89MCAP0\r\n"
CONFIDENCE = 0.95


@dataclass(frozen=True)
class FaultInterval:
    """One injected fault and its true windows [s] (the injector's catalog)."""

    label: str
    type: str
    target: str
    windows_s: tuple[tuple[float, float], ...]


@dataclass(frozen=True)
class AlarmEpisode:
    """One alarm episode of one detector: onset and end [s] (None: still on at the log's end),
    the last isolated hypothesis, and whether it is a false alarm (begins outside every fault
    window + :data:`~fdi_sim.decision.outcome.LATE_GRACE_S`)."""

    detector: str
    onset_t_s: float
    end_t_s: float | None
    isolation: str | None
    false: bool


@dataclass(frozen=True)
class DetectorReview:
    """One detector over the run.

    Attributes
    ----------
    id : str
    threshold : float
        The threshold at its first valid sample [-] (NaN when never valid).
    samples, alarm_samples : int
        Decision samples logged, and those in alarm.
    episodes : tuple of AlarmEpisode
    detections : tuple of FaultDetection
        Per injected fault (the live run summary's records, same rule).
    false_alarms : int
    exposure_h : float
        Armed fault-free time [h].
    far_per_h : float or None
        ``false_alarms / exposure_h`` [1/h] (None without exposure).
    far_ci_per_h : tuple of float or None
        Exact Poisson 95 % interval [1/h].
    design_far_per_h : float or None
        The bank's design rate split over its members [1/h] (None when the log does not say).
    schedule_switches : tuple of (float, int)
        ``(t_s, point)``: when the member moved to another schedule node [s].
    """

    id: str
    threshold: float
    samples: int
    alarm_samples: int
    episodes: tuple[AlarmEpisode, ...]
    detections: tuple[FaultDetection, ...]
    false_alarms: int
    exposure_h: float
    far_per_h: float | None
    far_ci_per_h: tuple[float, float] | None
    design_far_per_h: float | None
    schedule_switches: tuple[tuple[float, int], ...]


@dataclass(frozen=True)
class FailureLogRow:
    """One ``/fdi/failure_log`` entry: at ``t_s`` [s], an ``onset`` or ``end`` of a hypothesis."""

    t_s: float
    event: str
    detector: str
    hypothesis: str
    kind: str
    nature: str
    duration_s: float | None


@dataclass(frozen=True)
class Reconfiguration:
    """One ``/fdi/reconfiguration`` entry at ``t_s`` [s]."""

    t_s: float
    action: str
    sensor: str
    detector: str
    confirmed_by: str


@dataclass(frozen=True)
class RunReview:
    """Everything the review shows about one run, from its log.

    Attributes
    ----------
    path : str
        The log reviewed (the user's file).
    read_path : str
        The file actually read (a repaired temporary copy for a cut-off log; else ``path``).
    aircraft, scenario : str
    seed : int or None
    rate_hz : float or None
        Simulation rate [Hz].
    duration_s, t_end_s : float
        Logged span and last time on ``/truth/state`` [s].
    planned_s : float or None
        The scenario's ``duration_s`` [s].
    status : str
        ``completed``, ``diverged``, ``interrupted``, ``timeout``, ``error``, or ``cut off``
        (no final status record: the process died).
    reason : str
        The status message ("" when none).
    ending : str
        How the run ended, in words.
    kind : str
        ``run`` (``fdi-sim run``) or ``detect`` (``fdi-sim detect --out``).
    faults : tuple of FaultInterval
    bank : tuple of str
        The detector ids with a statistic topic ("" members: no bank in this log).
    detectors : tuple of DetectorReview
    bank_false_alarms : int
        Episodes of the members' OR that begin outside the fault windows + grace.
    bank_far_per_h, bank_far_ci_per_h, design_far_per_h
        The bank's rate, interval and design rate [1/h].
    failure_log : tuple of FailureLogRow
    reconfigurations : tuple of Reconfiguration
    notes : tuple of str
        Caveats (repaired copy, missing topics, bank notes).
    scenario_text : str
        The scenario TOML in the metadata ("" when absent).
    scenario_json : str
        The validated scenario as JSON, every key with its value ("" when absent).
    """

    path: str
    read_path: str
    aircraft: str
    scenario: str
    seed: int | None
    rate_hz: float | None
    duration_s: float
    t_end_s: float
    planned_s: float | None
    status: str
    reason: str
    ending: str
    kind: str
    faults: tuple[FaultInterval, ...]
    bank: tuple[str, ...]
    detectors: tuple[DetectorReview, ...]
    bank_false_alarms: int
    bank_exposure_h: float
    bank_far_per_h: float | None
    bank_far_ci_per_h: tuple[float, float] | None
    design_far_per_h: float | None
    failure_log: tuple[FailureLogRow, ...]
    reconfigurations: tuple[Reconfiguration, ...]
    notes: tuple[str, ...]
    scenario_text: str
    scenario_json: str = ""

    # --- headline -----------------------------------------------------------------------------
    def first_detection(self, fault: str | None = None) -> FaultDetection | None:
        """The earliest detection of ``fault`` (default: any fault) by any member (None: not detected)."""
        hits = [d for r in self.detectors for d in r.detections
                if d.detected_t_s is not None and (fault is None or d.fault == fault)]
        return min(hits, key=lambda d: d.detected_t_s) if hits else None

    def never_started(self, fault: str) -> str | None:
        """Why ``fault`` cannot have been detected, when every window of it began after the log ends
        (a cut-off run); None otherwise."""
        f = next((x for x in self.faults if x.label == fault), None)
        if f is None or not f.windows_s or any(a <= self.t_end_s for a, _ in f.windows_s):
            return None
        return f"never started: scheduled from {f.windows_s[0][0]:.2f} s, after the log ends at {self.t_end_s:.2f} s"

    def headline(self) -> list[tuple[str, str]]:
        """The numbers a reviewer asks first, as (label, value) rows."""
        rows = [("run", f"{self.scenario} ({self.aircraft}, seed {self.seed})"), ("ended", self.ending)]
        if not self.bank:
            rows.append(("FDI", "no FDI bank in this log"))
            return rows
        if self.faults:
            for f in self.faults:
                d = self.first_detection(f.label)
                if d is None and (why := self.never_started(f.label)):
                    rows.append((f"fault {f.label}", why))
                    continue
                if d is None:
                    rows.append((f"fault {f.label}", f"NOT detected (true interval {windows_text(f.windows_s, self.t_end_s)})"))
                    continue
                iso = d.isolation or "not isolated"
                mark = "" if d.isolation_correct is None else (" (right)" if d.isolation_correct else " (wrong)")
                rows.append((f"fault {f.label}", f"detected at {d.detected_t_s:.2f} s by {d.detector}, delay "
                             f"{d.delay_s:.2f} s, isolated as {iso}{mark}"))
        else:
            rows.append(("faults", "none injected"))
        far = "n/a (no armed fault-free time)" if self.bank_far_per_h is None else (
            f"{self.bank_far_per_h:.3g} /h (95 % {self.bank_far_ci_per_h[0]:.3g} .. {self.bank_far_ci_per_h[1]:.3g})")
        design = "" if self.design_far_per_h is None else f"; design {self.design_far_per_h:g} /h"
        rows.append(("false alarms", f"{self.bank_false_alarms} in {self.bank_exposure_h * 60:.2f} armed "
                     f"fault-free min: {far}{design}"))
        if self.reconfigurations:
            rows.append(("reconfigured", ", ".join(f"{r.sensor} at {r.t_s:.2f} s" for r in self.reconfigurations)))
        return rows

    def format(self) -> str:
        """The terminal summary."""
        head = self.headline()
        w = max(13, *(len(k) + 2 for k, _ in head))
        out = [f"{'log':{w}}{self.path}"]
        if self.read_path != self.path:
            out.append(f"{'read':{w}}{self.read_path} (a repaired temporary copy; the log itself is untouched)")
        out += [f"{k:{w}}{v}" for k, v in head]
        rate = "" if self.rate_hz is None else f" at {self.rate_hz:g} Hz"
        planned = "" if self.planned_s is None else f" of {self.planned_s:g} s planned"
        out.append(f"{'flown':{w}}{self.duration_s:.2f} s{planned}{rate}")
        for f in self.faults:
            out.append(f"{'fault':{w}}{f.label}: {f.type} on {f.target}, {windows_text(f.windows_s, self.t_end_s)}")
        for r in self.detectors:
            far = "" if r.far_per_h is None else f", {r.far_per_h:.3g} /h (95 % {r.far_ci_per_h[0]:.3g} .. " \
                                                  f"{r.far_ci_per_h[1]:.3g})"
            design = "" if r.design_far_per_h is None else f", design <= {r.design_far_per_h:.3g} /h"
            out.append(f"{'detector':{w}}{r.id}: {len(r.episodes)} alarm episodes, {r.false_alarms} false{far}{design}")
            for d in r.detections:
                if d.detected_t_s is None:
                    out.append(f"{'':{w}}  {d.fault}: not detected")
                else:
                    mark = "" if d.isolation_correct is None else (" (right)" if d.isolation_correct else " (wrong)")
                    out.append(f"{'':{w}}  {d.fault}: detected at {d.detected_t_s:.2f} s (delay {d.delay_s:.2f} s), "
                               f"isolated as {d.isolation or 'not isolated'}{mark}")
            for e in r.episodes:
                if e.false:
                    end = "open" if e.end_t_s is None else f"to {e.end_t_s:.2f} s"
                    out.append(f"{'':{w}}  FALSE ALARM at {e.onset_t_s:.2f} s ({end}), isolated as {e.isolation}")
            if r.schedule_switches:
                out.append(f"{'':{w}}  schedule switches: {len(r.schedule_switches)}")
        if self.failure_log:
            out.append(f"{'failure log':{w}}{len(self.failure_log)} entries "
                       f"({sum(r.event == 'onset' for r in self.failure_log)} onsets)")
        for r in self.reconfigurations:
            out.append(f"{'reconfig':{w}}{r.t_s:.2f} s: {r.action} {r.sensor} (by {r.detector}, confirmed by "
                       f"{r.confirmed_by or '-'})")
        out += [f"{'note':{w}}{n}" for n in self.notes]
        return "\n".join(out)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-able dict (``--json``); infinities and NaN become None."""
        return _clean(asdict(self))


def windows_text(windows: Sequence[tuple[float, float]], t_end_s: float = math.inf) -> str:
    """``"10.00 .. 25.00 s, 40.00 s .. the end"``: windows [s], one still open at ``t_end_s`` [s]."""
    return ", ".join(f"{a:.2f} s .. the end" if b >= t_end_s else f"{a:.2f} .. {b:.2f} s" for a, b in windows) \
        or "no window"


def _clean(x: Any) -> Any:
    if isinstance(x, dict):
        return {k: _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


# --- reading ------------------------------------------------------------------------------------
def open_log(path: str | Path) -> tuple[FlightLog, tuple[str, ...]]:
    """Read a log for review; a cut-off one from a repaired temporary copy (the file is left alone).

    Returns
    -------
    log : FlightLog
    notes : tuple of str
        What was done to read it.

    Raises
    ------
    ReviewError
        Not a file, not MCAP, unrecoverable.
    """
    p = Path(path)
    try:
        head = p.open("rb").read(len(MCAP_MAGIC)) if p.is_file() else None
    except OSError as exc:
        raise ReviewError(str(p), f"cannot read the file ({exc.strerror})", "check the path and its permissions") from None
    if head is None:
        what = "a folder" if p.is_dir() else "missing"
        raise ReviewError(str(p), f"the path is {what}", "pass an MCAP log written by `fdi-sim run`")
    if head != MCAP_MAGIC:
        raise ReviewError(str(p), "not an MCAP file (it does not start with the MCAP magic bytes)",
                          "pass an MCAP log written by `fdi-sim run`")
    try:
        return read_log(p), ()
    except LogError as exc:
        if "fdi-sim repair" not in exc.problem or "truncated" not in exc.problem:
            raise ReviewError(str(p), exc.problem, "") from None
    tmp = Path(tempfile.mkdtemp(prefix="fdi-sim-review-"))
    try:
        fixed = tmp / (p.stem + ".repaired.mcap")
        try:
            repair_log(p, fixed)
            log = read_log(fixed)
        except LogError as exc:
            raise ReviewError(str(p), f"the log is cut off and cannot be repaired: {exc.problem}", "") from None
    finally:  # the FlightLog holds its data in memory: the copy can go
        shutil.rmtree(tmp, ignore_errors=True)
    note = (f"the log has no footer (cut off by a crash): reviewed from a repaired temporary copy; the file is "
            f"untouched (`fdi-sim repair {p}` makes a permanent one)")
    return log, (note,)


def _meta_json(log: FlightLog, name: str, key: str, default: Any) -> Any:
    raw = log.metadata.get(name, {}).get(key)
    if raw is None:
        return default
    try:
        return json.loads(raw)
    except (TypeError, json.JSONDecodeError):
        return default


def _check_fdi_sim_log(log: FlightLog, path: str) -> None:
    missing = []
    if METADATA_SCENARIO not in log.metadata:
        missing.append("no `scenario` metadata")
    if TOPIC_TRUTH_STATE not in log.topics:
        missing.append(f"no {TOPIC_TRUTH_STATE} topic")
    if len(missing) == 2:
        has = ", ".join(sorted(log.topics)[:6]) or "no topics"
        raise ReviewError(path, f"{' and '.join(missing)}: not an fdi-sim log (it has {has})",
                          "pass a log written by `fdi-sim run` or `fdi-sim detect --out`")
    if missing:
        raise ReviewError(path, f"{missing[0]}: an incomplete fdi-sim log", "fly the run again with `fdi-sim run`")


def _ending(log: FlightLog, t_end_s: float, planned_s: float | None) -> tuple[str, str, str]:
    """(status, reason, ending in words)."""
    ev = log.topics.get(TOPIC_SIM_STATUS)
    events = list(ev.events) if ev is not None else []
    last = events[-1].payload if events else {}
    status, msg = str(last.get("status", "")), str(last.get("message", ""))
    at = f"at t = {t_end_s:.2f} s"
    if not events or status == "running":
        return ("cut off", "", f"ended without a final status record {at}: the process died (log repaired)")
    if status == "completed":
        full = "" if planned_s is None else f" (the scenario's {planned_s:g} s)"
        return status, msg, f"completed {at}{full}"
    words = {"diverged": "diverged", "interrupted": "interrupted", "timeout": "timed out", "error": "stopped by an error"}
    return status, msg, f"{words.get(status, status)} {at}" + (f": {msg}" if msg else "")


def _episodes(det: str, t: np.ndarray, alarm: np.ndarray, iso: Sequence[str | None],
              windows: Sequence[tuple[float, float]]) -> tuple[AlarmEpisode, ...]:
    """Alarm episodes as the bank records them: onset at the first alarm sample, end at the first
    sample without, isolation the last hypothesis named during it."""
    out = []
    prev = np.concatenate(([False], alarm[:-1]))
    on = np.flatnonzero(alarm & ~prev)
    off = np.flatnonzero(~alarm & prev)
    for j0 in on:
        later = off[off > j0]
        j1 = int(later[0]) if later.size else None
        names = [h for h in iso[j0:j1] if h is not None]
        t0 = float(t[j0])
        false = not any(w0 <= t0 <= w1 + LATE_GRACE_S for w0, w1 in windows)
        out.append(AlarmEpisode(det, t0, None if j1 is None else float(t[j1]), names[-1] if names else None, false))
    return tuple(out)


def _offline_isolation(log: FlightLog, det: str, t: np.ndarray, alarm: np.ndarray) -> tuple[str | None, ...]:
    """A ``fdi-sim detect`` log stores the isolation only at each raise (``/fdi/alarms``): hold it
    over the episode."""
    topic = "/fdi/offline/alarms" if det.startswith("offline/") else TOPIC_FDI_ALARMS
    ident = det.removeprefix("offline/")
    raises = [(e.t_s, e.payload.get("isolation")) for e in getattr(log.topics.get(topic), "events", [])
              if e.payload.get("detector") == ident and e.payload.get("alarm")]
    out: list[str | None] = [None] * len(t)
    k, cur = 0, None
    for j in range(len(t)):
        while k < len(raises) and raises[k][0] <= t[j] + 1e-9:
            cur = raises[k][1]
            k += 1
        out[j] = cur if alarm[j] else None
    return tuple(out)


def review_log(path: str | Path) -> RunReview:
    """Review one run from its MCAP log.

    Parameters
    ----------
    path : str or Path
        A log written by ``fdi-sim run`` (complete, repaired, or cut off: then a repaired temporary
        copy is read) or ``fdi-sim detect --out``.

    Returns
    -------
    RunReview

    Raises
    ------
    ReviewError
        Not an MCAP file, an MCAP file from another tool (what is missing), unrecoverable.
    """
    log, notes = open_log(path)
    return review_flight_log(log, str(path), notes)


def review_flight_log(log: FlightLog, path: str, notes: Sequence[str] = ()) -> RunReview:
    """:func:`review_log` of a log already read (``path`` is what the user named)."""
    from fdi_sim.decision.outcome import fault_outcome
    from fdi_sim.offline.detect import fault_windows
    from fdi_sim.study.stats import exposure_s, merge_episodes, rate

    _check_fdi_sim_log(log, path)
    notes = list(notes)
    meta = log.metadata[METADATA_SCENARIO]
    sc = _meta_json(log, METADATA_SCENARIO, "json", {})
    seed = int(meta["seed"]) if str(meta.get("seed", "")).lstrip("-").isdigit() else sc.get("seed")
    rate_hz = float(meta["rate_hz"]) if meta.get("rate_hz") else (float(sc["rate_hz"]) if "rate_hz" in sc else None)
    truth = log.topics[TOPIC_TRUTH_STATE]
    t_end = float(truth.t_s[-1]) if len(truth.t_s) else 0.0
    planned = float(sc["duration_s"]) if "duration_s" in sc else None
    status, reason, ending = _ending(log, t_end, planned)
    if notes and status == "cut off":
        ending = ending.replace("(log repaired)", "(reviewed from a repaired copy)")
    catalog = fault_windows(log)
    if TOPIC_FAULT_EVENTS not in log.topics and sc.get("faults"):
        notes.append(f"no {TOPIC_FAULT_EVENTS} topic: the injected faults are unknown")
    faults = tuple(FaultInterval(str(f.get("label", "")), str(f.get("type", "")), str(f.get("target", "")),
                                 tuple((float(a), float(b)) for a, b in f.get("windows_s", []))) for f in catalog)
    windows = [(a, min(b, t_end)) for f in faults for a, b in f.windows_s]
    fdi_cfg = sc.get("fdi") or {}
    arm_s = float(fdi_cfg.get("arm_s", 0.0))
    members = {m["id"]: m for m in _meta_json(log, "fdi", "members", [])}
    ids = [t[len("/fdi/"):-len("/statistic")] for t in log.topics if t.startswith("/fdi/") and t.endswith("/statistic")]
    kind = "detect" if "detect" in log.metadata else "run"
    record = {"arm_s": arm_s, "t_end_s": t_end, "faults": [dict(f) for f in catalog]}
    exposure_h = exposure_s(record) / S_PER_H
    design = float(fdi_cfg["far_per_h"]) if members and "far_per_h" in fdi_cfg else None
    detectors, all_eps = [], []
    for det in ids:
        T = log.topics[f"/fdi/{det}/statistic"]
        t = np.asarray(T.t_s, dtype=float)
        alarm = np.asarray(T["alarm"]) > 0.5
        if "isolation" in T.fields and det in members:
            hyps = members[det].get("hypotheses", [])
            iso = tuple(hyps[int(k)] if a and k >= 0 and int(k) < len(hyps) else None for k, a in zip(T["isolation"], alarm))
        else:
            iso = _offline_isolation(log, det, t, alarm)
        dets = tuple(FaultDetection(f["label"], f.get("target", ""), det, o.t_onset_s, o.first_alarm_s, o.delay_s,
                                    o.isolated_as, o.isolation_correct)
                     for f in catalog if f.get("windows_s") for o in [fault_outcome(f, t, alarm, iso)])
        eps = _episodes(det, t, alarm, iso, windows)
        all_eps += eps
        nfalse = sum(e.false for e in eps)
        far, ci = rate(nfalse, exposure_h, CONFIDENCE)
        valid = np.asarray(T["valid"]) > 0.5
        thr = float(np.asarray(T["threshold"])[valid][0]) if valid.any() else math.nan
        switches: tuple[tuple[float, int], ...] = ()
        if "point" in T.fields and len(t):
            pt = np.asarray(T["point"])
            ch = np.flatnonzero(pt[1:] != pt[:-1]) + 1
            switches = tuple((float(t[j]), int(pt[j])) for j in ch)
        detectors.append(DetectorReview(det, thr, len(t), int(alarm.sum()), eps, dets, nfalse, exposure_h, far,
                                        None if ci is None else (ci[0], ci[1]),
                                        None if design is None else design / max(1, len(members)), switches))
    merged = merge_episodes([{"onset_t_s": e.onset_t_s, "end_t_s": e.end_t_s} for e in all_eps])
    bank_false = sum(not any(w0 <= a <= w1 + LATE_GRACE_S for w0, w1 in windows) for a, _ in merged)
    bank_far, bank_ci = rate(bank_false, exposure_h, CONFIDENCE) if ids else (None, None)
    if not ids:
        notes.append("no FDI bank in this log (no /fdi/<detector>/statistic topic)")
    if kind == "detect":
        notes.append("offline detectors (`fdi-sim detect --out`): no failure log; the isolation is the one named "
                     "when each alarm was raised")
    notes += [str(n) for n in _meta_json(log, "fdi", "notes", [])]
    flog = tuple(FailureLogRow(e.t_s, str(e.payload.get("event", "")), str(e.payload.get("detector", "")),
                               str(e.payload.get("hypothesis", "")), str(e.payload.get("kind", "")),
                               str(e.payload.get("nature", "")), e.payload.get("duration_s"))
                 for e in getattr(log.topics.get(TOPIC_FDI_FAILURE_LOG), "events", []))
    reconf = tuple(Reconfiguration(e.t_s, str(e.payload.get("action", "")), str(e.payload.get("sensor", "")),
                                   str(e.payload.get("detector", "")), str(e.payload.get("confirmed_by", "") or ""))
                   for e in getattr(log.topics.get(TOPIC_RECONFIGURATION), "events", []))
    return RunReview(
        path=path, read_path=path if not notes or "temporary copy" not in notes[0] else "<repaired temporary copy>",
        aircraft=str(meta.get("aircraft", sc.get("aircraft", "?"))), scenario=str(meta.get("name", sc.get("name", "?"))),
        seed=seed, rate_hz=rate_hz, duration_s=float(log.duration_s), t_end_s=t_end, planned_s=planned, status=status,
        reason=reason, ending=ending, kind=kind, faults=faults, bank=tuple(ids), detectors=tuple(detectors),
        bank_false_alarms=int(bank_false), bank_exposure_h=exposure_h, bank_far_per_h=bank_far,
        bank_far_ci_per_h=None if bank_ci is None else (bank_ci[0], bank_ci[1]), design_far_per_h=design,
        failure_log=flog, reconfigurations=reconf, notes=tuple(notes), scenario_text=str(meta.get("text", "")),
        scenario_json=str(meta.get("json", "")))
