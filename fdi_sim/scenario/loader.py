"""Scenario files -> :class:`Scenario` objects, strictly.

Whatever is wrong in a file (TOML syntax, an unknown key, a key without its unit, a wrong type, a
value out of range, an unknown plugin id, a missing section) comes out as one
:class:`~fdi_sim.errors.ScenarioError` that names the file, the key and the fix.
"""
from __future__ import annotations

import difflib
import json
import math
import os
import stat
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, Mapping, get_args, get_origin

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
        """Canonical JSON of the validated scenario (stored in every log).

        The ``fdi`` and ``log`` sections are left out while they hold their defaults, so that the
        logs of scenarios without them are the same bytes as before those sections existed."""
        from fdi_sim.scenario.schema import FdiSection, LogSection

        exclude = {k for k, d in (("fdi", FdiSection()), ("log", LogSection())) if getattr(self.model, k) == d}
        return self.model.model_dump_json(exclude=exclude or None)


#: largest scenario file read [bytes]; shipped scenarios are a few kB (a guard against /dev/zero and the like)
MAX_SCENARIO_BYTES = 1 << 20
#: deepest nesting of tables and arrays a scenario may have; the deepest real key,
#: ``faults[i].intermittent.windows_s[j][k]``, is 5 levels (tomllib and pydantic recurse per level)
MAX_DEPTH = 16
_BOM = "\ufeff"


def load(path: str | Path) -> Scenario:
    """Read and validate a scenario file.

    Only a regular file of at most :data:`MAX_SCENARIO_BYTES` [bytes] is read (a symlink is
    followed): a directory, a FIFO or a device such as ``/dev/zero`` is refused before any read,
    so a wrong path can neither hang nor fill memory. The text must be UTF-8; a leading UTF-8
    byte-order mark is accepted and dropped.
    """
    p = Path(path)
    src = str(p)
    if p.suffix != ".toml":
        raise ScenarioError(src, "", "a scenario file must be TOML", "give a path ending in .toml")
    return loads(_read_text(p, src), src)


