"""Members' thresholds: from the fault-free training flights, or from a calibration study's file.

Training flights: the bank's design false-alarm rate ``far_per_h`` is split evenly over its
members (a union bound), and each member's threshold is the level whose alarm episodes come
``far_per_h / members`` times per flight hour on the training flights: the k-of-n decision applied
exactly (:func:`fdi_sim.decision.tail.persistence_series`), the episodes' peaks fitted by a
generalized Pareto (or exponential) tail and extrapolated
(:func:`fdi_sim.decision.tail.episode_threshold`), taken at its 95 % bootstrap bound over the
training flights. Every member the same way, built in or plugin. A study's file
(:mod:`fdi_sim.bank.thresholds_file`) replaces them where it covers the bank's design.
"""
from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from fdi_sim import __version__
from fdi_sim.data import shown_path
from fdi_sim.errors import DesignError, ScenarioError
from fdi_sim.scenario import Scenario
from fdi_sim.bank.members import design_hash, member_far_per_h
from fdi_sim.bank.thresholds_file import DEFAULT_THRESHOLDS, shipped_thresholds_path
from fdi_sim.bank.turbulence import (
    NOISE_COVER, NOISE_EXPONENTS, REFERENCE_QUANTILE, TAU_S, EstimateSpec, estimate_spec, power_schedule,
    reference_sigma, turbulence_series,
)
from fdi_sim.training.schedule import design_scenario
from fdi_sim.units import S_PER_H


#: thresholds meet the per-sample target with this confidence (flight-level bootstrap)
THRESHOLD_CONFIDENCE = 0.95


def thresholds_source(sc: Scenario) -> tuple[Path | None, bool]:
    """Where ``[fdi] thresholds`` takes the thresholds from: a thresholds file (None: the training
    flights), and whether the scenario named it (a mismatch is then an error, not trained thresholds).

    Raises
    ------
    ScenarioError
        ``"shipped"`` for an aircraft without a shipped file.
    """
    mode = sc.model.fdi.thresholds
    explicit = mode != "default"
    if mode == "default":
        mode = DEFAULT_THRESHOLDS.get(sc.aircraft, "trained")
    if mode == "trained":
        return None, explicit
    if mode == "shipped":
        path = shipped_thresholds_path(sc.aircraft)
        if not path.is_file():
            if not explicit:
                return None, False
            raise ScenarioError(sc.source, "fdi.thresholds", f"no shipped thresholds file for the {sc.aircraft} "
                                f"({path} does not exist)", 'use thresholds = "trained", or give the path of a file '
                                "written by `fdi-sim study STUDY --calibrate OUT.toml`")
        return path, explicit
    # a relative path: beside the scenario file (its source, before any " (bank design at ...)"
    # suffix), else from the working directory; a missing file is reported by read_thresholds
    path = Path(mode)
    if not path.is_absolute() and not path.is_file():
        beside = Path(sc.source.split(" (")[0]).parent / path
        if beside.is_file():
            path = beside
    return path, True


def design_node(sc: Scenario) -> dict[str, Any]:
    """The bank's design conditions (of :func:`design_scenario`): node, turbulence, wind, noise scale."""
    from fdi_sim.training.schedule import initial_vc_kts

    d = design_scenario(sc)
    return {"h_ft": float(d.model.initial.h_ft), "vc_kts": round(float(initial_vc_kts(d)), 6),
            "turbulence": d.model.atmosphere.turbulence, "wind_speed_kts": float(d.model.atmosphere.wind_speed_kts),
            "noise_scale": float(d.model.sensors.noise_scale)}


def note_no_match(sc: Scenario, path: Path) -> str:
    n = design_node(sc)
    return (f"thresholds = \"default\": {shown_path(path)} does not cover this bank's design (h {n['h_ft']:g} ft, vc "
            f"{n['vc_kts']:g} kt, {n['turbulence']} turbulence): trained thresholds")


