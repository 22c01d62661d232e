"""Statistics of a finished study from its run records: false alarms, detection, isolation.

Definitions (one per number, so that two studies can be compared):

- Only runs with status ``completed`` count for rates and probabilities; every status is counted.
- **Exposure** of a run: the armed, fault-free part of the flight, ``[arm_s, t_end_s]`` minus each
  fault window ``[w0, min(w1, t_end_s) + grace_s]`` (``grace_s`` =
  :data:`fdi_sim.decision.outcome.LATE_GRACE_S`, the rule by which :func:`fdi_sim.bank.runtime.fdi_outcomes`
  calls an alarm false); before ``arm_s`` the bank never decides (its samples are logged with
  ``valid = 0``). ``exposure_h`` is its sum over the runs [h], ``flight_h`` the whole flights'.
  It includes armed samples at which a member's statistic is not valid yet (a kinematic check's
  window filling: up to 17 s for ``kinematic-altitude-v1`` on the DHC-6), so on short flights a
  member's rate is a little low.
- **False alarm**: an alarm episode that begins outside every fault window + grace (the record's
  ``false_alarms``). ``far_per_h = false_alarms / exposure_h`` with the exact Poisson (Garwood)
  interval; ``p_false_alarm_per_run`` = runs with at least one / runs, Clopper-Pearson interval.
- **Prediction**: the bank splits its design rate evenly over its members by a union bound
  (:func:`fdi_sim.bank.members.per_sample_target`), so a member is predicted at most
  ``design_far_per_h / n_members`` per armed hour and the bank at most ``design_far_per_h``
  (an upper bound: an onset needs an exceedance, persistence needs several).
- **Detection** (per run and injected fault, the record's ``detections``,
  :func:`fdi_sim.decision.outcome.fault_outcome`): the first alarm sample at or after the fault's first
  onset; ``p_detect`` over (run, fault) pairs with its Clopper-Pearson interval; delays [s] as
  median and 95th percentile (linear interpolation between order statistics).
- **Confusion**: true target -> isolated as -> count, with the columns ``not isolated`` (an alarm
  without a hypothesis) and ``not detected``.
- **Bank** (any member): its alarm is the OR of the members' (episodes that overlap or touch are
  merged); a fault is detected at the earliest member detection; the bank's isolation is the one
  named by the earliest detecting member that names one (the failure log's first entry).
- **ALFA form** (Keipour, Mousaei & Scherer 2019, 2021): one outcome per flight. A fault flight
  whose first alarm comes before the (first) fault onset is a false positive (FP), else it is a
  true positive (TP) if detected, else a false negative (FN); a fault-free flight with any alarm
  is an FP, else a true negative (TN). ``precision = TP / (TP + FP)``, ``recall = TP / (TP + FN)``
  (Clopper-Pearson intervals), ``mean_detection_time_s`` = mean over the TP flights of the first
  detection's delay after the onset.

- **Overdispersion**: alarms of one member often cluster by run (a flight whose conditions sit
  near the threshold alarms several times), so the counts vary more between runs than a Poisson
  process allows and the Garwood interval is too narrow. ``dispersion`` is the Pearson estimate of
  the quasi-Poisson factor, ``phi = sum_i (k_i - lam e_i)^2 / (lam e_i) / (n - 1)`` with
  ``lam = sum k / sum e`` over the runs (McCullagh & Nelder 1989, sec. 6.2); ``far_per_h_ci_overdispersed``
  is the Garwood interval of ``K / phi`` events in ``E / phi`` hours with ``phi`` floored at 1 (the
  effective number of independent events). Simulated with gamma-mixed rates (200 runs of 20 s,
  36 /h, shape 0.2), the plain interval covered 86 % and this one 95 % of 2,000 studies
  (``tests/study/test_stats.py``); use it whenever ``dispersion`` is well above 1.

Probabilities and intervals assume independent runs (they are: seeds from ``SeedSequence``).
"""
from __future__ import annotations

import math
from collections import Counter
from typing import Any, Iterable, Mapping, Sequence

import numpy as np
from scipy import stats as scipy_stats

