"""Scenario files -> :class:`Scenario` objects, strictly.

Whatever is wrong in a file (TOML syntax, an unknown key, a key without its unit, a wrong type, a
value out of range, an unknown plugin id, a missing section) comes out as one
:class:`~fdi_sim.errors.ScenarioError` that names the file, the key and the fix.
"""
from __future__ import annotations

import difflib
import json
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from pydantic import BaseModel, ValidationError

from fdi_sim import registry
from fdi_sim.errors import RegistryError, ScenarioError
from fdi_sim.operating_point import OperatingPoint
from fdi_sim.scenario.schema import ScenarioModel

_PLUGIN_SECTIONS = {"maneuvers": "maneuver", "faults": "fault", "detectors": "detector"}


@dataclass(frozen=True)
class Scenario:
    """A validated scenario.

    Attributes
    ----------
    model : ScenarioModel
        The validated sections (frozen pydantic model).
    maneuvers, faults, detectors : tuple
        ``(plugin id, validated parameters)`` per entry, in file order.
    source : str
        File path, or ``"<scenario>"`` when built in Python.
    text : str
        The TOML text it came from (or a JSON dump when built from a dict).
    """

    model: ScenarioModel
    maneuvers: tuple[tuple[str, Any], ...] = ()
    faults: tuple[tuple[str, Any], ...] = ()
    detectors: tuple[tuple[str, Any], ...] = ()
    source: str = "<scenario>"
    text: str = field(default="", repr=False)

    # -- convenient views -------------------------------------------------------------
    @property
    def name(self) -> str:
        return self.model.name

    @property
    def aircraft(self) -> str:
        return self.model.aircraft

    @property
    def seed(self) -> int:
        return self.model.seed

    @property
    def duration_s(self) -> float:
        return self.model.duration_s

    @property
    def dt_s(self) -> float:
        return 1.0 / self.model.rate_hz

    def operating_point(self) -> OperatingPoint:
        i = self.model.initial
        return OperatingPoint(
            aircraft=self.model.aircraft, h_ft=i.h_ft, vt_kts=i.vt_kts, vc_kts=i.vc_kts, gamma_deg=i.gamma_deg,
            phi_deg=i.phi_deg, psi_deg=i.psi_deg, flaps_deg=i.flaps_deg,
        )

    def replace(self, **changes: Any) -> "Scenario":
        """A copy with top-level keys changed (``seed=3``, ``duration_s=10``), re-validated."""
        data = self.model.model_dump(mode="json")
        data.update(changes)
        return from_dict(data, self.source)

    def shortened(self, duration_s: float) -> tuple["Scenario", int]:
        """A copy flown for ``duration_s`` [s] without the maneuvers and faults that would start after it.

        Returns the copy and how many entries were dropped (a plain ``replace(duration_s=...)``
        refuses them, as a scenario file must).
        """
        m = self.model
        maneuvers = [e for e in m.maneuvers if e.get("t_start_s", 0.0) < duration_s]
        faults = [e for e in m.faults if e.get("t_start_s", 0.0) < duration_s]
        dropped = len(m.maneuvers) - len(maneuvers) + len(m.faults) - len(faults)
        return self.replace(duration_s=duration_s, maneuvers=maneuvers, faults=faults), dropped

    def to_json(self) -> str:
        """Canonical JSON of the validated scenario (stored in every log)."""
        return self.model.model_dump_json()


def load(path: str | Path) -> Scenario:
    """Read and validate a scenario file."""
    p = Path(path)
    src = str(p)
    if p.suffix != ".toml":
        raise ScenarioError(src, "", "a scenario file must be TOML", "give a path ending in .toml")
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ScenarioError(src, "", "no such file", "check the path; `fdi-sim scenarios` lists the shipped ones") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ScenarioError(src, "", f"cannot read the file ({exc})", "check the path and permissions") from None
    return loads(text, src)


