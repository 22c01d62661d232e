"""Study files: what a Monte Carlo study flies, and the scenario of each of its runs.

A study file (TOML, ``kind = "study"``, strict like a scenario: a misspelt key names the file,
the key and the fix) gives a base scenario, the number of runs or flight hours, distributions of
the scenario's keys, the fault set and the bank::

    kind = "study"
    name = "dhc6_false_alarms"
    scenario = "dhc6_cruise_doublets"      # a shipped scenario, or a path relative to this file
    seed = 1
    runs = 200                             # or flight_h = 1000.0
    duration_s = 600.0

    [sample]                               # dotted scenario keys -> distributions
    "initial.h_ft" = { uniform = [4000.0, 8000.0] }
    "atmosphere.turbulence" = { choice = ["light", "moderate"] }
    "sensors.noise_scale" = { normal = [1.0, 0.1], min = 0.5 }

    [[faults]]                              # none: a false-alarm study; several: one drawn per run
    type = "sensor-bias-v1"
    target = { choice = ["q_radps", "p_radps"] }
    bias_degps = { uniform = [0.5, 2.0] }
    t_start_s = { uniform = [20.0, 40.0] }

    [bank]                                 # the scenario's [fdi] section for every run
    bank = "default"
    design = { point = "grid", turbulence = "moderate", wind_speed_kts = 0.0 }

Distributions: ``{ uniform = [lo, hi] }``, ``{ loguniform = [lo, hi] }``, ``{ normal = [mean,
std] }`` (optionally clipped by ``min``/``max``), ``{ choice = [...] }`` (optional ``weights``),
``{ fixed = x }``, or a plain value.

Seeds (the study's one random-number convention): run ``i`` draws everything from
``numpy.random.SeedSequence([seed, i])``: its first child samples the distributions (keys in
sorted order, then the fault), its second gives the scenario seed. A run's scenario therefore
depends only on the study file and ``i``: never on the worker that flies it, or when.
"""
from __future__ import annotations

import hashlib
import json
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, Mapping, Sequence

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from fdi_sim.errors import ScenarioError, StudyError
from fdi_sim.scenario import Scenario, load
from fdi_sim.scenario.loader import from_dict
from fdi_sim.scenario.schema import FdiSection
from fdi_sim.units import S_PER_H

#: the distribution kinds a [sample] or fault value may be
DISTRIBUTIONS = ("uniform", "loguniform", "normal", "choice", "fixed")
#: scenario keys a study may not sample (the study sets them)
RESERVED_KEYS = ("name", "seed", "duration_s", "faults", "fdi", "log", "aircraft")


class _Strict(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True)


#: bytes per flight hour of a run's FDI topics without residuals (measured: 872,613 B for a
#: 300 s DHC-6 flight with the default bank at 20 Hz) and of a full 120 Hz log (issue 14's 0.5 TB
#: per 1,000 h); the disk check uses them with a margin, the help texts quote them, and
#: tests/study/test_execute.py checks both against a flown run's log
STATISTICS_BYTES_PER_H = 10.5e6
FULL_LOG_BYTES_PER_H = 0.5e9


class OutputSection(_Strict):
    """What each run keeps besides its summary record."""

    statistics: bool = Field(default=True, description="the run's FDI topics (statistics at the detector rate) as "
                             "an MCAP log, for re-scoring at other thresholds "
                             f"(about {STATISTICS_BYTES_PER_H / 1e6:.1f} MB per flight hour)")
    full_logs: bool = Field(default=False,
                            description=f"the 120 Hz topics too (up to {FULL_LOG_BYTES_PER_H / 1e9:.1f} GB per flight hour)")


class StudyModel(_Strict):
    """A study file (see the module docstring)."""

    kind: Literal["study"]
    name: str = Field(min_length=1, max_length=100, pattern=r"^[A-Za-z0-9_.\-]+$")
    description: str = ""
    scenario: str = Field(min_length=1, description="base scenario: a shipped name or a path relative to the file")
    seed: int = Field(default=0, ge=0, lt=2**63)
    runs: int | None = Field(default=None, ge=1, le=10_000_000)
    flight_h: float | None = Field(default=None, gt=0.0, le=1e7, strict=False)
    duration_s: float = Field(gt=0.0, le=360000.0, strict=False, description="simulated time per run [s]")
    time_limit_s: float = Field(default=3600.0, gt=0.0, strict=False, description="wall-clock limit per run [s]")
    retries: int = Field(default=2, ge=0, le=10, description="re-flights of a run whose worker died")
    sample: dict[str, Any] = Field(default_factory=dict, strict=False)
    faults: tuple[dict[str, Any], ...] = Field(default=(), strict=False)
    fault_weights: tuple[float, ...] | None = Field(default=None, strict=False)
    bank: dict[str, Any] = Field(default_factory=lambda: {"bank": "default"}, strict=False)
    output: OutputSection = OutputSection()

    @model_validator(mode="after")
    def _size(self) -> "StudyModel":
        if (self.runs is None) == (self.flight_h is None):
            raise ValueError("give exactly one of runs (a count) and flight_h (flight hours)")
        return self