from fdi_sim.decision.intervals import clopper_pearson, poisson_rate_interval
from fdi_sim.decision.outcome import LATE_GRACE_S
from fdi_sim.units import S_PER_H

COMPLETED = "completed"
#: the statuses a record can have (others are counted as they come)
STATUSES = ("completed", "diverged", "interrupted", "error", "timeout")
NOT_ISOLATED = "not isolated"
NOT_DETECTED = "not detected"
BANK = "bank"
#: why no member has Hagenblad's analytic probability of wrong diagnosis
WRONG_DIAGNOSIS_REASON = (
    "no analytic probability of wrong diagnosis: Hagenblad, Gustafsson & Klein (seed 003) Algorithm 2, eq. 14, "
    "needs a stochastic parity space's mean fault vectors mu_bar_j; it is implemented for parity-stochastic-v1 "
    "(fdi_sim.detectors.stochastic_parity.incorrect_diagnosis_matrix) from its design, and a study does not "
    "compute it for a parity-stochastic-v1 member yet")


# --- reading records ------------------------------------------------------------------------------
def completed(records: Iterable[Mapping[str, Any]]) -> list[Mapping[str, Any]]:
    """The records with status ``completed``."""
    return [r for r in records if r.get("status") == COMPLETED]


def fault_windows(record: Mapping[str, Any]) -> dict[str, list[tuple[float, float]]]:
    """Per fault label, its windows [s], each end clipped to the flight's end (as ``fdi_outcomes``).

    A fault entry without ``windows_s`` gets ``[(onset, t_end_s)]`` from the record's detections.
    """
    t_end = float(record.get("t_end_s", 0.0))
    out: dict[str, list[tuple[float, float]]] = {}
    for i, f in enumerate(record.get("faults", [])):
        label = f.get("label", f"f{i}")
        if "windows_s" in f:
            out[label] = [(float(a), min(float(b), t_end)) for a, b in f["windows_s"]]
    for d in record.get("detections", []):
        if d["fault"] not in out:
            out[d["fault"]] = [(float(d["onset_t_s"]), t_end)]
    return out


def fault_types(record: Mapping[str, Any]) -> dict[str, str]:
    """Per fault label, its registered type id (``unknown`` when the record does not say)."""
    out = {}
    faults = list(record.get("faults", []))
    for i, f in enumerate(faults):
        out[f.get("label", f"f{i}")] = f.get("type", "unknown")
    for d in record.get("detections", []):
        if d.get("type"):
            out[d["fault"]] = d["type"]
        elif d["fault"] not in out or out[d["fault"]] == "unknown":
            same = [f.get("type", "unknown") for f in faults if f.get("target") == d.get("target")]
            out[d["fault"]] = same[0] if len(set(same)) == 1 else "unknown"
    return out


def in_fault_window(t_s: float, windows: Iterable[tuple[float, float]], grace_s: float = LATE_GRACE_S) -> bool:
    """``w0 <= t_s <= w1 + grace_s`` for some window (an onset there is not a false alarm)."""
    return any(w0 <= t_s <= w1 + grace_s for w0, w1 in windows)


def exposure_s(record: Mapping[str, Any], grace_s: float = LATE_GRACE_S) -> float:
    """Armed fault-free time of a run [s]: ``[arm_s, t_end_s]`` minus the union of the fault
    windows ``[w0, w1 + grace_s]``."""
    t0, t1 = float(record.get("arm_s", 0.0)), float(record.get("t_end_s", 0.0))
    if t1 <= t0:
        return 0.0
    spans = sorted((max(t0, a), min(t1, b + grace_s)) for ws in fault_windows(record).values() for a, b in ws)
    covered, end = 0.0, t0
    for a, b in spans:  # union length of the clipped spans, swept left to right
        a = max(a, end)
        if b > a:
            covered += b - a
            end = b
    return (t1 - t0) - covered


def merge_episodes(alarms: Sequence[Mapping[str, Any]]) -> list[tuple[float, float]]:
    """The episodes of the OR of several members' alarms: ``(onset, end)`` [s] with an open
    episode's end ``inf``; episodes that overlap or touch (one ends at the sample where the next
    begins) are one."""
    spans = sorted((float(a["onset_t_s"]), math.inf if a["end_t_s"] is None else float(a["end_t_s"])) for a in alarms)
    out: list[list[float]] = []
    for a, b in spans:
        if out and a <= out[-1][1]:
            out[-1][1] = max(out[-1][1], b)
        else:
            out.append([a, b])
    return [(a, b) for a, b in out]


