"""Persistence (k-of-n): alarm when at least k of the last n per-sample tests fired.

With independent samples, each firing with probability ``p``, the count over a window of n is
Binomial(n, p), so the false-alarm probability of the k-of-n output *per sample* is exactly

    P_FA = P(Bin(n, p) >= k) = sum_{j=k}^{n} C(n, j) p^j (1 - p)^(n - j) = I_p(k, n - k + 1)

(``I`` the regularized incomplete beta function), and the per-sample ``p`` that gives a target
``P_FA`` is ``p = I^-1_{P_FA}(k, n - k + 1)`` (``scipy.stats.beta.ppf``). Consecutive outputs share
n - 1 samples and are correlated; outputs n samples apart are independent.
"""
from __future__ import annotations

import math

import numba
import numpy as np
from numpy.typing import NDArray
from scipy.stats import beta, binom, chi2

from fdi_sim.decision.base import Decision, DecisionTrace, check_positive, check_probability
from fdi_sim.decision.chi2 import chi2_threshold
from fdi_sim.errors import DesignError

__all__ = ["Persistence", "k_of_n", "k_of_n_step", "persistence_false_alarm", "persistence_sample_probability"]


@numba.njit(cache=True, nogil=True)
def k_of_n_step(fired, k, ring, state):  # pragma: no cover - compiled
    """The one k-of-n kernel: push one per-sample test result, return the alarm.

    ``count_j = count_{j-1} + a_j - a_{j-n}`` over a ring of the last ``n`` results (``ring``,
    int64 (n,), starts all 0: a reset window holds no firing); ``state[0]`` is the ring position,
    ``state[1]`` the count. The alarm is ``count_j >= k``. Called per sample by the bank's decision
    (:func:`fdi_sim.bank.kernels.decide`) and by :meth:`Persistence.step`; :func:`k_of_n` is its
    vectorised twin (a test checks the two against each other).
    """
    pos = state[0]
    state[1] += (1 if fired else 0) - ring[pos]
    ring[pos] = 1 if fired else 0
    state[0] = (pos + 1) % ring.shape[0]
    return state[1] >= k


def k_of_n(fired: NDArray[np.bool_], k: int, n: int) -> NDArray[np.bool_]:
    """:func:`k_of_n_step` over whole sequences, along the last axis, from an empty window:
    ``a_j = sum_{i=j-n+1..j} e_i >= k`` (``e_i = 0`` for ``i < 0``), the window sum as
    ``c_j - c_{j-n}`` of the cumulative sum ``c`` (exact: integers)."""
    k, n = _check_kn(k, n)
    c = np.cumsum(fired, axis=-1, dtype=np.int64)
    w = c.copy()
    w[..., n:] -= c[..., :-n]
    return w >= k


def _check_kn(k: int, n: int) -> tuple[int, int]:
    k, n = int(k), int(n)
    if not 1 <= k <= n:
        raise DesignError(f"persistence needs 1 <= k <= n, got k={k}, n={n}")
    return k, n


def persistence_false_alarm(p_sample: float, k: int, n: int) -> float:
    """False-alarm probability per sample of a k-of-n rule, ``P(Bin(n, p_sample) >= k)``.

    Parameters
    ----------
    p_sample : float
        False-alarm probability of the per-sample test, in (0, 1).
    k, n : int
        Alarm when at least ``k`` of the last ``n`` samples fired (1 <= k <= n).
    """
    k, n = _check_kn(k, n)
    return float(binom.sf(k - 1, n, check_probability(p_sample, "p_sample")))


def persistence_sample_probability(p_false_alarm: float, k: int, n: int) -> float:
    """The per-sample probability ``p`` with ``P(Bin(n, p) >= k) = p_false_alarm`` (exact inverse)."""
    k, n = _check_kn(k, n)
    # P(Bin(n, p) >= k) = I_p(k, n - k + 1), the Beta(k, n - k + 1) CDF at p
    return float(beta.ppf(check_probability(p_false_alarm, "p_false_alarm"), k, n - k + 1))


class Persistence:
    """k-of-n persistence on a chi-square statistic.

    Parameters
    ----------
    k, n : int
        Alarm when at least ``k`` of the last ``n`` samples exceed the per-sample threshold.
    dof : int
        Degrees of freedom of the input chi-square statistic.
    p_false_alarm : float
        Target false-alarm probability per sample of the k-of-n *output*, in (0, 1); the per-sample
        test gets ``p = persistence_sample_probability(p_false_alarm, k, n)``.
    sample_threshold : float, optional
        An explicit per-sample threshold instead (then ``p_false_alarm`` is recomputed from it).

    Notes
    -----
    The statistic is the count of firings in the window and the alarm is ``count >= k``
    (``threshold == k``). Until n samples have been seen the window holds fewer, so the early rate
    is lower than ``P_FA``. A non-finite input counts as a sample that did not fire.
    """

    id = "persistence-v1"
    hypotheses: tuple[str, ...] = ()

    def __init__(self, k: int, n: int, dof: int, p_false_alarm: float = 1e-3,
                 sample_threshold: float | None = None) -> None:
        self.k, self.n = _check_kn(k, n)
        self.dof = int(dof)
        if sample_threshold is None:
            self.p_false_alarm = check_probability(p_false_alarm, "p_false_alarm")
            self.p_sample = persistence_sample_probability(self.p_false_alarm, self.k, self.n)
            self.sample_threshold = chi2_threshold(self.dof, self.p_sample)
        else:
            self.sample_threshold = check_positive(sample_threshold, "sample_threshold")
            if self.dof < 1:
                raise DesignError(f"a chi-square test needs at least 1 degree of freedom, got {dof}")
            self.p_sample = float(chi2.sf(self.sample_threshold, self.dof))
            self.p_false_alarm = persistence_false_alarm(self.p_sample, self.k, self.n)
        self.threshold = float(self.k)
        self._ring = np.zeros(self.n, dtype=np.int64)
        self._state = np.zeros(2, dtype=np.int64)  # ring position, count
        self.reset()

    def reset(self, rng: np.random.Generator | None = None) -> None:
        """Empty the window."""
        self._ring[:] = 0
        self._state[:] = 0

    def step(self, t_s: float, statistic: float) -> Decision:
        """One chi-square value at time ``t_s`` [s]."""
        s = float(statistic)
        ok = math.isfinite(s)
        fired = ok and s > self.sample_threshold
        on = k_of_n_step(fired, self.k, self._ring, self._state)  # count_k = count_{k-1} + a_k - a_{k-n}
        return Decision(t_s, float(self._state[1]), self.threshold, ok and on, None, ok)

    def run(self, statistic: NDArray[np.float64]) -> DecisionTrace:
        """A whole trace (time on axis 0, any trailing shape)."""
        s = np.asarray(statistic, float)
        ok = np.isfinite(s)
        c = np.cumsum(s > self.sample_threshold, axis=0, dtype=np.int64)
        count = c.copy()
        count[self.n:] -= c[:-self.n]  # count_k = C_k - C_{k-n} (the count of k_of_n)
        return DecisionTrace(count.astype(float), (count >= self.k) & ok, self.threshold, None,
                             None if ok.all() else ok)
