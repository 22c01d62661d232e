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
    """

    kind: str
    id: str
    summary: str
    factory: Callable[..., Any]
    params: Any = None


_REGISTRY: dict[str, dict[str, PluginSpec]] = {k: {} for k in KINDS}


def _table(kind: str) -> dict[str, PluginSpec]:
    table = _REGISTRY.get(kind)
    if table is None:
        raise RegistryError(f"unknown plugin kind {kind!r}; kinds are {', '.join(KINDS)}")
    return table


def register(kind: str, id: str, summary: str, factory: Callable[..., Any], params: Any = None) -> PluginSpec:
    """Add a plugin to the catalogue; a duplicate id raises :class:`RegistryError`."""
    table = _table(kind)
    if not _valid_id(id):
        raise RegistryError(f"plugin id {id!r} must look like 'name-v1' (lower case, versioned)")
    if id in table:
        raise RegistryError(f"{kind} id {id!r} is already registered")
    spec = PluginSpec(kind=kind, id=id, summary=summary, factory=factory, params=params)
    table[id] = spec
    return spec


def _valid_id(id: str) -> bool:
    name, _, version = id.rpartition("-v")
    return bool(name) and version.isdigit() and id == id.lower()


def get(kind: str, id: str) -> PluginSpec:
    """Look a plugin up; an unknown id raises with the closest known ids."""
    load_builtin_plugins()
    table = _table(kind)
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
