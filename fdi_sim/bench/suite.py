"""Benchmark suites: a frozen, versioned list of cases (flights with their labels), and its hash.

A suite file (TOML, ``kind = "bench-suite"``, shipped in ``fdi_sim/_bench/``; ``docs/bench.md``)
names *phases* (a base scenario and what a case samples around it), the *air* every case samples
(turbulence, wind, sensor noise) and *groups*: a number of cases of one phase list, fault-free (a
hard negative says what makes it hard) or with one fault drawn per case, at each of the group's
sizes (``size = { key = "bias_degps", values = [small, medium, gross] }``).

Cases. Group ``g`` (its index in the file), size ``s`` (its index, 0 without sizes), run ``r``:

- id ``<group>/s<s>/<r:03d>`` (``<group>/<r:03d>`` without sizes);
- phase ``phases[r % len(phases)]``;
- randomness from ``numpy.random.SeedSequence([seed, g, s, r])``: its first child samples the air,
  the phase's and the group's keys (sorted), then the fault's keys (sorted) and its onset (the
  suite's ``onset_s`` unless the fault gives ``t_start_s``); its second gives the flight's seed;
- split by whole flights, per (group, size): a permutation of the runs drawn from
  ``SeedSequence([seed, g, s, SPLIT_STREAM])`` puts the first 60 % in ``train``, the next 20 % in
  ``validation``, the rest in ``test`` (rounded: 5 runs give 3 / 1 / 1).

Freezing. The suite's hash is the SHA-256 of its cases as canonical JSON (sorted keys, no spaces):
each case's id, split, labels and scenario (every key a flight depends on: aircraft, point,
atmosphere, sensors, maneuvers, fault, seed, duration; not the bank, which the benchmark run
chooses). :data:`FROZEN` holds the hash of every shipped version, and loading a shipped suite whose
cases no longer give it is refused: a changed suite is a new version, never the same name.
"""
from __future__ import annotations

import difflib
import hashlib
import json
import tomllib
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from fdi_sim.bench.errors import BenchError
from fdi_sim.data import shown_path
from fdi_sim.errors import ScenarioError
from fdi_sim.units import S_PER_H

#: the shipped suites' folder
SUITES_DIR = Path(__file__).resolve().parents[1] / "_bench"
#: every shipped suite version -> the hash of its cases (module docstring); a new version is a new entry
FROZEN: dict[str, str] = {
    "fdi-bench-v1": "4ed7ec8d7db4a708723406538c1d3b76dfc06ce1edb3ba04eef77339b7ec52dc",
    "fdi-bench-v2": "ca071da523c00d718292fd38d6e7254bb35739b36db8fe925d0205ad2aece6c2",
}
#: the suite a command uses when none is named: the newest shipped version (v2 holds every case of v1
#: with the same id, split and scenario, and every fault type of the catalogue on each aircraft)
LATEST = "fdi-bench-v2"
SPLITS = ("train", "validation", "test")
#: the split fractions (train, validation; test is the rest)
SPLIT_FRACTIONS = (0.6, 0.2)
#: the SeedSequence word of the split permutation (beyond any run index)
SPLIT_STREAM = 2**31 - 1
#: scenario keys a case's hash leaves out: the benchmark run sets them
UNHASHED_KEYS = ("fdi", "detectors", "log", "name", "description")


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)


class PhaseModel(_Strict):
    scenario: str = Field(min_length=1, description="a shipped scenario's name or a path relative to the suite file")
    sample: dict[str, Any] = Field(default_factory=dict, strict=False)


class SizeModel(_Strict):
    key: str = Field(min_length=1, description="the fault parameter that sets its size")
    values: tuple[float, ...] = Field(min_length=3, strict=False, description="from barely detectable to gross")


