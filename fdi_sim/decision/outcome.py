"""Scoring alarms against injected faults: the first alarm after an onset, its delay, its isolation.

One rule for every consumer (the run summary, ``fdi-sim detect``, studies, review): a fault is
detected at the first alarm sample at or after its onset and before its window ends (plus
:data:`LATE_GRACE_S`); its isolation is the most frequent hypothesis in the
:data:`ISOLATION_WINDOW_S` after that first alarm, judged right when it names the fault's target
(a sensor by its signal name, an actuator by its command). Pure functions of arrays: below the
bank, so the review and the studies score without importing the loop.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np
from numpy.typing import NDArray

#: an alarm up to this long after a fault window ends still belongs to that fault [s]
LATE_GRACE_S = 2.0



@dataclass(frozen=True)
class FaultOutcome:
    """One injected fault as one detector saw it."""

    label: str
    target: str
    type: str
    t_onset_s: float
    first_alarm_s: float | None
    delay_s: float | None
    isolated_as: str | None
    isolation_correct: bool | None


#: the isolation a fault is reported with: the most frequent one in this time after the first alarm
ISOLATION_WINDOW_S = 1.0


def _matches(isolation: str | None, target: str) -> bool | None:
    """Whether an isolated hypothesis names the fault's target (None: nothing to compare).

    Hypotheses are signal names: a surface's command (``elevator_cmd_norm`` for ``elevator``), the
    engines' thrust through the throttle (``throttle_cmd_norm``: right for ``throttle`` and for any
    ``engine_<i>``, a hypothesis that cannot tell engines apart), one engine by its target name
    (``engine_0``: the engine-gauge check), a sensor by its name (an engine's gauge,
    ``torque_0_ftlb``, names a sensor fault, not the engine's). Icing (``airframe``) has no
    hypothesis in any bank: None.
    """
    if isolation is None or target in ("airframe", ""):
        return None
    if target.startswith("engine_"):
        return isolation in ("throttle_cmd_norm", target)
    if target == "throttle":
        return isolation == "throttle_cmd_norm" or isolation.startswith("engine_")
    return isolation == target or isolation.startswith(target + "_")


def not_monitored(hypotheses: Sequence[str], faults: Sequence[Mapping[str, Any]]) -> tuple[tuple[str, str], ...]:
    """The injected faults no hypothesis of a bank names (``(label, target)``): none of its members
    could isolate them right, so a miss is by design, not by chance (icing, ``airframe``: no bank
    has an icing hypothesis). A fault without a window (never active) is left out."""
    out = []
    for f in faults:
        target = str(f.get("target", ""))
        if f.get("windows_s") and not any(_matches(h, target) for h in hypotheses):
            out.append((str(f["label"]), target))
    return tuple(out)


def alarm_onsets(alarm: NDArray[np.bool_]) -> int:
    """Rising edges of an alarm sequence (an alarm at the first sample counts as one)."""
    a = np.asarray(alarm, dtype=bool)
    return int(np.count_nonzero(a[1:] & ~a[:-1]) + (int(a[0]) if len(a) else 0))


def first_alarm(t_s: NDArray[np.float64], alarm: NDArray[np.bool_], isolation: Sequence[str | None],
                t_onset_s: float) -> tuple[float | None, str | None]:
    """The first alarm at or after ``t_onset_s`` [s] and the isolation reported for it: the most
    frequent hypothesis in the :data:`ISOLATION_WINDOW_S` after it (None: none, or all rejected)."""
    idx = np.flatnonzero(alarm & (t_s >= t_onset_s))
    if not idx.size:
        return None, None
    t1 = float(t_s[idx[0]])
    named = [isolation[k] for k in idx if t_s[k] < t1 + ISOLATION_WINDOW_S and isolation[k] is not None]
    if not named:
        return t1, None
    # the most frequent; a tie goes to the one named first (max over a set would follow the
    # process's string-hash seed: the same log gave nx_g in one process, throttle in another)
    best = max(named.count(h) for h in named)
    return t1, next(h for h in named if named.count(h) == best)


def fault_outcome(f: Mapping[str, Any], t_s: NDArray[np.float64], alarm: NDArray[np.bool_],
                  isolation: Sequence[str | None]) -> FaultOutcome:
    """One injected fault (an entry of :func:`fault_windows`) against an alarm sequence."""
    t_on = float(f["windows_s"][0][0])
    t1, iso = first_alarm(t_s, alarm, isolation, t_on)
    target = f.get("target", "")
    return FaultOutcome(f["label"], target, f.get("type", ""), t_on, t1, None if t1 is None else t1 - t_on, iso,
                        _matches(iso, target))