# --- small statistics -----------------------------------------------------------------------------
def _ci(lo_hi: tuple[float, float]) -> list[float]:
    return [float(lo_hi[0]), float(lo_hi[1])]


def proportion(k: int, n: int, confidence: float) -> tuple[float | None, list[float] | None]:
    """``k / n`` and its Clopper-Pearson interval (None, None when ``n = 0``)."""
    if n == 0:
        return None, None
    return k / n, _ci(clopper_pearson(k, n, confidence))


def rate(k: int, exposure_h: float, confidence: float) -> tuple[float | None, list[float] | None]:
    """``k / exposure_h`` [1/h] and its exact Poisson interval (None, None without exposure)."""
    if exposure_h <= 0.0:
        return None, None
    return k / exposure_h, _ci(poisson_rate_interval(k, exposure_h, confidence))


def dispersion(counts: Sequence[float], exposures: Sequence[float]) -> float | None:
    """Pearson estimate of the quasi-Poisson dispersion of per-run event counts [-].

    ``phi = sum_i (k_i - lam e_i)^2 / (lam e_i) / (n - 1)``, ``lam = sum k / sum e``, over the runs with
    exposure; 1 for a Poisson process, above 1 when events cluster by run. None with fewer than two
    runs or no event.
    """
    k, e = np.asarray(counts, dtype=float), np.asarray(exposures, dtype=float)
    keep = e > 0.0
    k, e = k[keep], e[keep]
    if k.size < 2 or k.sum() == 0.0:
        return None
    mu = k.sum() / e.sum() * e
    return float(np.sum((k - mu) ** 2 / mu) / (k.size - 1))


def overdispersed_rate(counts: Sequence[float], exposures_h: Sequence[float], confidence: float
                       ) -> tuple[float | None, list[float] | None, float | None]:
    """Rate [1/h], its dispersion-scaled Garwood interval [1/h] and the dispersion [-].

    The interval is the exact Poisson interval of ``K / phi`` events in ``E / phi`` hours,
    ``phi = max(1, dispersion)`` (module docstring); with ``phi = 1`` it is :func:`rate`'s.
    """
    k_sum, e_sum = float(np.sum(counts)), float(np.sum(exposures_h))
    if e_sum <= 0.0:
        return None, None, None
    phi = dispersion(counts, exposures_h)
    scale = max(1.0, phi if phi is not None else 1.0)
    a = (1.0 - confidence) / 2.0  # Garwood with a non-integer count (chi2 of non-integer dof)
    k_eff = k_sum / scale
    lo = 0.0 if k_eff == 0.0 else float(scipy_stats.chi2.ppf(a, 2.0 * k_eff)) / 2.0
    hi = float(scipy_stats.chi2.ppf(1.0 - a, 2.0 * k_eff + 2.0)) / 2.0
    return k_sum / e_sum, [lo * scale / e_sum, hi * scale / e_sum], phi


def rate_ratio_interval(k_a: float, expo_a_h: float, k_b: float, expo_b_h: float, confidence: float,
                        phi: float = 1.0) -> tuple[float, tuple[float, float]]:
    """The ratio of two Poisson rates ``(k_b / E_b) / (k_a / E_a)`` and its exact conditional interval.

    Given ``k_a + k_b`` events, ``k_b`` is binomial with ``w = E_b rho / (E_a + E_b rho)``
    (``rho`` the rate ratio); the Clopper-Pearson interval of ``w`` mapped to ``rho`` is the exact
    conditional interval (Breslow and Day 1987, sec. 2.3). Where the per-run counts are
    overdispersed (quasi-Poisson, ``phi > 1``) both counts are divided by ``phi`` (the effective
    numbers of independent events), the Beta quantiles taking non-integer counts.

    Returns
    -------
    tuple
        ``(rho, (lo, hi))`` [-]; ``hi`` is inf when ``k_a = 0``.
    """
    if expo_a_h <= 0.0 or expo_b_h <= 0.0:
        raise ValueError("both exposures must be positive")
    scale = max(1.0, float(phi))
    a, b = k_a / scale, k_b / scale
    alpha = (1.0 - confidence) / 2.0
    w_lo = 0.0 if b == 0 else float(scipy_stats.beta.ppf(alpha, b, a + 1.0))
    w_hi = 1.0 if a == 0 else float(scipy_stats.beta.ppf(1.0 - alpha, b + 1.0, a))
    odds = expo_a_h / expo_b_h  # rho = w / (1 - w) x E_a / E_b

    def to_rho(w: float) -> float:
        return math.inf if w >= 1.0 else w / (1.0 - w) * odds

    rho = math.inf if k_a == 0 else (k_b / expo_b_h) / (k_a / expo_a_h)
    return rho, (to_rho(w_lo), to_rho(w_hi))