#: a thresholds file whose design hash differs from the bank's still covers it when every member's
#: trained threshold is within this relative distance of the file's: measured between two CPUs
#: (the file made on an AMD EPYC without FMA, the bank on an Intel Xeon with AVX-512 and FMA, the
#: same code): design hashes differ (libm and BLAS round differently, the turbulent training
#: flights diverge from their last bits), the five DHC-6 trained thresholds by 0.2-0.9 %
TRAINED_MATCH_REL = 0.05


def apply_study_thresholds(sc: Scenario, bank: Any, path: Path, *, explicit: bool = True,
                           retrain: Callable[[], Any] | None = None) -> str | None:
    """Set the members' thresholds from a thresholds file where it matches the bank (aircraft,
    design node, member ids, rate and k-of-n rule; then the design hash, or, on a machine that
    rounds differently, the members' trained thresholds within :data:`TRAINED_MATCH_REL` of the
    file's, from ``retrain()``, which sets them on the bank); record the method per member.

    The calibrated thresholds describe the members' fault-free statistics, so the trained
    thresholds (the same statistics' tails on the bank's own training flights) are the test of
    whether the file still describes this bank: a bit-exact design hash ties a file to the CPU
    that made it.

    Returns None (nothing set) for a mismatch when ``explicit`` is False (``thresholds = "default"``).

    Raises
    ------
    ScenarioError
        A mismatch when the scenario named the file (``explicit``): names the file, the key, what
        differs and the fix.
    """
    from fdi_sim.bank.thresholds_file import read_thresholds

    t = read_thresholds(path)
    f = sc.model.fdi
    node = design_node(sc)
    want = {"aircraft": (t.aircraft, sc.aircraft),
            "design node": ((t.design_h_ft, t.design_vc_kts, t.design_turbulence, t.design_wind_speed_kts,
                             t.design_noise_scale),
                            (node["h_ft"], node["vc_kts"], node["turbulence"], node["wind_speed_kts"],
                             node["noise_scale"])),
            "members": ([m.id for m in t.members], [m.id for m in bank.members]),
            "decision": ((t.rate_hz, t.persistence_k, t.persistence_n),
                         (float(f.rate_hz), f.persistence_k, f.persistence_n))}
    bad = [(k, a, b) for k, (a, b) in want.items() if (round(a, 6) if isinstance(a, float) else a) !=
           (round(b, 6) if isinstance(b, float) else b)]
    matched = "design hash"
    if not bad:
        h = design_hash(bank)
        if h != t.design_hash:
            bad = [("design hash", t.design_hash, h)]
            if retrain is not None:
                retrain()
                rel = [abs(mem.threshold - m.trained_threshold) / abs(m.trained_threshold)
                       for mem, m in zip(bank.members, t.members)]
                worst = int(np.argmax(rel))
                if rel[worst] <= TRAINED_MATCH_REL:
                    bad = []
                    matched = (f"trained thresholds within {rel[worst]:.2%} of the file's (design hash {h}, the "
                               f"file's {t.design_hash}: another CPU's rounding, or a design change too small to move them)")
                else:
                    bad = [(f"{t.members[worst].id} trained threshold", t.members[worst].trained_threshold,
                            f"{bank.members[worst].threshold} ({rel[worst]:.1%} apart, more than "
                            f"{TRAINED_MATCH_REL:.0%}; design hash {h}, the file's {t.design_hash})")]
    if bad:
        if not explicit:
            return None
        k, a, b = bad[0]
        raise ScenarioError(sc.source, "fdi.thresholds", f"the thresholds file {path} does not match this bank: its "
                            f"{k} is {a}, the bank's is {b} (the file holds thresholds of study {t.study}'s bank, "
                            f"designed at h {t.design_h_ft:g} ft, vc {t.design_vc_kts:g} kt, {t.design_turbulence} "
                            "turbulence)", 'use thresholds = "trained" (the bank\'s own training flights), set [fdi.design] '
                            f"to the file's design (e.g. design = {{ point = \"grid\", turbulence = \"{t.design_turbulence}\" }} "
                            "at a point of that node), or calibrate a study at this bank's design with "
                            "`fdi-sim study STUDY --calibrate OUT.toml`")
    rec = {"source": "study", "file": shown_path(path), "study": t.study, "study_identity": t.study_identity,
           "runs": t.runs, "flight_h": t.flight_h, "design_hash": t.design_hash, "far_per_h": t.far_per_h,
           "matched_by": matched, "members": []}
    for mem, m in zip(bank.members, t.members):
        mem.set_threshold(float(m.threshold))
        rec["members"].append({"id": m.id, "threshold": m.threshold, "method": t.member_method(m.id),
                               "trained_threshold": m.trained_threshold})
    bank.calibration = rec
    bank.keep_trace(False)
    bank.reset()
    return rec["members"][0]["method"] if rec["members"] else ""