@dataclass(frozen=True)
class Study:
    """A validated study file.

    Attributes
    ----------
    model : StudyModel
    source : str
        The file it came from.
    base : Scenario
        The base scenario.
    """

    model: StudyModel
    source: str
    base: Scenario

    @property
    def name(self) -> str:
        return self.model.name

    @property
    def n_runs(self) -> int:
        """Runs the study flies (``flight_h`` rounded up to whole runs)."""
        m = self.model
        return int(m.runs) if m.runs is not None else int(math.ceil(m.flight_h * S_PER_H / m.duration_s - 1e-9))

    def run_indices(self) -> tuple[int, ...]:
        """The runs this study flies (all of them; a benchmark flies a selection)."""
        return tuple(range(self.n_runs))

    def run_duration_s(self, index: int) -> float:
        """Simulated time of run ``index`` [s]."""
        return float(self.model.duration_s)

    def with_overrides(self, *, runs: int | None = None, duration_s: float | None = None) -> "Study":
        """The study with the command line's ``--runs`` / ``--duration``."""
        d = self.model.model_dump()
        if runs is not None:
            d.update(runs=int(runs), flight_h=None)
        if duration_s is not None:
            d["duration_s"] = float(duration_s)
        return Study(_validate(d, self.source), self.source, self.base)

    def identity(self) -> str:
        """Hash of everything a run's result depends on (not the run count, limits or retries):
        a results folder holds the runs of one identity only."""
        d = self.model.model_dump(mode="json")
        for k in ("runs", "flight_h", "time_limit_s", "retries", "description"):
            d.pop(k, None)
        d["scenario"] = json.loads(self.base.to_json())  # the base's content, not its path
        from fdi_sim import __version__

        blob = json.dumps({"study": d, "version": __version__}, sort_keys=True, default=str)
        return hashlib.sha256(blob.encode()).hexdigest()[:20]

    def run_seeds(self, index: int) -> tuple[np.random.Generator, int]:
        """Run ``index``'s sampling generator and scenario seed (module docstring)."""
        s_sample, s_flight = np.random.SeedSequence([int(self.model.seed), int(index)]).spawn(2)
        return np.random.default_rng(s_sample), int(s_flight.generate_state(1, np.uint64)[0] >> np.uint64(1))

    def run_scenario(self, index: int) -> tuple[Scenario, dict[str, Any]]:
        """Run ``index``'s scenario and the values sampled for it (dotted key -> value).

        Raises
        ------
        StudyError
            A sampled value the scenario refuses (names the study file, the key and the value).
        """
        m = self.model
        rng, seed = self.run_seeds(index)
        data = json.loads(self.base.to_json())
        params: dict[str, Any] = {}
        for key in sorted(m.sample):
            v = draw(m.sample[key], rng)
            params[key] = v
            _set_dotted(data, key, v)
        faults = []
        if m.faults:
            w = np.asarray(m.fault_weights if m.fault_weights is not None else [1.0] * len(m.faults), dtype=float)
            j = int(rng.choice(len(m.faults), p=w / w.sum()))
            entry = {k: draw(v, rng) for k, v in sorted(m.faults[j].items())}
            faults.append(entry)
            params["fault"] = entry
        data.update(name=f"{m.name}_run{index:06d}"[:120], seed=seed, duration_s=float(m.duration_s), faults=faults,
                    description=f"run {index} of study {m.name} (seed {m.seed})")
        data["maneuvers"] = [e for e in data.get("maneuvers", []) if float(e.get("t_start_s", 0.0)) < m.duration_s]
        data["fdi"] = {**data.get("fdi", {}), **m.bank}
        if not m.output.full_logs:
            data["fdi"].setdefault("log_residuals", False)  # statistics are what a study keeps
        data["log"] = {"per_step": bool(m.output.full_logs)}
        try:
            sc = from_dict(data, source=f"{self.source} run {index}")
        except ScenarioError as exc:
            raise StudyError(self.source, _study_key(exc.key, params),
                             f"run {index}: the sampled scenario is refused ({exc.problem}; sampled "
                             f"{json.dumps(params, default=str)})",
                             exc.fix or "narrow the distribution to values the scenario accepts") from None
        return sc, params


