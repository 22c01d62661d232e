"""Scoring a benchmark results folder: every member and the bank, per split, from the runs' logs.

Per member, its ``/fdi/<id>/statistic`` topic gives the alarm, the score ``statistic / threshold``
(so that scores of differently scheduled thresholds rank on one scale; NaN where not valid) and the
isolation; the bank: the OR of the members' alarms, the largest member score, and at each sample the
isolation of the first member (in the log's order) that alarms and names one.

Which cases count: completed ones, and **departed** ones (status ``diverged``: the aircraft left the
envelope; its log is whole up to the departure, and a fault that departs the aircraft is the one a
detector most needs to catch), scored up to their end. Cases that were interrupted, timed out or
raised are listed with their status and not scored: their flight did not end by the physics.
The definitions are :mod:`fdi_sim.scoring`'s.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from fdi_sim.bench.errors import BenchError
from fdi_sim.bench.export import SCORED_STATUSES, case_truth
from fdi_sim.bench.run import SuiteStudy
from fdi_sim.scoring import CaseOutput, CaseTruth, score_suite
from fdi_sim.units import S_PER_H

BANK = "bank"
def case_outputs(log_path: Path) -> dict[str, CaseOutput]:
    """Per member id, and :data:`BANK`, the method's output on one flown case (module docstring)."""
    from fdi_sim.flightlog import read_log

    log = read_log(log_path)
    try:
        members = {m["id"]: m for m in json.loads(log.metadata.get("fdi", {}).get("members", "[]"))}
    except (TypeError, ValueError):
        members = {}
    out: dict[str, CaseOutput] = {}
    alarms, scores, isos = [], [], []
    t_ref = None
    for topic, data in log.topics.items():
        parts = topic.split("/")
        if not (len(parts) == 4 and parts[1] == "fdi" and parts[3] == "statistic"):
            continue
        ident = parts[2]
        t = np.asarray(data.t_s, dtype=float)
        alarm = np.asarray(data["alarm"]) > 0.5
        valid = np.asarray(data["valid"]) > 0.5
        with np.errstate(divide="ignore", invalid="ignore"):
            score = np.where(valid, np.asarray(data["statistic"], float) / np.asarray(data["threshold"], float), np.nan)
        hyps = members.get(ident, {}).get("hypotheses", [])
        k = np.asarray(data["isolation"]).astype(np.int64)
        iso = [hyps[j] if a and 0 <= j < len(hyps) else None for j, a in zip(k, alarm)]
        out[ident] = CaseOutput(t, alarm, score, iso)
        if t_ref is None or np.array_equal(t, t_ref):
            t_ref = t
            alarms.append(alarm)
            scores.append(score)
            isos.append(iso)
    if alarms and t_ref is not None:
        a = np.any(alarms, axis=0)
        with np.errstate(invalid="ignore"):
            s = np.nanmax(np.where(np.isnan(scores), -np.inf, scores), axis=0)
        s = np.where(np.isfinite(s), s, np.nan)
        iso_bank = [next((m[j] for m in isos if m[j] is not None), None) for j in range(len(t_ref))]
        out[BANK] = CaseOutput(t_ref, a, s, iso_bank)
    return out


@dataclass(frozen=True)
class BenchResult:
    """A scored benchmark run.

    Attributes
    ----------
    suite, suite_hash, bank : str
    cases : int
        Cases asked for.
    scored : dict
        Subset -> method (member id or ``bank``) -> the scorer's dict. Subsets: ``all``, each split
        present, ``aircraft:<aircraft>``, ``group:<group>``, ``phase:<phase>`` (the phase's fault-free
        flights), ``air:<aircraft>:<turbulence>`` and ``ended:<aircraft>:<completed|departed>`` (every
        case of the aircraft, by the air it flew in and by how its flight ended).
    not_scored : list of dict
        Cases interrupted, timed out or failed (case, status, reason): not scored.
    departed : list of dict
        Cases that departed (status ``diverged``; case, reason): scored up to the departure.
    flight_h : float
        Flight hours of the scored cases [h].
    """

    suite: str
    suite_hash: str
    bank: str
    cases: int
    scored: dict[str, dict[str, dict[str, Any]]]
    not_scored: list[dict[str, Any]]
    departed: list[dict[str, Any]]
    flight_h: float

    def to_dict(self) -> dict[str, Any]:
        return {"suite": self.suite, "suite_hash": self.suite_hash, "bank": self.bank, "cases": self.cases,
                "flight_h": self.flight_h, "not_scored": self.not_scored, "departed": self.departed,
                "scored": self.scored}


