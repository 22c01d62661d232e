"""One catalogue of plugins: maneuvers, sensors, faults, detectors, decision rules.

Ids are versioned (``"doublet-v1"``, ``"parity-robust-v1"``). Registering an id twice raises;
looking up an unknown id raises with a "did you mean". The registry is consulted where
scenario files become objects; core code receives instances.
"""
from __future__ import annotations

import difflib
from dataclasses import dataclass
from typing import Any, Callable

from fdi_sim.errors import RegistryError

KINDS: tuple[str, ...] = ("maneuver", "sensor", "fault", "detector", "decision")


@dataclass(frozen=True)
class PluginSpec:
    """One registered plugin.

    Attributes
    ----------
    kind : str
        One of :data:`KINDS`.
    id : str
        Versioned id, ``name-vN``.
    summary : str
        One line for ``fdi-sim plugins``.
    factory : Callable
        Builds the plugin from its scenario parameters.
    params : Any
        The pydantic model (or dataclass) the scenario section is validated against, or None.
    origin : str
        ``"fdi-sim"`` for a built-in, else the distribution that registered it (an entry point).
    """

    kind: str
    id: str
    summary: str
    factory: Callable[..., Any]
    params: Any = None
    origin: str = "fdi-sim"


_REGISTRY: dict[str, dict[str, PluginSpec]] = {k: {} for k in KINDS}


def _table(kind: str) -> dict[str, PluginSpec]:
    table = _REGISTRY.get(kind)
    if table is None:
        raise RegistryError(f"unknown plugin kind {kind!r}; kinds are {', '.join(KINDS)}")
    return table


def register(kind: str, id: str, summary: str, factory: Callable[..., Any], params: Any = None,
             origin: str | None = None) -> PluginSpec:
    """Add a plugin to the catalogue; a duplicate id raises :class:`RegistryError`. ``origin``
    defaults to whoever is being loaded: fdi-sim's catalogues, or the plugin being imported."""
    origin = origin if origin is not None else _ORIGIN
    if origin == "fdi-sim" and _ORIGIN != "fdi-sim":  # a plugin's module cannot claim to be a built-in
        origin = _ORIGIN
    table = _table(kind)
    if not _valid_id(id):
        raise RegistryError(f"plugin id {id!r} must look like 'name-v1' (lower case, versioned)")
    if id in table:
        raise RegistryError(f"{kind} id {id!r} is already registered (by {table[id].origin})")
    spec = PluginSpec(kind=kind, id=id, summary=summary, factory=factory, params=params, origin=origin)
    table[id] = spec
    return spec


def _valid_id(id: str) -> bool:
    name, _, version = id.rpartition("-v")
    return bool(name) and version.isdigit() and id == id.lower()


def get(kind: str, id: str) -> PluginSpec:
    """Look a plugin up; an unknown id raises with the closest known ids."""
    load_builtin_plugins()
    table = _table(kind)
    if id not in table and (kind, id) in _BROKEN:
        b = _BROKEN[(kind, id)]
        raise RegistryError(f"{kind} plugin {id!r} from {b.origin} is installed but was refused: {b.reason}")
    if id not in table:
        close = difflib.get_close_matches(id, list(table), n=3, cutoff=0.5)
        hint = f" Did you mean {' or '.join(repr(c) for c in close)}?" if close else ""
        raise RegistryError(f"unknown {kind} id {id!r}.{hint} Known: {', '.join(sorted(table)) or 'none'}")
    return table[id]


def ids(kind: str) -> list[str]:
    """Sorted ids of one kind."""
    load_builtin_plugins()
    return sorted(_table(kind))


def all_plugins() -> list[PluginSpec]:
    """Every registered plugin, by kind then id."""
    load_builtin_plugins()
    return [_REGISTRY[k][i] for k in KINDS for i in sorted(_REGISTRY[k])]


_LOADED = False


def load_builtin_plugins() -> None:
    """Import the modules that register the built-in plugins (once).

    Each stage keeps its own ``catalogue.py`` of ``register(...)`` calls; this imports them.
    """
    global _LOADED
    if _LOADED:
        return
    _LOADED = True
    import importlib

    for mod in (
        "fdi_sim.pilot.catalogue",
        "fdi_sim.sensors.catalogue",
        "fdi_sim.faults.catalogue",
        "fdi_sim.detectors.catalogue",
        "fdi_sim.decision.catalogue",
    ):
        try:
            importlib.import_module(mod)
        except ModuleNotFoundError as exc:  # a stage not built yet registers nothing
            if exc.name != mod:
                raise
    load_entry_point_plugins()