def delay_quantiles(delays_s: Sequence[float]) -> tuple[float | None, float | None]:
    """Median and 95th percentile [s] (None without detections)."""
    if not len(delays_s):
        return None, None
    d = np.asarray(delays_s, dtype=float)
    return float(np.median(d)), float(np.percentile(d, 95.0))


# --- per (run, fault) outcomes ------------------------------------------------------------------
def _member_outcomes(record: Mapping[str, Any], detector: str) -> list[dict[str, Any]]:
    types = fault_types(record)
    out = []
    for d in record.get("detections", []):
        if d["detector"] == detector:
            out.append({"fault": d["fault"], "type": types.get(d["fault"], "unknown"), "target": d.get("target") or "",
                        "onset_t_s": d["onset_t_s"], "detected_t_s": d["detected_t_s"], "delay_s": d["delay_s"],
                        "isolation": d["isolation"], "isolation_correct": d.get("isolation_correct")})
    return out


def _bank_outcomes(record: Mapping[str, Any]) -> list[dict[str, Any]]:
    """Per fault: the earliest member detection and the isolation of the earliest member naming one."""
    types = fault_types(record)
    by_fault: dict[str, list[Mapping[str, Any]]] = {}
    for d in record.get("detections", []):
        by_fault.setdefault(d["fault"], []).append(d)
    out = []
    for label, ds in by_fault.items():
        hit = sorted((d for d in ds if d["detected_t_s"] is not None), key=lambda d: d["detected_t_s"])
        first = hit[0] if hit else None
        named = next((d for d in hit if d["isolation"] is not None), None)
        out.append({"fault": label, "type": types.get(label, "unknown"), "target": ds[0].get("target") or "",
                    "onset_t_s": ds[0]["onset_t_s"], "detected_t_s": first["detected_t_s"] if first else None,
                    "delay_s": first["delay_s"] if first else None,
                    "isolation": named["isolation"] if named else None,
                    "isolation_correct": named.get("isolation_correct") if named else None})
    return out


def _detection_block(outcomes: Sequence[Mapping[str, Any]], confidence: float) -> dict[str, Any]:
    """p_detect, delays, isolation and confusion of a set of (run, fault) outcomes."""
    hit = [o for o in outcomes if o["detected_t_s"] is not None]
    p, p_ci = proportion(len(hit), len(outcomes), confidence)
    delays = [float(o["delay_s"]) for o in hit]
    med, p95 = delay_quantiles(delays)
    right = sum(1 for o in hit if o["isolation_correct"] is True)  # the run's rule (detect._matches)
    pi, pi_ci = proportion(right, len(hit), confidence)
    confusion: dict[str, dict[str, int]] = {}
    for o in outcomes:
        col = NOT_DETECTED if o["detected_t_s"] is None else (o["isolation"] or NOT_ISOLATED)
        row = confusion.setdefault(o["target"] or "unknown", {})
        row[col] = row.get(col, 0) + 1
    return {"faults": len(outcomes), "detected": len(hit), "p_detect": p, "p_detect_ci": p_ci,
            "delay_s_median": med, "delay_s_p95": p95, "delays_s": delays,
            "isolated_correctly": right, "p_isolation_correct": pi, "p_isolation_correct_ci": pi_ci,
            "confusion": confusion}