def score_folder(study: SuiteStudy, out_dir: str | Path) -> BenchResult:
    """Score the selected cases found in a results folder (every member and the bank, per split).

    Raises
    ------
    BenchError
        A selected case not flown yet (run ``bench run`` again), or a completed case without its log.
    """
    from fdi_sim.study.execute import load_records

    suite = study._suite
    out = Path(out_dir)
    recs = {int(r["index"]): r for r in load_records(out)}
    missing = [suite.cases[i].case for i in study.selected if i not in recs]
    if missing:
        raise BenchError(str(out), "", f"{len(missing)} selected case(s) are not flown yet (first {missing[:3]})",
                         "run the same `fdi-sim bench run` again: it flies only those")
    truths: list[CaseTruth] = []
    outputs: dict[str, dict[str, CaseOutput]] = {}
    bad, departed = [], []
    ended: dict[str, str] = {}  # case -> "completed" or "departed"
    for i in study.selected:
        r, case = recs[i], suite.cases[i]
        if r.get("status") not in SCORED_STATUSES:
            bad.append({"case": case.case, "status": r.get("status"), "reason": r.get("reason", "")})
            continue
        if not r.get("log"):
            raise BenchError(str(out / "runs" / f"{i:06d}.json"), "log", "a flown case without its statistics log",
                             "delete the record and run `fdi-sim bench run` again")
        if r["status"] == "diverged":
            departed.append({"case": case.case, "reason": r.get("reason", "")})
        ended[case.case] = "departed" if r["status"] == "diverged" else "completed"
        truths.append(case_truth(case, r))
        for ident, o in case_outputs(out / "runs" / r["log"]).items():
            outputs.setdefault(ident, {})[case.case] = o
    scored: dict[str, dict[str, dict[str, Any]]] = {}
    # "all", each split, and each aircraft (a default bank is one per aircraft: "aircraft:f16")
    subsets = {"all": truths} | {sp: [t for t in truths if t.split == sp] for sp in ("train", "validation", "test")}
    subsets |= {f"aircraft:{a}": [t for t in truths if t.aircraft == a] for a in sorted({t.aircraft for t in truths})}
    subsets |= {f"group:{g}": [t for t in truths if t.group == g] for g in dict.fromkeys(t.group for t in truths)}
    phase = {c.case: c.phase for c in suite.cases}
    subsets |= {f"phase:{p}": [t for t in truths if phase[t.case] == p and not t.windows_s]  # fault-free flights
                for p in dict.fromkeys(phase[t.case] for t in truths)}
    # per aircraft, by the air the case flew in and by how it ended: where a bank's false alarms are
    # (the bank is not told the turbulence level; a departed flight is scored up to its departure)
    air = {c.case: str(json.loads(c.params).get("atmosphere.turbulence", "")) for c in suite.cases}
    for a in sorted({t.aircraft for t in truths}):
        mine = [t for t in truths if t.aircraft == a]
        subsets |= {f"air:{a}:{lvl}": [t for t in mine if air[t.case] == lvl]
                    for lvl in ("none", "light", "moderate", "severe")}
        subsets |= {f"ended:{a}:{e}": [t for t in mine if ended[t.case] == e] for e in ("completed", "departed")}
    for sp, ts in subsets.items():
        if not ts:
            continue
        scored[sp] = {}
        for ident, outs in outputs.items():
            mine = [t for t in ts if t.case in outs]  # a member skipped at a design point has no output there
            if mine:
                scored[sp][ident] = score_suite(mine, outs) | {"cases_scored": len(mine), "cases_without": len(ts) - len(mine)}
    assert study.bank is not None
    return BenchResult(suite.name, suite.hash, study.bank.name, len(study.selected), scored, bad, departed,
                       sum(t.t_end_s for t in truths) / S_PER_H)