# --- thresholds from the training flights ---------------------------------------------------------
def _cache_path(key: str) -> Path:
    from fdi_sim.training.cache import cache_dir

    return cache_dir() / f"bank-{key}.json"


def _thresholds_key(sc: Scenario, bank: Any, p: float) -> str:
    from fdi_sim.decision.tail import TAIL_METHOD
    from fdi_sim.detectors.stream import stream_design_key
    from fdi_sim.training.cache import training_scenario_json

    f = sc.model.fdi
    ff = training_scenario_json(sc, f.calibration_duration_s, drop=("name", "description", "fdi"))
    h = hashlib.sha256()
    for mem in bank.members:
        h.update(mem.id.encode())
        h.update(stream_design_key(mem.stream))
    blob = json.dumps({"scenario": ff, "p": p, "arm_s": f.arm_s, "confidence": THRESHOLD_CONFIDENCE, "n": f.calibration_flights, "T": f.calibration_duration_s,
                       "decision": [f.persistence_k, f.persistence_n], "method": f"episodes-v5-{TAIL_METHOD}-ref-{_signal(sc)}", "version": __version__,
                       "members": h.hexdigest()},
                      sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:24]


def _signal(sc: Scenario) -> str | None:
    spec = estimate_spec(sc.aircraft)
    return None if spec is None else spec.signal


def _thresholds_atlas_key(sc: Scenario, bank: Any, p: float) -> tuple[str, list[list[float]]]:
    """The atlas key of the members' thresholds (:func:`_thresholds_key` with each member's design
    bits replaced: a member whose stream gives ``design_arrays()`` by its ``design_key_exact()`` and a
    fingerprint of the arrays, :mod:`fdi_sim.training.atlas`; any other by its design key) and the
    fingerprint."""
    from fdi_sim.decision.tail import TAIL_METHOD
    from fdi_sim.detectors.stream import stream_design_key
    from fdi_sim.training.atlas import fingerprint, inputs_key
    from fdi_sim.training.cache import training_scenario_json

    f = sc.model.fdi
    ff = training_scenario_json(sc, f.calibration_duration_s, drop=("name", "description", "fdi"))
    members, fp = [], []
    for mem in bank.members:
        arrays = getattr(mem.stream, "design_arrays", None)
        if arrays is not None:
            members.append([mem.id, mem.stream.design_key_exact().decode()])
            fp.extend(fingerprint(arrays()))
        else:
            members.append([mem.id, hashlib.sha256(stream_design_key(mem.stream)).hexdigest()])
    return inputs_key({"scenario": ff, "p": p, "arm_s": f.arm_s, "confidence": THRESHOLD_CONFIDENCE,
                       "n": f.calibration_flights, "T": f.calibration_duration_s,
                       "decision": [f.persistence_k, f.persistence_n], "method": f"episodes-v5-{TAIL_METHOD}",
                       "version": __version__, "members": members, "rate_hz": bank.rate_hz,
                       "meas": list(bank.meas_names)}), fp


class MemberThresholdError(DesignError):
    """One member's threshold cannot be set on the training flights (``member`` names it)."""

    def __init__(self, member: str, source: str, reason: str) -> None:
        super().__init__(f"{source}: {reason}")
        self.member, self.reason = member, reason  # the reason without the source: a cached refusal is said
        # again with the source of the scenario that meets it


