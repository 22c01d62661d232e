"""The plugin catalogue: versioned ids, duplicates refused, unknown ids answered with a 'did you mean'."""
from __future__ import annotations

import pytest

from fdi_sim import registry
from fdi_sim.errors import RegistryError


@pytest.fixture
def scratch(monkeypatch: pytest.MonkeyPatch) -> None:
    """A copy of the loaded catalogue, so registrations here do not leak into other tests."""
    registry.load_builtin_plugins()
    monkeypatch.setattr(registry, "_REGISTRY", {k: dict(v) for k, v in registry._REGISTRY.items()})


def test_register_then_get(scratch: None) -> None:
    spec = registry.register("decision", "majority-vote-v1", "test rule", dict)
    assert registry.get("decision", "majority-vote-v1") is spec
    assert "majority-vote-v1" in registry.ids("decision") and spec in registry.all_plugins()


@pytest.mark.parametrize("kind,id,match", [
    ("maneuver", "doublet-v1", "already registered"),
    ("decision", "MajorityVote-v1", "lower case, versioned"),
    ("decision", "majority-vote", "lower case, versioned"),
    ("decision", "-v1", "lower case, versioned"),
    ("decisions", "majority-vote-v1", "kinds are maneuver, sensor, fault, detector, decision"),
])
def test_bad_registrations_raise(scratch: None, kind: str, id: str, match: str) -> None:
    with pytest.raises(RegistryError, match=match):
        registry.register(kind, id, "x", dict)


def test_unknown_ids_and_kinds(scratch: None) -> None:
    with pytest.raises(RegistryError) as ei:
        registry.get("maneuver", "dublet-v1")
    assert str(ei.value).startswith("unknown maneuver id 'dublet-v1'. Did you mean 'doublet-v1'")  # no KeyError quotes
    assert isinstance(ei.value, KeyError)
    for call in (lambda: registry.get("maneuvers", "doublet-v1"), lambda: registry.ids("maneuvers")):
        with pytest.raises(RegistryError, match="unknown plugin kind 'maneuvers'"):
            call()