class GroupModel(_Strict):
    name: str = Field(min_length=1, max_length=60, pattern=r"^[a-z0-9][a-z0-9\-]*$")
    phases: tuple[str, ...] = Field(min_length=1, strict=False)
    runs: int = Field(ge=1, le=100_000, description="cases per size")
    duration_s: float = Field(gt=0.0, le=36000.0, strict=False)
    negative: str = Field(default="", description="a fault-free group: what makes it hard")
    sample: dict[str, Any] = Field(default_factory=dict, strict=False)
    maneuvers: tuple[dict[str, Any], ...] = Field(default=(), strict=False)
    fault: dict[str, Any] | None = Field(default=None, strict=False)
    size: SizeModel | None = None


class SuiteModel(_Strict):
    kind: Literal["bench-suite"]
    name: str = Field(min_length=1, max_length=60, pattern=r"^[a-z0-9][a-z0-9\-.]*$")
    description: str = ""
    seed: int = Field(ge=0, lt=2**63)
    onset_s: Any = Field(description="the fault onset's distribution [s]")
    phases: dict[str, PhaseModel] = Field(strict=False)
    air: dict[str, Any] = Field(default_factory=dict, strict=False)
    groups: tuple[GroupModel, ...] = Field(min_length=1, strict=False)


@dataclass(frozen=True)
class Case:
    """One flight of a suite, with its labels (before it is flown).

    Attributes
    ----------
    index : int
        Its position in the suite (the results folder's run index).
    case, aircraft, group, phase, split : str
    fault_type, target : str
        ``""`` for a fault-free case.
    size : str
        ``"<value> <key>"`` (``"0.6 bias_degps"``), ``""`` without a size.
    size_rank : int
        0 for the group's first (smallest) size; -1 fault-free.
    negative : str
        A hard negative's label.
    duration_s : float
        [s]
    scenario_json : str
        The case's scenario without a bank (:data:`UNHASHED_KEYS` aside, what its hash covers).
    params : str
        The sampled values as JSON (dotted key -> value, ``fault``).
    """

    index: int
    case: str
    aircraft: str
    group: str
    phase: str
    split: str
    fault_type: str
    target: str
    size: str
    size_rank: int
    negative: str
    duration_s: float
    scenario_json: str
    params: str

    def hashed(self) -> list[Any]:
        sc = {k: v for k, v in json.loads(self.scenario_json).items() if k not in UNHASHED_KEYS}
        return [self.case, self.split, self.negative, self.size, self.size_rank, sc]


@dataclass(frozen=True)
class Suite:
    """A loaded suite: its file, its cases and its hash."""

    model: SuiteModel
    source: str
    cases: tuple[Case, ...]

    @property
    def name(self) -> str:
        return self.model.name

    @cached_property
    def hash(self) -> str:
        """SHA-256 of the cases as canonical JSON (module docstring)."""
        blob = json.dumps({"suite": self.model.name, "seed": self.model.seed, "cases": [c.hashed() for c in self.cases]},
                          sort_keys=True, separators=(",", ":"), allow_nan=False)
        return hashlib.sha256(blob.encode()).hexdigest()

    def flight_h(self, cases: tuple[Case, ...] | None = None) -> float:
        """Planned flight hours of ``cases`` (default: all) [h]."""
        return sum(c.duration_s for c in (self.cases if cases is None else cases)) / S_PER_H

    def select(self, *, split: str | None = None, groups: tuple[str, ...] = (), aircraft: str | None = None,
               per_group: int | None = None) -> tuple[Case, ...]:
        """The cases of a split, of some groups (names or ``fnmatch`` patterns), of one aircraft,
        and at most ``per_group`` per (group, size) (the first by run index)."""
        import fnmatch

        if split is not None and split not in SPLITS:
            raise BenchError(self.source, "--split", f"no split {split!r}", f"give one of {', '.join(SPLITS)}")
        known = {g.name for g in self.model.groups}
        for pat in groups:
            if not fnmatch.filter(known, pat):
                near = difflib.get_close_matches(pat, sorted(known), n=3)
                raise BenchError(self.source, "--group", f"no group matches {pat!r}",
                                 f"did you mean {', '.join(near)}?" if near else f"groups: {', '.join(sorted(known))}")
        out, seen = [], {}
        for c in self.cases:
            if split is not None and c.split != split:
                continue
            if groups and not any(fnmatch.fnmatch(c.group, p) for p in groups):
                continue
            if aircraft is not None and c.aircraft.lower() != aircraft.lower():
                continue
            k = (c.group, c.size_rank)
            seen[k] = seen.get(k, 0) + 1
            if per_group is not None and seen[k] > per_group:
                continue
            out.append(c)
        return tuple(out)


