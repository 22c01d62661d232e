"""Scenario-level checks of the ``[[faults]]`` entries (called by the scenario loader).

Each fault's keys are validated by its parameter model; what needs the aircraft, the sensor
suite or the other faults is checked here, with errors that name the file, the key and the fix:

* the target exists on the aircraft (the error lists the ones it has) and fits the fault type;
* magnitudes are given in a unit of the target's dimension;
* **one fault per target at a time**: two faults on the same target must not overlap in time
  (their spans ``[t_start_s, t_end_s)``, the whole run when ``t_end_s`` is omitted). Composing
  two corruptions of one signal has no single order a user could rely on, and the logged error
  of each would be ambiguous; put compound failures on different targets, or one after the other;
* icing (target ``airframe``, so one icing fault at a time by the rule above): ``eta_final``
  within the range the coefficients were fitted for (refused above it:
  :func:`fdi_sim.aircraft.icing.eta_max`);
* the fault starts before the run ends.
"""
from __future__ import annotations

import math
from typing import Any

from fdi_sim.errors import ScenarioError
from fdi_sim.faults.quantities import allowed_units, target_unit, to_native


def targets(aircraft: str, sensor_names: tuple[str, ...]) -> dict[str, tuple[str, ...]]:
    """Fault targets of an aircraft by family."""
    from fdi_sim.aircraft.properties import ENGINE_COUNT, surfaces

    return {
        "actuator": tuple(surfaces(aircraft)) + ("throttle",),
        "engine": tuple(f"engine_{i}" for i in range(ENGINE_COUNT[aircraft])),
        "sensor": sensor_names,
        "airframe": ("airframe",),
    }


def check_faults(sc: Any) -> None:
    """Raise :class:`ScenarioError` for the first fault entry that cannot be flown."""
    if not sc.faults:
        return
    from fdi_sim.faults.catalogue import fault_def
    from fdi_sim.sensors import load_suite

    m = sc.model
    sensor_names = tuple(s.name for s in load_suite(m.aircraft, m.sensors.suite))
    tg = targets(m.aircraft, sensor_names)
    spans: dict[str, list[tuple[float, float, int]]] = {}
    for i, (tid, p) in enumerate(sc.faults):
        key = f"faults[{i}]"
        d = fault_def(tid, p)
        allowed = tg[d.family]
        if d.law == "float":
            allowed = tuple(a for a in allowed if a != "throttle")
        if p.target not in allowed:
            where = "its sensor suite has" if d.family == "sensor" else "it has"
            raise ScenarioError(sc.source, f"{key}.target", f"{m.aircraft} has no {d.family} target {p.target!r} for {tid}",
                                f"{where}: {', '.join(allowed)}")
        native = target_unit(d.family, p.target)
        for prefix, (_, is_rate) in type(p).MAGNITUDES.items():
            mag = p.magnitude(prefix)
            if mag is None or native is None:
                continue
            try:
                to_native(mag[0], mag[1], native, is_rate)
            except ValueError:
                raise ScenarioError(sc.source, f"{key}.{prefix}_{mag[1]}", f"unit {mag[1]!r} does not fit target {p.target!r}",
                                    f"write {' or '.join(f'{prefix}_{u}' for u in allowed_units(native, is_rate))}") from None
        if d.law == "runaway" and p.magnitude("rate")[0] == 0.0:
            raise ScenarioError(sc.source, f"{key}.rate", "a runaway needs a non-zero rate", "give a signed rate, e.g. rate_degps = -5")
        if d.law == "rate-limit" and p.magnitude("rate")[0] == 0.0:
            raise ScenarioError(sc.source, f"{key}.rate", "a zero rate limit is a stuck actuator", "use actuator-stuck-v1, or a rate > 0")
        if d.family == "airframe":
            from fdi_sim.aircraft import icing

            hi = icing.eta_max(m.aircraft)
            if p.eta_final > hi:
                raise ScenarioError(sc.source, f"{key}.eta_final", f"eta_final {p.eta_final} is beyond the range the "
                                    f"{m.aircraft} icing coefficients were fitted for (eta <= {hi})",
                                    f"use eta_final <= {hi}")
        if p.t_start_s >= m.duration_s:
            raise ScenarioError(sc.source, f"{key}.t_start_s", f"starts at {p.t_start_s} s, after the run ends ({m.duration_s} s)",
                                "start it earlier or lengthen duration_s")
        t1 = p.t_end_s if p.t_end_s is not None else math.inf
        for a, b, j in spans.get(p.target, []):
            if p.t_start_s < b and a < t1:
                raise ScenarioError(sc.source, f"{key}.t_start_s",
                                    f"overlaps faults[{j}] on the same target {p.target!r} ([{a}, {b}) s): one fault per target at a time",
                                    f"end faults[{j}] (t_end_s) before this one starts, or target another {d.family}")
        spans.setdefault(p.target, []).append((p.t_start_s, t1, i))
