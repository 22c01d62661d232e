"""``fdi-sim bench run``: fly (or reuse) a suite's cases with a bank, then score every member and the bank.

A benchmark run is a study whose runs are the suite's cases (:class:`SuiteStudy`), flown by
:func:`fdi_sim.study.execute.fly_study` on Dask into one results folder: a run is done when its record
is there, so an interrupted run resumes without flying a case twice, and a later call with more
cases (``--split``, ``--group``, ``--per-group``) adds only the missing ones. The folder's identity
is the suite's hash and the bank (:meth:`SuiteStudy.identity`): another bank needs another folder.

What flies. ``--bank default``: the aircraft's default bank in the loop, with reconfiguration,
designed per schedule-grid node at moderate turbulence (the envelope studies' design: the bank is
not told the case's air). ``--detector ID ...``: those registered (or plugin) detectors side by
side, thresholds trained at the same design points, reconfiguration off, so that each member sees
the same flight as it would alone and is scored as its own method.

Scoring the folder: :mod:`fdi_sim.bench.score` (this module is what the flights depend on).
"""
from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from fdi_sim.bench.errors import BenchError
from fdi_sim.data import shown_path
from fdi_sim.bench.suite import Case, Suite
from fdi_sim.study.spec import OutputSection, Study, StudyModel

#: the default bank's design: per schedule-grid node at nominal conditions, moderate turbulence
DESIGN = {"point": "grid", "turbulence": "moderate", "wind_speed_kts": 0.0, "noise_scale": 1.0}
#: wall-clock limit of one case [s] (a per-sample Python detector on a 600 s flight needs minutes)
TIME_LIMIT_S = 3600.0


@dataclass(frozen=True)
class BenchBank:
    """What flies in the loop: the default bank, or detectors side by side.

    Attributes
    ----------
    name : str
        ``default`` or ``detectors:<id>+<id>``.
    fdi : dict
        The cases' ``[fdi]`` section.
    detectors : tuple of dict
        Their ``[[detectors]]`` entries.
    """

    name: str
    fdi: Mapping[str, Any]
    detectors: tuple[Mapping[str, Any], ...] = ()

    @property
    def slug(self) -> str:
        """The name as a file name (``detectors-parity-v1.pca-v1``, options kept as ``key-value``)."""
        import re

        return re.sub(r"[^A-Za-z0-9_.\-]+", "-", self.name.replace("+", ".")).strip("-")

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "fdi": dict(self.fdi), "detectors": [dict(d) for d in self.detectors]}


def bench_bank(default: bool = True, detector_ids: Sequence[str] = ()) -> BenchBank:
    """The bank of ``--bank default`` or of ``--detector ID ...`` (ids checked, "did you mean").

    Raises
    ------
    BenchError
        An unknown detector id, or both or neither given.
    """
    from fdi_sim import registry
    from fdi_sim.errors import RegistryError, ScenarioError

    if bool(default) == bool(detector_ids):
        raise BenchError("fdi-sim bench run", "--bank / --detector", "give the default bank or detectors, not both",
                         "--bank default, or --detector ID (repeatable; `fdi-sim plugins` lists them)")
    if default:
        return BenchBank("default", {"bank": "default", "far_per_h": 0.1, "design": dict(DESIGN)})
    from fdi_sim.detectors.spec import check_options, parse_detector_arg

    specs = [parse_detector_arg(d) for d in dict.fromkeys(detector_ids)]  # ID[:key=value,...]
    for spec in specs:
        try:
            registry.get("detector", spec.id)
            check_options(spec)
        except RegistryError as exc:
            raise BenchError("fdi-sim bench run", "--detector", str(exc).strip("'\""),
                             "give a registered detector id (`fdi-sim plugins`)") from None
        except ScenarioError as exc:
            raise BenchError("fdi-sim bench run", f"--detector {spec.id}", exc.problem, exc.fix) from None
    ids = [s.id + (":" + ",".join(f"{k}={json.dumps(v)}" for k, v in sorted(s.params.items())) if s.params else "")
           for s in specs]
    fdi = {"bank": "none", "far_per_h": 0.1, "thresholds": "trained", "reconfigure": False,
           "on_design_failure": "skip", "design": dict(DESIGN)}
    return BenchBank("detectors:" + "+".join(ids), fdi, tuple({"type": s.id, **dict(s.params)} for s in specs))