def suite_names() -> list[str]:
    """The shipped suite versions."""
    return sorted(FROZEN)


def resolve_suite(ref: str) -> Path:
    """A shipped suite's name, or a suite file's path.

    Raises
    ------
    BenchError
        Neither (with a "did you mean").
    """
    p = Path(ref)
    if p.suffix == ".toml" and p.is_file():
        return p
    if ref in FROZEN:
        return SUITES_DIR / f"{ref}.toml"
    near = difflib.get_close_matches(ref, suite_names(), n=3)
    raise BenchError(ref, "--suite", "no such suite version or file",
                     f"did you mean {', '.join(near)}?" if near else f"shipped: {', '.join(suite_names())}")


def load_suite(ref: str = LATEST, *, check_frozen: bool = True) -> Suite:
    """Read a suite, build every case's scenario (each is validated) and check a shipped one's hash.

    Raises
    ------
    BenchError
        A bad file (names the file, the key and the fix), or a shipped suite whose cases changed.
    """
    path = resolve_suite(ref)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise BenchError(str(path), "", f"cannot read the suite file ({exc.strerror})", "give a suite TOML file") from None
    except ValueError as exc:
        raise BenchError(str(path), "", f"not valid TOML ({exc})", "fix the syntax at that line") from None
    try:
        model = SuiteModel.model_validate(data)
    except ValidationError as exc:
        from fdi_sim.scenario.loader import _to_scenario_error

        err = _to_scenario_error(exc, str(path), SuiteModel)
        raise BenchError(err.source, err.key, err.problem, err.fix) from None
    suite = Suite(model, str(path), _build_cases(model, path))
    frozen = FROZEN.get(model.name)
    if check_frozen and path.parent == SUITES_DIR and frozen is not None and frozen and suite.hash != frozen:
        raise BenchError(str(path), "", f"its cases hash to {suite.hash[:16]}..., not to the frozen {frozen[:16]}... of "
                         f"{model.name}: a suite version never changes (a scenario default, a fault model or the file "
                         "moved under it)", "restore what changed, or ship the new cases as a new version "
                         "(a new file and a new FROZEN entry in fdi_sim/bench/suite.py)")
    return suite


def _build_cases(model: SuiteModel, path: Path) -> tuple[Case, ...]:
    from fdi_sim.scenario import load
    from fdi_sim.study.spec import (
        check_distribution,
        resolve_scenario,
    )

    src = str(path)
    bases: dict[str, dict[str, Any]] = {}
    for name, ph in model.phases.items():
        try:
            bases[name] = json.loads(load(resolve_scenario(ph.scenario, path.parent)).to_json())
        except (ScenarioError, FileNotFoundError) as exc:
            raise BenchError(src, f"phases.{name}.scenario", f"{ph.scenario!r} cannot be used ({exc})",
                             "name a shipped scenario (`fdi-sim scenarios`) or a path relative to the suite file") from None
        for k, v in ph.sample.items():
            check_distribution(v, src, f"phases.{name}.sample.{k}")
    for k, v in model.air.items():
        check_distribution(v, src, f"air.{k}")
    check_distribution(model.onset_s, src, "onset_s")
    names = [g.name for g in model.groups]
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise BenchError(src, "groups", f"group names repeat: {dup}", "give every group its own name")
    cases: list[Case] = []
    for gi, g in enumerate(model.groups):
        where = f"groups[{gi}] ({g.name})"
        for ph in g.phases:
            if ph not in model.phases:
                near = difflib.get_close_matches(ph, sorted(model.phases), n=3)
                raise BenchError(src, f"{where}.phases", f"no phase {ph!r}",
                                 f"did you mean {', '.join(near)}?" if near else f"phases: {', '.join(model.phases)}")
        aircraft = {bases[ph]["aircraft"] for ph in g.phases}
        if len(aircraft) != 1:
            raise BenchError(src, f"{where}.phases", f"its phases fly {sorted(aircraft)}", "one aircraft per group")
        if (g.fault is None) != (g.size is None) and g.size is not None:
            raise BenchError(src, f"{where}.size", "a size without a fault", "give the group a fault, or no size")
        if g.fault is not None and g.negative:
            raise BenchError(src, f"{where}.negative", "a hard negative is fault-free", "drop the fault or the label")
        for k, v in {**g.sample, **(g.fault or {})}.items():
            check_distribution(v, src, f"{where}.{k}")
        levels: list[tuple[int, float | None]] = list(enumerate(g.size.values)) if g.size else [(0, None)]
        for si, value in levels:
            order = np.random.default_rng(np.random.SeedSequence([model.seed, gi, si, SPLIT_STREAM])).permutation(g.runs)
            n_train = round(SPLIT_FRACTIONS[0] * g.runs)
            n_val = round(SPLIT_FRACTIONS[1] * g.runs)
            split_of = {int(r): SPLITS[0] if k < n_train else SPLITS[1] if k < n_train + n_val else SPLITS[2]
                        for k, r in enumerate(order)}
            for r in range(g.runs):
                cases.append(_case(model, src, gi, g, si, value, r, split_of[r], bases, len(cases)))
    return tuple(cases)


