"""Re-scoring a finished study at other thresholds and decision rules, without flying again.

Every run's log keeps, per bank member, ``/fdi/<id>/statistic`` at the detector rate
(:data:`fdi_sim.bank.topics.STAT_FIELDS`). The bank's decision (:func:`fdi_sim.bank.kernels.decide`,
rule ``persistence``) is a function of three of its columns only::

    e_j = valid_j and statistic_j > threshold_j          (exceedance)
    a_j = sum_{i = j-n+1 .. j} e_i >= k                  (k-of-n persistence; e_i = 0 for i < 0)

with the ring of the last ``n`` exceedances carried across the whole flight from zeros, and
``valid_j = 0`` for the samples before ``arm_s`` (the bank logs the statistic of an unarmed sample
but zeroes its validity before deciding), so the replay needs no arming rule of its own. Here the
window sum is a difference of cumulative sums, vectorized over samples and threshold scales.

Exactness. At the logged threshold and the run's ``k, n`` the replay is the decision itself: it
gives exactly the alarms the run raised (:func:`check_replay` checks it, episode by episode, to
the bit of the onset and end times). At another threshold ``scale x threshold_j`` or another
``k, n`` it is **open loop after the first alarm**: the statistic does not depend on the threshold
(the kernels use it only for isolation), but in the loop an alarm confirmed by isolation makes
the bank reconfigure (exclude a sensor, correct the pilot's input, rescale a command), which
changes the flight and so every later statistic; the log holds the flight as flown at the
logged threshold. Isolation is not re-scored (the kernels' isolation depends on when the
exceedance began, which the log does not keep per threshold), nor is the ``angle-magnitude``
rule (its per-sample direction test is not logged).

Outcomes re-scored per threshold scale (definitions as :mod:`fdi_sim.study.stats`): false alarms
(episodes beginning outside every fault window + :data:`fdi_sim.decision.outcome.LATE_GRACE_S`) per
armed fault-free flight hour, and per (run, fault) the detection: with ``detection =
"first-alarm"`` (default, the run's own rule :func:`fdi_sim.decision.outcome.fault_outcome`) the first
alarm sample at or after the fault's first onset, so that scale 1 reproduces the records'
detections; with ``detection = "onset"`` the first episode *beginning* in ``[w0, w1 + grace]`` of
one of the fault's windows (an alarm already on at the onset does not count). Delays are from
the fault's first onset [s]. Only completed runs count.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

from fdi_sim.decision.intervals import clopper_pearson, poisson_rate_interval
from fdi_sim.decision.persistence import k_of_n
from fdi_sim.errors import StudyError
from fdi_sim.decision.outcome import LATE_GRACE_S
from fdi_sim.study.stats import BANK, completed, exposure_s, fault_types, fault_windows
from fdi_sim.units import S_PER_H

DETECTION_RULES = ("first-alarm", "onset")
#: a calibrated scale is returned this far (relative) above its breakpoint, so that the direct
#: comparison ``statistic > threshold x scale`` agrees with ``statistic / threshold > scale``
SCALE_NUDGE = 1e-12


# --- the logged statistics ------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class RunStatistics:
    """One member's ``/fdi/<id>/statistic`` of one run, one entry per detector sample.

    Attributes
    ----------
    detector : str
    t_s : NDArray
        Sample times [s].
    statistic, threshold : NDArray
        The test statistic and the threshold it was compared with [-].
    valid : NDArray of bool
        The sample was decided on (armed, finite, usable measurements).
    exceedance, alarm : NDArray of bool
        The bank's exceedance and alarm as logged.
    isolation : NDArray of int
        The isolated hypothesis' index during an alarm (-1: none).
    """

    detector: str
    t_s: NDArray[np.float64]
    statistic: NDArray[np.float64]
    threshold: NDArray[np.float64]
    valid: NDArray[np.bool_]
    exceedance: NDArray[np.bool_]
    alarm: NDArray[np.bool_]
    isolation: NDArray[np.int64]


def _read(mcap_path: str | Path) -> tuple[dict[str, RunStatistics], list[dict[str, Any]]]:
    """The members' statistics and the log's fault catalog."""
    from fdi_sim.flightlog import METADATA_FAULTS, VectorTopic, read_log

    log = read_log(mcap_path)
    out = {}
    for topic, data in log.topics.items():
        parts = topic.split("/")
        if len(parts) == 4 and parts[1] == "fdi" and parts[3] == "statistic" and isinstance(data, VectorTopic):
            out[parts[2]] = RunStatistics(
                parts[2], np.array(data["t_s"]), np.array(data["statistic"]), np.array(data["threshold"]),
                data["valid"] != 0.0, data["exceedance"] != 0.0, data["alarm"] != 0.0,
                data["isolation"].astype(np.int64))
    catalog = json.loads(log.metadata.get(METADATA_FAULTS, {}).get("catalog", "[]"))
    return out, catalog


def load_statistics(mcap_path: str | Path) -> dict[str, RunStatistics]:
    """Per member id, the ``/fdi/<id>/statistic`` topic of a run's log."""
    return _read(mcap_path)[0]