def calibrate_thresholds(sc: Scenario, bank: Any, p: float, *, training_logs: Sequence[Any] | None = None,
                         progress: bool = True, use_cache: bool = True) -> dict[str, Any]:
    """Set each member's threshold from its statistic on the fault-free training flights (the same
    flights the filters were calibrated on): the level of ``far_per_h / members`` alarm episodes per
    flight hour under the bank's k-of-n rule (module docstring); for the angle-magnitude rule, and
    where the flights hold too few episodes to fit, the ``1 - p`` per-sample quantile.

    Returns the record stored in the cache (thresholds, method, training samples per member).
    """
    from fdi_sim.training.atlas import lookup as atlas_lookup, record as atlas_record
    from fdi_sim.training.cache import cache_lock, read_entry, write_entry

    key = _thresholds_key(sc, bank, p)
    path = _cache_path(key)
    with cache_lock(path, use_cache):  # another process computing this entry: wait, then read it
        rec = read_entry(path, use_cache)
        try:
            if rec is not None and [r["id"] for r in rec["members"]] != [m.id for m in bank.members]:
                rec = None
            if rec is not None and rec.get("refused"):  # a member without a threshold, found by an earlier
                r = rec["refused"]  # build: said again, not replayed again
                raise MemberThresholdError(str(r["member"]), sc.source, str(r["reason"]))
        except (KeyError, TypeError, AttributeError):
            rec = None  # a damaged entry is recomputed
        akey, afp = _thresholds_atlas_key(sc, bank, p)
        if rec is None and use_cache:  # the shipped atlas: the same entry, made by the project
            hit, _ = atlas_lookup(sc.aircraft, "bank", akey, afp)
            if hit is not None and [r.get("id") for r in hit["entry"].get("members", [])] == [m.id for m in bank.members]:
                rec = {**hit["entry"], "atlas": hit["atlas"]}  # not copied to the cache: the atlas may be remade
        if rec is None:
            try:
                rec = _calibrated(sc, bank, p, training_logs, progress)
            except MemberThresholdError as exc:  # kept, so the next build of this bank does not replay again
                write_entry(path, {"members": [{"id": m.id} for m in bank.members],
                                   "refused": {"member": exc.member, "reason": exc.reason}}, use_cache)
                raise
            write_entry(path, rec, use_cache)
    atlas_record("bank", akey, afp, {k: v for k, v in rec.items() if k != "atlas"})
    for mem, r in zip(bank.members, rec["members"]):
        mem.set_threshold(float(r["threshold"]))
    bank.set_schedule(None)  # apply_turbulence_schedule sets the one these thresholds have
    bank.calibration = rec
    bank.keep_trace(False)  # the replays kept every block; a flight must not
    bank.reset()
    return rec