def loads(text: str, source: str = "<scenario>") -> Scenario:
    """Validate scenario TOML text."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(source, "", f"not valid TOML: {exc}", "fix the syntax at the line given") from None
    return from_dict(data, source, text)


def from_dict(data: Mapping[str, Any], source: str = "<scenario>", text: str | None = None) -> Scenario:
    """Validate a scenario given as nested dicts (what TOML parses to)."""
    if not isinstance(data, Mapping):
        raise ScenarioError(source, "", "a scenario must be a table of keys", "start from a file in scenarios/")
    try:
        model = ScenarioModel.model_validate(dict(data))
    except ValidationError as exc:
        raise _to_scenario_error(exc, source, ScenarioModel) from None
    plugins: dict[str, tuple[tuple[str, Any], ...]] = {}
    for section, kind in _PLUGIN_SECTIONS.items():
        entries = []
        for i, entry in enumerate(getattr(model, section)):
            key = f"{section}[{i}]"
            type_id = entry.get("type")
            if not isinstance(type_id, str):
                known = ", ".join(registry.ids(kind)) or "none registered yet"
                raise ScenarioError(source, f"{key}.type", f"missing or not a string", f"set type to one of: {known}")
            try:
                spec = registry.get(kind, type_id)
            except RegistryError:
                known = registry.ids(kind)
                close = difflib.get_close_matches(type_id, known, n=2, cutoff=0.5)
                fix = (f"did you mean {' or '.join(close)}? " if close else "") + f"known {kind} ids: {', '.join(known) or 'none yet'}"
                raise ScenarioError(source, f"{key}.type", f"unknown {kind} id {type_id!r}", fix) from None
            if spec.params is None or not (isinstance(spec.params, type) and issubclass(spec.params, BaseModel)):
                params: Any = dict(entry)
            else:
                try:
                    params = spec.params.model_validate(dict(entry))
                except ValidationError as exc:
                    raise _to_scenario_error(exc, source, spec.params, prefix=key) from None
            entries.append((type_id, params))
        plugins[section] = tuple(entries)
    if text is None:
        text = json.dumps(data, default=str, sort_keys=True)
    sc = Scenario(model=model, source=source, text=text, **plugins)
    _cross_checks(sc)
    return sc


def _cross_checks(sc: Scenario) -> None:
    m = sc.model
    if m.aircraft == "f16" and m.initial.flaps_deg:
        raise ScenarioError(sc.source, "initial.flaps_deg", "the F-16 has no pilot flaps", "remove initial.flaps_deg")
    from fdi_sim.faults.check import check_faults

    check_faults(sc)
    for i, (tid, p) in enumerate(sc.maneuvers):
        t0 = getattr(p, "t_start_s", 0.0)
        if t0 >= m.duration_s:
            raise ScenarioError(sc.source, f"maneuvers[{i}].t_start_s", f"starts at {t0} s, after the run ends ({m.duration_s} s)",
                                "start it earlier or lengthen duration_s")


def _model_fields(model: type[BaseModel], loc: tuple[Any, ...]) -> list[str]:
    """Field names of the (sub)model at ``loc`` (for 'did you mean')."""
    cur: Any = model
    for part in loc[:-1]:
        if isinstance(part, int):
            continue
        f = getattr(cur, "model_fields", {}).get(part)
        if f is None:
            return []
        ann = f.annotation
        sub = [a for a in getattr(ann, "__args__", (ann,)) if isinstance(a, type) and issubclass(a, BaseModel)]
        if not sub:
            return []
        cur = sub[0]
    return list(getattr(cur, "model_fields", {}))


def _to_scenario_error(exc: ValidationError, source: str, model: type[BaseModel], prefix: str = "") -> ScenarioError:
    errs = exc.errors()
    # an unknown key usually explains a "missing" one (a typo or a missing unit): report it first
    err = next((e for e in errs if e.get("type") == "extra_forbidden"), errs[0])
    loc = tuple(err.get("loc", ()))
    # pydantic puts the failing union member or validator name in loc; keep the data path only
    key = ".".join(str(p) if not isinstance(p, int) else f"[{p}]" for p in loc).replace(".[", "[")
    key = f"{prefix}.{key}" if prefix and key else (prefix or key)
    typ, msg = err.get("type", ""), err.get("msg", "invalid")
    if typ == "extra_forbidden":
        name = str(loc[-1]) if loc else ""
        known = _model_fields(model, loc)
        close = difflib.get_close_matches(name, known, n=2, cutoff=0.4)
        unitless = [k for k in known if k.startswith(name + "_")]
        if unitless:
            fix = f"keys carry their unit: write {' or '.join(unitless)}"
        elif close:
            fix = f"did you mean {' or '.join(close)}?"
        else:
            fix = f"remove it; allowed keys here: {', '.join(known)}" if known else "remove it"
        return ScenarioError(source, key, "unknown key", fix)
    if typ == "missing":
        return ScenarioError(source, key, "required key is missing", f"add {loc[-1] if loc else key} (see scenarios/ for examples)")
    value = err.get("input")
    shown = repr(value) if not isinstance(value, (dict, list)) else type(value).__name__
    fix = ""
    ctx = err.get("ctx") or {}
    if "expected" in ctx:
        fix = f"use one of {ctx['expected']}"
    elif any(k in ctx for k in ("ge", "gt", "le", "lt")):
        fix = "use a value " + " and ".join(f"{ {'ge': '>=', 'gt': '>', 'le': '<=', 'lt': '<'}[k]} {v}" for k, v in ctx.items() if k in ("ge", "gt", "le", "lt"))
    elif typ == "value_error":
        return ScenarioError(source, key, "invalid section", msg.removeprefix("Value error, "))
    elif typ.endswith("_type") or typ.endswith("_parsing"):
        fix = f"give a {typ.split('_')[0]}"
    return ScenarioError(source, key, f"{msg} (got {shown})", fix or "see the scenario reference in README.md")