def _study_key(scenario_key: str, params: Mapping[str, Any]) -> str:
    if scenario_key.startswith("faults[0]"):
        return "faults" + scenario_key.removeprefix("faults[0]")
    if scenario_key.startswith("fdi"):
        return "bank" + scenario_key.removeprefix("fdi")
    for k in params:
        if scenario_key == k or scenario_key.startswith(k + "."):
            return f"sample.{k}"
    return scenario_key


def _set_dotted(data: dict[str, Any], key: str, value: Any) -> None:
    parts = key.split(".")
    d = data
    for p in parts[:-1]:
        d = d.setdefault(p, {})
    d[parts[-1]] = value


def _distribution_error(source: str, key: str, problem: str) -> StudyError:
    return StudyError(source, key, problem, "write { uniform = [lo, hi] }, { loguniform = [lo, hi] }, "
                      "{ normal = [mean, std], min = .., max = .. }, { choice = [a, b, ...], weights = [...] }, "
                      "{ fixed = x } or a plain value")


def check_distribution(value: Any, source: str, key: str) -> None:
    """Refuse a distribution that cannot be drawn from (empty, reversed, negative spread...)."""
    if not isinstance(value, Mapping):
        if isinstance(value, (list, tuple)):
            raise _distribution_error(source, key, f"a bare list {list(value)!r} is ambiguous")
        return
    kinds = [k for k in value if k in DISTRIBUTIONS]
    if not kinds and not set(value) & {"min", "max", "weights"}:
        return  # a plain table (a fault's intermittent profile): passed on as it is
    extra = sorted(set(value) - set(DISTRIBUTIONS) - {"min", "max", "weights"})
    if len(kinds) != 1 or extra:
        raise _distribution_error(source, key, f"{dict(value)!r} is not one distribution"
                                  + (f" (unknown keys {extra})" if extra else ""))
    kind = kinds[0]
    a = value[kind]
    if kind == "fixed":
        return
    if kind == "choice":
        if not isinstance(a, (list, tuple)) or not a:
            raise _distribution_error(source, key, "choice is empty: there is nothing to draw")
        w = value.get("weights")
        if w is not None and (len(w) != len(a) or any(not isinstance(x, (int, float)) or x < 0 for x in w) or sum(w) <= 0):
            raise _distribution_error(source, key, f"weights {w!r} must be {len(a)} non-negative numbers, not all 0")
        return
    if not isinstance(a, (list, tuple)) or len(a) != 2 or not all(isinstance(x, (int, float)) for x in a):
        raise _distribution_error(source, key, f"{kind} takes two numbers, got {a!r}")
    lo, hi = float(a[0]), float(a[1])
    if kind in ("uniform", "loguniform") and not lo <= hi:
        raise _distribution_error(source, key, f"{kind} [{lo:g}, {hi:g}] is empty (lo > hi)")
    if kind == "loguniform" and lo <= 0:
        raise _distribution_error(source, key, f"loguniform needs lo > 0, got {lo:g}")
    if kind == "normal" and hi < 0:
        raise _distribution_error(source, key, f"normal's std {hi:g} is negative")
    if "min" in value and "max" in value and value["min"] > value["max"]:
        raise _distribution_error(source, key, f"min {value['min']} > max {value['max']}: nothing can be drawn")


def draw(value: Any, rng: np.random.Generator) -> Any:
    """One draw of a (checked) distribution; a plain value is returned as it is."""
    if not isinstance(value, Mapping) or not any(k in value for k in DISTRIBUTIONS):
        return value
    if "fixed" in value:
        return value["fixed"]
    if "choice" in value:
        a = list(value["choice"])
        w = value.get("weights")
        p = None if w is None else np.asarray(w, dtype=float) / float(sum(w))
        return a[int(rng.choice(len(a), p=p))]
    if "uniform" in value:
        x = float(rng.uniform(*value["uniform"]))
    elif "loguniform" in value:
        lo, hi = value["loguniform"]
        x = float(math.exp(rng.uniform(math.log(lo), math.log(hi))))
    else:
        x = float(rng.normal(*value["normal"]))
    if "min" in value:
        x = max(x, float(value["min"]))
    if "max" in value:
        x = min(x, float(value["max"]))
    return x


