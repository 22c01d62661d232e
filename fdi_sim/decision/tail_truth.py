"""Synthetic statistics whose alarm-episode rate is known exactly, for validating a tail method
at the extrapolation it is used at.

The bank's statistics are persistent and correlated: a windowed mean of a residual, a chi-square
form. Their stand-in here is ``s = g(|x|)`` of a stationary Gaussian AR(1) sequence

    x[j] = rho x[j-1] + sqrt(1 - rho^2) e[j],   e[j] ~ N(0, 1),   rho = exp(-dt_s / tau_s),

with ``g`` increasing (``|x|``, ``x^2`` (chi-square(1)), or a transform to a Pareto-like upper
tail). Under the bank's k-of-n rule an alarm episode starts at sample ``j`` when at least ``k`` of
samples ``j-n+1 .. j`` exceed the threshold and fewer than ``k`` of ``j-n .. j-1`` did; with
``c`` the count among the ``n - 1`` samples the two windows share, that is exactly

    |x[j-n]| <= u,   c = k - 1,   |x[j]| > u,          (u = g^-1(threshold))

so the per-sample probability of an episode start is an ``n + 1``-sample path probability of the
Markov chain ``x``, computed here by propagating its density on a fine grid (a transfer operator)
while counting the samples above ``u``. Because ``g`` is increasing, every ``g`` has the same
episodes as ``|x|``: one exact rate curve serves them all. :func:`simulate_episode_rate` checks
the curve against brute-force simulation (``tests/decision/test_tail_truth.py``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from numpy.typing import NDArray
from scipy import sparse
from scipy.special import log_ndtr, ndtr

from fdi_sim.decision.tail import persistence_series
from fdi_sim.errors import DesignError

__all__ = ["Ar1Statistic", "TRANSFORMS", "ar1_flights", "episode_rate_curve", "simulate_episode_rate"]


def _abs(a: NDArray[np.float64]) -> NDArray[np.float64]:
    return a


def _square(a: NDArray[np.float64]) -> NDArray[np.float64]:
    return a * a


def _pareto(a: NDArray[np.float64], xi: float = 0.3) -> NDArray[np.float64]:
    """``((P(|X| > a))^-xi - 1) / xi``: a generalized-Pareto upper tail of shape ``xi`` (heavy)."""
    log_sf = math.log(2.0) + log_ndtr(-np.asarray(a, float))  # P(|X| > a) = 2 Phi(-a)
    return np.expm1(-xi * log_sf) / xi


#: increasing maps of ``a = |x|`` to the statistic, by name (what the statistic's tail looks like)
TRANSFORMS: dict[str, Callable[[NDArray[np.float64]], NDArray[np.float64]]] = {
    "gaussian |x|": _abs,
    "chi-square(1) x^2": _square,
    "heavy (GPD xi 0.3)": _pareto,
}


@dataclass(frozen=True)
class Ar1Statistic:
    """A stationary Gaussian AR(1) sequence sampled at ``rate_hz``, its statistic ``g(|x|)`` and the
    bank's ``k``-of-``n`` persistence.

    Attributes
    ----------
    tau_s : float
        Correlation time of ``x`` [s].
    rate_hz : float
        Sample rate [Hz].
    k, n : int
        Persistence: an alarm needs ``k`` of the last ``n`` samples above the threshold.
    transform : str
        A key of :data:`TRANSFORMS`.
    """

    tau_s: float = 10.0
    rate_hz: float = 20.0
    k: int = 3
    n: int = 5
    transform: str = "gaussian |x|"

    @property
    def rho(self) -> float:
        """One-sample correlation ``exp(-dt / tau)`` [-]."""
        return math.exp(-1.0 / (self.rate_hz * self.tau_s))

    def statistic(self, a: NDArray[np.float64]) -> NDArray[np.float64]:
        """The statistic of ``a = |x|``."""
        return TRANSFORMS[self.transform](np.asarray(a, float))

    def level(self, threshold: float) -> float:
        """``u = g^-1(threshold)`` on the ``|x|`` scale (bisection: ``g`` is increasing)."""
        lo, hi = 0.0, 40.0
        if not np.isfinite(threshold) or threshold >= float(self.statistic(np.array([hi]))[0]):
            return hi
        if threshold <= float(self.statistic(np.array([0.0]))[0]):
            return 0.0
        for _ in range(80):
            mid = 0.5 * (lo + hi)
            if float(self.statistic(np.array([mid]))[0]) < threshold:
                lo = mid
            else:
                hi = mid
        return 0.5 * (lo + hi)


def ar1_flights(stat: Ar1Statistic, n_flights: int, duration_s: float,
                rng: np.random.Generator) -> list[NDArray[np.float64]]:
    """``n_flights`` independent stationary flights of the statistic, each ``duration_s`` long,
    as the k-of-n :func:`~fdi_sim.decision.tail.persistence_series` the bank thresholds.

    Parameters
    ----------
    stat : Ar1Statistic
    n_flights : int
    duration_s : float
        [s]
    rng : numpy.random.Generator

    Returns
    -------
    list of NDArray
        One persistence series per flight.
    """
    from scipy.signal import lfilter

    m = int(round(duration_s * stat.rate_hz))
    rho = stat.rho
    e = rng.standard_normal((n_flights, m))
    e[:, 1:] *= math.sqrt(1.0 - rho * rho)  # x[0] ~ N(0, 1): stationary from the start
    x = lfilter([1.0], [1.0, -rho], e, axis=1)
    valid = np.ones(m, dtype=bool)
    return [persistence_series(stat.statistic(np.abs(row)), valid, stat.k, stat.n) for row in x]


@dataclass(frozen=True)
class EpisodeRateCurve:
    """Exact alarm episodes per hour of an :class:`Ar1Statistic` against the level ``u`` on the
    ``|x|`` scale (log-linear interpolation between the computed levels).

    Attributes
    ----------
    stat : Ar1Statistic
    u : NDArray
        Levels on the ``|x|`` scale [-], increasing.
    per_h : NDArray
        Episode starts per hour at each level [1/h].
    """

    stat: Ar1Statistic
    u: NDArray[np.float64]
    per_h: NDArray[np.float64]

    def rate_per_h(self, threshold: float) -> float:
        """Episodes per hour at ``threshold`` on the statistic's own scale [1/h]."""
        u = self.stat.level(threshold)
        lr = np.log(self.per_h)
        # past either end: the end segment's log-linear slope (log rate falls ever faster, about
        # -u^2/2, so beyond the last level this overstates the rate: a coverage check stays safe)
        if u > self.u[-1]:
            slope = (lr[-1] - lr[-2]) / (self.u[-1] - self.u[-2])
            return float(np.exp(lr[-1] + slope * (u - self.u[-1])))
        if u < self.u[0]:
            slope = (lr[1] - lr[0]) / (self.u[1] - self.u[0])
            return float(np.exp(lr[0] + slope * (u - self.u[0])))
        return float(np.exp(np.interp(u, self.u, lr)))

    def level_at(self, per_h: float) -> float:
        """The level ``u`` whose episode rate is ``per_h``, on the ``|x|`` scale."""
        lr = np.log(self.per_h)[::-1]  # increasing
        return float(np.interp(math.log(per_h), lr, self.u[::-1]))