def _calibrated(sc: Scenario, bank: Any, p: float, training_logs: Sequence[Any] | None,
                progress: bool) -> dict[str, Any]:
    """:func:`calibrate_thresholds`'s cache record, computed: the bank replayed over the training
    flights (flown here when not given) and each member's threshold fitted.

    Raises
    ------
    MemberThresholdError
        A member with fewer than two valid samples, or without a finite threshold.
    """
    from fdi_sim.decision.tail import confident_episode_threshold, confident_tail_threshold, persistence_series
    from fdi_sim.training.flights import fly_training, training_seeds

    f = sc.model.fdi
    logs = training_logs
    if logs is None:
        logs = fly_training(sc, training_seeds(f.calibration_flights), f.calibration_duration_s, progress=progress)
    src, logs = logs, list(logs)
    departed = tuple(getattr(src, "departed", ()))  # flights replaced by spares (fly_training)
    d = bank.decision
    episodes = d.rule == "persistence"  # the angle rule's exceedance also needs a direction
    stats: list[list[np.ndarray]] = [[] for _ in bank.members]
    series: list[list[np.ndarray]] = [[] for _ in bank.members]
    hours: list[list[float]] = [[] for _ in bank.members]
    for lg in logs:
        _replay_log(bank, lg, raw_thresholds=True)
        for i, mem in enumerate(bank.members):
            st, ok = mem.trace_series()
            stats[i].append(st[ok])
            if episodes:
                series[i].append(persistence_series(st, ok, d.k, d.n))
                hours[i].append(float(ok.sum()) / (float(f.rate_hz) * S_PER_H))
    rate = member_far_per_h(f.far_per_h, len(bank.members))
    rec = {"p_per_sample": p, "episodes_per_h": rate if episodes else None,
           "confidence": THRESHOLD_CONFIDENCE, "members": []}
    if departed:
        rec["training_departed"] = [[int(seed), str(reason)] for seed, reason in departed]
    rng = np.random.default_rng(0)  # the bootstrap's resampling: fixed, so a calibration is reproducible
    for i, (mem, s) in enumerate(zip(bank.members, stats)):
        s = [x[np.isfinite(x)] for x in s]
        x = np.concatenate(s)
        if x.size < 2:
            raise MemberThresholdError(mem.id, sc.source, f"{mem.id} gave {x.size} valid statistic samples on its "
                              f"{len(logs)} fault-free training flights (armed from {f.arm_s:g} s): no "
                              "threshold can be set; its design does not settle on this aircraft")
        if episodes:
            try:
                thr, method = confident_episode_threshold(series[i], rate, hours[i], rng,
                                                          level=THRESHOLD_CONFIDENCE,
                                                          power=getattr(mem.stream, "tail_power", None),
                                                          heavy=getattr(mem.stream, "tail_heavy", True))
            except DesignError as e:  # short training flights: too few episodes to fit
                thr, method = confident_tail_threshold(s, p, rng, level=THRESHOLD_CONFIDENCE)
                method = f"per-sample ({e}): {method}"
        else:
            thr, method = confident_tail_threshold(s, p, rng, level=THRESHOLD_CONFIDENCE)
        if not math.isfinite(thr):  # a statistic that diverges on fault-free flights has no level
            raise MemberThresholdError(mem.id, sc.source, f"{mem.id} has no finite threshold on its "
                                       f"{len(logs)} fault-free training flights ({method}; statistic up "
                                       f"to {float(x.max()):.3g}): it diverges on this aircraft here")
        rec["members"].append({"id": mem.id, "threshold": thr, "method": method, "samples": int(x.size),
                               "max_training": float(x.max()) if x.size else None})
    spec = estimate_spec(sc.aircraft)
    if spec is not None and spec.signal in bank.meas_names:  # where rougher air begins (power_schedule)
        rec["turbulence_reference"] = turbulence_reference(bank, logs, f"{len(logs)} training flights", spec)
    return rec


def _replay_log(bank: Any, log: Any, *, raw_thresholds: bool = False) -> None:
    """Run the bank over a log's rows (trace kept per member)."""
    from fdi_sim.flightlog import TOPIC_COMMANDS, TOPIC_SENSORS, TOPIC_SENSORS_VALID

    cmd = log.topics[TOPIC_COMMANDS]
    meas = log.topics[TOPIC_SENSORS]
    K = min(len(cmd.t_s), len(meas.t_s))
    u = np.column_stack([cmd[nm][:K] for nm in bank.cmd_names])
    y = np.column_stack([meas[nm][:K] for nm in bank.meas_names])
    valid = None
    if TOPIC_SENSORS_VALID in log.topics:
        vt = log.topics[TOPIC_SENSORS_VALID]
        valid = np.column_stack([vt[nm][:K] > 0.5 if nm in vt.fields else np.ones(K, bool) for nm in bank.meas_names])
    if raw_thresholds:
        bank.set_schedule(None)  # the statistic itself, at no threshold
    bank.reset()
    bank.keep_trace(True)
    if raw_thresholds:
        for mem in bank.members:
            mem.set_threshold(np.inf)
    dt = float(np.median(np.diff(np.asarray(meas.t_s[:K]))))
    bank.replay(u, y, valid, dt, t_rows_s=np.asarray(meas.t_s[:K], dtype=float))