# --- the decision rule, vectorized ----------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Episodes:
    """Alarm episodes as sample indices.

    Attributes
    ----------
    onset : NDArray of int
        First sample of each episode.
    end : NDArray of int
        First sample after it with the alarm off (the bank's ``end_t_s`` is that sample's time);
        ``n_samples`` for an episode still on at the end of the flight.
    n_samples : int
    """

    onset: NDArray[np.int64]
    end: NDArray[np.int64]
    n_samples: int

    @property
    def is_open(self) -> NDArray[np.bool_]:
        """Episodes still on at the last sample (``end_t_s = None`` in a record)."""
        return self.end == self.n_samples

    def __len__(self) -> int:
        return int(self.onset.size)


def exceedances(stat: NDArray[np.float64], thr: NDArray[np.float64], valid: NDArray[np.bool_],
                scales: float | Sequence[float] | NDArray[np.float64] = 1.0) -> NDArray[np.bool_]:
    """``valid and statistic > threshold x scale``; one row per scale for a sequence of scales
    (a NaN statistic never exceeds)."""
    s = np.asarray(scales, dtype=float)
    stat, thr, valid = np.asarray(stat, float), np.asarray(thr, float), np.asarray(valid, bool)
    if s.ndim == 0:
        return valid & (stat > thr * s)
    return valid[None, :] & (stat[None, :] > thr[None, :] * s[:, None])


def episodes_of(alarm: NDArray[np.bool_]) -> Episodes:
    """Rising and falling edges of one alarm sequence."""
    a = np.asarray(alarm, dtype=np.int8)
    d = np.diff(np.concatenate(([0], a, [0])))
    return Episodes(np.flatnonzero(d == 1).astype(np.int64), np.flatnonzero(d == -1).astype(np.int64), int(a.size))


def alarm_episodes(stat: NDArray[np.float64], thr: NDArray[np.float64], valid: NDArray[np.bool_],
                   k: int, n: int) -> Episodes:
    """The bank's alarm episodes (:func:`fdi_sim.bank.kernels.decide`, rule ``persistence``) from a
    member's statistic, threshold [-] and validity per sample.

    Parameters
    ----------
    stat, thr : NDArray
        Statistic and threshold per sample [-] (pass ``threshold x scale`` to re-score).
    valid : NDArray of bool
        As logged (False before ``arm_s``).
    k, n : int
        Alarm while at least ``k`` of the last ``n`` samples exceed.
    """
    return episodes_of(k_of_n(exceedances(stat, thr, valid), k, n))


def persistence_level(stat: NDArray[np.float64], thr: NDArray[np.float64], valid: NDArray[np.bool_],
                      k: int, n: int) -> NDArray[np.float64]:
    """``z_j``: the k-th largest ``statistic / threshold`` among the valid samples of the window
    ``j-n+1 .. j`` (``-inf`` with fewer than ``k``), so that the alarm at scale ``s`` is exactly
    ``z_j > s`` (at least ``k`` ratios above ``s``). Up to rounding, ``statistic > threshold x s``
    and ``statistic / threshold > s`` agree (see :data:`SCALE_NUDGE`)."""
    stat, thr, valid = np.asarray(stat, float), np.asarray(thr, float), np.asarray(valid, bool)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(valid & np.isfinite(stat) & (thr > 0), stat / thr, -np.inf)
    padded = np.concatenate((np.full(n - 1, -np.inf), r))
    win = np.lib.stride_tricks.sliding_window_view(padded, n)
    return np.partition(win, n - k, axis=1)[:, n - k]  # k-th largest = (n-k)-th smallest


# --- the study's runs -----------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class _Run:
    record: Mapping[str, Any]
    stats: dict[str, RunStatistics]
    k: int
    n: int