@dataclass(frozen=True)
class SuiteStudy(Study):
    """A suite's cases as the runs of a study (the executor flies :meth:`run_indices`)."""

    suite: Suite | None = None
    bank: BenchBank | None = None
    selected: tuple[int, ...] = field(default=())

    @property
    def n_runs(self) -> int:
        return len(self._suite.cases)

    @property
    def _suite(self) -> Suite:
        assert self.suite is not None and self.bank is not None
        return self.suite

    def run_indices(self) -> tuple[int, ...]:
        return self.selected

    def run_duration_s(self, index: int) -> float:
        return self._suite.cases[index].duration_s

    def identity(self) -> str:
        """The suite's hash, the bank and the code version: a folder holds the cases of one of each."""
        from fdi_sim import __version__

        d = {"suite": self._suite.hash, "bank": self.bank.to_dict() if self.bank else None, "version": __version__}
        if self.model.output.full_logs:  # (only then: folders of statistics logs keep their identity)
            d["full_logs"] = True
        blob = json.dumps(d, sort_keys=True)
        return hashlib.sha256(blob.encode()).hexdigest()[:20]

    def run_scenario(self, index: int) -> tuple[Any, dict[str, Any]]:
        from fdi_sim.scenario.loader import from_dict

        case = self._suite.cases[index]
        data = json.loads(case.scenario_json)
        assert self.bank is not None
        data["fdi"] = {**self.bank.fdi, "log_residuals": False}
        # the design trains on the phase's whole maneuver list, not the case's (cut at its end): a case
        # shorter than the training flights would otherwise be designed apart from its phase's longer cases
        data["fdi"]["design"] = {**dict(self.bank.fdi.get("design", {})),
                                 "maneuvers": phase_maneuvers(self._suite, case.group, case.phase)}
        data["detectors"] = [dict(d) for d in self.bank.detectors]
        data["log"] = {"per_step": bool(self.model.output.full_logs)}  # the 120 Hz topics too (export)
        sc = from_dict(data, source=f"{shown_path(self._suite.source)} case {case.case}")  # no checkout path in a log
        return sc, {"case": case.case, **json.loads(case.params)}


def phase_maneuvers(suite: Suite, group: str, phase: str) -> list[dict[str, Any]]:
    """The maneuvers of ``group``'s cases in ``phase`` before the suite cut them at a case's end: the
    phase's base scenario's, then the group's (the order of :func:`fdi_sim.bench.suite._case`)."""
    key = (suite.source, suite.hash, group, phase)
    if key not in _PHASE_MANEUVERS:
        from fdi_sim.scenario import load
        from fdi_sim.study.spec import resolve_scenario

        base = json.loads(load(resolve_scenario(suite.model.phases[phase].scenario, Path(suite.source).parent)).to_json())
        g = next(x for x in suite.model.groups if x.name == group)
        _PHASE_MANEUVERS[key] = list(base.get("maneuvers", [])) + [dict(m) for m in g.maneuvers]
    return [dict(m) for m in _PHASE_MANEUVERS[key]]


#: (suite, hash, group, phase) -> maneuvers (a study worker builds many cases of few phases)
_PHASE_MANEUVERS: dict[tuple[str, str, str, str], list[dict[str, Any]]] = {}


def suite_study(suite: Suite, bank: BenchBank, cases: Sequence[Case], *, full_logs: bool = False) -> SuiteStudy:
    """The study that flies ``cases`` of ``suite`` with ``bank`` (``full_logs``: the 120 Hz topics too,
    what a learned detector trains on; a folder of its own)."""
    if not cases:
        raise BenchError(suite.source, "--split / --group", "the selection holds no case",
                         "widen it (`fdi-sim bench list` shows the groups and splits)")
    model = StudyModel(kind="study", name=f"{suite.name}.{bank.slug}"[:100],
                       description=f"{suite.name} flown with {bank.name}", scenario="(suite)", seed=suite.model.seed,
                       runs=len(suite.cases), duration_s=max(c.duration_s for c in suite.cases),
                       time_limit_s=TIME_LIMIT_S, bank=dict(bank.fdi),
                       output=OutputSection(statistics=True, full_logs=bool(full_logs)))
    probe = SuiteStudy(model, suite.source, None, suite, bank, tuple(c.index for c in cases))  # type: ignore[arg-type]
    base, _ = probe.run_scenario(cases[0].index)
    return SuiteStudy(model, suite.source, base, suite, bank, tuple(c.index for c in cases))


def fly_bench(study: SuiteStudy, out_dir: str | Path, **kwargs: Any) -> Any:
    """Fly the selected cases not yet in ``out_dir`` (:func:`fdi_sim.study.execute.fly_study`'s keywords),
    then write the suite's labels beside them (:data:`fdi_sim.bench.export.CASES_FILE`): the folder
    is then an exportable benchmark folder however the flight ended."""
    from fdi_sim.bench.export import write_cases_file
    from fdi_sim.study.execute import fly_study

    o = fly_study(study, out_dir, **kwargs)
    write_cases_file(Path(out_dir), study._suite)
    return o