def sample_signal(bank: Any, log: Any, name: str) -> tuple[np.ndarray, np.ndarray]:
    """A measurement at the bank's samples of a log, and whether each is usable: the rows
    :func:`_replay_log` gives the bank (``FdiBank.replay``: every ``n``-th row from the ``n``-th)."""
    from fdi_sim.flightlog import TOPIC_COMMANDS, TOPIC_SENSORS, TOPIC_SENSORS_VALID

    meas = log.topics[TOPIC_SENSORS]
    K = min(len(log.topics[TOPIC_COMMANDS].t_s), len(meas.t_s))
    rows = bank.n * np.arange(1, (K - 1) // bank.n + 1)
    z = np.asarray(meas[name][:K], dtype=float)[rows]
    ok = np.isfinite(z)
    if TOPIC_SENSORS_VALID in log.topics and name in log.topics[TOPIC_SENSORS_VALID].fields:
        ok &= np.asarray(log.topics[TOPIC_SENSORS_VALID][name][:K])[rows] > 0.5
    return z, ok


def turbulence_reference(bank: Any, logs: Sequence[Any], flights: str, spec: EstimateSpec) -> dict[str, Any]:
    """The turbulence estimate's reference on flights at the design conditions
    (:func:`fdi_sim.bank.turbulence.reference_sigma`; the aircraft's ``spec``), as a thresholds record
    keeps it."""
    series = [turbulence_series(*sample_signal(bank, lg, spec.signal), bank.rate_hz, spec.clip) for lg in logs]
    return {"signal": spec.signal, "tau_s": TAU_S, "clip": spec.clip, "quantile": REFERENCE_QUANTILE,
            "sigma_ref": reference_sigma(series, bank.arm_samples), "flights": flights}


def apply_turbulence_schedule(sc: Scenario, bank: Any, p: float) -> str:
    """Raise the members' thresholds with the estimated turbulence above their calibration's
    (:func:`fdi_sim.bank.turbulence.power_schedule`), from the reference the thresholds record
    keeps, or for a study's file the atlas's record of the same design; a note for the log ("" when
    none applies: no reference, a schedule already set, or no such measurement)."""
    from fdi_sim.training.atlas import lookup as atlas_lookup

    cal = bank.calibration or {}
    spec = estimate_spec(sc.aircraft)
    if bank.schedule is not None or spec is None or spec.signal not in bank.meas_names:
        return ""
    ref = cal.get("turbulence_reference")
    if ref is None and cal.get("source") == "study":
        akey, afp = _thresholds_atlas_key(sc, bank, p)
        hit, _ = atlas_lookup(sc.aircraft, "bank", akey, afp)
        ref = hit["entry"].get("turbulence_reference") if hit is not None else None
    if ref is None:
        return ""
    if ref.get("signal") != spec.signal or "sigma_ref" not in ref:
        raise DesignError(f"the turbulence reference of this bank's calibration ({cal.get('source', '?')}) is of "
                          f"{ref.get('signal')!r}, the schedule needs {spec.signal!r}: made by older code; make "
                          f"the atlas's references again: python -m fdi_sim.study.atlas {sc.aircraft} "
                          "--turbulence-reference-only (a trained bank retrains on its own)")
    sch = power_schedule({m.id: m.threshold for m in bank.members}, float(ref["sigma_ref"]), spec)
    if sch is None:
        return ""
    bank.set_schedule(sch)
    cover = {k: NOISE_COVER ** NOISE_EXPONENTS[k] for k in sch.thresholds if NOISE_EXPONENTS.get(k, 0.0) > 0}
    note = (f"thresholds raised as (sigma / {float(ref['sigma_ref']):.3g})^gamma above the {spec.signal} increments' "
            f"reference ({ref.get('flights', '')}; gamma " + ", ".join(
                f"{k} {float(np.log(v[1] / v[0]) / np.log(sch.sigma[1] / sch.sigma[0])):g}"
                for k, v in sch.thresholds.items()) + f"); sensor noise up to {NOISE_COVER:g} x the calibration's "
            "covered: " + ", ".join(f"{k} x {v:.3g}" for k, v in cover.items()))
    bank.calibration = {**cal, "turbulence": {**sch.to_dict(), "reference": ref, "noise_cover": NOISE_COVER,
                                              "noise_factors": cover, "note": note}}
    return note