def _read_text(p: Path, src: str) -> str:
    """The file's text, after checking what the path is (regular, small, readable, UTF-8)."""
    try:
        # O_NONBLOCK: opening a FIFO for reading would otherwise wait for a writer
        fd = os.open(p, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise ScenarioError(src, "", "no such file", "check the path; `fdi-sim scenarios` lists the shipped ones") from None
    except IsADirectoryError:
        raise ScenarioError(src, "", "is a directory, not a scenario file", "give the path of a .toml file in it") from None
    except PermissionError:
        raise ScenarioError(src, "", "permission denied: the file cannot be read",
                            "make it readable (chmod u+r) or copy it somewhere readable") from None
    except OSError as exc:
        raise ScenarioError(src, "", f"cannot open the file ({exc.strerror or exc})", "check the path") from None
    mode = os.fstat(fd).st_mode  # of what was opened (a symlink followed), so no check-then-open race
    if not stat.S_ISREG(mode):
        os.close(fd)
        kind = _FILE_KINDS.get(stat.S_IFMT(mode), "special file")
        raise ScenarioError(src, "", f"is a {kind}, not a regular file",
                            "give the path of a scenario .toml file (a symlink must point to a regular file)")
    with os.fdopen(fd, "rb") as f:
        try:
            data = f.read(MAX_SCENARIO_BYTES + 1)  # never more than the limit, whatever fstat said
        except OSError as exc:
            raise ScenarioError(src, "", f"cannot read the file ({exc.strerror or exc})",
                                "check the path and permissions") from None
    if len(data) > MAX_SCENARIO_BYTES:
        raise ScenarioError(src, "", f"file is larger than {MAX_SCENARIO_BYTES} bytes (scenario files are a few kB)",
                            "give a scenario .toml file; put long data in the aircraft/ folder, not in the scenario")
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise ScenarioError(src, "", "file is UTF-16 text (it starts with a UTF-16 byte-order mark)", "save it as UTF-8")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data[: exc.start].count(b"\n") + 1
        raise ScenarioError(src, "", f"not UTF-8 text: byte 0x{data[exc.start]:02x} at line {line} "
                            f"(offset {exc.start}) cannot be decoded", "save the file as UTF-8") from None


_FILE_KINDS = {
    stat.S_IFDIR: "directory", stat.S_IFCHR: "character device", stat.S_IFBLK: "block device",
    stat.S_IFIFO: "FIFO (named pipe)", stat.S_IFSOCK: "socket",
}


def loads(text: str, source: str = "<scenario>") -> Scenario:
    """Validate scenario TOML text (a leading UTF-8 byte-order mark is dropped)."""
    text = text.removeprefix(_BOM)  # tomllib reads U+FEFF as a bad statement ("Invalid statement (at line 1)")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(source, "", f"not valid TOML: {exc}", "fix the syntax at the line given") from None
    except (RecursionError, MemoryError) as exc:  # tomllib recurses once per nested array or inline table
        raise ScenarioError(source, "", f"the TOML nests too deeply to parse ({type(exc).__name__})",
                            f"scenario values nest at most {MAX_DEPTH} levels: flatten the arrays") from None
    return from_dict(data, source, text)


def from_dict(data: Mapping[str, Any], source: str = "<scenario>", text: str | None = None) -> Scenario:
    """Validate a scenario given as nested dicts (what TOML parses to)."""
    if not isinstance(data, Mapping):
        raise ScenarioError(source, "", "a scenario must be a table of keys", "start from a file in scenarios/")
    _check_depth(data, source)
    try:
        return _from_dict(data, source, text)
    except (RecursionError, MemoryError) as exc:  # a bound, not a traceback, whatever slipped past _check_depth
        raise ScenarioError(source, "", f"the scenario is too large or nests too deeply to validate ({type(exc).__name__})",
                            f"scenario values nest at most {MAX_DEPTH} levels: flatten the arrays") from None


def _from_dict(data: Mapping[str, Any], source: str, text: str | None) -> Scenario:
    _check_finite(data, source)
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
                raise ScenarioError(source, f"{key}.type", "missing or not a string", f"set type to one of: {known}")
            try:
                spec = registry.get(kind, type_id)
            except RegistryError as exc:
                if "was refused" in str(exc):  # an installed plugin that could not be registered: say why
                    raise ScenarioError(source, f"{key}.type", str(exc), "fix or uninstall the plugin "
                                        "(`fdi-sim plugins` lists the refused ones)") from None
                known = registry.ids(kind)
                close = difflib.get_close_matches(type_id, known, n=2, cutoff=0.5)
                fix = (f"did you mean {' or '.join(close)}? " if close else "") + f"known {kind} ids: {', '.join(known) or 'none yet'}"
                raise ScenarioError(source, f"{key}.type", f"unknown {kind} id {type_id!r}", fix) from None
            if spec.params is None or not (isinstance(spec.params, type) and issubclass(spec.params, BaseModel)):
                params: Any = dict(entry)
                if kind == "detector":
                    _check_factory_keys(entry, spec, source, key)
            else:
                try:  # strict as the sections are (schema.py); TOML arrays read as tuples
                    params = spec.params.model_validate(_tuples(dict(entry)), strict=True)
                except ValidationError as exc:
                    raise (_typo_error(entry, spec.params, source, key)
                           or _to_scenario_error(exc, source, spec.params, prefix=key)) from None
            entries.append((type_id, params))
        plugins[section] = tuple(entries)
    if text is None:
        text = json.dumps(data, default=str, sort_keys=True)
    sc = Scenario(model=model, source=source, text=text, **plugins)
    _cross_checks(sc)
    return sc


#: keys a [[detectors]] entry may carry besides its factory's options (the calibration of
#: kalman-gust-v1, fdi_sim.training.gust)
DETECTOR_ENTRY_KEYS = ("type", "n_flights", "duration_s", "target")


def _check_factory_keys(entry: Mapping[str, Any], spec: Any, source: str, key: str) -> None:
    """A detector without a parameter model: its keys must be options of its factory."""
    import inspect

    try:
        params = inspect.signature(spec.factory).parameters
    except (TypeError, ValueError):
        return
    if any(p.kind == p.VAR_KEYWORD for p in params.values()):
        return
    known = [n for n in params if n != "model"] + list(DETECTOR_ENTRY_KEYS)
    for k in entry:
        if k not in known:
            close = difflib.get_close_matches(k, known, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise ScenarioError(source, f"{key}.{k}", f"unknown key {k!r} for detector {spec.id!r}{hint}",
                                f"options of {spec.id}: {', '.join(n for n in known if n != 'type')}")


def _check_depth(data: Any, source: str) -> None:
    """Refuse nesting deeper than :data:`MAX_DEPTH` (iteratively: the check itself cannot overflow)."""
    stack: list[tuple[Any, str, int]] = [(data, "", 0)]
    while stack:
        node, key, depth = stack.pop()
        if isinstance(node, Mapping):
            items: Any = ((f"{key}.{k}" if key else str(k), v) for k, v in node.items())
        elif isinstance(node, (list, tuple)):
            items = ((f"{key}[{i}]", v) for i, v in enumerate(node))
        else:
            continue
        if depth >= MAX_DEPTH:
            raise ScenarioError(source, key, f"tables and arrays nest more than {MAX_DEPTH} levels deep here",
                                f"no scenario key takes values nested deeper than {MAX_DEPTH} levels: flatten it")
        stack.extend((v, k, depth + 1) for k, v in items)


def _typo_error(entry: Mapping[str, Any], params: type[BaseModel], source: str, key: str) -> ScenarioError | None:
    """A misspelt key of a plugin entry, when one is close to a key of ``params`` (else None).

    Plugin models that allow extra keys (faults: unit-suffixed magnitudes) report a misspelt
    required key as "missing" and never see the misspelling; this names it: ``unknown key
    't_strat_s' (did you mean 't_start_s'?)``. Keys starting with a declared magnitude prefix
    (``bias_`` in ``bias_deg``) are left to the plugin's own unit check.
    """
    fields = list(params.model_fields)
    prefixes = tuple(f"{m}_" for m in getattr(params, "MAGNITUDES", {}) or {})
    for name in entry:
        if not isinstance(name, str) or name in fields or (prefixes and name.startswith(prefixes)):
            continue
        close = difflib.get_close_matches(name, fields, n=1, cutoff=0.6)
        if close:
            need = " (a required key)" if params.model_fields[close[0]].is_required() else ""
            return ScenarioError(source, f"{key}.{name}", f"unknown key {name!r} (did you mean {close[0]!r}?)",
                                 f"rename it to {close[0]}{need}")
    return None


def _check_finite(data: Any, source: str, key: str = "") -> None:
    """Refuse ``nan`` and ``inf`` (valid TOML) anywhere: no scenario key means them."""
    if isinstance(data, float) and not math.isfinite(data):
        raise ScenarioError(source, key, f"{data} is not a finite number", "give a finite number")
    items = data.items() if isinstance(data, Mapping) else enumerate(data) if isinstance(data, (list, tuple)) else ()
    for k, v in items:
        _check_finite(v, source, f"{key}[{k}]" if isinstance(k, int) else f"{key}.{k}" if key else str(k))


def _tuples(data: Any) -> Any:
    """Lists (TOML arrays, JSON) as tuples, recursively, for strict validation of tuple fields."""
    if isinstance(data, (list, tuple)):
        return tuple(_tuples(v) for v in data)
    if isinstance(data, Mapping):
        return {k: _tuples(v) for k, v in data.items()}
    return data


def _check_sensors(sc: Scenario) -> None:
    """The sensor suite exists and every override names one of its sensors (before any run)."""
    from fdi_sim.sensors.suite import load_suite, suite_names

    s = sc.model.sensors
    try:
        specs = load_suite(sc.aircraft, s.suite)
    except FileNotFoundError:
        known = suite_names(sc.aircraft)
        close = difflib.get_close_matches(s.suite, known, n=1, cutoff=0.5)
        fix = (f"did you mean {close[0]!r}? " if close else "") + f"{sc.aircraft} suites: {', '.join(known)}"
        raise ScenarioError(sc.source, "sensors.suite", f"no sensor suite {s.suite!r} for {sc.aircraft}", fix) from None
    names = [sp.name for sp in specs]
    for name in s.overrides:
        if name not in names:
            close = difflib.get_close_matches(name, names, n=2, cutoff=0.5)
            fix = (f"did you mean {' or '.join(close)}? " if close else "") + f"sensors are: {', '.join(names)}"
            raise ScenarioError(sc.source, f"sensors.overrides.{name}", "no such sensor in the suite", fix)


def _cross_checks(sc: Scenario) -> None:
    m = sc.model
    if m.aircraft == "f16" and m.initial.flaps_deg:
        raise ScenarioError(sc.source, "initial.flaps_deg", "the F-16 has no pilot flaps", "remove initial.flaps_deg")
    _check_sensors(sc)
    from fdi_sim.faults.check import check_faults

    check_faults(sc)
    _check_fdi(sc)
    for i, (tid, p) in enumerate(sc.maneuvers):
        t0 = getattr(p, "t_start_s", 0.0)
        if t0 >= m.duration_s:
            raise ScenarioError(sc.source, f"maneuvers[{i}].t_start_s", f"starts at {t0} s, after the run ends ({m.duration_s} s)",
                                "start it earlier or lengthen duration_s")


def _check_fdi(sc: Scenario) -> None:
    """The detector rate divides the simulation rate; the block is a whole number of samples."""
    f, rate = sc.model.fdi, float(sc.model.rate_hz)
    d = rate / f.rate_hz
    if abs(d - round(d)) > 1e-9 or round(d) < 1:
        ok = [f"{rate / k:g}" for k in range(1, int(rate) + 1) if abs(rate / k - round(rate / k)) < 1e-9][:10]
        raise ScenarioError(sc.source, "fdi.rate_hz", f"{f.rate_hz:g} Hz does not divide the simulation rate "
                            f"{rate:g} Hz", f"use one of {', '.join(ok)} Hz")
    b = f.block_s * f.rate_hz
    if abs(b - round(b)) > 1e-9 or round(b) < 1:
        raise ScenarioError(sc.source, "fdi.block_s", f"{f.block_s:g} s is not a whole number of detector samples "
                            f"at {f.rate_hz:g} Hz", f"use a multiple of {1.0 / f.rate_hz:g} s")


def _model_fields(model: type[BaseModel], loc: tuple[Any, ...]) -> dict[str, Any]:
    """Fields of the (sub)model holding the key at ``loc`` (for 'did you mean', what to add)."""
    cur: Any = model
    in_mapping = False  # the previous part was a dict field: this part is one of its keys
    for part in loc[:-1]:
        if isinstance(part, int) or in_mapping:
            in_mapping = False
            continue
        f = getattr(cur, "model_fields", {}).get(part)
        if f is None:
            return {}
        ann = f.annotation
        in_mapping = get_origin(ann) is dict  # dict[str, Model]: skip the key
        sub = [a for a in get_args(ann) or (ann,) if isinstance(a, type) and issubclass(a, BaseModel)]
        if not sub:
            return {}
        cur = sub[0]
    return dict(getattr(cur, "model_fields", {}))


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
        known = list(_model_fields(model, loc))
        close = difflib.get_close_matches(name, known, n=2, cutoff=0.4)
        unitless = [k for k in known if k.startswith(name + "_")]
        if unitless:
            fix = f"keys carry their unit: write {' or '.join(unitless)}"
        elif close:
            fix = f"rename it to {close[0]}" + (f" (or {close[1]})" if len(close) > 1 else "")
        else:
            fix = f"remove it; allowed keys here: {', '.join(known)}" if known else "remove it"
        return ScenarioError(source, key, f"unknown key {name!r}" + (f" (did you mean {close[0]!r}?)" if close and not unitless else ""), fix)
    if typ == "missing":
        name = str(loc[-1]) if loc else key
        f = _model_fields(model, loc).get(name)
        ann = f.annotation if f is not None else None
        if isinstance(ann, type) and issubclass(ann, BaseModel):
            fix = f"add the [{key}] table with {', '.join(k for k, v in ann.model_fields.items() if v.is_required())}"
        elif get_origin(ann) is Literal:
            fix = f"add {name} = one of {', '.join(repr(a) for a in get_args(ann))}"
        else:
            fix = f"add {name}"
        return ScenarioError(source, key, "required key is missing", fix + " (see scenarios/ for examples)")
    value = err.get("input")
    shown = repr(value) if not isinstance(value, (dict, list, tuple)) else type(value).__name__
    fix = ""
    ctx = err.get("ctx") or {}
    if "expected" in ctx:
        fix = f"use one of {ctx['expected']}"
    elif any(k in ctx for k in _BOUNDS):
        fix = "use a value " + " and ".join(f"{_BOUNDS[k]} {v}" for k, v in ctx.items() if k in _BOUNDS)
    elif "min_length" in ctx or "max_length" in ctx:
        fix = "give " + " and ".join(f"{w} {ctx[k]}" for k, w in (("min_length", "at least"), ("max_length", "at most"))
                                     if k in ctx) + " characters"
    elif "pattern" in ctx:
        fix = f"make it match the regular expression {ctx['pattern']}"
    elif typ == "tuple_type" and len(loc) == 1 and str(loc[0]) in _PLUGIN_SECTIONS:
        fix = f"write each entry as a [[{loc[0]}]] table"
    elif typ == "value_error":
        return ScenarioError(source, key, "invalid section", msg.removeprefix("Value error, "))
    elif typ.endswith(("_type", "_parsing")) or typ == "int_from_float":
        fix = next((f for prefix, f in _TYPE_FIXES.items() if typ.startswith(prefix)), "")
    return ScenarioError(source, key, f"{msg} (got {shown})", fix or "see the scenario reference in README.md")


_BOUNDS = {"ge": ">=", "gt": ">", "le": "<=", "lt": "<"}
#: pydantic type-error prefix (``float_type``, ``int_from_float``, ...) -> what to write in TOML
_TYPE_FIXES = {
    "int": "give a whole number (no decimal point, no quotes)",
    "float": "give a number (no quotes)",
    "bool": "give true or false (no quotes)",
    "string": "give a quoted string",
    "tuple": "give an array",
    "list": "give an array",
    "dict": "give a table",
    "model": "give a table",
}
