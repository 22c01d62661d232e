"""The benchmark's scorer: control and machine-learning metrics of alarms and scores against labelled flights.

One module for every consumer (``fdi-sim bench run``, ``fdi-sim bench score``, the leaderboard). Pure
functions of arrays: a case's truth (:class:`CaseTruth`) and a method's output on it
(:class:`CaseOutput`: sample times, alarms, optionally a raw score and an isolation). Nothing here
flies or reads a log.

Time convention: every time is seconds of flight time from the case's start (the log clock,
``t_s``). A fault window is ``[w0, w1]``, ``w1`` the end of the flight for a fault that never clears.

Definitions (each number has one):

- **Armed**: only samples at or after ``arm_s`` count (before it the bank never decides).
- **Episode**: a maximal run of armed alarm samples; it begins at its first sample.
- **Exposure** (fault-free time): ``[arm_s, t_end_s]`` minus each window extended by the grace,
  ``[w0, min(w1, t_end_s) + grace_s]`` (``grace_s`` = :data:`fdi_sim.decision.outcome.LATE_GRACE_S`).
- **False alarm**: an episode that begins outside every ``[w0, w1 + grace_s]``.
  ``far_per_h = false alarms / exposure [h]``, exact Garwood interval.
- **Detection** of a fault case: :func:`fdi_sim.decision.outcome.fault_outcome` (the run summary's rule):
  the first alarm sample at or after the onset; its delay; its isolation, the most frequent
  hypothesis in the second after it, right when it names the target
  (:func:`fdi_sim.decision.outcome._matches`). ``p_detect`` per fault class and per (class, size) (the
  detectability curve) with Clopper-Pearson intervals; delay median and 95th percentile.
- **Isolation**: accuracy over detected faults with a comparable target (icing names no part: left
  out); the confusion matrix target -> isolated as (``not isolated``, ``not detected``).
- **ALFA criterion** (Keipour, Mousaei & Scherer 2021, the ALFA dataset's scorer): per flight, a
  fault flight with an episode beginning before the onset is a false positive; else a true positive
  if it is detected within ``alfa_window_s`` (5 s) of the onset; else a false negative (a later
  detection is a miss). A fault-free flight with any episode is a false positive, else a true
  negative. ``precision = TP / (TP + FP)``, ``recall = TP / (TP + FN)``, mean and maximum detection
  time over the TPs, so a number can stand beside ALFA's RLS (precision 88.23 %, recall 88.23 %,
  2.02 s mean, 5.6 s max).
- **Per-flight detection**: fault flights detected (any delay) with no episode before the onset,
  over fault flights.
- **Event-level precision, recall, F1** (no point adjustment): a fault case is one true event,
  recalled when an episode *begins* inside one of its windows (``[w0, w1 + grace_s]``); an alarm
  already on before the onset does not claim it. False events are the false alarms above.
  ``precision = recalled / (recalled + false alarms)``, ``recall = recalled / fault cases``.
- **Sample-level metrics** on a uniform grid of :data:`GRID_HZ` from ``arm_s`` to ``t_end_s`` (so
  that a method's own sample rate does not weigh it): at each grid time the method's latest output
  at or before it (zero-order hold; none yet: no alarm and the lowest score). Label 1 inside a window,
  0 outside every window + grace, left out in the grace. Point-wise precision, recall and F1 of the
  alarm, **never point-adjusted**; AUROC and AUPRC (average precision) of the raw score, pooled over
  the cases (:mod:`sklearn.metrics`); a NaN score (the method said its statistic is not valid) is
  the lowest score, never a hidden sample.

Point adjustment (Xu et al. 2018; shown misleading by Kim et al. 2022): after it, one alarm sample
inside a fault window marks every sample of the window detected. :func:`point_adjust` exists to
show the trap (``tests/decision/test_scoring.py``: a random detector's F1 jumps); the scorer never
applies it.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from fdi_sim.decision.intervals import clopper_pearson, poisson_rate_interval
from fdi_sim.decision.outcome import LATE_GRACE_S, fault_outcome
from fdi_sim.units import S_PER_H

#: the ALFA dataset's detection window: detected more than this after the onset is a miss [s]
ALFA_WINDOW_S = 5.0
#: the uniform grid the sample-level metrics are computed on [Hz]
GRID_HZ = 10.0
NOT_ISOLATED = "not isolated"
NOT_DETECTED = "not detected"


@dataclass(frozen=True)
class CaseTruth:
    """What happened in one flight of a suite (its label).

    Attributes
    ----------
    case : str
        The case id (``group/size/index``).
    aircraft, group, split : str
        The aircraft, the suite group, ``train`` / ``validation`` / ``test``.
    fault_type : str
        The fault's type id, ``""`` for a fault-free flight.
    target : str
        The fault's target, ``""`` for a fault-free flight.
    size : str
        The fault's size label (``"0.3 bias_degps"``), ``""`` without a size.
    size_rank : int
        0 for the smallest size of its group, upwards; -1 fault-free.
    windows_s : tuple of (float, float)
        The fault's active windows [s] (empty: fault-free).
    arm_s, t_end_s : float
        The bank's arming time and the end of the flight [s].
    negative : str
        For a fault-free flight, what makes it hard (``"turns"``, ``"severe air"``) or ``""``.
    """

    case: str
    aircraft: str
    group: str
    split: str
    fault_type: str
    target: str
    size: str
    size_rank: int
    windows_s: tuple[tuple[float, float], ...]
    arm_s: float
    t_end_s: float
    negative: str = ""

    @property
    def onset_s(self) -> float | None:
        """The fault's first onset [s] (None: fault-free)."""
        return self.windows_s[0][0] if self.windows_s else None

    @property
    def fault_class(self) -> str:
        """``sensor``, ``actuator``, ``engine``, ``icing`` (from the type id) or ``none``."""
        return self.fault_type.split("-")[0] if self.fault_type else "none"

    def to_dict(self) -> dict[str, Any]:
        return {"case": self.case, "aircraft": self.aircraft, "group": self.group, "split": self.split,
                "fault_type": self.fault_type, "target": self.target, "size": self.size, "size_rank": self.size_rank,
                "windows_s": [list(w) for w in self.windows_s], "arm_s": self.arm_s, "t_end_s": self.t_end_s,
                "negative": self.negative}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> CaseTruth:
        return cls(str(d["case"]), str(d["aircraft"]), str(d["group"]), str(d["split"]), str(d["fault_type"]),
                   str(d["target"]), str(d["size"]), int(d["size_rank"]),
                   tuple((float(a), float(b)) for a, b in d["windows_s"]), float(d["arm_s"]), float(d["t_end_s"]),
                   str(d.get("negative", "")))


