"""The one contract for everything time-stepped (pilot, faults, sensors, detectors, decisions).

``reset(..., rng)`` prepares a run; ``step(t_s, ...)`` advances it by one step and returns an
immutable result (a frozen dataclass, or a named tuple where one is built every step). Argument
order is fixed: time first, then the command ``u``, then the measurement ``y``. Randomness
only through the ``numpy.random.Generator`` given to ``reset``.
"""
from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class TimeStepped(Protocol):
    """Anything advanced once per simulation step."""

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Return to the initial state; take all randomness from ``rng``."""
        ...

    def step(self, t_s: float, *args: Any) -> Any:
        """Advance to time ``t_s`` [s] and return an immutable result."""
        ...
