"""Which detectors a scenario's bank runs, and what identifies a bank's design.

``[fdi] bank = "default"`` gives every aircraft the detectors ``docs/detectors.md`` finds working
on it (:data:`DEFAULT_BANKS`); ``[[detectors]]`` entries add any registered detector, built in or
a plugin (they replace a default member of the same id). The bank's design false-alarm rate is
split evenly over its members (:func:`member_far_per_h`, :func:`per_sample_target`: a union bound).
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from typing import Any

from fdi_sim import registry
from fdi_sim.errors import ScenarioError
from fdi_sim.scenario import Scenario
from fdi_sim.scenario.schema import FdiSection
from fdi_sim.units import S_PER_H

#: the detectors a new user gets, per aircraft (``docs/detectors.md``: the ones that work on it)
#: (the flow-angle check watches the vanes, which nothing else isolates; in turbulence its threshold,
#: set on the scenario's flights, is large and it only catches gross vane faults).
#: The DHC-6's adds the engine-gauge check (``engine-gauges-v1``), which names the engine of a
#: flameout or thrust loss (the gust filter calls a flameout nx_g and sees no thrust loss the autopilot
#: makes up for). It joined once it allowed for the model's torque limiter near its limit and stopped
#: testing Np (fdi_sim.detectors.engine_gauges: on the envelope development study, seed 15102, its
#: episodes went from 11 in 29.6 h to none in 29.8 h; on the hold-out study written for it, seed 15005
#: (tests/data/engine_gauges), none in 30.0 h, 95 % up to 0.124 per h: that bound is not yet below its
#: share of the bank's rate, 0.1 / 6 per h, which would take about 180 h without an episode).
_COMMON = ("kalman-gust-v1", "kinematic-attitude-v1", "kinematic-altitude-v1", "kinematic-airspeed-v1",
           "kinematic-flow-angles-v1")
DEFAULT_BANKS: dict[str, tuple[str, ...]] = {"f16": _COMMON, "DHC6": _COMMON + ("engine-gauges-v1",)}


#: keys of a [[detectors]] entry that are not design options
ENTRY_KEYS = ("type", "n_flights", "duration_s", "target")


@dataclass(frozen=True)
class MemberSpec:
    """One detector of a scenario's bank: id and design options."""

    id: str
    params: dict[str, Any]
    source: str  # "bank" or "detectors[i]"


def bank_members(sc: Scenario) -> list[MemberSpec]:
    """The detectors a scenario's bank runs (empty: no bank): any registered detector, built in or
    a plugin (``fdi-sim plugins``).

    Raises
    ------
    ScenarioError
        An id that is not registered (with a "did you mean"), or two entries of the same id.
    """
    from fdi_sim.errors import RegistryError

    out: list[MemberSpec] = []
    f = sc.model.fdi
    if f.bank != "none":
        out += [MemberSpec(i, {}, "bank") for i in DEFAULT_BANKS[sc.aircraft]]
    seen: dict[str, str] = {}
    for i, (tid, params) in enumerate(sc.detectors):
        key = f"detectors[{i}]"
        try:
            registry.get("detector", tid)
        except RegistryError as e:
            raise ScenarioError(sc.source, f"{key}.type", str(e), "`fdi-sim plugins` lists every registered detector "
                                "(an installed plugin package registers its own)") from None
        if tid in seen:
            raise ScenarioError(sc.source, f"{key}.type", f"{tid!r} is already {seen[tid]}: detector ids in a bank "
                                "must be unique", "remove one of the two entries")
        seen[tid] = key
        p = dict(params) if isinstance(params, dict) else dict(getattr(params, "model_dump", lambda: {})())
        p = {k: v for k, v in p.items() if k != "type"}
        spec = MemberSpec(tid, p, key)
        out = [m for m in out if m.id != tid] + [spec]  # an entry replaces the bank's detector of that id
    return out


def member_far_per_h(far_per_h: float, n_detectors: int) -> float:
    """``far_per_h / n_detectors``: each member's alarm episodes per flight hour that keep the bank's
    below ``far_per_h`` (a union bound) [1/h]."""
    return float(far_per_h) / max(1, n_detectors)


def per_sample_target(far_per_h: float, n_detectors: int, rate_hz: float) -> float:
    """``far_per_h / (n_detectors rate_hz 3600)``: each detector's per-sample exceedance probability
    that keeps the bank's alarm onsets below ``far_per_h`` per flight hour (union bound)."""
    return float(far_per_h) / (max(1, n_detectors) * float(rate_hz) * S_PER_H)


def default_member_far_per_h() -> dict[str, float]:
    """Per aircraft, the member target of its default bank at the default ``[fdi] far_per_h`` [1/h]:
    what the tail method must hold where the default banks use it (``docs/tail_coverage.md``)."""
    far = FdiSection.model_fields["far_per_h"].default
    return {ac: member_far_per_h(far, len(ids)) for ac, ids in DEFAULT_BANKS.items()}


def design_hash(bank: Any) -> str:
    """Hash of what the members' statistics depend on (not their thresholds): per member its id and
    its stream's ``design_key()``; and the bank's rate and measurement columns."""
    h = hashlib.sha256()
    h.update(json.dumps([bank.rate_hz, list(bank.meas_names)], default=str).encode())
    from fdi_sim.detectors.stream import stream_design_key

    for mem in bank.members:
        h.update(mem.id.encode())
        h.update(stream_design_key(mem.stream))
    return h.hexdigest()[:24]