def _validate(data: Mapping[str, Any], source: str) -> StudyModel:
    from fdi_sim.scenario.loader import _to_scenario_error

    try:
        return StudyModel.model_validate(dict(data))
    except ValidationError as exc:
        err = _to_scenario_error(exc, source, StudyModel)
        raise StudyError(err.source, err.key, err.problem, err.fix) from None


def resolve_scenario(ref: str, study_dir: Path) -> Path:
    """A study's ``scenario``: a path relative to the study file, or a shipped scenario's name."""
    p = (study_dir / ref)
    if p.suffix == ".toml" and p.is_file():
        return p
    from fdi_sim.scenario import shipped

    return shipped.resolve(ref)


def load_study(path: str | Path) -> Study:
    """Read and check a study file; every run's scenario is checked by drawing run 0's.

    Raises
    ------
    StudyError
        Names the file, the key and the fix.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise StudyError(str(p), "", f"cannot read the study file ({exc.strerror})",
                         "give a study TOML file (`fdi-sim scenarios` lists the shipped ones)") from None
    try:
        data = tomllib.loads(text)
    except ValueError as exc:
        raise StudyError(str(p), "", f"not valid TOML ({exc})", "fix the syntax at that line") from None
    model = _validate(data, str(p))
    for key, v in model.sample.items():
        if key.split(".")[0] in RESERVED_KEYS:
            raise StudyError(str(p), f"sample.{key}", f"{key} is set by the study itself",
                             "set it with the study's own keys (duration_s, seed, [bank], [[faults]], [output])")
        check_distribution(v, str(p), f"sample.{key}")
    for i, f in enumerate(model.faults):
        for key, v in f.items():
            check_distribution(v, str(p), f"faults[{i}].{key}")
    if model.fault_weights is not None and len(model.fault_weights) != len(model.faults):
        raise StudyError(str(p), "fault_weights", f"{len(model.fault_weights)} weights for {len(model.faults)} faults",
                         "give one weight per [[faults]] entry")
    bad = sorted(set(model.bank) - set(FdiSection.model_fields))
    if bad:
        raise StudyError(str(p), f"bank.{bad[0]}", "not an [fdi] key",
                         f"the [bank] section is the runs' [fdi] section: {', '.join(FdiSection.model_fields)}")
    try:
        base = load(resolve_scenario(model.scenario, p.parent))
    except (ScenarioError, FileNotFoundError) as exc:
        raise StudyError(str(p), "scenario", f"the base scenario {model.scenario!r} cannot be used ({exc})",
                         "name a shipped scenario (`fdi-sim scenarios`) or a path relative to the study file") from None
    st = Study(model, str(p), base)
    st.run_scenario(0)  # every key and value must make a scenario
    return st


def scenario_toml(sc: Scenario, *, full_log: bool = True) -> str:
    """A run's scenario as a TOML file that ``fdi-sim run`` flies again (with the full 120 Hz
    log by default: the FDI topics are the same either way, ``[log] per_step`` only adds topics)."""
    import tomli_w

    data = json.loads(sc.model.model_dump_json())
    data["log"] = {"per_step": bool(full_log)}
    return tomli_w.dumps(_drop_none(data))


def _drop_none(x: Any) -> Any:
    if isinstance(x, dict):
        return {k: _drop_none(v) for k, v in x.items() if v is not None}
    if isinstance(x, list):
        return [_drop_none(v) for v in x]
    return x


def design_key(sc: Scenario) -> str:
    """What a run's bank is designed and calibrated on, as a hash: runs with one key share a bank
    (:func:`fdi_sim.training.schedule.design_scenario`, without the run's seed, name and duration)."""
    from fdi_sim.training.schedule import design_scenario
    from fdi_sim.training.flights import fault_free

    ff = json.loads(fault_free(design_scenario(sc), 0, 1.0).to_json())
    for k in ("name", "description", "maneuvers"):
        ff.pop(k, None)
    fdi = {k: v for k, v in sc.model.fdi.model_dump(mode="json").items() if k != "design"}
    blob = json.dumps({"ff": ff, "fdi": fdi, "m": sc.model.model_dump(mode="json")["maneuvers"]}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def design_groups(scenarios: Sequence[Scenario]) -> tuple[dict[str, Scenario], list[str]]:
    """The distinct bank designs the runs need (key -> the first run's scenario) and each run's key."""
    keys = [design_key(sc) for sc in scenarios]
    out: dict[str, Scenario] = {}
    for k, sc in zip(keys, scenarios):
        out.setdefault(k, sc)
    return out, keys