def episode_rate_curve(stat: Ar1Statistic, u: NDArray[np.float64], h: float = 0.0025,
                       x_max: float = 9.0) -> EpisodeRateCurve:
    """The exact episode rate of ``stat`` at each level ``u`` (on the ``|x|`` scale).

    The chain's density is carried on bins of width ``h`` over ``[-x_max, x_max]`` (each bin's
    mass moves to the next bins with the Gaussian transition from its centre: the midpoint rule,
    error O(h^2); ``tests/decision/test_tail_truth.py`` halves ``h`` and compares). Levels are
    rounded to the bin edges.

    Parameters
    ----------
    stat : Ar1Statistic
    u : NDArray
        Levels [-] in (0, x_max - 1).
    h : float
        Bin width [-].
    x_max : float
        Grid half-width [-]: past it the stationary mass is below 1e-18.

    Returns
    -------
    EpisodeRateCurve
    """
    u = np.sort(np.asarray(u, float))
    if u.size == 0 or u[0] <= 0.0 or u[-1] >= x_max - 1.0:
        raise DesignError(f"levels must lie in (0, {x_max - 1.0}); got {u[:1]} .. {u[-1:]}")
    m = int(round(x_max / h))
    edges = np.arange(-m, m + 1) * h
    centre = 0.5 * (edges[:-1] + edges[1:])
    rho = stat.rho
    sd = math.sqrt(1.0 - rho * rho)
    # transition from the centre of bin i to bin j: Phi((e_{j+1} - rho c_i) / sd) - Phi((e_j - rho c_i) / sd),
    # kept within 12 sd (the rest is below 1e-32)
    band = int(math.ceil(12.0 * sd / h)) + 2
    rows, cols, vals = [], [], []
    for off in range(-band, band + 1):
        i = np.arange(centre.size)
        mean = rho * centre[i]
        j = np.floor((mean + 0.5 * h) / h).astype(np.int64) + m - 1 + off  # bins around the mean
        ok = (j >= 0) & (j < centre.size)
        i, j, mean = i[ok], j[ok], mean[ok]
        p = ndtr((edges[j + 1] - mean) / sd) - ndtr((edges[j] - mean) / sd)
        rows.append(i)
        cols.append(j)
        vals.append(p)
    K = sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(centre.size, centre.size))
    KT = K.T.tocsr()
    pi = ndtr(edges[1:]) - ndtr(edges[:-1])  # stationary N(0, 1) mass per bin
    k, n = stat.k, stat.n
    per_sample = np.empty(u.size)
    for q, level in enumerate(u):
        above = np.abs(centre) > np.round(level / h) * h
        v = np.zeros((k, centre.size))
        v[0] = np.where(above, 0.0, pi)  # x[j-n] at or below u
        for _ in range(n - 1):  # the shared samples j-n+1 .. j-1: count those above u, at most k - 1
            w = (KT @ v.T).T
            v = np.where(above, 0.0, w)
            v[1:] += np.where(above, w[:-1], 0.0)
        last = KT @ v[k - 1]
        per_sample[q] = float(last[above].sum())
    return EpisodeRateCurve(stat, u, per_sample * stat.rate_hz * 3600.0)


def simulate_episode_rate(stat: Ar1Statistic, levels: NDArray[np.float64], hours: float,
                          rng: np.random.Generator, flight_s: float = 3600.0) -> NDArray[np.float64]:
    """Episodes per hour at ``levels`` (on the ``|x|`` scale) counted on ``hours`` of simulated
    flights (a flight that starts above a level counts an episode there, as the bank does).

    Returns
    -------
    NDArray
        Episodes counted at each level (not yet divided by ``hours``).
    """
    counts = np.zeros(len(levels))
    n_flights = int(math.ceil(hours * 3600.0 / flight_s))
    g_levels = stat.statistic(np.asarray(levels, float))
    for f in range(n_flights):
        m = ar1_flights(stat, 1, flight_s, rng)[0]
        prev = np.concatenate([[-np.inf], m[:-1]])
        for i, g in enumerate(g_levels):
            counts[i] += np.count_nonzero((prev <= g) & (m > g))
    return counts