@dataclass(frozen=True, eq=False)
class CaseOutput:
    """One method's output on one case.

    Attributes
    ----------
    t_s : NDArray
        Sample times, strictly increasing [s].
    alarm : NDArray of bool
        The method's decision per sample.
    score : NDArray, optional
        Its raw statistic (larger: more faulty; NaN: not valid), for AUROC/AUPRC. None: alarms only.
    isolation : sequence of (str or None), optional
        The hypothesis named per sample (None where none); None: the method does not isolate.
    """

    t_s: NDArray[np.float64]
    alarm: NDArray[np.bool_]
    score: NDArray[np.float64] | None = None
    isolation: Sequence[str | None] | None = None


# --- per-case pieces ------------------------------------------------------------------------------
def episode_onsets(t_s: NDArray[np.float64], alarm: NDArray[np.bool_], arm_s: float) -> NDArray[np.float64]:
    """Begin times [s] of the armed alarm episodes (an episode on at ``arm_s`` begins there)."""
    a = np.asarray(alarm, dtype=bool) & (np.asarray(t_s) >= arm_s)
    prev = np.concatenate(([False], a[:-1]))
    return np.asarray(t_s, dtype=float)[a & ~prev]


def _in_windows(t: float, windows: Sequence[tuple[float, float]], grace_s: float) -> bool:
    return any(w0 <= t <= w1 + grace_s for w0, w1 in windows)