def _case(model: SuiteModel, src: str, gi: int, g: GroupModel, si: int, value: float | None, r: int, split: str,
          bases: dict[str, dict[str, Any]], index: int) -> Case:
    from fdi_sim.scenario.loader import from_dict
    from fdi_sim.study.spec import _set_dotted as set_dotted
    from fdi_sim.study.spec import draw

    s_sample, s_flight = np.random.SeedSequence([model.seed, gi, si, r]).spawn(2)
    rng = np.random.default_rng(s_sample)
    seed = int(s_flight.generate_state(1, np.uint64)[0] >> np.uint64(1))
    phase = g.phases[r % len(g.phases)]
    cid = f"{g.name}/s{si}/{r:03d}" if g.size else f"{g.name}/{r:03d}"
    data = json.loads(json.dumps(bases[phase]))
    params: dict[str, Any] = {}
    sample = {**model.air, **model.phases[phase].sample, **g.sample}
    for key in sorted(sample):
        v = draw(sample[key], rng)
        params[key] = v
        set_dotted(data, key, v)
    faults = []
    if g.fault is not None:
        entry = {k: draw(v, rng) for k, v in sorted(g.fault.items())}
        if "t_start_s" not in entry:
            entry["t_start_s"] = float(draw(model.onset_s, rng))
        if g.size is not None:
            entry[g.size.key] = float(value)
        faults.append(entry)
        params["fault"] = entry
    man = [e for e in list(data.get("maneuvers", [])) + [dict(m) for m in g.maneuvers]
           if float(e.get("t_start_s", 0.0)) < g.duration_s]
    data.update(name=cid.replace("/", "_"), seed=seed, duration_s=float(g.duration_s), faults=faults, maneuvers=man,
                description=f"{model.name} case {cid} ({phase})")
    for k in ("fdi", "detectors"):
        data.pop(k, None)
    data["log"] = {"per_step": False}
    try:
        sc = from_dict(data, source=f"{shown_path(src)} case {cid}")  # no checkout path in a log
    except ScenarioError as exc:
        raise BenchError(src, f"groups[{gi}] ({g.name})", f"case {cid}: the scenario is refused ({exc.problem}; "
                         f"sampled {json.dumps(params, default=str)})", exc.fix or "fix the group's values") from None
    f = faults[0] if faults else {}
    return Case(index, cid, str(data["aircraft"]), g.name, phase, split, str(f.get("type", "")),
                str(f.get("target", "")), "" if value is None else f"{value:g} {g.size.key}",  # type: ignore[union-attr]
                si if faults else -1, g.negative, float(g.duration_s), sc.to_json(), json.dumps(params, sort_keys=True))
