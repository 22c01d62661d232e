"""A finished calibration study turned into a thresholds file the default bank can use.

The study flies the bank with its trained thresholds (``[bank] thresholds = "trained"``) at one
design node; every run logs each member's statistic (:mod:`fdi_sim.study.rescore`). Here each
member's threshold is calibrated, by exact inversion of the false-alarm count
(:func:`fdi_sim.study.rescore.calibrate_threshold`), to its share of the bank's rate,
``far_per_h / members`` (the split the trained thresholds use, a union bound), on the runs of
even index, and checked on the odd ones (:func:`fdi_sim.study.rescore.check_calibration`: exact
Poisson interval); the bank, the OR of its members at their calibrated thresholds under the
runs' own k-of-n rule, is checked against ``far_per_h`` on both halves. The result
(:class:`fdi_sim.sim.calibrate.StudyThresholds`) carries the study's name, identity hash, run
count and flight hours, the design node and :func:`fdi_sim.sim.bank_design.design_hash` of the
bank it holds thresholds for.
"""
from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from fdi_sim import __version__
from fdi_sim.decision.intervals import poisson_rate_interval
from fdi_sim.errors import StudyError
from fdi_sim.sim.bank import LATE_GRACE_S
from fdi_sim.sim.calibrate import HeldRate, StudyMemberThreshold, StudyThresholds
from fdi_sim.units import S_PER_H

#: how the file's thresholds were made (the file's ``method``)
STUDY_METHOD = (
    "per member: the threshold at which the member's false alarms per armed fault-free flight hour on the "
    "calibration half stay at or below far_per_h / members (exact inversion of the count, "
    "fdi_sim.study.rescore.calibrate_threshold), checked on the held-out half (exact Poisson interval); the bank: "
    "the OR of the members at those thresholds under the runs' k-of-n rule, against far_per_h")


def _trained_threshold(mem: Any) -> float:
    return float(mem.stream._thr[0]) if mem.kind == "gust" else float(mem.stream.threshold)


def _rate(c: int, expo_h: float, runs: int, target: float, confidence: float) -> HeldRate:
    lo, hi = poisson_rate_interval(c, expo_h, confidence)
    return HeldRate(int(runs), int(c), float(expo_h), c / expo_h if expo_h > 0 else math.nan, (lo, hi),
                    bool(lo <= target <= hi))


def bank_rate(records: Sequence[Mapping[str, Any]], out_dir: str | Path, scales: Mapping[str, float], target_per_h: float,
              *, confidence: float = 0.95, grace_s: float = LATE_GRACE_S) -> HeldRate:
    """False alarms of the bank (OR of its members, each at ``logged threshold x scales[id]``,
    each run's own k-of-n rule) on these runs, with the exact Poisson interval."""
    from fdi_sim.study.rescore import _outside, _runs, exceedances, persistence
    from fdi_sim.study.stats import exposure_s

    runs, _ = _runs(records, out_dir, None, None)
    c, expo = 0, 0.0
    for run in runs:
        ids = [d for d in run.record.get("detectors", []) if d in run.stats]
        a = np.logical_or.reduce([persistence(exceedances(run.stats[d].statistic, run.stats[d].threshold,
                                                          run.stats[d].valid, np.array([scales[d]])), run.k, run.n)[0]
                                  for d in ids])
        onset = a & ~np.concatenate(([False], a[:-1]))
        c += int((onset & _outside(run.stats[ids[0]].t_s, run.record, grace_s)).sum())
        expo += exposure_s(run.record, grace_s)
    return _rate(c, expo / S_PER_H, len(runs), target_per_h, confidence)


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
    from fdi_sim.sim.bank_design import design_hash, design_node, thresholds_source
    from fdi_sim.sim.run import build_loop_bank, build_sensors
    from fdi_sim.study.execute import load_records
    from fdi_sim.study.rescore import check_calibration
    from fdi_sim.study.stats import completed

    out = Path(out_dir)
    fix = "fly the study to the end first (`fdi-sim study STUDY --out DIR`), with [output] statistics = true"
    try:
        meta = json.loads((out / "study.json").read_text())
    except (OSError, ValueError):
        raise StudyError(str(out), "study.json", "not a study results folder", fix) from None
    recs = load_records(out)
    done = completed(recs)
    if not done or len(done) != len(recs) or not all(r.get("log") for r in done):
        raise StudyError(str(out), "runs", f"{len(done)} of {len(recs)} runs completed"
                         f"{'' if all(r.get('log') for r in done) else ', some without a statistics log'}: a "
                         "calibration needs every run", fix)
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
    fit_par = 0 if split == "even" else 1
    fit = [r for r in done if int(r["index"]) % 2 == fit_par]
    held = [r for r in done if int(r["index"]) % 2 != fit_par]
    for mem in bank.members:
        trained = _trained_threshold(mem)
        logged = json.loads(thr0.replace("'", '"')) if isinstance(thr0, str) else dict(thr0 or {})
        if mem.id in logged and not math.isclose(float(logged[mem.id]), trained, rel_tol=1e-9):
            raise StudyError(str(out), f"runs/{done[0]['scenario']}", f"{mem.id}: the runs flew threshold "
                             f"{logged[mem.id]!r}, the bank rebuilt here has {trained!r} (another cache, version or "
                             "sensor suite)", "calibrate with the FDI_SIM_CACHE and fdi-sim version that flew the "
                             "study, or fly it again")
        target = far / n_m
        chk = check_calibration(done, out, mem.id, target, split, confidence=confidence)
        cal = chk.calibration
        scales[mem.id] = cal.scale
        members.append(StudyMemberThreshold(
            mem.id, trained * cal.scale, trained, cal.scale, target,
            _rate(cal.false_alarms, cal.exposure_h, cal.runs, target, confidence),
            HeldRate(chk.held_out_runs, chk.false_alarms, chk.exposure_h, chk.far_per_h,
                     (float(chk.far_per_h_ci[0]), float(chk.far_per_h_ci[1])), chk.target_inside)))
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
                f"{h.ci_per_h[1]:.3g}]{'' if h.target_inside else ' (target outside)'}")

    lines = [f"calibration study {t.study} ({t.study_identity}): {t.runs} runs, {t.flight_h:.1f} h, {t.aircraft} bank at "
             f"h {t.design_h_ft:g} ft, vc {t.design_vc_kts:g} kt, {t.design_turbulence} turbulence; target "
             f"{t.far_per_h:g} per h for the bank, {t.far_per_h / max(1, len(t.members)):.3g} per member; "
             f"calibrated on the {t.split} runs",
             f"{'member':26} {'trained':>10} {'study':>10} {'scale':>6}  {'calibration half':34}  held-out half"]
    for m in t.members:
        lines.append(f"{m.id:26} {m.trained_threshold:10.4g} {m.threshold:10.4g} {m.scale:6.3f}  "
                     f"{r(m.calibration):34}  {r(m.held_out)}")
    lines.append(f"{'bank':26} {'':10} {'':10} {'':6}  {r(t.bank_calibration):34}  {r(t.bank_held_out)}")
    return "\n".join(lines)