def exposure_s(truth: CaseTruth, grace_s: float = LATE_GRACE_S) -> float:
    """Armed fault-free time of a case [s]: ``[arm_s, t_end_s]`` minus the union of the windows
    ``[w0, min(w1, t_end_s) + grace_s]`` (an intermittent fault's windows overlap once extended)."""
    t0, t1 = truth.arm_s, truth.t_end_s
    if t1 <= t0:
        return 0.0
    spans = sorted((max(t0, a), min(t1, min(b, t1) + grace_s)) for a, b in truth.windows_s)
    covered, end = 0.0, t0
    for a, b in spans:  # union length of the clipped spans, swept left to right
        a = max(a, end)
        if b > a:
            covered += b - a
            end = b
    return (t1 - t0) - covered


def sample_grid(truth: CaseTruth, out: CaseOutput, grace_s: float = LATE_GRACE_S,
                grid_hz: float = GRID_HZ) -> tuple[NDArray[np.int8], NDArray[np.bool_], NDArray[np.float64]]:
    """The case on the uniform grid: labels (1 fault, 0 fault-free, -1 left out), held alarms, held
    scores (-inf before the first sample and where NaN)."""
    n = math.floor((truth.t_end_s - truth.arm_s) * grid_hz + 1e-9) + 1
    g = truth.arm_s + np.arange(max(n, 0)) / grid_hz
    label = np.zeros(g.size, dtype=np.int8)
    for w0, w1 in truth.windows_s:
        label[(g > w1) & (g <= w1 + grace_s) & (label == 0)] = -1
    for w0, w1 in truth.windows_s:
        label[(g >= w0) & (g <= w1)] = 1
    t = np.asarray(out.t_s, dtype=float)
    k = np.searchsorted(t, g + 1e-9, side="right") - 1  # the latest sample at or before g
    have = k >= 0
    alarm = np.zeros(g.size, dtype=bool)
    alarm[have] = np.asarray(out.alarm, dtype=bool)[k[have]]
    score = np.full(g.size, -np.inf)
    if out.score is not None:
        s = np.asarray(out.score, dtype=float)[k[have]]
        score[have] = np.where(np.isfinite(s), s, -np.inf)
    return label, alarm, score