def _alfa(flights: Sequence[tuple[float | None, list[float], float | None]], confidence: float) -> dict[str, Any]:
    """ALFA counts from ``(first fault onset or None, alarm onsets, first detection delay or None)``."""
    tp = fp = fn = tn = 0
    times = []
    for t_on, onsets, delay in flights:
        if t_on is None:
            if onsets:
                fp += 1
            else:
                tn += 1
        elif any(t < t_on for t in onsets):
            fp += 1
        elif delay is not None:
            tp += 1
            times.append(delay)
        else:
            fn += 1
    prec, prec_ci = proportion(tp, tp + fp, confidence)
    rec, rec_ci = proportion(tp, tp + fn, confidence)
    return {"flights": len(flights), "tp": tp, "fp": fp, "fn": fn, "tn": tn, "precision": prec,
            "precision_ci": prec_ci, "recall": rec, "recall_ci": rec_ci,
            "mean_detection_time_s": float(np.mean(times)) if times else None}


def _first_onset(record: Mapping[str, Any]) -> float | None:
    starts = [w[0] for ws in fault_windows(record).values() for w in ws]
    return min(starts) if starts else None


def _block(ident: str, runs: Sequence[Mapping[str, Any]], confidence: float, grace_s: float) -> dict[str, Any]:
    """Every statistic of one member (``ident``) or of the bank (:data:`BANK`) over ``runs``."""
    bank = ident == BANK
    n_fa, runs_fa, expo_s, pred_x = 0, 0, 0.0, 0.0
    outcomes: list[dict[str, Any]] = []
    flights = []
    counts: list[int] = []
    exposures_h: list[float] = []
    for r in runs:
        e = exposure_s(r, grace_s)
        expo_s += e
        n_members = int(r.get("n_members") or len(r.get("detectors", [])) or 1)
        design = float(r.get("design_far_per_h") or math.nan)
        pred_x += (design if bank else design / n_members) * e  # exposure-weighted prediction
        windows = [w for ws in fault_windows(r).values() for w in ws]
        if bank:
            eps = merge_episodes(r.get("alarms", []))
            fa = sum(1 for a, _ in eps if not in_fault_window(a, windows, grace_s))
            onsets = [a for a, _ in eps]
            oc = _bank_outcomes(r)
        else:
            fa = sum(1 for a in r.get("false_alarms", []) if a["detector"] == ident)
            onsets = [float(a["onset_t_s"]) for a in r.get("alarms", []) if a["detector"] == ident]
            oc = _member_outcomes(r, ident)
        n_fa += fa
        runs_fa += fa > 0
        counts.append(fa)
        exposures_h.append(e / S_PER_H)
        outcomes += oc
        hit = [o["delay_s"] for o in oc if o["detected_t_s"] is not None]
        flights.append((_first_onset(r), onsets, min(hit) if hit else None))
    expo_h = expo_s / S_PER_H
    far, far_ci = rate(n_fa, expo_h, confidence)
    predicted = pred_x / expo_s if expo_s > 0 else None
    if predicted is not None and not math.isfinite(predicted):
        predicted = None
    pfa, pfa_ci = proportion(runs_fa, len(runs), confidence)
    _, far_ci_od, phi = overdispersed_rate(counts, exposures_h, confidence)
    out: dict[str, Any] = {
        "id": ident, "runs": len(runs), "exposure_h": expo_h, "flight_h": sum(float(r.get("flight_h", 0.0)) for r in runs),
        "false_alarms": n_fa, "far_per_h": far, "far_per_h_ci": far_ci, "predicted_far_per_h": predicted,
        "dispersion": phi, "far_per_h_ci_overdispersed": far_ci_od,
        "prediction_in_ci": None if far_ci is None or predicted is None else bool(far_ci[0] <= predicted <= far_ci[1]),
        "exceeds_prediction": None if far_ci is None or predicted is None else bool(far_ci[0] > predicted),
        "runs_with_false_alarm": runs_fa, "p_false_alarm_per_run": pfa, "p_false_alarm_per_run_ci": pfa_ci,
    }
    out.update(_detection_block(outcomes, confidence))
    out["wrong_diagnosis_analytic"] = None
    out["wrong_diagnosis_analytic_reason"] = WRONG_DIAGNOSIS_REASON
    out["alfa"] = _alfa(flights, confidence)
    types = sorted({o["type"] for o in outcomes})
    out["by_fault_type"] = {t: _detection_block([o for o in outcomes if o["type"] == t], confidence) for t in types}
    return out


