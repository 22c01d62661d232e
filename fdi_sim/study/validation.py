"""A thresholds file checked once on a fresh fault-free study: ``fdi-sim study STUDY --validate``.

The calibration study fits the file's thresholds (and checks them on its own other half, which
shares the study's conditions and whose verdict the calibration's method may already have
seen). The validation study flies the file as users get it, at the same conditions, on a master
seed from the seed registry's validation set (:mod:`fdi_sim.seeds`), and counts each member's
and the bank's alarm episodes per armed fault-free hour against its target: exact Poisson
interval (dispersion-scaled where alarms cluster by run), a verdict (contains, below, above) and
the smallest rate ratio those hours would have shown as above half the time
(:func:`fdi_sim.decision.intervals.detectable_ratio`). The result is written into the file's
``[validation]`` table.
"""
from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

from fdi_sim import __version__
from fdi_sim.bank.thresholds_file import (
    HeldRate,
    MemberRate,
    StudyThresholds,
    Validation,
    read_thresholds,
)
from fdi_sim.decision.intervals import detectable_ratio, interval_verdict
from fdi_sim.errors import StudyError
from fdi_sim.seeds import role_of

__all__ = ["validate_study"]


def validate_study(out_dir: str | Path, thresholds: str | Path | None = None) -> StudyThresholds:
    """The thresholds file the study's runs flew, with its ``validation`` from those runs.

    Parameters
    ----------
    out_dir : path
        A finished fault-free study's results folder (every run completed with its statistics log).
    thresholds : path, optional
        The file the runs flew (default: the file the first run's scenario names, or the shipped one).

    Raises
    ------
    StudyError
        Not a finished study; a seed outside the registry's validation sets; runs that flew other
        thresholds than the file's; runs with faults; the calibration study itself.
    """
    from fdi_sim.scenario import load
    from fdi_sim.study.calibration import bank_rate, finished_study, per_run_false_alarms
    from fdi_sim.study.stats import overdispersed_rate
    from fdi_sim.training.thresholds import thresholds_source

    out = Path(out_dir)
    meta, done = finished_study(out, "a validation")
    seed = int(meta["study"]["seed"])
    s = role_of(seed)
    if s is None or s.role != "validation":
        raise StudyError(str(out), "seed", f"the study's seed {seed} is "
                         f"{'not registered' if s is None else f'in the {s.role} set {s.name!r}'}: a validation needs "
                         "a fresh seed", "fly a study whose seed is in a validation set of fdi_sim/seeds.py")
    faulty = [r["index"] for r in done if r.get("faults")]
    if faulty:
        raise StudyError(str(out), f"runs/{faulty[0]:06d}.json", "a validation study flies no fault",
                         "remove the study's [[faults]]")
    sc = load(out / "runs" / done[0]["scenario"])
    path = Path(thresholds) if thresholds is not None else thresholds_source(sc)[0]
    if path is None:
        raise StudyError(str(out), "bank.thresholds", "the runs flew their training flights' thresholds, no file",
                         "fly the study with the thresholds file to validate ([bank] thresholds = FILE or the default)")
    t = read_thresholds(path)
    if t.study_identity == meta.get("identity"):
        raise StudyError(str(out), "study.json", f"this is the calibration study of {path} itself",
                         "validate on another study (a fresh seed)")
    want = {m.id: m.threshold for m in t.members}
    for r in done:
        flown = r.get("thresholds")
        flown = json.loads(flown.replace("'", '"')) if isinstance(flown, str) else dict(flown or {})
        bad = [k for k, v in want.items() if k not in flown or not math.isclose(float(flown[k]), v, rel_tol=1e-9)]
        if bad:
            raise StudyError(str(out), f"runs/{int(r['index']):06d}.json", f"run {r['index']} flew {bad[0]} at "
                             f"{flown.get(bad[0])!r}, the file {path} has {want[bad[0]]!r}",
                             "validate the file the runs flew (--validate FILE), or fly the study with it")
    conf = t.confidence
    members = []
    for m in t.members:
        _, counts, expos = per_run_false_alarms(done, out, m.id, 1.0)  # the file's thresholds as flown
        c, e = int(sum(counts)), float(sum(expos))
        _, ci, _ = overdispersed_rate(counts, expos, conf)
        v = interval_verdict(ci, m.target_per_h) if e > 0 else "undetermined"
        members.append(MemberRate(m.id, m.target_per_h, HeldRate(
            len(counts), c, e, c / e if e > 0 else math.nan, (float(ci[0]), float(ci[1])), v,
            detectable_ratio(e, m.target_per_h, conf))))
    b = bank_rate(done, out, {m.id: 1.0 for m in t.members}, t.far_per_h, confidence=conf)
    flight_h = float(sum(float(r.get("flight_h", 0.0)) for r in done))
    return replace(t, validation=Validation(str(meta["name"]), str(meta["identity"]), seed, len(done), flight_h, b,
                                            tuple(members), __version__))