def point_adjust(label: NDArray[np.int8], alarm: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """Point adjustment (never used by the scorer): every sample of a fault segment (a run of label
    1) becomes an alarm when one of its samples is."""
    out = np.asarray(alarm, dtype=bool).copy()
    lab = np.asarray(label) == 1
    edges = np.flatnonzero(np.diff(np.concatenate(([0], lab.astype(np.int8), [0]))))
    for a, b in zip(edges[::2], edges[1::2]):
        if out[a:b].any():
            out[a:b] = True
    return out


def prf(tp: int, fp: int, fn: int) -> dict[str, float | None]:
    """Precision, recall and F1 of counts (None where the denominator is 0)."""
    p = tp / (tp + fp) if tp + fp else None
    r = tp / (tp + fn) if tp + fn else None
    f1 = 2 * tp / (2 * tp + fp + fn) if tp + fp + fn else None
    return {"precision": p, "recall": r, "f1": f1}


def _prop(k: int, n: int, level: float) -> dict[str, Any]:
    return {"k": k, "n": n, "p": k / n if n else None, "ci": list(clopper_pearson(k, n, level)) if n else None}


def _quantiles(x: Sequence[float]) -> tuple[float | None, float | None]:
    if not len(x):
        return None, None
    a = np.asarray(x, dtype=float)
    return float(np.median(a)), float(np.percentile(a, 95.0))


@dataclass(frozen=True)
class _CaseScore:
    truth: CaseTruth
    onsets: NDArray[np.float64]
    false_alarms: int
    exposure_s: float
    detected_s: float | None
    delay_s: float | None
    isolated_as: str | None
    isolation_correct: bool | None
    early: bool  # an episode began before the onset
    recalled: bool  # an episode began inside a window (event level)
    labels: NDArray[np.int8] = field(repr=False)
    alarm_grid: NDArray[np.bool_] = field(repr=False)
    score_grid: NDArray[np.float64] = field(repr=False)


def score_case(truth: CaseTruth, out: CaseOutput, grace_s: float = LATE_GRACE_S) -> _CaseScore:
    """Every per-case quantity of the module docstring."""
    t = np.asarray(out.t_s, dtype=float)
    alarm = np.asarray(out.alarm, dtype=bool) & (t >= truth.arm_s)
    onsets = episode_onsets(t, alarm, truth.arm_s)
    fa = sum(1 for x in onsets if not _in_windows(x, truth.windows_s, grace_s))
    det = iso = ok = None
    delay = None
    early = recalled = False
    if truth.windows_s:
        iso_seq = out.isolation if out.isolation is not None else _NoIsolation(len(t))
        o = fault_outcome({"label": truth.case, "target": truth.target, "type": truth.fault_type,
                           "windows_s": [list(w) for w in truth.windows_s]}, t, alarm, iso_seq)
        det, delay, iso, ok = o.first_alarm_s, o.delay_s, o.isolated_as, o.isolation_correct
        early = bool(np.any(onsets < truth.onset_s))
        recalled = any(_in_windows(x, truth.windows_s, grace_s) for x in onsets)
    lab, ag, sg = sample_grid(truth, out, grace_s)
    return _CaseScore(truth, onsets, fa, exposure_s(truth, grace_s), det, delay, iso, ok, early, recalled, lab, ag, sg)


class _NoIsolation:
    """A method without isolation: None at every sample (no list built per sample)."""

    def __init__(self, n: int) -> None:
        self.n = n

    def __len__(self) -> int:
        return self.n

    def __getitem__(self, k: int) -> None:
        return None


# --- the suite ------------------------------------------------------------------------------------
def _detection(cs: Sequence[_CaseScore], level: float) -> dict[str, Any]:
    hit = [c for c in cs if c.detected_s is not None]
    med, p95 = _quantiles([c.delay_s for c in hit])
    comparable = [c for c in hit if c.isolation_correct is not None]
    return {"faults": len(cs), "detected": _prop(len(hit), len(cs), level), "delay_s_median": med, "delay_s_p95": p95,
            "isolation": _prop(sum(1 for c in comparable if c.isolation_correct), len(comparable), level)}


def _alfa(cs: Sequence[_CaseScore], alfa_window_s: float, level: float) -> dict[str, Any]:
    tp = fp = fn = tn = 0
    times = []
    for c in cs:
        if not c.truth.windows_s:
            fp += int(c.onsets.size > 0)
            tn += int(c.onsets.size == 0)
        elif c.early:
            fp += 1
        elif c.delay_s is not None and c.delay_s <= alfa_window_s:
            tp += 1
            times.append(c.delay_s)
        else:
            fn += 1
    out = {"tp": tp, "fp": fp, "fn": fn, "tn": tn, **prf(tp, fp, fn),
           "precision_ci": list(clopper_pearson(tp, tp + fp, level)) if tp + fp else None,
           "recall_ci": list(clopper_pearson(tp, tp + fn, level)) if tp + fn else None,
           "mean_detection_time_s": float(np.mean(times)) if times else None,
           "max_detection_time_s": float(np.max(times)) if times else None, "window_s": alfa_window_s}
    return out


def _auc(labels: NDArray[np.int8], scores: NDArray[np.float64]) -> tuple[float | None, float | None]:
    from sklearn.metrics import average_precision_score, roc_auc_score

    keep = labels >= 0
    y, s = labels[keep], scores[keep]
    if not y.size or y.min() == y.max():
        return None, None  # one class only: undefined
    s = np.where(np.isfinite(s), s, np.finfo(float).min)  # -inf: the lowest score (sklearn wants finite)
    return float(roc_auc_score(y, s)), float(average_precision_score(y, s))


def score_suite(truths: Sequence[CaseTruth], outputs: Mapping[str, CaseOutput], *, grace_s: float = LATE_GRACE_S,
                alfa_window_s: float = ALFA_WINDOW_S, confidence: float = 0.95) -> dict[str, Any]:
    """Score one method on a set of cases (every definition in the module docstring).

    Parameters
    ----------
    truths : sequence of CaseTruth
    outputs : mapping
        Case id -> :class:`CaseOutput`; every case of ``truths`` must be there.
    grace_s, alfa_window_s : float
        [s].
    confidence : float
        Level of every interval [-].

    Returns
    -------
    dict
        JSON-serializable: ``cases``, ``flight_h``, ``exposure_h``, ``false_alarms``, ``far_per_h``
        (+ ``_ci``), ``detection`` (all faults), ``by_class``, ``by_type``, ``detectability`` (type ->
        size rank -> detection), ``confusion``, ``alfa``, ``alfa_by_class`` (each class's fault flights
        with every fault-free one), ``per_flight_detection``, ``event``
        (precision, recall, F1 and counts), ``sample`` (point-wise precision, recall, F1; AUROC,
        AUPRC; ``None`` without scores or with one class).

    Raises
    ------
    KeyError
        A case without output (the caller names the file and the fix).
    """
    missing = [t.case for t in truths if t.case not in outputs]
    if missing:
        raise KeyError(f"{len(missing)} case(s) have no output, first {missing[:3]}")
    cs = [score_case(t, outputs[t.case], grace_s) for t in truths]
    faulty = [c for c in cs if c.truth.windows_s]
    expo_h = sum(c.exposure_s for c in cs) / S_PER_H
    n_fa = sum(c.false_alarms for c in cs)
    out: dict[str, Any] = {
        "cases": len(cs), "fault_cases": len(faulty), "flight_h": sum(c.truth.t_end_s for c in cs) / S_PER_H,
        "exposure_h": expo_h, "false_alarms": n_fa, "far_per_h": n_fa / expo_h if expo_h > 0 else None,
        "far_per_h_ci": list(poisson_rate_interval(n_fa, expo_h, confidence)) if expo_h > 0 else None,
        "confidence": confidence, "grace_s": grace_s, "grid_hz": GRID_HZ,
    }
    out["detection"] = _detection(faulty, confidence)
    out["by_class"] = {k: _detection([c for c in faulty if c.truth.fault_class == k], confidence)
                       for k in sorted({c.truth.fault_class for c in faulty})}
    out["by_type"] = {k: _detection([c for c in faulty if c.truth.fault_type == k], confidence)
                      for k in sorted({c.truth.fault_type for c in faulty})}
    out["detectability"] = {k: {str(r): {"size": next(c.truth.size for c in faulty if c.truth.fault_type == k
                                                     and c.truth.size_rank == r),
                                         **_detection([c for c in faulty if c.truth.fault_type == k
                                                       and c.truth.size_rank == r], confidence)}
                                for r in sorted({c.truth.size_rank for c in faulty if c.truth.fault_type == k})}
                            for k in out["by_type"]}
    confusion: dict[str, dict[str, int]] = {}
    for c in faulty:
        col = NOT_DETECTED if c.detected_s is None else (c.isolated_as or NOT_ISOLATED)
        row = confusion.setdefault(c.truth.target or "unknown", {})
        row[col] = row.get(col, 0) + 1
    out["confusion"] = confusion
    out["alfa"] = _alfa(cs, alfa_window_s, confidence)
    clean = [c for c in cs if not c.truth.windows_s]  # ALFA per fault class: its fault flights and every fault-free one
    out["alfa_by_class"] = {k: _alfa([c for c in faulty if c.truth.fault_class == k] + clean, alfa_window_s, confidence)
                            for k in out["by_class"]}
    out["per_flight_detection"] = _prop(sum(1 for c in faulty if c.detected_s is not None and not c.early),
                                        len(faulty), confidence)
    rec = sum(1 for c in faulty if c.recalled)
    out["event"] = {"true_events": len(faulty), "recalled": rec, "false_events": n_fa,
                    **prf(rec, n_fa, len(faulty) - rec)}
    lab = np.concatenate([c.labels for c in cs]) if cs else np.zeros(0, np.int8)
    al = np.concatenate([c.alarm_grid for c in cs]) if cs else np.zeros(0, bool)
    keep = lab >= 0
    y, a = lab[keep] == 1, al[keep]
    tp, fp, fn = int(np.sum(a & y)), int(np.sum(a & ~y)), int(np.sum(~a & y))
    have_score = all(outputs[t.case].score is not None for t in truths)
    auroc, auprc = _auc(lab, np.concatenate([c.score_grid for c in cs])) if have_score and cs else (None, None)
    out["sample"] = {"samples": int(keep.sum()), "positives": int(y.sum()), **prf(tp, fp, fn),
                     "auroc": auroc, "auprc": auprc}
    return out