def _runs(records: Sequence[Mapping[str, Any]], out_dir: str | Path, k: int | None, n: int | None,
          only_completed: bool = True) -> tuple[list[_Run], int]:
    """The runs with a log (completed ones only, by default), their records completed with the
    log's fault catalog when a record lacks the windows; and the count of runs without a log."""
    runs, no_log = [], 0
    chosen = completed(records) if only_completed else list(records)
    for r in chosen:
        if not r.get("log"):
            no_log += 1
            continue
        path = Path(out_dir) / "runs" / r["log"]
        stats, catalog = _read(path)
        if catalog and not all("windows_s" in f for f in r.get("faults", [])):
            r = dict(r, faults=catalog)
        if r.get("decision", "persistence") != "persistence":
            raise StudyError(str(out_dir), f"runs/{r['log']}", f"run {r.get('index')} decided by the "
                             f"{r['decision']!r} rule, whose per-sample direction test is not logged",
                             "re-score studies flown with decision = \"persistence\"")
        pk, pn = r.get("persistence") or (3, 5)
        runs.append(_Run(r, stats, int(k if k is not None else pk), int(n if n is not None else pn)))
    return runs, no_log


def _outside(t_s: NDArray[np.float64], record: Mapping[str, Any], grace_s: float) -> NDArray[np.bool_]:
    """Samples at which an onset would be a false alarm (outside every window + grace)."""
    inside = np.zeros(t_s.shape, dtype=bool)
    for ws in fault_windows(record).values():
        for w0, w1 in ws:
            inside |= (t_s >= w0) & (t_s <= w1 + grace_s)
    return ~inside


# --- re-scoring ------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class TypeScores:
    """One member's detections of one fault type, per threshold scale.

    Attributes
    ----------
    fault_type : str
    faults : int
        (run, fault) pairs of the type.
    detected : NDArray of int
        Detected pairs per scale.
    delay_s : NDArray
        (faults, scales) delay after the fault's first onset [s]; NaN when not detected.
    """

    fault_type: str
    faults: int
    detected: NDArray[np.int64]
    delay_s: NDArray[np.float64]

    @property
    def p_detect(self) -> NDArray[np.float64]:
        return self.detected / self.faults if self.faults else np.full(self.detected.shape, np.nan)


@dataclass(frozen=True, eq=False)
class DetectorScores:
    """One member (or the bank, id ``bank``: the OR of its members, all at the same scale).

    Attributes
    ----------
    id : str
    runs : int
    exposure_h : float
        Armed fault-free flight hours [h] (:func:`fdi_sim.study.stats.exposure_s`).
    false_alarms, runs_with_false_alarm : NDArray of int
        Per scale.
    by_type : dict of str to TypeScores
    """

    id: str
    runs: int
    exposure_h: float
    false_alarms: NDArray[np.int64]
    runs_with_false_alarm: NDArray[np.int64]
    by_type: dict[str, TypeScores]

    @property
    def far_per_h(self) -> NDArray[np.float64]:
        """False alarms per armed fault-free flight hour, per scale [1/h]."""
        return self.false_alarms / self.exposure_h if self.exposure_h > 0 else np.full(self.false_alarms.shape, np.nan)


@dataclass(frozen=True, eq=False)
class Rescored:
    """A study re-scored over threshold scales (module docstring for the definitions).

    Attributes
    ----------
    scales : NDArray
        Threshold multipliers [-] (1: the logged thresholds).
    k, n : int or None
        The persistence used (None: each run's own).
    detection : str
        ``first-alarm`` or ``onset``.
    grace_s : float
    runs, runs_without_log : int
        Completed runs re-scored; completed runs skipped for want of a log.
    detectors : dict of str to DetectorScores
        Per member id, and ``bank``.
    """

    scales: NDArray[np.float64]
    k: int | None
    n: int | None
    detection: str
    grace_s: float
    runs: int
    runs_without_log: int
    detectors: dict[str, DetectorScores] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """A JSON-serializable form (delays as lists with None for not detected)."""
        def fl(a: NDArray) -> list:
            return [None if not math.isfinite(x) else float(x) for x in np.asarray(a, float).ravel()]

        return {"scales": fl(self.scales), "k": self.k, "n": self.n, "detection": self.detection,
                "grace_s": self.grace_s, "runs": self.runs, "runs_without_log": self.runs_without_log,
                "detectors": {d: {"runs": s.runs, "exposure_h": s.exposure_h, "false_alarms": s.false_alarms.tolist(),
                                  "far_per_h": fl(s.far_per_h), "runs_with_false_alarm": s.runs_with_false_alarm.tolist(),
                                  "by_type": {t: {"faults": ts.faults, "detected": ts.detected.tolist(),
                                                  "p_detect": fl(ts.p_detect)} for t, ts in s.by_type.items()}}
                              for d, s in self.detectors.items()}}


