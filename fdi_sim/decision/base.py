"""What every decision rule shares: the ``Decision`` record, the ``DecisionTrace`` of a whole run, the contract.

A decision rule turns a detector's scalar statistic (or its residual vector) into an alarm and,
where it can, an isolation. Two ways to drive one, with the same arithmetic:

- ``reset(rng=None)`` then ``step(t_s, x) -> Decision``, one sample at a time (the loop);
- ``run(x) -> DecisionTrace`` over a whole trace (replay, Monte Carlo, the in-loop bank running
  many traces at once): array code, no Python object per sample. ``run`` always starts from the
  reset state and gives, sample for sample, what ``step`` gives after ``reset``.

A sample that is not finite (a diverged detector) is a *non-sample*: it yields ``valid=False``, no
alarm, and leaves the rule's state as it was (each rule says how).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from fdi_sim.errors import DesignError

__all__ = ["Decision", "DecisionRule", "DecisionTrace", "check_probability"]


@dataclass(frozen=True)
class Decision:
    """One sample of one decision rule.

    Attributes
    ----------
    t_s : float
        Time of the sample [s].
    statistic : float
        The rule's decision statistic after this sample (chi-square value, CUSUM ``g``, GLR, SPRT
        log-likelihood ratio, k-of-n count...).
    threshold : float
        The alarm threshold on ``statistic``.
    alarm : bool
        The rule's verdict at this sample.
    isolation : str or None
        The hypothesis isolated, or None (no alarm, a rule that does not isolate, or rejected).
    valid : bool
        False when the input sample was not finite (then ``alarm`` is False).
    """

    t_s: float
    statistic: float
    threshold: float
    alarm: bool
    isolation: str | None = None
    valid: bool = True


@dataclass(frozen=True, eq=False)
class DecisionTrace:
    """A rule run over a whole trace: arrays with time (samples) on axis 0.

    Attributes
    ----------
    statistic : NDArray
        (N,) or (N, m) decision statistic, same shape as the rule's scalar input.
    alarm : NDArray
        Boolean verdicts, same shape as ``statistic``.
    threshold : float
        The alarm threshold on ``statistic``.
    isolation : NDArray or None
        Integer index into the rule's ``hypotheses`` per sample, -1 for none or rejected; None
        for rules that do not isolate.
    valid : NDArray or None
        Boolean, False where the input was not finite; None when every sample was valid.
    """

    statistic: NDArray[np.float64]
    alarm: NDArray[np.bool_]
    threshold: float
    isolation: NDArray[np.intp] | None = None
    valid: NDArray[np.bool_] | None = None


@runtime_checkable
class DecisionRule(Protocol):
    """The contract of every registered decision rule."""

    #: versioned registry id, e.g. ``"cusum-v1"``
    id: str
    #: names of the hypotheses the rule can isolate (empty for detection-only rules)
    hypotheses: tuple[str, ...]
    #: the alarm threshold on the rule's statistic
    threshold: float

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Return to the initial state (no rule here draws random numbers; ``rng`` is accepted
        for the one contract)."""
        ...

    def step(self, t_s: float, x: float | NDArray[np.float64]) -> Decision:
        """Process one sample at time ``t_s`` [s]."""
        ...

    def run(self, x: NDArray[np.float64]) -> DecisionTrace:
        """Process a whole trace from the reset state (time on axis 0)."""
        ...


def check_probability(value: float, name: str) -> float:
    """``value`` as a float in the open interval (0, 1), else :class:`DesignError` naming ``name``."""
    v = float(value)
    if not 0.0 < v < 1.0:
        raise DesignError(f"{name} must be in (0, 1), got {value}")
    return v


def check_positive(value: float, name: str) -> float:
    """``value`` as a finite float > 0, else :class:`DesignError` naming ``name``."""
    v = float(value)
    if not (np.isfinite(v) and v > 0.0):
        raise DesignError(f"{name} must be a finite number > 0, got {value}")
    return v
