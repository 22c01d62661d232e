"""Chi-square test on a normalized residual's statistic, threshold from a per-sample false-alarm target.

Under H0 a whitened residual ``r ~ N(0, I_dof)`` gives ``T = r'r ~ chi2(dof)``; the test alarms when
``T > h`` with ``P(chi2(dof) > h) = p`` (Hagenblad et al. eq. 13), so its false-alarm probability
per sample is exactly ``p``.
"""
from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy.stats import chi2

from fdi_sim.decision.base import Decision, DecisionTrace, check_positive, check_probability
from fdi_sim.errors import DesignError

__all__ = ["Chi2Test", "chi2_threshold"]


def chi2_threshold(dof: int, p_false_alarm: float) -> float:
    """Threshold h with ``P(chi2(dof) > h) = p_false_alarm`` (Hagenblad et al. eq. 13).

    Parameters
    ----------
    dof : int
        Degrees of freedom (residual dimension), at least 1.
    p_false_alarm : float
        False-alarm probability per test, in (0, 1).
    """
    p_false_alarm = check_probability(p_false_alarm, "p_false_alarm")
    if dof < 1:
        raise DesignError(f"a chi-square test needs at least 1 degree of freedom, got {dof}")
    return float(chi2.isf(p_false_alarm, dof))


class Chi2Test:
    """Alarm when a chi-square statistic exceeds ``h`` (``P(chi2(dof) > h) = p_false_alarm``).

    Parameters
    ----------
    dof : int
        Degrees of freedom of the statistic (the whitened residual's dimension).
    p_false_alarm : float
        False-alarm probability per sample, in (0, 1); used when ``threshold`` is not given.
    threshold : float, optional
        An explicit threshold on the statistic (then ``p_false_alarm`` is recomputed from it).

    Notes
    -----
    False-alarm probability per sample: ``p = P(chi2(dof) > h)``, exact for a whitened Gaussian
    residual. Samples of a white residual are independent, so the alarm count over N samples is
    Binomial(N, p).
    """

    id = "chi2-v1"
    hypotheses: tuple[str, ...] = ()

    def __init__(self, dof: int, p_false_alarm: float = 1e-3, threshold: float | None = None) -> None:
        self.dof = int(dof)
        if threshold is None:
            self.threshold = chi2_threshold(self.dof, p_false_alarm)
            self.p_false_alarm = check_probability(p_false_alarm, "p_false_alarm")
        else:
            if self.dof < 1:
                raise DesignError(f"a chi-square test needs at least 1 degree of freedom, got {dof}")
            self.threshold = check_positive(threshold, "threshold")
            self.p_false_alarm = float(chi2.sf(self.threshold, self.dof))

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Stateless: nothing to clear."""

    def step(self, t_s: float, statistic: float) -> Decision:
        """Test one statistic value at time ``t_s`` [s]; a non-finite value is invalid, no alarm."""
        s = float(statistic)
        if not math.isfinite(s):
            return Decision(t_s, s, self.threshold, False, None, False)
        return Decision(t_s, s, self.threshold, s > self.threshold)

    def run(self, statistic: NDArray[np.float64]) -> DecisionTrace:
        """Test a whole trace (any shape, time on axis 0)."""
        s = np.asarray(statistic, float)
        ok = np.isfinite(s)
        return DecisionTrace(s, s > self.threshold, self.threshold, None, None if ok.all() else ok)