def _first(mask: NDArray[np.bool_]) -> NDArray[np.int64]:
    """Per row, the first True column (-1: none)."""
    j = np.argmax(mask, axis=1)
    return np.where(mask.any(axis=1), j, -1)


def rescore(records: Sequence[Mapping[str, Any]], out_dir: str | Path,
            scales: Sequence[float] | NDArray[np.float64], *, k: int | None = None, n: int | None = None,
            detection: str = "first-alarm", grace_s: float = LATE_GRACE_S) -> Rescored:
    """False alarms and detections of every member and of the bank at ``threshold x scale``.

    Parameters
    ----------
    records : sequence of mapping
        The study's run records; completed runs with a log are re-scored.
    out_dir : path
        The results folder (logs in ``out_dir/runs``).
    scales : sequence of float
        Threshold multipliers [-].
    k, n : int, optional
        Another k-of-n persistence (default: each run's own).
    detection : str
        ``first-alarm`` (the run's rule) or ``onset`` (module docstring).
    grace_s : float
        An onset this long after a fault window still belongs to the fault [s].

    Returns
    -------
    Rescored
        Exact at scale 1 with the runs' own ``k, n``; open loop after the first alarm otherwise
        (module docstring).
    """
    if detection not in DETECTION_RULES:
        raise ValueError(f"detection must be one of {DETECTION_RULES}, got {detection!r}")
    sc = np.asarray(scales, dtype=float).ravel()
    runs, no_log = _runs(records, out_dir, k, n)
    S = sc.size
    acc: dict[str, dict[str, Any]] = {}

    def slot(ident: str) -> dict[str, Any]:
        return acc.setdefault(ident, {"runs": 0, "expo": 0.0, "fa": np.zeros(S, np.int64), "rfa": np.zeros(S, np.int64),
                                      "types": {}})

    for run in runs:
        r = run.record
        ids = [d for d in r.get("detectors", []) if d in run.stats] or list(run.stats)
        if not ids:
            continue
        t = run.stats[ids[0]].t_s
        outside = _outside(t, r, grace_s)
        expo = exposure_s(r, grace_s)
        windows = fault_windows(r)
        types = fault_types(r)
        alarms = {}
        for d in ids:
            st = run.stats[d]
            if st.t_s.shape != t.shape or not np.array_equal(st.t_s, t):
                raise StudyError(str(out_dir), f"runs/{r['log']}", f"{d}'s samples are not at the times of {ids[0]}'s",
                                 "re-fly the run: every member of a bank samples at the same times")
            alarms[d] = k_of_n(exceedances(st.statistic, st.threshold, st.valid, sc), run.k, run.n)
        alarms[BANK] = np.logical_or.reduce([alarms[d] for d in ids])
        for ident, a in alarms.items():
            s = slot(ident)
            s["runs"] += 1
            s["expo"] += expo
            onset = a & ~np.concatenate((np.zeros((S, 1), bool), a[:, :-1]), axis=1)
            fa = (onset & outside[None, :]).sum(axis=1)
            s["fa"] += fa
            s["rfa"] += fa > 0
            for label, ws in windows.items():
                t_on = ws[0][0]
                if detection == "first-alarm":
                    j = _first(a & (t >= t_on)[None, :])
                else:
                    inw = np.zeros(t.shape, bool)
                    for w0, w1 in ws:
                        inw |= (t >= w0) & (t <= w1 + grace_s)
                    j = _first(onset & inw[None, :])
                delay = np.where(j >= 0, t[np.maximum(j, 0)] - t_on, np.nan)
                s["types"].setdefault(types.get(label, "unknown"), []).append(delay)
    dets = {}
    for ident, s in acc.items():
        by_type = {}
        for ty, rows in sorted(s["types"].items()):
            dl = np.array(rows, dtype=float).reshape(len(rows), S)
            by_type[ty] = TypeScores(ty, len(rows), np.isfinite(dl).sum(axis=0).astype(np.int64), dl)
        dets[ident] = DetectorScores(ident, s["runs"], s["expo"] / S_PER_H, s["fa"], s["rfa"], by_type)
    order = [d for r in runs for d in r.record.get("detectors", [])]
    ordered = {d: dets[d] for d in dict.fromkeys(order) if d in dets}
    ordered.update({d: v for d, v in dets.items() if d not in ordered and d != BANK})
    if BANK in dets:
        ordered[BANK] = dets[BANK]
    return Rescored(sc, k, n, detection, grace_s, len(runs), no_log, ordered)


