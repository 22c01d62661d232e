"""A detector to build: its registry id and design options, parsed, checked and built.

``ID[:key=value,...]`` on the command line (:func:`parse_detector_arg`), a ``[[detectors]]`` entry
in a scenario; :func:`build_detector` designs it from a model with the registry's factory and
refuses an option the factory does not take (with a "did you mean").
"""
from __future__ import annotations

import difflib
import inspect
import json
from dataclasses import dataclass, field
from typing import Any, Mapping, Sequence

from fdi_sim import registry
from fdi_sim.errors import ScenarioError
from fdi_sim.threads import single_blas_thread

@dataclass(frozen=True)
class DetectorSpec:
    """A detector to run: registry id and design options."""

    id: str
    params: Mapping[str, Any] = field(default_factory=dict)


def parse_detector_arg(text: str) -> DetectorSpec:
    """``ID[:key=value,...]``; values are JSON (numbers, true/false, lists, quoted strings) or bare words.

    Raises
    ------
    ScenarioError
        A malformed option.
    """
    ident, _, opts = text.partition(":")
    params: dict[str, Any] = {}
    if opts:
        for item in _split_options(opts):
            key, eq, raw = item.partition("=")
            if not eq or not key.strip():
                raise ScenarioError("--detector", text, f"option {item!r} is not key=value",
                                    "write ID:key=value,key2=value2")
            try:
                params[key.strip()] = json.loads(raw)
            except json.JSONDecodeError:
                params[key.strip()] = raw.strip()
    return DetectorSpec(ident.strip(), params)


def _split_options(opts: str) -> list[str]:
    """Split on commas outside brackets (``faults=["a","b"],alpha=0.01``)."""
    out, depth, cur = [], 0, ""
    for ch in opts:
        depth += ch in "[{"
        depth -= ch in "]}"
        if ch == "," and depth == 0:
            out.append(cur)
            cur = ""
        else:
            cur += ch
    return out + ([cur] if cur else [])


@single_blas_thread
def build_detector(spec: DetectorSpec, model: Any) -> Any:
    """Design one registered detector from ``model``; unknown options get a "did you mean"."""
    check_options(spec)
    return registry.get("detector", spec.id).factory(model, **dict(spec.params))


def check_options(spec: DetectorSpec, extra: Sequence[str] = ()) -> None:
    """Refuse an option the detector's factory does not take (with a "did you mean")."""
    plugin = registry.get("detector", spec.id)
    try:
        sig = inspect.signature(plugin.factory)
        known = [p for p in sig.parameters if p != "model"]
        has_var = any(p.kind == p.VAR_KEYWORD for p in sig.parameters.values())
    except (TypeError, ValueError):
        known, has_var = [], True
    known = [*known, *extra]
    for k in spec.params:
        if not has_var and k not in known:
            close = difflib.get_close_matches(k, known, n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            raise ScenarioError("--detector", f"{spec.id}:{k}", f"unknown option {k!r}{hint}",
                                f"options of {spec.id}: {', '.join(known)}")

