"""What every detector (residual generator + test) shares: the ``Residual`` record and the contract.

A detector is designed from a :class:`~fdi_sim.linear.model.LinearModel` (or a set of them),
then run with ``reset(rng)`` / ``step(t_s, u, y) -> Residual``. ``u`` and ``y`` are absolute
values in the model's input and output order; a detector built from a model subtracts the
model's trim values ``u0``/``y0`` itself.

Time convention (the one rule; measured and applied by :mod:`fdi_sim.detectors.samples`): the
log's row k holds y(t_k), read before JSBSim's step k, and the command u_k written before that
step. Detector sample j at rate R = f_sim / n pairs the command *averaged over the interval
ending at t_j* (rows (j-1)n .. jn-1) with the measurement y(t_j) (row jn); at n = 1 that is
(u_{k-1}, y_k). Every detector is designed from ``paired_model(model, f_sim)``, which puts a ZOH
model in the standard form x_{j+1} = A x_j + B u_j, y_j = C x_j + D u_j for these pairs, and is
fed ``samples_from_arrays`` / ``log_samples`` output: signals by name, trim subtracted, heading
wrapped, dropouts flagged invalid. No detector asks its user to pad or reorder columns.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray


@dataclass(frozen=True, eq=False)
class Residual:
    """One step of one detector.

    Attributes
    ----------
    t_s : float
        Time of the step [s].
    r : NDArray
        The residual vector (the detector's own units; normalized where the method normalizes).
    statistic : float
        The scalar test statistic (e.g. ``r' S^-1 r`` for a chi-square test).
    dof : int
        Degrees of freedom of the statistic (0 if not chi-square).
    threshold : float
        The alarm threshold on ``statistic``.
    alarm : bool
        ``statistic > threshold`` (after whatever the detector's own test logic is).
    isolation : str or None
        Name of the fault hypothesis the detector points at, or None (no alarm or rejected).
    scores : NDArray or None
        Per-hypothesis isolation scores (angles [rad], probabilities...), in ``hypotheses`` order.
    valid : bool
        False while the detector is still filling its window or converging, and whenever its
        residual or statistic is not finite (:func:`finite_or_invalid`): a NaN is never a valid
        "no alarm".
    """

    t_s: float
    r: NDArray[np.float64]
    statistic: float
    dof: int
    threshold: float
    alarm: bool
    isolation: str | None = None
    scores: NDArray[np.float64] | None = None
    valid: bool = True


def finite_or_invalid(res: Residual) -> Residual:
    """The same residual, marked invalid (``valid=False``, no alarm, no isolation) if its vector
    ``r`` or its ``statistic`` is not all finite; unchanged otherwise.

    A diverged filter gives NaN or inf, and ``nan > threshold`` is False: without this rule an
    overflow would read as a valid "no alarm". Every detector's ``step`` should return through
    it. ``scores`` are not checked (an angle to a zero direction is legitimately NaN); a detector
    whose scores come from a state that can diverge checks that state itself.
    """
    ok = bool(np.isfinite(res.statistic) and np.all(np.isfinite(res.r)))
    if ok:
        return res
    return replace(res, alarm=False, isolation=None, valid=False)


@runtime_checkable
class Detector(Protocol):
    """The contract of every registered detector."""

    #: versioned registry id, e.g. ``"parity-robust-v1"``
    id: str
    #: names of the fault hypotheses the detector can isolate (order of ``Residual.scores``)
    hypotheses: tuple[str, ...]

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Clear windows and filter states."""
        ...

    def step(self, t_s: float, u: NDArray[np.float64], y: NDArray[np.float64]) -> Residual:
        """Process one sample: time [s], inputs ``u``, measurements ``y`` (model order)."""
        ...