# --- ROC --------------------------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class RocCurve:
    """Detection probability against false alarms per flight hour for one member and fault type.

    Attributes
    ----------
    detector, fault_type : str
    scales : NDArray
        Threshold multipliers [-], one point each.
    far_per_h, far_per_h_lo, far_per_h_hi : NDArray
        False alarms per armed fault-free hour and its exact Poisson interval [1/h].
    p_detect, p_detect_lo, p_detect_hi : NDArray
        Detection probability and its Clopper-Pearson interval [-].
    false_alarms, detected : NDArray of int
    faults : int
    exposure_h : float
    """

    detector: str
    fault_type: str
    scales: NDArray[np.float64]
    far_per_h: NDArray[np.float64]
    far_per_h_lo: NDArray[np.float64]
    far_per_h_hi: NDArray[np.float64]
    p_detect: NDArray[np.float64]
    p_detect_lo: NDArray[np.float64]
    p_detect_hi: NDArray[np.float64]
    false_alarms: NDArray[np.int64]
    detected: NDArray[np.int64]
    faults: int
    exposure_h: float


def roc(rescored: Rescored, confidence: float = 0.95) -> dict[str, dict[str, RocCurve]]:
    """Per member id (and ``bank``) and fault type, the ROC over the re-scored scales.

    The false-alarm axis comes from every completed run's fault-free part (fault-free runs and
    the faulty runs outside their windows), the detection axis from the runs with that fault type.
    """
    out: dict[str, dict[str, RocCurve]] = {}
    for ident, d in rescored.detectors.items():
        fa_ci = (np.array([poisson_rate_interval(int(c), d.exposure_h, confidence) for c in d.false_alarms])
                 if d.exposure_h > 0 else np.full((d.false_alarms.size, 2), np.nan))
        for ty, ts in d.by_type.items():
            p_ci = np.array([clopper_pearson(int(c), ts.faults, confidence) for c in ts.detected])
            out.setdefault(ident, {})[ty] = RocCurve(
                ident, ty, rescored.scales, d.far_per_h, fa_ci[:, 0], fa_ci[:, 1], ts.p_detect, p_ci[:, 0], p_ci[:, 1],
                d.false_alarms, ts.detected, ts.faults, d.exposure_h)
    return out


# --- replay check -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class ReplayMismatch:
    """A difference between the re-scored decision at the logged threshold and the run's own.

    Attributes
    ----------
    index : int
        The run.
    detector : str
    what : str
        ``exceedance``, ``alarm`` (a logged column differs), ``episodes`` (the record's alarms
        differ), ``missing`` (a member of the record has no statistic in the log).
    detail : str
    """

    index: int
    detector: str
    what: str
    detail: str


def check_replay(records: Sequence[Mapping[str, Any]], out_dir: str | Path) -> list[ReplayMismatch]:
    """Replay every run with a log (any status) at its logged thresholds and its ``k, n``; list
    every difference from what the run decided (empty: the replay is exact).

    Compared per member: the recomputed exceedance and alarm with the logged columns, sample by
    sample; the episodes (onset time, end time or None while still on) with the record's
    ``alarms``, in order, as exact floats.
    """
    bad: list[ReplayMismatch] = []
    runs, _ = _runs(records, out_dir, None, None, only_completed=False)
    for run in runs:
        r = run.record
        idx = int(r.get("index", -1))
        for d in r.get("detectors", []):
            st = run.stats.get(d)
            if st is None:
                bad.append(ReplayMismatch(idx, d, "missing", f"no /fdi/{d}/statistic in runs/{r['log']}"))
                continue
            e = exceedances(st.statistic, st.threshold, st.valid)
            a = k_of_n(e, run.k, run.n)
            for what, mine, logged in (("exceedance", e, st.exceedance), ("alarm", a, st.alarm)):
                diff = np.flatnonzero(mine != logged)
                if diff.size:
                    bad.append(ReplayMismatch(idx, d, what, f"{diff.size} samples differ, first at t = "
                                              f"{st.t_s[diff[0]]!r} s (replay {bool(mine[diff[0]])}, logged "
                                              f"{bool(logged[diff[0]])})"))
            ep = episodes_of(a)
            mine_eps = [(float(st.t_s[o]), None if o_end == ep.n_samples else float(st.t_s[o_end]))
                        for o, o_end in zip(ep.onset, ep.end)]
            rec_eps = [(float(x["onset_t_s"]), None if x["end_t_s"] is None else float(x["end_t_s"]))
                       for x in r.get("alarms", []) if x["detector"] == d]
            if mine_eps != rec_eps:
                bad.append(ReplayMismatch(idx, d, "episodes", f"replay {mine_eps} vs record {rec_eps}"))
    return bad
