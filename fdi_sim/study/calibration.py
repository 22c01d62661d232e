"""Thresholds calibrated on a study's runs, and a finished calibration study turned into the
thresholds file a default bank can use.

:func:`calibrate_threshold` and :func:`check_calibration` (moved here from
:mod:`fdi_sim.study.rescore`, which still exports them) calibrate one member, or the bank, to a
target rate by exact inversion of the re-scored false-alarm count (:data:`CALIBRATION_METHOD`).

The study flies the bank with its trained thresholds (``[bank] thresholds = "trained"``) at one
design node; every run logs each member's statistic (:mod:`fdi_sim.study.rescore`). Here each
member's threshold is calibrated, from the tail of its alarm episodes' peaks
(:func:`tail_calibrate_threshold`; the exact inversion of the count, :func:`calibrate_threshold`,
rests on the half's largest peak when the target allows less than one alarm), to its share of the bank's rate,
``far_per_h / members`` (the split the trained thresholds use, a union bound), on the runs of
even index, and checked on the odd ones (:func:`check_calibration`: exact
Poisson interval, scaled by the runs' dispersion); the bank, the OR of its members at their calibrated thresholds under the
runs' own k-of-n rule, is checked against ``far_per_h`` on both halves. The result
(:class:`fdi_sim.bank.thresholds_file.StudyThresholds`) carries the study's name, identity hash, run
count and flight hours, the design node and :func:`fdi_sim.bank.members.design_hash` of the
bank it holds thresholds for.
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from fdi_sim import __version__
from fdi_sim.decision.intervals import detectable_ratio, interval_verdict, poisson_rate_interval, rate_verdict
from fdi_sim.errors import StudyError
from fdi_sim.decision.outcome import LATE_GRACE_S
from fdi_sim.bank.members import member_far_per_h
from fdi_sim.bank.thresholds_file import HeldRate, StudyMemberThreshold, StudyThresholds
from fdi_sim.decision.persistence import k_of_n
from fdi_sim.study.rescore import (SCALE_NUDGE, _outside, _runs, exceedances, persistence_level,
                                   rescore)
from fdi_sim.study.stats import BANK, dispersion, exposure_s, overdispersed_rate, rate_ratio_interval
from fdi_sim.units import S_PER_H

__all__ = ["Calibration", "CALIBRATION_METHOD", "calibrate_threshold", "tail_calibrate_threshold", "CalibrationCheck", "check_calibration",
           "STUDY_METHOD", "bank_rate", "calibrate_study", "format_thresholds"]


# --- a threshold scale calibrated on a set of runs (was in fdi_sim.study.rescore) --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Calibration:
    """A threshold scale calibrated to a target false-alarm rate on a set of runs.

    Attributes
    ----------
    detector : str
        A member id or ``bank`` (every member at the same scale).
    target_per_h : float
        [1/h].
    scale : float
        The smallest threshold multiplier from which on the rate stays at or below the target on
        these runs [-].
    false_alarms : int
        At ``scale``.
    exposure_h : float
        Armed fault-free hours [h].
    far_per_h : float
        ``false_alarms / exposure_h`` [1/h].
    runs : int
    threshold_median : float
        Median over the runs of the logged threshold x scale [-] (the member's threshold; NaN for
        the bank).
    method : str
    """

    detector: str
    target_per_h: float
    scale: float
    false_alarms: int
    exposure_h: float
    far_per_h: float
    runs: int
    threshold_median: float
    method: str


CALIBRATION_METHOD = (
    "exact inversion of the false-alarm count: with z_j the k-th largest statistic/threshold in the persistence "
    "window ending at sample j, the alarm at scale s is z_j > s, so an onset at a fault-free sample j exists for s "
    "in [z_(j-1), z_j); the count is summed over these intervals as a step function of s and the scale is the "
    "lowest breakpoint from which on the count stays <= target x exposure (no bisection needed)")


def calibrate_threshold(records: Sequence[Mapping[str, Any]], out_dir: str | Path, detector: str,
                        target_per_h: float, *, k: int | None = None, n: int | None = None,
                        grace_s: float = LATE_GRACE_S) -> Calibration:
    """The threshold scale at which ``detector``'s false-alarm rate on these runs meets the target.

    The count ``N(s)`` of false alarms at scale ``s`` is a step function; the scale returned is
    the lowest ``s`` with ``N(s') <= target_per_h x exposure_h`` for every ``s' >= s`` (the
    rate is at most the target from there on), found exactly from its breakpoints
    (:data:`CALIBRATION_METHOD`, :func:`persistence_level`), then raised by :data:`SCALE_NUDGE`
    relative so that :func:`rescore` at it counts the same. With fewer than one false alarm
    allowed (``target x exposure < 1``) it is the scale just above the largest fault-free
    persistence level: the calibration then rests on one extreme, and held-out runs
    (:func:`check_calibration`) say how well.

    Parameters
    ----------
    records : sequence of mapping
        The runs to calibrate on (completed runs with a log count).
    out_dir : path
    detector : str
        A member id, or ``bank``.
    target_per_h : float
        False alarms per armed fault-free flight hour [1/h].
    k, n : int, optional
        Persistence (default: each run's own).
    """
    runs, _ = _runs(records, out_dir, k, n)
    lo, hi, expo, thr = [], [], 0.0, []
    used = 0
    for run in runs:
        ids = [d for d in run.record.get("detectors", []) if d in run.stats]
        if detector != BANK and detector not in ids:
            continue
        members = ids if detector == BANK else [detector]
        if not members:
            continue
        used += 1
        st0 = run.stats[members[0]]
        z = np.max([persistence_level(run.stats[m].statistic, run.stats[m].threshold, run.stats[m].valid, run.k, run.n)
                    for m in members], axis=0)  # the bank alarms when some member does
        if detector != BANK:
            thr.append(float(np.median(st0.threshold)))
        zprev = np.concatenate(([-np.inf], z[:-1]))
        elig = _outside(st0.t_s, run.record, grace_s) & (z > zprev)
        lo.append(zprev[elig])
        hi.append(z[elig])
        expo += exposure_s(run.record, grace_s)
    if not used:
        raise StudyError(str(out_dir), detector, f"no completed run with a log has {detector!r}",
                         "name a member of the study's bank, or 'bank'")
    a = np.sort(np.concatenate(lo)) if lo else np.zeros(0)
    b = np.sort(np.concatenate(hi)) if hi else np.zeros(0)
    expo_h = expo / S_PER_H
    allowed = target_per_h * expo_h
    pts = np.unique(np.concatenate((a[np.isfinite(a)], b[np.isfinite(b)])))
    if pts.size == 0:
        s_star, count = 0.0, 0
    else:
        # N(p) = #{a <= p} - #{b <= p}: onsets with a <= p < b (a < b always)
        N = np.searchsorted(a, pts, side="right") - np.searchsorted(b, pts, side="right")
        over = np.flatnonzero(N > allowed)
        if over.size == 0:
            s_star, count = float(pts[0]), int(N[0])
        else:
            i = over[-1] + 1  # N(p_top) = 0 <= allowed, so i is a breakpoint
            s_star, count = float(pts[i]), int(N[i])
        s_star *= 1.0 + SCALE_NUDGE
    return Calibration(detector, float(target_per_h), s_star, count, expo_h,
                       count / expo_h if expo_h > 0 else math.nan, used,
                       float(np.median(thr)) * s_star if thr else math.nan, CALIBRATION_METHOD)


def tail_calibrate_threshold(records: Sequence[Mapping[str, Any]], out_dir: str | Path, detector: str,
                             target_per_h: float, rng: np.random.Generator, *, level: float = 0.95,
                             k: int | None = None, n: int | None = None, grace_s: float = LATE_GRACE_S,
                             power: float | None = None, heavy: bool = True) -> Calibration:
    """The threshold scale at which ``detector``'s alarm *episodes* on these runs come at
    ``target_per_h``, from the tail of their peaks (:func:`fdi_sim.decision.tail.confident_episode_threshold`
    at its ``level`` bootstrap bound over whole runs), the method the bank's trained thresholds use.

    Why not the count (:func:`calibrate_threshold`): at a target of 0.02 per h a half of 200 runs of
    300 s (16.4 h) allows 0.33 false alarms, so the inverted count puts the threshold just above the
    half's largest peak, which the next 16 h exceed about once: measured on the shipped DHC-6 study
    (session 10), the flow-angle check 3 alarms in 16.4 h held out, 0.18 per h against 0.02, and
    the bank 5 (0.31 per h against 0.1). The tail fit extrapolates from about 100 episode peaks
    instead (and is the empirical level itself where the runs hold 10 or more episodes at the target).
    Runs whose statistics hold too few episodes for a fit fall back to the count, and the method
    says so.

    Parameters
    ----------
    records, out_dir, detector, k, n, grace_s
        As :func:`calibrate_threshold` (``detector`` a member id).
    target_per_h : float
        Alarm episodes per armed fault-free flight hour [1/h].
    rng : numpy.random.Generator
        The bootstrap's resampling.
    level : float
        Confidence of the bound.
    power, heavy
        The form of the member's statistic (its stream's ``tail_power``, None: chosen from the
        data; ``tail_heavy``), :func:`fdi_sim.decision.tail.episode_threshold`.
    """
    from fdi_sim.decision.tail import confident_episode_threshold
    from fdi_sim.errors import DesignError

    runs, _ = _runs(records, out_dir, k, n)
    series, hours, thr = [], [], []
    for run in runs:
        if detector not in run.record.get("detectors", []) or detector not in run.stats:
            continue
        st = run.stats[detector]
        z = persistence_level(st.statistic, st.threshold, st.valid, run.k, run.n)
        series.append(np.where(_outside(st.t_s, run.record, grace_s), z, -np.inf))  # fault windows: no false alarm
        hours.append(exposure_s(run.record, grace_s) / S_PER_H)
        thr.append(float(np.median(st.threshold)))
    if not series:
        raise StudyError(str(out_dir), detector, f"no completed run with a log has {detector!r}",
                         "name a member of the study's bank")
    try:
        s_star, how = confident_episode_threshold(series, target_per_h, hours, rng, level=level, power=power,
                                                  heavy=heavy)
    except DesignError as exc:
        cal = calibrate_threshold(records, out_dir, detector, target_per_h, k=k, n=n, grace_s=grace_s)
        return replace(cal, method=f"count (too few episodes for a tail fit: {exc}): {CALIBRATION_METHOD}")
    s_star *= 1.0 + SCALE_NUDGE
    count = int(rescore(list(records), out_dir, [s_star], k=k, n=n, grace_s=grace_s).detectors[detector].false_alarms[0])
    expo_h = float(sum(hours))
    return Calibration(detector, float(target_per_h), float(s_star), count, expo_h,
                       count / expo_h if expo_h > 0 else math.nan, len(series), float(np.median(thr)) * s_star,
                       f"episode tail of the runs' statistics/threshold, {level:.0%} bound over runs: {how}")


@dataclass(frozen=True)
class CalibrationCheck:
    """A calibration on one half of the runs, its rate on the other half.

    Attributes
    ----------
    calibration : Calibration
        On the calibration half.
    split : str
        ``even`` (calibrated on even run indices, checked on odd ones) or ``odd``.
    held_out_runs : int
    false_alarms : int
        On the held-out half at the calibrated scale.
    exposure_h : float
        Held-out armed fault-free hours [h].
    far_per_h : float
        [1/h].
    far_per_h_ci : tuple of float
        Exact Poisson interval [1/h], scaled by the held-out runs' dispersion where their false
        alarms cluster by run (:func:`fdi_sim.study.stats.overdispersed_rate`).
    target_inside : bool
        The target lies in the held-out interval.
    confidence : float
    dispersion : float or None
        Quasi-Poisson dispersion of the held-out per-run counts (1: Poisson; None: no alarm).
    far_per_h_ci_poisson : tuple of float
        The plain exact Poisson interval [1/h] (independent events).
    calibration_false_alarms : int
        On the calibration half at the calibrated scale (by the direct rule, like the held-out count).
    rate_ratio : float
        Held-out rate over the calibration half's rate at that scale [-].
    rate_ratio_ci : tuple of float
        Its exact conditional interval, scaled by the dispersion of the per-run counts of both
        halves (:func:`fdi_sim.study.stats.rate_ratio_interval`).
    ratio_check : str
        ``"consistent"``: 1 lies in ``rate_ratio_ci``, the held-out rate is what the calibration
        predicts; ``"inconsistent"``; ``"undetermined"`` when neither half has an alarm (0 against
        0 says nothing). This is the check that allows for the calibration's own sampling error
        (the threshold rests on the calibration half's few alarms); ``target_inside`` treats the
        threshold as exact.
    """

    calibration: Calibration
    split: str
    held_out_runs: int
    false_alarms: int
    exposure_h: float
    far_per_h: float
    far_per_h_ci: tuple[float, float]
    target_inside: bool
    confidence: float
    dispersion: float | None = None
    far_per_h_ci_poisson: tuple[float, float] | None = None
    calibration_false_alarms: int | None = None
    rate_ratio: float | None = None
    rate_ratio_ci: tuple[float, float] | None = None
    ratio_check: str | None = None


def per_run_false_alarms(records: Sequence[Mapping[str, Any]], out_dir: str | Path, detector: str, scale: float,
                         *, k: int | None = None, n: int | None = None,
                         grace_s: float = LATE_GRACE_S) -> tuple[int, list[int], list[float]]:
    """Run by run, ``detector``'s false alarms at ``scale`` x its logged threshold (the direct
    rule, :func:`rescore`): the runs that have it, and the count and armed fault-free hours [h] of
    each run with exposure. Run by run because a run's sampled turbulence, wind and biases make its
    false alarms cluster (measured on the DHC-6 attitude check: one run holds several), so rates
    get the dispersion-scaled Garwood interval (quasi-Poisson,
    :func:`fdi_sim.study.stats.overdispersed_rate`), which equals the plain one when phi <= 1."""
    n_runs, counts, expos = 0, [], []
    for r in records:
        dr = rescore([r], out_dir, [scale], k=k, n=n, grace_s=grace_s).detectors.get(detector)
        if dr is not None:
            n_runs += dr.runs
            if dr.exposure_h > 0:
                counts.append(int(dr.false_alarms[0]))
                expos.append(dr.exposure_h)
    return n_runs, counts, expos


def check_calibration(records: Sequence[Mapping[str, Any]], out_dir: str | Path, detector: str,
                      target_per_h: float, split: str = "even", *, confidence: float = 0.95,
                      k: int | None = None, n: int | None = None, grace_s: float = LATE_GRACE_S,
                      calibration: Calibration | None = None) -> CalibrationCheck:
    """Calibrate on the runs of even index (``split = "even"``; ``"odd"``: the other way) and
    give the other half's false-alarm rate at that scale with its exact Poisson interval, scaled by
    the held-out runs' dispersion (quasi-Poisson) where their alarms cluster by run, and the ratio
    of that rate to the calibration half's at the same scale with its exact conditional interval
    (``consistent``: the held-out rate is what the calibration predicts, allowing for the
    calibration's own sampling error).

    The held-out count is re-scored by the direct rule (:func:`rescore`), not by the
    calibration's own sweep, so the two halves share nothing but the scale. ``calibration``, when
    given, is that scale, made on the calibration half by another method
    (:func:`tail_calibrate_threshold`); by default :func:`calibrate_threshold`.
    """
    if split not in ("even", "odd"):
        raise ValueError(f"split must be 'even' or 'odd', got {split!r}")
    par = 0 if split == "even" else 1
    fit = [r for r in records if int(r["index"]) % 2 == par]
    held = [r for r in records if int(r["index"]) % 2 != par]
    cal = calibration if calibration is not None else \
        calibrate_threshold(fit, out_dir, detector, target_per_h, k=k, n=n, grace_s=grace_s)
    def per_run(rs: Sequence[Mapping[str, Any]]) -> tuple[int, list[int], list[float]]:
        return per_run_false_alarms(rs, out_dir, detector, cal.scale, k=k, n=n, grace_s=grace_s)

    runs, counts, expos = per_run(held)
    expo_h = float(sum(expos))
    if expo_h <= 0:
        raise StudyError(str(out_dir), detector, f"no held-out ({'odd' if par == 0 else 'even'}) completed run "
                         f"with a log has {detector!r}", "fly more runs")
    c = int(sum(counts))
    _, (lo, hi), phi = overdispersed_rate(counts, expos, confidence)
    plain = poisson_rate_interval(c, expo_h, confidence)
    # the threshold rests on the calibration half's own alarms (a few, at a low target): the
    # held-out rate is compared with that half's rate at the same scale, both counts uncertain
    _, c_counts, c_expos = per_run(fit)
    phi_both = dispersion(counts + c_counts, expos + c_expos)
    c_cal = int(sum(c_counts))
    rho, (r_lo, r_hi) = rate_ratio_interval(c_cal, float(sum(c_expos)), c, expo_h, confidence,
                                            phi_both if phi_both is not None else 1.0)
    return CalibrationCheck(cal, split, runs, c, expo_h, c / expo_h, (float(lo), float(hi)),
                            bool(lo <= target_per_h <= hi), confidence, phi, (float(plain[0]), float(plain[1])),
                            c_cal, float(rho), (float(r_lo), float(r_hi)),
                            "undetermined" if c == c_cal == 0 else "consistent" if r_lo <= 1.0 <= r_hi else "inconsistent")


# --- the thresholds file of a study ------------------------------------------------------------------
#: how the file's thresholds were made (the file's ``method``)
STUDY_METHOD = (
    "per member: the threshold at which the member's alarm episodes per armed fault-free flight hour on the "
    "calibration half come at far_per_h / members, from the tail of their peaks at its 95 % bootstrap bound over "
    "runs (fdi_sim.study.calibration.tail_calibrate_threshold: the trained thresholds' method, on the study's "
    "runs; the count where too few episodes), checked on the held-out half (exact Poisson interval, scaled by the "
    "runs' dispersion where their alarms cluster) and against the calibration half's own count (rate ratio, exact "
    "conditional interval: consistent when it holds 1, undetermined when neither half alarms); the bank: the OR of the members at those thresholds under "
    "the runs' k-of-n rule, against far_per_h (exact Poisson interval)")


def _rate(c: int, expo_h: float, runs: int, target: float, confidence: float) -> HeldRate:
    lo, hi = poisson_rate_interval(c, expo_h, confidence)
    return HeldRate(int(runs), int(c), float(expo_h), c / expo_h if expo_h > 0 else math.nan, (lo, hi),
                    rate_verdict(c, expo_h, target, confidence), detectable_ratio(expo_h, target, confidence))


def bank_rate(records: Sequence[Mapping[str, Any]], out_dir: str | Path, scales: Mapping[str, float], target_per_h: float,
              *, confidence: float = 0.95, grace_s: float = LATE_GRACE_S) -> HeldRate:
    """False alarms of the bank (OR of its members, each at ``logged threshold x scales[id]``,
    each run's own k-of-n rule) on these runs, with the exact Poisson interval."""
    runs, _ = _runs(records, out_dir, None, None)
    c, expo = 0, 0.0
    for run in runs:
        ids = [d for d in run.record.get("detectors", []) if d in run.stats]
        a = np.logical_or.reduce([k_of_n(exceedances(run.stats[d].statistic, run.stats[d].threshold,
                                                          run.stats[d].valid, np.array([scales[d]])), run.k, run.n)[0]
                                  for d in ids])
        onset = a & ~np.concatenate(([False], a[:-1]))
        c += int((onset & _outside(run.stats[ids[0]].t_s, run.record, grace_s)).sum())
        expo += exposure_s(run.record, grace_s)
    return _rate(c, expo / S_PER_H, len(runs), target_per_h, confidence)


def finished_study(out: Path, purpose: str) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """A study results folder's ``study.json`` and its run records, every run completed with a
    statistics log (``purpose`` words the refusal: "a calibration", "a validation").

    Raises
    ------
    StudyError
        Not a results folder, or a run not completed or without its log.
    """
    from fdi_sim.study.execute import load_records
    from fdi_sim.study.stats import completed

    fix = "fly the study to the end first (`fdi-sim study STUDY --out DIR`), with [output] statistics = true"
    try:
        meta = json.loads((out / "study.json").read_text())
    except (OSError, ValueError):
        raise StudyError(str(out), "study.json", "not a study results folder", fix) from None
    recs = load_records(out)
    done = completed(recs)
    if not done or len(done) != len(recs) or not all(r.get("log") for r in done):
        raise StudyError(str(out), "runs", f"{len(done)} of {len(recs)} runs completed"
                         f"{'' if all(r.get('log') for r in done) else ', some without a statistics log'}: "
                         f"{purpose} needs every run", fix)
    return meta, done


def calibrate_study(out_dir: str | Path, *, far_per_h: float | None = None, split: str = "even",
                    confidence: float = 0.95) -> StudyThresholds:
    """The thresholds a finished study gives its bank (module docstring).

    Parameters
    ----------
    out_dir : path
        The study's results folder (every run completed, with its statistics log).
    far_per_h : float, optional
        The bank's target rate [1/h] (default: the runs' ``[fdi] far_per_h``).
    split : str
        ``even`` (calibrate on even run indices) or ``odd``.
    confidence : float
        Of the Poisson intervals.

    Raises
    ------
    StudyError
        A folder that is not a finished study, runs without logs or not completed, runs at more
        than one design, a study flown with thresholds other than the trained ones.
    """
    from fdi_sim.scenario import load
    from fdi_sim.bank.members import design_hash
    from fdi_sim.training.thresholds import design_node, THRESHOLD_CONFIDENCE, thresholds_source
    from fdi_sim.sim.run import build_sensors
    from fdi_sim.training.build import build_loop_bank

    out = Path(out_dir)
    meta, done = finished_study(out, "a calibration")
    thr0 = done[0].get("thresholds")
    other = [r["index"] for r in done if r.get("thresholds") != thr0]
    if other:
        raise StudyError(str(out), f"runs/{other[0]:06d}.json", f"run {other[0]} flew other thresholds than run "
                         f"{done[0]['index']} (the study's runs span more than one design node)",
                         "calibrate a study at one node: [bank] design = { point = \"grid\", ... } with a "
                         "sampled point inside one grid cell")
    sc = load(out / "runs" / done[0]["scenario"])
    path, _ = thresholds_source(sc)
    if path is not None:
        raise StudyError(str(out), "bank.thresholds", f"the runs flew thresholds from {path}, not their "
                         "training flights", 'set [bank] thresholds = "trained" in the study file and fly it again')
    bank = build_loop_bank(sc, build_sensors(sc, sc.dt_s), progress=False)
    f = sc.model.fdi
    far = float(f.far_per_h if far_per_h is None else far_per_h)
    n_m = len(bank.members)
    members, scales = [], {}
    rng = np.random.default_rng(int(str(meta["identity"]), 16))  # the bootstrap: fixed by the study, reproducible
    fit_par = 0 if split == "even" else 1
    fit = [r for r in done if int(r["index"]) % 2 == fit_par]
    held = [r for r in done if int(r["index"]) % 2 != fit_par]
    # the calibration's own thresholds: the runs flew them times the schedule's noise cover
    # (fdi_sim.bank.turbulence.power_schedule), which the file's users get again when it is applied
    raw = {str(m["id"]): float(m["threshold"]) for m in (bank.calibration or {}).get("members", [])}
    for mem in bank.members:
        flown = mem.threshold
        trained = raw.get(mem.id, flown)
        logged = json.loads(thr0.replace("'", '"')) if isinstance(thr0, str) else dict(thr0 or {})
        if mem.id in logged and not math.isclose(float(logged[mem.id]), flown, rel_tol=1e-9):
            raise StudyError(str(out), f"runs/{done[0]['scenario']}", f"{mem.id}: the runs flew threshold "
                             f"{logged[mem.id]!r}, the bank rebuilt here has {flown!r} (another cache, version or "
                             "sensor suite)", "calibrate with the FDI_SIM_CACHE and fdi-sim version that flew the "
                             "study, or fly it again")
        target = member_far_per_h(far, n_m)
        cal = tail_calibrate_threshold(fit, out, mem.id, target, rng, level=THRESHOLD_CONFIDENCE,
                                       power=getattr(mem.stream, "tail_power", None),
                                       heavy=getattr(mem.stream, "tail_heavy", True))
        chk = check_calibration(done, out, mem.id, target, split, confidence=confidence, calibration=cal)
        scales[mem.id] = cal.scale
        members.append(StudyMemberThreshold(
            mem.id, trained * cal.scale, trained, cal.scale, target,
            _rate(cal.false_alarms, cal.exposure_h, cal.runs, target, confidence),
            HeldRate(chk.held_out_runs, chk.false_alarms, chk.exposure_h, chk.far_per_h,
                     (float(chk.far_per_h_ci[0]), float(chk.far_per_h_ci[1])),
                     interval_verdict(chk.far_per_h_ci, target), detectable_ratio(chk.exposure_h, target, confidence)),
            cal.method, float(chk.rate_ratio), (float(chk.rate_ratio_ci[0]), float(chk.rate_ratio_ci[1])),
            str(chk.ratio_check)))
    node = design_node(sc)
    bad = [r["index"] for r in done[1:] if design_node(load(out / "runs" / r["scenario"])) != node]
    if bad:
        raise StudyError(str(out), f"runs/{bad[0]:06d}.toml", f"run {bad[0]}'s bank is designed at another node than "
                         f"run {done[0]['index']}'s ({node})", "calibrate a study at one design node")
    flight_h = float(sum(float(r.get("flight_h", 0.0)) for r in done))
    return StudyThresholds(
        sc.aircraft, str(meta["name"]), str(meta["identity"]), len(done), flight_h, __version__,
        node["h_ft"], node["vc_kts"], node["turbulence"], node["wind_speed_kts"], node["noise_scale"],
        design_hash(bank), float(f.rate_hz), int(f.persistence_k), int(f.persistence_n), far, split, confidence,
        tuple(members), bank_rate(fit, out, scales, far, confidence=confidence),
        bank_rate(held, out, scales, far, confidence=confidence), STUDY_METHOD)


def format_thresholds(t: StudyThresholds) -> str:
    """A table of a thresholds file: per member its threshold and the two halves' rates."""
    def r(h: HeldRate) -> str:
        return (f"{h.false_alarms:3d} in {h.exposure_h:5.1f} h = {h.far_per_h:6.3g} [{h.ci_per_h[0]:.3g}, "
                f"{h.ci_per_h[1]:.3g}] {h.verdict}, sees {h.detectable_ratio:.2g} x")

    lines = [f"calibration study {t.study} ({t.study_identity}): {t.runs} runs, {t.flight_h:.1f} h, {t.aircraft} bank at "
             f"h {t.design_h_ft:g} ft, vc {t.design_vc_kts:g} kt, {t.design_turbulence} turbulence; target "
             f"{t.far_per_h:g} per h for the bank, {member_far_per_h(t.far_per_h, len(t.members)):.3g} per member; "
             f"calibrated on the {t.split} runs",
             f"{'member':26} {'trained':>10} {'study':>10} {'scale':>6}  {'calibration half':34}  held-out half"]
    for m in t.members:
        lines.append(f"{m.id:26} {m.trained_threshold:10.4g} {m.threshold:10.4g} {m.scale:6.3f}  "
                     f"{r(m.calibration):34}  {r(m.held_out)}; ratio to the calibration half "
                     f"[{m.rate_ratio_ci[0]:.3g}, {m.rate_ratio_ci[1]:.3g}] ({m.ratio_check})")
    lines.append(f"{'bank':26} {'':10} {'':10} {'':6}  {r(t.bank_calibration):34}  {r(t.bank_held_out)}")
    v = t.validation
    if v is None:
        lines.append("validation: none yet (fly a fresh study with --validate)")
    else:
        lines.append(f"validation on {v.study} ({v.study_identity}, seed {v.seed}): {v.runs} runs, {v.flight_h:.1f} h")
        for m in v.members:
            lines.append(f"{m.id:26} target {m.target_per_h:.3g}: {r(m.rate)}")
        lines.append(f"{'bank':26} target {t.far_per_h:.3g}: {r(v.bank)}")
    return "\n".join(lines)