#: entry-point group per plugin kind: a package registers a detector by an entry point whose *name*
#: is the detector id (``cusum-residual-v1``) and whose *value* is its factory (``pkg.mod:make``),
#: called as ``factory(model, **options)``; the first line of the factory's docstring is its summary
ENTRY_POINT_GROUPS: dict[str, str] = {"detector": "fdi_sim.detectors"}


@dataclass(frozen=True)
class BrokenPlugin:
    """An installed plugin that was refused, and why (``fdi-sim plugins`` lists them)."""

    kind: str
    id: str
    origin: str
    reason: str


_BROKEN: dict[tuple[str, str], BrokenPlugin] = {}


def broken_plugins() -> list[BrokenPlugin]:
    """The installed plugins that were refused (bad id, duplicate id, import error, not callable)."""
    load_builtin_plugins()
    return [_BROKEN[k] for k in sorted(_BROKEN)]


def load_entry_point_plugins() -> None:
    """Register every installed entry-point plugin (:data:`ENTRY_POINT_GROUPS`), after the built-ins.

    A plugin that cannot be used (an id that is not ``name-vN``, an id already taken, an import
    that fails or exits, a factory that is not callable, a registration of its own that clashes)
    is not registered; it is kept with its reason (:func:`broken_plugins`), so one broken package
    never stops the others or fdi-sim itself, and asking for it says why. Whatever a plugin's
    module registers while it is imported is recorded with the plugin's origin, never as a
    built-in (a built-in skips the contract check a plugin gets before it flies).
    """
    global _ORIGIN
    from importlib.metadata import entry_points

    for kind, group in ENTRY_POINT_GROUPS.items():
        try:
            eps = sorted(entry_points(group=group), key=lambda e: e.name)
        except Exception as exc:  # noqa: BLE001 - a malformed entry_points.txt of any installed package
            _BROKEN[(kind, f"<{group}>")] = BrokenPlugin(kind, f"<{group}>", "the installed packages",
                                                         f"reading the entry points failed: {type(exc).__name__}: {exc}")
            continue
        for ep in eps:
            origin = _origin_of(ep)
            why = None
            try:
                if not _valid_id(ep.name):
                    why = f"its id {ep.name!r} (the entry point's name) must look like 'name-v1' (lower case, versioned)"
                elif ep.name in _table(kind):
                    why = f"its id {ep.name!r} is already registered by {_table(kind)[ep.name].origin}"
                else:
                    _ORIGIN = origin
                    try:
                        factory = ep.load()
                    finally:
                        _ORIGIN = "fdi-sim"
                    if not callable(factory):
                        why = f"{ep.value} is a {type(factory).__name__}, not a factory callable"
                    elif ep.name in _table(kind):  # its module registered itself while imported: kept as is
                        pass
                    else:
                        doc = factory.__doc__ if isinstance(getattr(factory, "__doc__", None), str) else ""
                        lines = doc.strip().splitlines()
                        register(kind, ep.name, lines[0].strip() if lines else f"plugin from {origin}", factory,
                                 origin=origin)
            except KeyboardInterrupt:
                raise
            except BaseException as exc:  # noqa: BLE001 - an import that raises, or calls sys.exit, is its reason
                why = f"loading {ep.value} failed: {type(exc).__name__}: {exc}"
            if why is not None:
                _BROKEN[(kind, ep.name)] = BrokenPlugin(kind, ep.name, origin, why)


#: the origin stamped on what ``register`` records: a plugin's while its module is being imported
_ORIGIN = "fdi-sim"


def _origin_of(ep: Any) -> str:
    """``"<distribution> <version>"`` of an entry point, or its value when the metadata is incomplete."""
    dist = getattr(ep, "dist", None)
    name = getattr(dist, "name", None) if dist is not None else None
    return f"{name} {getattr(dist, 'version', '')}".strip() if name else f"{ep.value}"