def detector_ids(records: Iterable[Mapping[str, Any]]) -> list[str]:
    """Every member id of the records, in the order they first appear."""
    ids: list[str] = []
    for r in records:
        ids += [d for d in r.get("detectors", []) if d not in ids]
    return ids


def summarize(records: Sequence[Mapping[str, Any]], *, confidence: float = 0.95,
              grace_s: float = LATE_GRACE_S) -> dict[str, Any]:
    """The statistics of a study (module docstring for every definition), JSON-serializable.

    Parameters
    ----------
    records : sequence of mapping
        The run records (``runs/NNNNNN.json``), any status.
    confidence : float
        Level of every interval [-].
    grace_s : float
        An alarm this long after a fault window still belongs to the fault [s].

    Returns
    -------
    dict
        ``runs``, ``completed``, ``statuses`` (count per status), ``not_completed`` (index, status,
        reason), ``flight_h`` (completed runs) [h], ``flight_h_all`` [h], ``detectors`` (a list, per
        member: ``id``, ``runs``, ``exposure_h``, ``false_alarms``, ``far_per_h``, ``far_per_h_ci``,
        ``predicted_far_per_h``, ``dispersion``, ``far_per_h_ci_overdispersed``, ``prediction_in_ci``, ``exceeds_prediction``,
        ``runs_with_false_alarm``, ``p_false_alarm_per_run`` (+ ``_ci``), ``faults``, ``detected``,
        ``p_detect`` (+ ``_ci``), ``delay_s_median``, ``delay_s_p95``, ``delays_s``,
        ``p_isolation_correct`` (+ ``_ci``), ``confusion``, ``wrong_diagnosis_analytic`` (None)
        with ``wrong_diagnosis_analytic_reason``, ``alfa``, ``by_fault_type``), ``bank`` (the same
        for the bank as a whole), ``fault_types``, ``confidence``, ``grace_s``, ``notes`` (what
        the records lacked). A probability or rate without data is None.
    """
    runs = completed(records)
    statuses = Counter(str(r.get("status", "unknown")) for r in records)
    summary: dict[str, Any] = {
        "runs": len(records), "completed": len(runs),
        "statuses": {s: statuses.get(s, 0) for s in STATUSES} | {s: c for s, c in statuses.items() if s not in STATUSES},
        "not_completed": [{"index": r.get("index"), "status": r.get("status"), "reason": r.get("reason", "")}
                          for r in records if r.get("status") != COMPLETED],
        "flight_h": sum(float(r.get("flight_h", 0.0)) for r in runs),
        "flight_h_all": sum(float(r.get("flight_h", 0.0)) for r in records),
        "confidence": confidence, "grace_s": grace_s,
        "design_far_per_h": sorted({float(r["design_far_per_h"]) for r in runs if r.get("design_far_per_h") is not None}),
        "persistence": sorted({tuple(r["persistence"]) for r in runs if r.get("persistence")}),
    }
    summary["persistence"] = [list(p) for p in summary["persistence"]]
    summary["detectors"] = [_block(d, [r for r in runs if d in r.get("detectors", [])], confidence, grace_s)
                            for d in detector_ids(runs)]
    summary["bank"] = _block(BANK, [r for r in runs if r.get("detectors")], confidence, grace_s)
    summary["fault_types"] = sorted(summary["bank"]["by_fault_type"])
    no_windows = [r.get("index") for r in runs if any("windows_s" not in f for f in r.get("faults", []))]
    summary["notes"] = ([f"{len(no_windows)} completed runs (first: {no_windows[:5]}) have faults without windows_s: "
                         "each fault's window is taken as [onset, end of flight], so exposure and the bank's false "
                         "alarms after a fault that ended are wrong; store the injector's catalog (label, type, "
                         "target, windows_s) in the record"] if no_windows else [])
    return summary
